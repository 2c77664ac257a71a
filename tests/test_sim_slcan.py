"""The simulated slcan adapter: python-can's unmodified slcan interface, and the raw LAWICEL
command set over pyserial; echo and counter nodes behind it; injected faults."""

from __future__ import annotations

import contextlib
import os
import struct
import time

import can
import pytest
import serial
from sim_support import short_gil_switch, wait_until  # noqa: F401 - short_gil_switch is a fixture

from sim_devices.can_node import CanFrame, CounterNode, EchoNode
from sim_devices.slcan_adapter import SlcanAdapter, encode_frame, parse_frame

pytestmark = pytest.mark.usefixtures("short_gil_switch")


def open_bus(adapter: SlcanAdapter, bitrate: int = 1_000_000) -> can.BusABC:
    return can.Bus(interface="slcan", channel=adapter.path, bitrate=bitrate, sleep_after_open=0)


def receive(bus: can.BusABC, count: int, timeout: float = 2.0) -> list[can.Message]:
    messages = []
    deadline = time.monotonic() + timeout
    while len(messages) < count and time.monotonic() < deadline:
        message = bus.recv(timeout=0.05)
        if message is not None:
            messages.append(message)
    return messages


def drain(bus: can.BusABC, quiet: float = 0.25) -> list[can.Message]:
    """Receive until nothing arrives for ``quiet`` seconds."""
    messages = []
    while (message := bus.recv(timeout=quiet)) is not None:
        messages.append(message)
    return messages


class Raw:
    """A pyserial client speaking LAWICEL commands directly."""

    def __init__(self, path: str) -> None:
        self.port = serial.Serial(path, 115200, timeout=0.3)

    def __call__(self, command: str, reply_size: int) -> bytes:
        self.port.write(command.encode() + b"\r")
        reply = self.port.read(reply_size)
        self.port.timeout = 0.02  # replies are immediate: this only catches extra bytes
        reply += self.port.read(64)
        self.port.timeout = 0.3
        return reply

    def close(self) -> None:
        self.port.close()


# -- python-can ------------------------------------------------------------------------------------

def test_python_can_version_serial_and_echo():
    with SlcanAdapter([EchoNode(0x100, 0x101)]) as adapter:
        bus = open_bus(adapter)
        assert wait_until(lambda: adapter.is_open)
        assert bus.get_version(1.0) == (10, 13)
        assert bus.get_serial_number(1.0) == "SIM1"
        bus.send(can.Message(arbitration_id=0x100, data=[1, 2, 3], is_extended_id=False))
        (reply,) = receive(bus, 1)
        assert (reply.arbitration_id, bytes(reply.data), reply.is_extended_id) == (0x101, b"\x01\x02\x03", False)
        bus.send(can.Message(arbitration_id=0x102, data=[9], is_extended_id=False))  # nobody answers
        assert drain(bus) == []
        bus.shutdown()
        assert wait_until(lambda: not adapter.is_open)
        assert adapter.stats.frames_from_host == 2


def test_counter_node_frames_arrive_in_order():
    node = CounterNode(0x200, period=0.002)
    with SlcanAdapter([node]) as adapter:
        bus = open_bus(adapter)
        messages = receive(bus, 30)
        bus.shutdown()
    counts = [struct.unpack("<I", bytes(m.data))[0] for m in messages]
    assert counts == list(range(30))
    assert all(m.arbitration_id == 0x200 and m.dlc == 4 for m in messages)


def test_no_traffic_at_the_wrong_bitrate():
    with SlcanAdapter([EchoNode(0x100, 0x101)], bus_bitrate=500_000) as adapter:
        bus = open_bus(adapter, bitrate=1_000_000)
        bus.send(can.Message(arbitration_id=0x100, data=[1], is_extended_id=False))
        assert drain(bus) == []
        assert adapter.stats.frames_lost == 1
        bus.shutdown()
        bus = open_bus(adapter, bitrate=500_000)
        bus.send(can.Message(arbitration_id=0x100, data=[1], is_extended_id=False))
        assert len(receive(bus, 1)) == 1
        bus.shutdown()


# -- LAWICEL commands ------------------------------------------------------------------------------

def test_lawicel_command_set():
    with SlcanAdapter([EchoNode(0x100, 0x101)], serial_number="AB12") as adapter:
        raw = Raw(adapter.path)
        assert raw("V", 6) == b"V1013\r"
        assert raw("v", 6) == b"v1013\r"
        assert raw("N", 6) == b"NAB12\r"
        assert raw("", 1) == b"\r"
        assert raw("O", 1) == b"\a"  # no bitrate yet
        assert raw("S9", 1) == b"\a"
        assert raw("F", 1) == b"\a"  # channel closed
        assert raw("t1001AA", 1) == b"\a"  # channel closed
        assert raw("S8", 1) == b"\r"
        assert raw("Z1", 1) == b"\r"
        assert raw("O", 1) == b"\r"
        assert raw("S4", 1) == b"\a"  # channel open
        assert raw("Z0", 1) == b"\a"
        assert raw("F", 4) == b"F00\r"
        reply = raw("t1002AABB", 16)
        assert reply[:2] == b"z\r" and reply[2:11] == b"t1012AABB" and reply[-1:] == b"\r"
        int(reply[11:15], 16)  # 4 hex digits of timestamp
        assert len(reply) == 16
        assert raw("T000001002AABB", 2) == b"Z\r"  # extended frame: acknowledged, nobody answers
        assert raw("r1000", 2) == b"z\r"
        assert raw("t1003AABB", 1) == b"\a"  # dlc 3 with 2 data bytes
        assert raw("t10", 1) == b"\a"
        assert raw("X", 1) == b"\a"
        assert raw("C", 1) == b"\r"
        assert raw("L", 1) == b"\r"  # listen only: may not send
        assert raw("t1001AA", 1) == b"\a"
        raw.close()


