"""Protocol 2.0 byte for byte: the ROBOTIS e-manual's example packets fed to the simulated chain
over its pty, and the packet codec checked against dynamixel-sdk's own CRC and byte stuffing.

Examples: https://emanual.robotis.com/docs/en/dxl/protocol2/ (instruction and status packets of
Ping, Read, Write, Reg Write, Action, Factory Reset, Reboot, Clear, Sync Read/Write, Bulk
Read/Write, Fast Sync/Bulk Read). The simulated servos are configured to each example's
conditions (model number, firmware, present values)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import serial
from dynamixel_sdk.protocol2_packet_handler import Protocol2PacketHandler
from hypothesis import given, settings
from hypothesis import strategies as st
from sim_support import short_gil_switch  # noqa: F401 - a fixture

from livezmp.links.dynamixel_crc import _crc16_python, crc16_after_itself
from sim_devices.dynamixel_chain import STALL_CURRENT, DynamixelChain
from sim_devices.dynamixel_control_table import OVERLOAD_ERROR
from sim_devices.dynamixel_packet import PacketReader, crc16, encode_fast_status, encode_packet, stuff, unstuff

pytestmark = pytest.mark.usefixtures("short_gil_switch")

SDK = Protocol2PacketHandler()


def h(text: str) -> bytes:
    return bytes.fromhex(text)


class FixedPlant:
    """A plant whose state the test sets directly (the JointPlant interface, nothing more)."""

    def __init__(self, ticks: list[int]) -> None:
        self.position = (np.array(ticks, dtype=float) - 2048) * 2 * math.pi / 4096
        self.velocity = np.zeros(len(ticks))
        self.current = np.zeros(len(ticks))

    def set_goal(self, idx: int, position: float) -> None:
        pass

    def set_torque(self, idx: int, on: bool) -> None:
        pass

    def step(self, dt: float) -> None:
        pass


def exchange(ser: serial.Serial, packet: bytes, reply_size: int) -> bytes:
    """Write ``packet``; read ``reply_size`` bytes, then check nothing else follows."""
    ser.reset_input_buffer()
    ser.write(packet)
    ser.timeout = 1.0
    reply = ser.read(reply_size)
    ser.timeout = 0.02  # replies come within a millisecond; this only catches extra bytes
    return reply + ser.read(64)


@pytest.fixture
def bus():
    """Yield a factory: (ids, ticks) -> (chain, pyserial port), closed afterwards."""
    opened = []

    def make(ids, ticks=None):
        chain = DynamixelChain(ids, FixedPlant(ticks or [2048] * len(ids)))
        ser = serial.Serial(chain.path, 1_000_000, timeout=1.0)
        opened.append((chain, ser))
        return chain, ser

    yield make
    for chain, ser in opened:
        ser.close()
        chain.close()


def as_xm430_w210(chain, ids):
    for dxl_id in ids:
        chain.set_register(dxl_id, "model_number", 1030)
        chain.set_register(dxl_id, "firmware_version", 38)


# -- e-manual examples --------------------------------------------------------------------------

def test_ping_example_1(bus):
    chain, ser = bus([1])
    as_xm430_w210(chain, [1])
    assert exchange(ser, h("FF FF FD 00 01 03 00 01 19 4E"), 14) == h("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D")


def test_broadcast_ping_example_2(bus):
    chain, ser = bus([2, 1])
    as_xm430_w210(chain, [1, 2])
    assert exchange(ser, h("FF FF FD 00 FE 03 00 01 31 42"), 28) == (
        h("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D") + h("FF FF FD 00 02 07 00 55 00 06 04 26 6F 6D"))


def test_read_example(bus):
    chain, ser = bus([1], [166])
    assert exchange(ser, h("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15"), 15) == h(
        "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0")


def test_write_example_and_its_acknowledgement(bus):
    chain, ser = bus([1])
    assert exchange(ser, h("FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89"), 11) == h(
        "FF FF FD 00 01 04 00 55 00 A1 0C")
    assert chain.register(1, "goal_position") == 512


def test_sync_read_example(bus):
    chain, ser = bus([1, 2], [166, 2079])
    assert exchange(ser, h("FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA"), 30) == (
        h("FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0") + h("FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE"))


def test_sync_write_example(bus):
    chain, ser = bus([1, 2])
    packet = h("FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87")
    assert exchange(ser, packet, 0) == b""  # broadcast write: no status packet
    assert (chain.register(1, "goal_position"), chain.register(2, "goal_position")) == (150, 170)


def test_bulk_read_example(bus):
    chain, ser = bus([1, 2])
    chain.set_register(1, "present_input_voltage", 119)
    chain.set_register(2, "present_temperature", 36)
    packet = h("FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05")
    assert exchange(ser, packet, 25) == (
        h("FF FF FD 00 01 06 00 55 00 77 00 C3 69") + h("FF FF FD 00 02 05 00 55 00 24 8B A9"))


def test_bulk_write_example(bus):
    chain, ser = bus([1, 2])
    chain.set_register(1, "max_voltage_limit", 140)
    chain.set_register(2, "temperature_limit", 70)
    packet = h("FF FF FD 00 FE 10 00 93 01 20 00 02 00 A0 00 02 1F 00 01 00 50 B7 68")
    assert exchange(ser, packet, 0) == b""
    assert (chain.register(1, "max_voltage_limit"), chain.register(2, "temperature_limit")) == (160, 80)


def test_reg_write_and_action_examples(bus):
    chain, ser = bus([1])
    ack = h("FF FF FD 00 01 04 00 55 00 A1 0C")
    assert exchange(ser, h("FF FF FD 00 01 09 00 04 68 00 C8 00 00 00 AE 8E"), 11) == ack
    assert (chain.register(1, "registered_instruction"), chain.register(1, "goal_velocity")) == (1, 0)
    assert exchange(ser, h("FF FF FD 00 01 03 00 05 02 CE"), 11) == ack
    assert (chain.register(1, "registered_instruction"), chain.register(1, "goal_velocity")) == (0, 200)


def test_action_without_reg_write_is_an_instruction_error(bus):
    chain, ser = bus([1])
    reply = exchange(ser, h("FF FF FD 00 01 03 00 05 02 CE"), 11)
    assert reply[8] == 0x02 and len(reply) == 11


def test_reboot_example(bus):
    chain, ser = bus([1])
    chain.set_register(1, "led", 1)
    assert exchange(ser, h("FF FF FD 00 01 03 00 08 2F 4E"), 11) == h("FF FF FD 00 01 04 00 55 00 A1 0C")
    assert chain.register(1, "led") == 0  # RAM back to its initial values


def test_factory_reset_example_keeps_only_the_id(bus):
    chain, ser = bus([1])
    chain.set_register(1, "return_delay_time", 0)
    assert exchange(ser, h("FF FF FD 00 01 04 00 06 01 A1 E6"), 11) == h("FF FF FD 00 01 04 00 55 00 A1 0C")
    assert chain.register(1, "id") == 1
    assert chain.register(1, "return_delay_time") == 250
    assert chain.register(1, "baud_rate") == 1  # factory 57600 bps: the 1 Mbps host no longer reaches it
    assert exchange(ser, h("FF FF FD 00 01 03 00 01 19 4E"), 0) == b""


def test_clear_example_resets_the_multi_turn_count(bus):
    chain, ser = bus([1], [2048 + 2 * 4096 + 100])
    chain.set_register(1, "operating_mode", 4)  # extended position mode
    assert chain.register(1, "present_position") == 2048 + 2 * 4096 + 100
    assert exchange(ser, h("FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC"), 11) == h(
        "FF FF FD 00 01 04 00 55 00 A1 0C")
    assert chain.register(1, "present_position") == 2148


def test_fast_sync_read_example(bus):
    chain, ser = bus([3, 7, 4], [166, 2079, 1023])
    packet = h("FF FF FD 00 FE 0A 00 8A 84 00 04 00 03 07 04 20 F2")
    assert exchange(ser, packet, 32) == h(
        "FF FF FD 00 FE 19 00 55 00 03 A6 00 00 00 84 08 00 07 1F 08 00 00 16 CA 00 04 FF 03 00 00 D1 9E")


def test_fast_bulk_read_example(bus):
    chain, ser = bus([3, 7, 4], [166, 2048, 2048])
    chain.plant.current[1] = 421 / 885 * STALL_CURRENT  # Present PWM 421
    chain.set_register(4, "present_temperature", 31)
    params = "9A 03 84 00 04 00 07 7C 00 02 00 04 92 00 01 00"
    published = h("FF FF FD 00 FE 12 00 " + params + " 20 F2")
    # The e-manual prints the Fast Sync Read example's CRC (20 F2) here too; the real CRC is DA 2D.
    # With the printed CRC the servos see a CRC error and, as the packet is broadcast, stay silent.
    assert exchange(ser, published, 0) == b""
    assert crc16(published[:-2]) == 0x2DDA
    fixed = h("FF FF FD 00 FE 12 00 " + params + " DA 2D")
    assert exchange(ser, fixed, 27) == h(
        "FF FF FD 00 FE 14 00 55 00 03 A6 00 00 00 67 A4 00 07 A5 01 24 74 00 04 1F D9 C1")


# -- behaviour seen on the wire -------------------------------------------------------------------

def sdk_packet(packet_id: int, instruction: int, params: bytes) -> bytes:
    """An instruction packet built by dynamixel-sdk's own stuffing and CRC code."""
    length = len(params) + 3
    packet = [0xFF, 0xFF, 0xFD, 0x00, packet_id, length & 0xFF, length >> 8, instruction, *params, 0, 0]
    packet = SDK.addStuffing(packet)
    total = (packet[5] | packet[6] << 8) + 7
    crc = SDK.updateCRC(0, packet, total - 2)
    packet[total - 2: total] = [crc & 0xFF, crc >> 8]
    return bytes(packet[:total])


