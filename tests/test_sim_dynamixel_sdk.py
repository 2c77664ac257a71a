"""The unmodified dynamixel-sdk client against the simulated chain on a real pty."""

from __future__ import annotations

import contextlib
import math
import os
import time

import numpy as np
import pytest
import serial
from dynamixel_sdk import (
    BROADCAST_ID,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    DXL_HIBYTE,
    DXL_HIWORD,
    DXL_LOBYTE,
    DXL_LOWORD,
    GroupBulkRead,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)
from sim_support import sdk_latency_timer, short_gil_switch, wait_until  # noqa: F401 - fixtures

from livezmp.links.bus_timing import sync_read_bytes, wire_time
from livezmp.links.dynamixel import WaitingPortHandler
from sim_devices.dynamixel_chain import DynamixelChain
from sim_devices.dynamixel_packet import encode_packet
from sim_devices.servo_plant import ServoPlant

pytestmark = pytest.mark.usefixtures("short_gil_switch", "sdk_latency_timer")

IDS = list(range(1, 21))
PRESENT_POSITION, GOAL_POSITION, TORQUE_ENABLE = 132, 116, 64


def le32(value: int) -> list[int]:
    return [DXL_LOBYTE(DXL_LOWORD(value)), DXL_HIBYTE(DXL_LOWORD(value)),
            DXL_LOBYTE(DXL_HIWORD(value)), DXL_HIBYTE(DXL_HIWORD(value))]


@pytest.fixture
def rig():
    """20 servos (ids 1..20) at distinct positions 0, 0.05, ... rad; return delay 0; an open client. The
    bytes take their wire time, but no USB adapter adds its latency: the protocol is what is tested here."""
    plant = ServoPlant(len(IDS), position=np.arange(len(IDS)) * 0.05)
    chain = DynamixelChain(IDS, plant, settings={"return_delay_time": 0}, adapter="none")
    port = PortHandler(chain.path)
    assert port.openPort()
    yield chain, port, PacketHandler(2.0)
    port.closePort()
    chain.close()


def expected_ticks(rad: float) -> int:
    return round(2048 + rad * 4096 / (2 * math.pi))


def sync_write(port, ph, address, size, values: dict[int, int]) -> int:
    group = GroupSyncWrite(port, ph, address, size)
    for dxl_id, value in values.items():
        assert group.addParam(dxl_id, le32(value)[:size])
    return group.txPacket()


def test_ping_unicast_and_broadcast(rig):
    chain, port, ph = rig
    assert ph.ping(port, 7) == (1020, COMM_SUCCESS, 0)
    assert ph.ping(port, 42)[1] == COMM_RX_TIMEOUT  # nobody has id 42
    found, result = ph.broadcastPing(port)
    assert result == COMM_SUCCESS
    assert found == {dxl_id: [1020, 46] for dxl_id in IDS}


def test_read_and_write_each_width(rig):
    chain, port, ph = rig
    assert ph.write1ByteTxRx(port, 3, 65, 1) == (COMM_SUCCESS, 0)  # LED
    assert ph.read1ByteTxRx(port, 3, 65) == (1, COMM_SUCCESS, 0)
    assert ph.write2ByteTxRx(port, 3, 84, 1234) == (COMM_SUCCESS, 0)  # Position P Gain
    assert ph.read2ByteTxRx(port, 3, 84) == (1234, COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 3, 112, 30000) == (COMM_SUCCESS, 0)  # Profile Velocity
    assert ph.read4ByteTxRx(port, 3, 112) == (30000, COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 3, 20, -1000 & 0xFFFFFFFF) == (COMM_SUCCESS, 0)  # Homing Offset
    assert chain.register(3, "homing_offset") == -1000
    assert ph.read4ByteTxRx(port, 3, PRESENT_POSITION)[0] == expected_ticks(0.1) - 1000
    assert chain.register(4, "led") == 0  # only servo 3 was written


def test_sync_write_and_sync_read_over_20_servos(rig):
    chain, port, ph = rig
    assert sync_write(port, ph, TORQUE_ENABLE, 1, dict.fromkeys(IDS, 1)) == COMM_SUCCESS
    goals = {dxl_id: 1000 + 100 * dxl_id for dxl_id in IDS}
    assert sync_write(port, ph, GOAL_POSITION, 4, goals) == COMM_SUCCESS
    reader = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
    for dxl_id in IDS:
        assert reader.addParam(dxl_id)

    def arrived() -> bool:
        assert reader.txRxPacket() == COMM_SUCCESS
        return all(abs(reader.getData(i, PRESENT_POSITION, 4) - goals[i]) <= 1 for i in IDS)

    assert wait_until(arrived, timeout=5.0)
    moving = GroupSyncRead(port, ph, 122, 1)
    for dxl_id in IDS:
        moving.addParam(dxl_id)
    assert moving.txRxPacket() == COMM_SUCCESS
    assert [moving.getData(i, 122, 1) for i in IDS] == [0] * len(IDS)


