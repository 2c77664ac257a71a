"""The simulated socketcand daemon, through python-can's unmodified socketcand interface."""

from __future__ import annotations

import time

import can
import numpy as np
import pytest
from sim_support import short_gil_switch  # noqa: F401 - fixture

from livezmp.links.can_timing import frame_bits
from sim_devices.can_node import CounterNode, EchoNode
from sim_devices.socketcand_server import SocketcandServer

pytestmark = pytest.mark.usefixtures("short_gil_switch")


def open_bus(server: SocketcandServer) -> can.BusABC:
    return can.Bus(interface="socketcand", channel="can0", host="127.0.0.1", port=server.port, tcp_tune=True)


def test_frames_go_both_ways_with_their_ids_and_data():
    with SocketcandServer([EchoNode(0x123, 0x321)]) as server:
        bus = open_bus(server)
        try:
            bus.send(can.Message(arbitration_id=0x123, data=b"\x01\x02\xfe", is_extended_id=False))
            reply = bus.recv(timeout=2.0)
        finally:
            bus.shutdown()
    assert reply.arbitration_id == 0x321 and not reply.is_extended_id and bytes(reply.data) == b"\x01\x02\xfe"
    assert server.frames_from_host == 1 and server.frames_to_host == 1


def test_an_exchange_takes_the_frames_time_on_the_bus():
    # at 10 kbit/s a standard frame with 8 data bytes holds the bus 47 + 64 = 111 bits and its stuff bits: the
    # request and the echo are about 23 ms, far above the ~0.2 ms the client and server take in Python
    with SocketcandServer([EchoNode(0x10, 0x11)], bitrate=10_000) as server:
        bus = open_bus(server)
        took = []
        try:
            for k in range(5):
                start = time.perf_counter()
                bus.send(can.Message(arbitration_id=0x10, data=bytes(range(k, k + 8)), is_extended_id=False))
                assert bus.recv(timeout=2.0) is not None
                took.append(time.perf_counter() - start)
        finally:
            bus.shutdown()
    bits = [frame_bits(0x10, bytes(range(k, k + 8))) + frame_bits(0x11, bytes(range(k, k + 8))) for k in range(5)]
    assert 2 * 111 < min(bits)  # these frames are stuffed
    assert float(np.median(took)) == pytest.approx(float(np.median(bits)) / 10_000, rel=0.1)


def test_a_busy_bus_delivers_only_what_its_bitrate_carries():
    # 10 nodes each sending a standard frame of 4 data bytes (47 + 32 = 79 bits and their stuff bits) every 1 ms
    # want over 790 kbit/s; a 250 kbit/s bus carries about 2 900 frames/s of them (small counts: many zeros,
    # many stuff bits), and the rest are lost in the nodes' transmit queues
    with SocketcandServer([CounterNode(0x100 + k, 1e-3) for k in range(10)], bitrate=250_000) as server:
        bus = open_bus(server)
        try:
            assert bus.recv(timeout=2.0) is not None
            start, count = time.perf_counter(), 0
            while time.perf_counter() - start < 1.0:
                count += bus.recv(timeout=0.1) is not None
            elapsed = time.perf_counter() - start
        finally:
            bus.shutdown()
    mean_bits = float(np.mean([frame_bits(0x100, k.to_bytes(4, "little")) for k in range(300)]))
    assert count / elapsed == pytest.approx(250_000 / mean_bits, rel=0.15)
    assert server.frames_lost > 0