def test_sync_read_replies_follow_the_instruction_id_order(bus):
    chain, ser = bus([1, 2, 3], [100, 200, 300])
    reply = exchange(ser, sdk_packet(0xFE, 0x82, bytes([0x84, 0, 4, 0, 3, 1, 2])), 45)
    assert [reply[4], reply[19], reply[34]] == [3, 1, 2]
    assert [reply[9], reply[24], reply[39]] == [300 & 0xFF, 100, 200]


def test_status_packet_is_byte_stuffed(bus):
    chain, ser = bus([1])
    # Homing Offset 0xFFFDFFFF = -131073: its bytes FF FF FD FF need stuffing both ways.
    assert exchange(ser, sdk_packet(1, 0x03, bytes([20, 0, 0xFF, 0xFF, 0xFD, 0xFF])), 11)[8] == 0
    assert chain.register(1, "homing_offset") == -131073
    reply = exchange(ser, sdk_packet(1, 0x02, bytes([20, 0, 4, 0])), 16)
    assert reply == sdk_packet(1, 0x55, bytes([0, 0xFF, 0xFF, 0xFD, 0xFF]))
    assert reply[5] == 9 and h("FF FF FD FD FF") in reply


@pytest.mark.parametrize(("params", "error"), [
    (bytes([116, 0, 0x00, 0x20, 0, 0]), 6),  # goal position 8192 > Max Position Limit: data limit
    (bytes([132, 0, 0, 0, 0, 0]), 7),  # present position is read-only: access
    (bytes([116, 0, 0, 2]), 5),  # 2 bytes of a 4-byte item: data length
    (bytes([9, 0, 255]), 4),  # return delay time 255 > 254: data range
    (bytes([14, 0, 1]), 7),  # reserved address: access
    (bytes([147, 0, 0, 0]), 7),  # past the end of the table: access
])
def test_write_errors(bus, params, error):
    chain, ser = bus([1])
    reply = exchange(ser, sdk_packet(1, 0x03, params), 11)
    assert reply == sdk_packet(1, 0x55, bytes([error]))