def test_bulk_read_mixed_items(rig):
    chain, port, ph = rig
    chain.set_register(3, "present_input_voltage", 118)
    bulk = GroupBulkRead(port, ph)
    items = {1: (PRESENT_POSITION, 4), 2: (146, 1), 3: (144, 2), 4: (0, 2)}
    for dxl_id, (address, size) in items.items():
        assert bulk.addParam(dxl_id, address, size)
    assert bulk.txRxPacket() == COMM_SUCCESS
    values = [bulk.getData(i, a, n) for i, (a, n) in items.items()]
    assert values == [expected_ticks(0.0), 36, 118, 1020]
    assert bulk.fastBulkRead() == COMM_SUCCESS
    assert [bulk.getData(i, a, n) for i, (a, n) in items.items()] == values


def test_fast_sync_read_matches_sync_read_and_plant(rig):
    chain, port, ph = rig
    reader = GroupSyncRead(port, ph, 126, 10)  # present current, velocity, position
    for dxl_id in IDS:
        reader.addParam(dxl_id)
    expected = [expected_ticks(0.05 * i) for i in range(len(IDS))]
    assert reader.txRxPacket() == COMM_SUCCESS
    slow = [reader.getData(i, PRESENT_POSITION, 4) for i in IDS]
    assert reader.fastSyncRead() == COMM_SUCCESS
    assert [reader.getData(i, PRESENT_POSITION, 4) for i in IDS] == slow == expected


def test_reg_write_then_broadcast_action(rig):
    chain, port, ph = rig
    for dxl_id in (1, 2, 3):
        assert ph.regWriteTxRx(port, dxl_id, 65, 1, [1]) == (COMM_SUCCESS, 0)
    assert [chain.register(i, "led") for i in (1, 2, 3)] == [0, 0, 0]
    assert ph.action(port, BROADCAST_ID) == COMM_SUCCESS
    assert wait_until(lambda: [chain.register(i, "led") for i in (1, 2, 3)] == [1, 1, 1], timeout=1.0)


