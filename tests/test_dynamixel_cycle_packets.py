"""The loop's per-cycle Dynamixel packets made once: the goals' Sync Write byte for byte as the
sdk builds it, and the Fast Sync Read reply (as the simulated servos encode it) received
from a real pty and checked whole."""

from __future__ import annotations

import os
import tty

import numpy as np
import pytest
from dynamixel_sdk import GroupSyncWrite, PacketHandler

from livezmp.links.dynamixel_cycle_packets import FastReply, GoalPacket
from sim_devices.dynamixel_packet import encode_fast_status, encode_packet

IDS = list(range(1, 21))
TICKS = np.arange(20, dtype="<i4") * 97 - 800
POSITION = np.dtype([("position", "<i4")])


class HeldPort:
    """Just enough of a port for the sdk to build a packet into ``sent``."""

    def __init__(self):
        self.sent = b""
        self.is_using = False

    def clearPort(self):
        pass

    def writePort(self, packet):
        self.sent += bytes(packet)
        return len(packet)


def sdk_sync_write(ticks: np.ndarray) -> bytes:
    port = HeldPort()
    writer = GroupSyncWrite(port, PacketHandler(2.0), 116, 4)
    for dxl_id, tick in zip(IDS, ticks, strict=True):
        writer.addParam(dxl_id, int(tick).to_bytes(4, "little", signed=True))
    writer.txPacket()
    return port.sent


def test_goal_packet_is_the_sdks_sync_write_then_the_trailer():
    packet = GoalPacket(IDS, 116, b"NEXT")
    for ticks in (TICKS, TICKS[::-1] * 3, np.zeros(20, dtype="<i4")):
        payload, size = packet.fill(ticks)
        assert bytes(payload) == sdk_sync_write(ticks) + b"NEXT"
        assert size == len(sdk_sync_write(ticks)) == 14 + 5 * 20


def test_goal_bytes_holding_the_header_pattern_are_stuffed():
    ticks = TICKS.copy()
    ticks[4] = -131073  # bytes FF FF FD FF: sent as FF FF FD FD FF
    payload, size = GoalPacket(IDS, 116, b"NEXT").fill(ticks)
    assert size == 14 + 5 * 20 + 1 and payload[size:] == b"NEXT"
    # what the simulated servos' codec (written from the e-manual) makes of the same sync write
    params = (116).to_bytes(2, "little") + (4).to_bytes(2, "little") + b"".join(
        bytes((i,)) + int(t).to_bytes(4, "little", signed=True) for i, t in zip(IDS, ticks, strict=True))
    assert bytes(payload[:size]) == encode_packet(0xFE, 0x83, params)


def reply(ticks=TICKS, errors=None, ids=IDS) -> bytes:
    errors = [0] * len(ids) if errors is None else errors
    return encode_fast_status([(e, i, int(t).to_bytes(4, "little", signed=True))
                               for e, i, t in zip(errors, ids, ticks, strict=True)])


@pytest.fixture
def pty_pair():
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(slave, False)
    yield master, slave
    os.close(master)
    os.close(slave)


def test_a_good_reply_is_read_into_the_records(pty_pair):
    master, slave = pty_pair
    fast = FastReply(IDS, POSITION)
    packet = reply()
    assert fast.size == len(packet) == 8 + 20 * 8
    for ticks in (TICKS, -TICKS):
        os.write(master, reply(ticks))
        assert fast.receive(slave, 1.0) == (None, len(packet))
        np.testing.assert_array_equal(fast.records["position"], ticks)
        np.testing.assert_array_equal(fast.records["id"], IDS)
        assert fast.alerted() == []


def test_a_reply_in_pieces_is_waited_for(pty_pair):
    master, slave = pty_pair
    fast = FastReply(IDS, POSITION)
    packet = reply()
    os.write(master, packet[:50])
    os.write(master, packet[50:])
    assert fast.receive(slave, 1.0)[0] is None


@pytest.mark.parametrize(("damage", "kind"), [
    (lambda p: p[:40] + bytes([p[40] ^ 0x10]) + p[41:], "bad_crc"),  # a data bit flipped
    (lambda p: b"\x00" + p[:-1], "bad_crc"),  # a stray byte before the header
    (lambda p: p[:-5], "short_reply"),
    (lambda p: b"", "no_reply"),
    (lambda p: reply(ids=IDS[::-1]), "short_reply"),  # another servo's segment where this one's belongs
    (lambda p: reply(errors=[0] * 7 + [0x04] + [0] * 12), "bad_reply"),  # a data range error
])
def test_a_damaged_reply_is_refused_and_named(pty_pair, damage, kind):
    master, slave = pty_pair
    fast = FastReply(IDS, POSITION)
    bad = damage(reply())
    if bad:
        os.write(master, bad)
    assert fast.receive(slave, 0.02) == (kind, min(len(bad), fast.size))


def test_the_alert_bit_names_its_servo_and_is_not_an_error(pty_pair):
    master, slave = pty_pair
    fast = FastReply(IDS, POSITION)
    os.write(master, reply(errors=[0] * 5 + [0x80] + [0] * 14))
    assert fast.receive(slave, 1.0)[0] is None
    assert fast.alerted() == [5]