def test_eeprom_is_locked_while_torque_is_on(bus):
    chain, ser = bus([1])
    exchange(ser, sdk_packet(1, 0x03, bytes([64, 0, 1])), 11)
    assert exchange(ser, sdk_packet(1, 0x03, bytes([9, 0, 0])), 11)[8] == 7


def test_read_past_the_table_is_an_access_error_without_data(bus):
    chain, ser = bus([1])
    assert exchange(ser, sdk_packet(1, 0x02, bytes([146, 0, 4, 0])), 11) == sdk_packet(1, 0x55, bytes([7]))


def test_status_return_level_and_broadcast_rules(bus):
    chain, ser = bus([1])
    chain.set_register(1, "status_return_level", 1)
    assert exchange(ser, sdk_packet(1, 0x03, bytes([65, 0, 1])), 0) == b""  # write: silent at level 1
    assert len(exchange(ser, sdk_packet(1, 0x02, bytes([65, 0, 1, 0])), 12)) == 12  # read answered
    chain.set_register(1, "status_return_level", 0)
    assert exchange(ser, sdk_packet(1, 0x02, bytes([65, 0, 1, 0])), 0) == b""
    assert len(exchange(ser, sdk_packet(1, 0x01, b""), 14)) == 14  # ping always answered
    assert exchange(ser, sdk_packet(0xFE, 0x02, bytes([65, 0, 1, 0])), 0) == b""  # no broadcast read