def test_torque_on_holds_position_then_follows_goal(rig):
    chain, port, ph = rig
    start = ph.read4ByteTxRx(port, 5, PRESENT_POSITION)[0]
    assert ph.write1ByteTxRx(port, 5, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    assert ph.read4ByteTxRx(port, 5, GOAL_POSITION)[0] == start  # goal starts at the present position
    assert ph.write4ByteTxRx(port, 5, GOAL_POSITION, start + 300) == (COMM_SUCCESS, 0)
    assert wait_until(lambda: abs(ph.read4ByteTxRx(port, 5, PRESENT_POSITION)[0] - start - 300) <= 1)


def test_write_errors_reach_the_client(rig):
    chain, port, ph = rig
    assert ph.write4ByteTxRx(port, 1, GOAL_POSITION, 5000) == (COMM_SUCCESS, 6)  # beyond Max Position Limit
    assert ph.write1ByteTxRx(port, 1, 11, 2) == (COMM_SUCCESS, 4)  # operating mode 2 does not exist
    # Past the end of the table: access error and no data (the SDK hands back the CRC bytes as "data").
    assert ph.readTxRx(port, 1, 147, 2)[1:] == (COMM_SUCCESS, 7)


def test_bus_watchdog_stops_the_servo_and_refuses_goals_until_cleared(rig):
    chain, port, ph = rig
    assert ph.write1ByteTxRx(port, 1, TORQUE_ENABLE, 1) == (COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, 98, 5) == (COMM_SUCCESS, 0)  # 5 x 20 ms
    start = ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[0]
    end = time.monotonic() + 0.15
    while time.monotonic() < end:  # talking (for 150 ms, longer than the 100 ms watchdog) keeps it fed
        assert ph.read1ByteTxRx(port, 1, 98) == (5, COMM_SUCCESS, 0)
    assert ph.write4ByteTxRx(port, 1, GOAL_POSITION, start + 2000) == (COMM_SUCCESS, 0)
    # silence on the bus (the simulator's registers are read directly): the watchdog fires mid-move
    assert wait_until(lambda: chain.register(1, "bus_watchdog") == -1, timeout=2.0)
    assert ph.read1ByteTxRx(port, 1, 98) == (0xFF, COMM_SUCCESS, 0)  # -1: Bus Watchdog Error
    assert ph.write4ByteTxRx(port, 1, GOAL_POSITION, start) == (COMM_SUCCESS, 4)  # goals read-only
    assert wait_until(lambda: chain.register(1, "present_velocity") == 0, timeout=2.0)  # braked to a standstill
    stopped = ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[0]
    assert start + 100 < stopped < start + 1500  # stopped on the way, well short of the goal
    # and stays there
    assert not wait_until(lambda: abs(ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[0] - stopped) > 1, timeout=0.05)
    assert ph.write1ByteTxRx(port, 1, 98, 0) == (COMM_SUCCESS, 0)  # clears the error
    assert ph.write4ByteTxRx(port, 1, GOAL_POSITION, start) == (COMM_SUCCESS, 0)
    assert wait_until(lambda: abs(ph.read4ByteTxRx(port, 1, PRESENT_POSITION)[0] - start) <= 1)


def test_return_delay_time_is_honoured_in_sync_read(rig):
    chain, port, ph = rig
    reader = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
    for dxl_id in IDS:
        reader.addParam(dxl_id)

    def fastest_sync_read() -> float:
        best = math.inf
        for _ in range(5):
            start = time.perf_counter()
            assert reader.txRxPacket() == COMM_SUCCESS
            best = min(best, time.perf_counter() - start)
        return best

    without = fastest_sync_read()
    assert sync_write(port, ph, 9, 1, dict.fromkeys(IDS, 254)) == COMM_SUCCESS  # 508 us each
    with_delay = fastest_sync_read()
    # The bytes alone (1 Mbps, no adapter) take their wire time; each servo then answers 508 us after the
    # previous one, so the read cannot take less than the wire time + 10.16 ms. Against the model, not the
    # read without delays: that one's time grows with the machine's load, the model's does not.
    instruction, reply = sync_read_bytes(len(IDS), 4, fast=False)
    wire = wire_time(instruction + reply, 1_000_000)
    assert without >= wire
    assert with_delay >= wire + 20 * 508e-6


def test_byte_stuffed_values_round_trip_through_the_sdk(rig):
    chain, port, ph = rig
    value = -131073 & 0xFFFFFFFF  # bytes FF FF FD FF
    assert ph.write4ByteTxRx(port, 2, 20, value) == (COMM_SUCCESS, 0)
    assert chain.register(2, "homing_offset") == -131073
    assert ph.read4ByteTxRx(port, 2, 20) == (value, COMM_SUCCESS, 0)


def test_baud_rate_mismatch_means_silence():
    with DynamixelChain([1], baud_rate=57600) as chain:
        port = PortHandler(chain.path)
        assert port.openPort()  # dynamixel-sdk opens at 1 Mbps
        assert ph_ping(port, 1)[1] == COMM_RX_TIMEOUT
        assert chain.stats.unheard == 1
        assert port.setBaudRate(57600)
        assert ph_ping(port, 1) == (1020, COMM_SUCCESS, 0)
        port.closePort()


def ph_ping(port, dxl_id):
    return PacketHandler(2.0).ping(port, dxl_id)


def timed_sync_reads(chain, baud: int, fast: bool, n: int = 7) -> float:
    """Median seconds of ``n`` (Fast) Sync Reads of the 20 Present Positions, each after a Sync Write of
    20 goals (the loop's cycle), measured by the sdk client (with the link's port handler, which waits for
    bytes instead of spinning: a spinning client holds the GIL the simulator's thread needs to reply)."""
    port = WaitingPortHandler(chain.path)
    assert port.openPort() and port.setBaudRate(baud)
    ph = PacketHandler(2.0)
    reader = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
    for dxl_id in IDS:
        reader.addParam(dxl_id)
    took = []
    for _ in range(n):
        start = time.perf_counter()
        assert sync_write(port, ph, GOAL_POSITION, 4, dict.fromkeys(IDS, 2048)) == COMM_SUCCESS  # no reply
        assert (reader.fastSyncRead() if fast else reader.txRxPacket()) == COMM_SUCCESS
        took.append(time.perf_counter() - start)
    port.closePort()
    return float(np.median(took))


@pytest.mark.parametrize(("baud", "fast", "delay_units", "adapter", "expected"), [
    # Sync Write of 20 goals: 14 + 20 x 5 = 114 bytes; Sync Read instruction 14 + 20 = 34 bytes;
    # replies 20 x (11 + 4) = 300 bytes, or one Fast Sync Read reply of 8 + 20 x (4 + 4) = 168 bytes.
    # 10 bits a byte; a full-speed FTDI adapter adds 0.5 ms out and 1 ms back per transaction. At these
    # rates the client's and simulator's own ~0.2 ms of Python per exchange stays inside the 10 %.
    (115200, False, 0, "none", (114 + 34 + 300) * 10 / 115200),
    (115200, True, 0, "none", (114 + 34 + 168) * 10 / 115200),
    (115200, False, 250, "none", (114 + 34 + 300) * 10 / 115200 + 20 * 500e-6),  # factory 500 us per servo
    (115200, False, 0, "ftdi-fs", (114 + 34 + 300) * 10 / 115200 + 0.5e-3 + 1e-3),
    (57600, True, 0, "hs", (114 + 34 + 168) * 10 / 57600 + 62.5e-6 + 125e-6),
])
def test_a_packet_exchange_takes_the_time_its_packet_sizes_predict(baud, fast, delay_units, adapter, expected):
    with DynamixelChain(IDS, baud_rate=baud, adapter=adapter, settings={"return_delay_time": delay_units}) as chain:
        measured = timed_sync_reads(chain, baud, fast)
    assert measured == pytest.approx(expected, rel=0.10)


def test_changing_the_id_register_readdresses_the_servo(rig):
    chain, port, ph = rig
    assert ph.read1ByteTxRx(port, 20, 7) == (20, COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 20, 7, 30) == (COMM_SUCCESS, 0)
    assert ph.ping(port, 30) == (1020, COMM_SUCCESS, 0)
    assert ph.ping(port, 20)[1] == COMM_RX_TIMEOUT


@pytest.mark.parametrize(("kwargs", "error", "message"), [
    ({"ids": [1, 1]}, ValueError, "ids must be distinct integers in 0..252"),
    ({"ids": [1], "baud_rate": 12345}, ValueError, "baud_rate 12345 is not an XM430 rate"),
    ({"ids": [1], "settings": {"return_dalay_time": 0}}, KeyError, "no control-table field 'return_dalay_time'"),
    ({"ids": [1], "settings": {"led": 300}}, ValueError, "field 'led': value 300 does not fit 1 byte"),
    ({"ids": [1, 2], "plant": ServoPlant(1)}, ValueError, "plant has 1 joints for 2 servos"),
])
def test_construction_errors_name_the_problem(kwargs, error, message):
    with pytest.raises(error, match=message):
        DynamixelChain(**kwargs)


def spun_exchanges(chain, n: int = 40) -> np.ndarray:
    """Seconds from writing a Fast Sync Read of the 20 positions (4 Mbps) until all its reply was read, for
    ``n`` reads; the client polls without sleeping, so it has the bytes the moment the pty does."""
    instruction = encode_packet(BROADCAST_ID, 0x8A, (PRESENT_POSITION).to_bytes(2, "little") + (4).to_bytes(2, "little")
                                + bytes(IDS))
    size = sync_read_bytes(len(IDS), 4, fast=True)[1]
    took = []
    with serial.Serial(chain.path, 4_000_000) as client:
        for _ in range(n):
            got = 0
            start = time.monotonic()
            os.write(client.fd, instruction)
            while got < size and time.monotonic() - start < 0.1:
                with contextlib.suppress(BlockingIOError):
                    got += len(os.read(client.fd, size - got))
            took.append(time.monotonic() - start)
            assert got == size
    return np.array(took)


def test_a_reply_never_reaches_even_a_polling_client_before_the_bus_model_says():
    """At 4 Mbps the host's own hand-offs are a good part of an exchange: however quickly the client takes the
    reply in, it never has it before the wire time and the adapter's latency have passed."""
    instruction, reply = sync_read_bytes(len(IDS), 4, fast=True)
    model = wire_time(instruction + reply, 4_000_000) + 62.5e-6 + 125e-6  # high-speed adapter
    with DynamixelChain(IDS, baud_rate=4_000_000, adapter="hs", settings={"return_delay_time": 0}) as chain:
        assert spun_exchanges(chain).min() >= model