def test_timestamps_count_milliseconds_since_open():
    with SlcanAdapter([CounterNode(0x7FF, period=0.01)]) as adapter:
        raw = Raw(adapter.path)
        raw("S8", 1)
        raw("Z1", 1)
        raw.port.write(b"O\r")
        start = time.monotonic()
        assert raw.port.read(1) == b"\r"
        lines = [raw.port.read_until(b"\r") for _ in range(10)]
        elapsed_ms = (time.monotonic() - start) * 1000
        raw.close()
    stamps = [int(line[13:17], 16) for line in lines]  # after t, 3 id digits, dlc and 4 data bytes
    assert all(line.startswith(b"t7FF4") and len(line) == 18 for line in lines)
    assert stamps == sorted(stamps)
    assert stamps[-1] - stamps[0] >= 9 * 10 - 2  # 10 frames, 10 ms apart
    assert stamps[-1] <= elapsed_ms + 1


def test_frame_codec_round_trip():
    for frame in (CanFrame(0x123, b"\x01\x02"), CanFrame(0x1ABCDEF0, b"", is_extended=True),
                  CanFrame(0x7FF, is_remote=True, dlc=8), CanFrame(0x5, bytes(range(8)))):
        line = encode_frame(frame)
        assert parse_frame(line[:-1].decode()) == frame
    with pytest.raises(ValueError, match="arbitration_id 0x800 exceeds 0x7ff"):
        CanFrame(0x800)


# -- faults ----------------------------------------------------------------------------------------

def test_dropped_and_corrupted_frames_match_the_counters():
    with SlcanAdapter([EchoNode(0x100, 0x101)], faults="drop=0.1,corrupt=0.1,seed=7") as adapter:
        bus = open_bus(adapter)
        for i in range(200):  # the number twice: one changed byte makes the halves differ
            bus.send(can.Message(arbitration_id=0x100, data=struct.pack("<HH", i, i), is_extended_id=False))
        received = [bytes(m.data) for m in drain(bus)]
        bus.shutdown()
        counters = adapter.fault_counters
    assert len(received) == 200 - counters.dropped
    assert sum(data[:2] != data[2:] for data in received) == counters.corrupted
    assert counters.dropped > 0 and counters.corrupted > 0


def test_bus_off_episode():
    with SlcanAdapter([EchoNode(0x100, 0x101)], faults="busoff=0.2s+0.3s") as adapter:
        raw = Raw(adapter.path)
        raw("S8", 1)
        raw("O", 1)
        assert raw("t1001AA", 10) == b"z\rt1011AA\r"
        assert wait_until(lambda: raw("F", 4) == b"FA0\r")  # bus error + error passive
        assert raw("t1001AA", 1) == b"\a"
        assert wait_until(lambda: raw("t1001AA", 10) == b"z\rt1011AA\r")
        assert adapter.fault_counters.bus_offs == 1
        raw.close()


def test_adapter_vanishes_and_comes_back_power_cycled():
    with SlcanAdapter([EchoNode(0x100, 0x101)], faults="vanish=0.2s+0.3s") as adapter:
        bus = open_bus(adapter)
        assert wait_until(lambda: not os.path.exists(adapter.path))
        with pytest.raises(can.CanError):
            bus.send(can.Message(arbitration_id=0x100, data=[1], is_extended_id=False))
        with contextlib.suppress(can.CanError):
            bus.shutdown()
        assert wait_until(lambda: os.path.exists(adapter.path))
        assert not adapter.is_open
        bus = open_bus(adapter)
        bus.send(can.Message(arbitration_id=0x100, data=[7], is_extended_id=False))
        assert [bytes(m.data) for m in receive(bus, 1)] == [b"\x07"]
        bus.shutdown()
        assert adapter.fault_counters.vanishes == 1


def test_delayed_frames_arrive_late_but_intact():
    with SlcanAdapter([EchoNode(0x100, 0x101)], faults="delay=1:30ms") as adapter:
        raw = Raw(adapter.path)
        raw("S8", 1)
        raw("O", 1)
        raw.port.write(b"t1001AA\r")
        start = time.monotonic()
        assert raw.port.read(2) == b"z\r"  # the acknowledgement is not a frame: not delayed
        assert raw.port.read(9) == b"t1011AA\r"
        assert time.monotonic() - start >= 0.03
        assert adapter.fault_counters.delayed == 1
        raw.close()