def test_unknown_instruction_is_an_instruction_error(bus):
    chain, ser = bus([1])
    assert exchange(ser, sdk_packet(1, 0x42, b""), 11) == sdk_packet(1, 0x55, bytes([2]))


def test_bad_crc_is_answered_with_crc_error(bus):
    chain, ser = bus([1])
    packet = bytearray(sdk_packet(1, 0x02, bytes([132, 0, 4, 0])))
    packet[-1] ^= 0xFF
    assert exchange(ser, bytes(packet), 11) == sdk_packet(1, 0x55, bytes([3]))
    assert chain.stats.crc_errors == 1


def test_alert_bit_while_hardware_error_is_set(bus):
    chain, ser = bus([1])
    chain.trip(1, 0x20)
    assert exchange(ser, sdk_packet(1, 0x02, bytes([70, 0, 1, 0])), 12) == sdk_packet(1, 0x55, bytes([0x80, 0x20]))


def test_return_delay_time_delays_the_reply(bus):
    chain, ser = bus([1])
    chain.set_register(1, "return_delay_time", 254)  # 508 us
    packet = sdk_packet(1, 0x01, b"")
    ser.reset_input_buffer()
    start = time.perf_counter()
    ser.write(packet)
    assert len(ser.read(14)) == 14
    assert time.perf_counter() - start >= 508e-6


# -- codec against dynamixel-sdk ----------------------------------------------------------------

@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=900), st.integers(0, 0xFFFF))
def test_crc16_matches_dynamixel_sdk(data, start):
    # crc16 is crcmod's C function where it is installed; _crc16_python the table loop / numpy sum without it
    for crc in (crc16, _crc16_python):
        assert crc(data) == SDK.updateCRC(0, list(data), len(data))
        assert crc(data, start) == SDK.updateCRC(start, list(data), len(data))
        assert crc(memoryview(bytearray(data)), start) == SDK.updateCRC(start, list(data), len(data))
    assert crc16_after_itself(start) == SDK.updateCRC(start, [start & 0xFF, start >> 8], 2)


_STUFFY = st.lists(st.sampled_from([0xFF, 0xFD, 0x00, 0x42]), max_size=60).map(bytes)


@settings(max_examples=300, deadline=None)
@given(st.integers(0, 252), st.integers(0, 255), _STUFFY)
def test_encoded_packets_match_dynamixel_sdk_and_read_back(packet_id, instruction, params):
    packet = encode_packet(packet_id, instruction, params)
    assert packet == sdk_packet(packet_id, instruction, params)
    assert unstuff(stuff(params)) == params
    # (dynamixel-sdk 4.1's removeStuffing is not an oracle: it edits in place and mis-decodes e.g.
    # FF FF FD FF FD FD, so the read-back is checked against the original parameters.)
    reader = PacketReader()
    received = [p for i in range(len(packet)) for p in reader.feed(packet[i: i + 1], 0.0)]
    assert [(p.id, p.instruction, p.params, p.crc_ok) for p in received] == [
        (packet_id, instruction, params, True)]


def test_reader_resynchronises_after_garbage_and_drops_stale_partials():
    reader = PacketReader()
    ping = encode_packet(1, 0x01)
    assert [p.id for p in reader.feed(b"\x00\xff\xff\xfd\x01" + ping, 0.0)] == [1]
    assert reader.feed(ping[:6], 1.0) == []
    assert [p.id for p in reader.feed(ping, 1.1)] == [1]  # 100 ms of silence dropped the partial
    assert reader.feed(bytes(5000), 2.0) == []  # garbage is not kept
    assert len(reader._buffer) <= 3


def test_fast_sync_read_reply_has_each_servo_s_segment_after_their_delays(bus):
    """The chain answers a Fast Sync Read from its table rows at once: the same segments (the alert bit
    of a servo with a hardware error included) and the same delays as servo by servo; a servo whose
    Status Return Level is 0 is left out."""
    ids, ticks = [3, 7, 4], [166, 2079, 1023]
    chain, _ = bus(ids, ticks)
    chain.set_register(7, "return_delay_time", 10)
    chain.set_register(4, "return_delay_time", 3)
    chain.trip(4, OVERLOAD_ERROR)
    packet = encode_packet(0xFE, 0x8A, bytes((132, 0, 4, 0)) + bytes(ids))
    segments = [(0, 3, (166).to_bytes(4, "little")), (0, 7, (2079).to_bytes(4, "little")),
                (0x80, 4, (1023).to_bytes(4, "little"))]
    byte = 10 / 1_000_000
    adapter = chain.adapter.out_s + chain.adapter.in_s
    for silent in (None, 7):
        if silent is not None:
            chain.set_register(silent, "status_return_level", 0)
        [(due, reply)] = chain.on_bytes(packet, 100.0)
        expected = encode_fast_status([s for s in segments if s[1] != silent])
        assert reply == expected
        delays = sum(2e-6 * chain.register(i, "return_delay_time") for i in ids if i != silent)
        assert due == pytest.approx(100.0 + adapter + (len(packet) + len(expected)) * byte + delays, abs=1e-9)
        chain._bus_free = -math.inf  # the next exchange starts on an idle bus


def test_fast_status_has_running_crcs():
    reply = encode_fast_status([(0, 3, bytes(4)), (0, 7, bytes(4))])
    assert crc16(reply[:-2]) == reply[-2] | reply[-1] << 8
    assert crc16(reply[:14]) == reply[14] | reply[15] << 8


class GoalLog(FixedPlant):
    """Records every goal the chain gives the plant, in order."""

    def __init__(self, ticks: list[int]) -> None:
        super().__init__(ticks)
        self.goals: list[tuple[int, float]] = []

    def set_goal(self, idx: int, position: float) -> None:
        self.goals.append((idx, position))


def test_a_sync_write_of_goals_does_what_a_write_to_each_servo_does():
    """The goals' sync write (the loop's packet every cycle, handled for all servos at once) against the
    same goals sent as one Write instruction each (the general write path), servo for servo: goals in
    range and limits taken, the one beyond its mode-3 limits, the one whose bus watchdog tripped, the one
    beyond the register's range and the one on another baud rate refused, an unknown id ignored."""
    ids = [1, 2, 3, 4, 5, 6]
    goals = {1: 100, 2: 4000, 3: 5000, 4: 200, 5: 2_000_000, 6: 300, 9: 400}
    outcomes = []
    for sync in (True, False):
        plant = GoalLog([2048] * len(ids))
        with DynamixelChain(ids, plant, emulate_wire_time=False, adapter="none") as chain, \
                serial.Serial(chain.path, 1_000_000) as ser:
            chain.set_register(2, "max_position_limit", 3000)  # mode 3: 4000 is beyond it
            chain.set_register(3, "operating_mode", 4)  # extended position: no limits
            chain.set_register(4, "bus_watchdog", -1)  # tripped: goals refused
            chain.set_register(6, "baud_rate", 1)  # 57600: does not hear the host
            for i in ids:
                chain.set_register(i, "torque_enable", 1)
            plant.goals.clear()
            unheard = chain.stats.unheard
            if sync:
                params = (116).to_bytes(2, "little") + (4).to_bytes(2, "little") + b"".join(
                    bytes((i,)) + v.to_bytes(4, "little", signed=True) for i, v in goals.items())
                assert exchange(ser, encode_packet(0xFE, 0x83, params), 0) == b""
            else:
                for i, v in goals.items():  # servos 6 (not hearing) and 9 (none) do not answer
                    value = (116).to_bytes(2, "little") + v.to_bytes(4, "little", signed=True)
                    status = 11 if i <= 5 else 0
                    assert len(exchange(ser, encode_packet(i, 0x03, value), status)) == status
            outcomes.append(([chain.register(i, "goal_position") for i in ids], plant.goals,
                             chain.stats.unheard - unheard))
    assert outcomes[0] == outcomes[1]
    table, steered, unheard = outcomes[0]
    assert table[:3] == [100, 2048, 5000] and table[4] == 2048  # 2 and 5 refused, 4 held where it was
    assert [i for i, _ in steered] == [0, 2] and unheard == 1
    assert steered[1][1] == pytest.approx((5000 - 2048) * 2 * math.pi / 4096)


def test_a_read_refreshes_every_live_register_it_covers_after_a_narrower_read_at_the_same_instant():
    """The chain refreshes only the plant-driven registers a read covers (a loop reading positions pays for
    nothing else): a read of all of them right after a read of the positions, at the same instant and
    later, still gives each register from the plant in the e-manual's units."""
    plant = FixedPlant([2048, 3000])
    plant.velocity[:] = [0.0, 1.0]  # rad/s
    plant.current[:] = [0.0, 0.5]  # A
    rpm_unit, ma_unit = 0.229 * 2 * math.pi / 60, 2.69e-3  # velocity and current units (e-manual)
    with DynamixelChain([1, 2], plant, emulate_wire_time=False, adapter="none") as chain, \
            serial.Serial(chain.path, 1_000_000):
        for i in (1, 2):
            chain.set_register(i, "torque_enable", 1)  # goals: the present positions 2048, 3000
        positions = encode_packet(0xFE, 0x8A, h("84 00 04 00 01 02"))
        everything = encode_packet(0xFE, 0x82, h("78 00 18 00 01 02"))  # addresses 120-143
        live = np.dtype([("tick", "<u2"), ("moving", "u1"), ("status", "u1"), ("pwm", "<i2"), ("current", "<i2"),
                         ("velocity", "<i4"), ("position", "<i4"), ("velocity_trajectory", "<i4"),
                         ("position_trajectory", "<i4")])

        def read_all(now):
            assert len(chain.on_bytes(positions, now)) == 1
            replies = chain.on_bytes(everything, now)
            return np.frombuffer(b"".join(payload[9:-2] for _, payload in replies), dtype=live)

        now = time.monotonic()
        r = read_all(now)
        assert r["position"].tolist() == [2048, 3000] and r["position_trajectory"].tolist() == [2048, 3000]
        assert r["velocity"].tolist() == r["velocity_trajectory"].tolist() == [0, round(1.0 / rpm_unit)]
        assert r["current"].tolist() == [0, round(0.5 / ma_unit)]
        assert r["pwm"].tolist() == [0, round(0.5 / STALL_CURRENT * 885)]
        assert r["moving"].tolist() == [0, 1] and (r["status"] & 1).tolist() == [1, 0]
        plant.velocity[:] = [-1.0, 0.0]
        plant.position[1] = (3100 - 2048) * 2 * math.pi / 4096
        r = read_all(now + 0.01)
        assert r["position"].tolist() == [2048, 3100] and r["velocity"].tolist() == [-round(1.0 / rpm_unit), 0]
        assert r["moving"].tolist() == [1, 0] and (r["status"] & 1).tolist() == [0, 0]  # 3100 is 100 off its goal
        assert (r["tick"] - r["tick"][0]).tolist() == [0, 0]
