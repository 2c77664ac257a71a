"""A simulated chain of Dynamixel X-series servos (XM430-W350) speaking Protocol 2.0 on a pty.

Any number of servo ids share one `PtyPort`; unmodified dynamixel-sdk clients
open :attr:`DynamixelChain.path`. Servo ``ids[i]`` drives joint ``i`` of a
`JointPlant` (default `ServoPlant`).

Behaviour, as the e-manual describes the real servo:

* instructions: ping (also broadcast), read, write, reg write / action, factory
  reset (0xFF, 0x01, 0x02; broadcast 0xFF ignored), reboot, clear (multi-turn),
  sync read / write, bulk read / write, fast sync read, fast bulk read;
* status error numbers: result fail, instruction, CRC, data range, data
  length, data limit, access; alert bit 0x80 while Hardware Error Status != 0;
* Status Return Level (ping always; read-class from level 1; all at level 2;
  never for broadcast write-class), Return Delay Time (2 us units) before each
  reply, sync/bulk replies in the instruction's id order, each after the
  previous one plus its own delay;
* EEPROM writes refused (access error) while torque is on; goal writes beyond
  the limit registers give data limit error (goal position only in position
  mode 3);
* Bus Watchdog (20 ms units): with torque on and no instruction packet on the
  bus for that long, the servo stops, the register reads -1 and goal writes get
  data range error until the register is written again;
* hardware errors (e.g. the injected overload) set Hardware Error Status; if
  the Shutdown mask has the bit, torque goes off and cannot be switched on
  (result fail) until a reboot clears the error;
* a servo only hears the host when the client's line speed matches its Baud
  Rate register (when the line speed can be read from the pty);
* a write that changes the ID is acknowledged under the id it was sent to.

Positions are ticks (4096 per revolution); the plant works in radians with
``ticks = zero_tick + rad * 4096 / 2pi`` (before Homing Offset and the Drive
Mode reverse bit), so ``zero_tick=2048`` puts 0 rad mid-range. Velocity in
0.229 rpm, current in 2.69 mA, PWM in 885ths of full duty estimated from the
current relative to the stall current.

Timing: the plant is stepped lazily, by the elapsed time, whenever a packet
needs its state or changes its goals, and at each timed fault; there is no
background physics thread. Replies are written at their due times by the
port thread. By default the bus is physical (:mod:`livezmp.links.bus_timing`):
each byte takes 10 bit times at the line speed (instruction and replies, one
after the other on the half-duplex bus), each servo waits its Return Delay Time
before answering, and the USB-serial ``adapter`` (default a full-speed FTDI
with its latency timer at 1 ms) delays the instruction on its way to the bus
and the replies on their way back. ``emulate_wire_time=False`` and
``adapter="none"`` make bytes take no time (only to test the protocol).

A sub-controller (``sub_controller``: an :class:`~sim_devices.dynamixel_imu_board.ImuBoard`,
the OP3's OpenCR with its IMU) may share the bus: it answers Ping, Read and its part of
Sync/Bulk (and Fast) Reads, with its own Return Delay Time, under the same wire timing.

Not modelled: indirect addresses, velocity/current/PWM control modes (the
registers are kept but the joint only follows goal positions), profiles, and
the time a real servo takes to reboot.
"""

from __future__ import annotations

import functools
import math
import struct
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from livezmp.links.bus_timing import DEFAULT_ADAPTER, Adapter, parse_adapter, wire_time
from sim_devices import dynamixel_control_table as ct
from sim_devices.dynamixel_imu_board import ImuBoard
from sim_devices.dynamixel_packet import (
    ALERT,
    BROADCAST_ID,
    ErrorCode,
    FastStatus,
    Instruction,
    Packet,
    PacketReader,
    encode_fast_status,
    encode_status,
)
from sim_devices.faults import FaultInjector, FaultSpec
from sim_devices.pty_port import PortServer, PtyDevice, PtyPort, Reply
from sim_devices.servo_plant import JointPlant, ServoPlant

SUPPORTED_FAULTS = frozenset({"drop", "corrupt", "delay", "overload", "vanish"})
TICKS_PER_RAD = ct.POSITION_TICKS_PER_REV / (2.0 * math.pi)
STALL_CURRENT = 2.3  # A, XM430-W350 at 12 V: the current at full PWM when stalled
IN_POSITION_TICKS = 20  # Moving Status bit 0 tolerance chosen for the simulator
_CLEAR_KEY = b"\x01\x44\x58\x4c\x22"
# Realtime Tick .. Position Trajectory (addresses 120-143), refreshed from the plant for all servos at once
_LIVE = np.dtype([("tick", "<u2"), ("moving", "u1"), ("moving_status", "u1"), ("pwm", "<i2"),
                  ("current", "<i2"), ("velocity", "<i4"), ("position", "<i4"), ("velocity_trajectory", "<i4"),
                  ("position_trajectory", "<i4")])
_LIVE_START = 120
_LIVE_END = _LIVE_START + _LIVE.itemsize
_LIVE_SPANS = [(name, _LIVE_START + offset, _LIVE_START + offset + dtype.itemsize)
               for name, (dtype, offset) in _LIVE.fields.items()]  # (field, first address, end address)
_MOTION = frozenset({"velocity", "velocity_trajectory", "moving", "moving_status"})  # refreshed together
_PING = struct.Struct("<HB")
_ADDRESS_LENGTH = struct.Struct("<HH")
_POSITION_LIMITS = struct.Struct("<ii")  # Max and Min Position Limit, adjacent (addresses 48 and 52)
_GOAL_ROW = np.dtype([("id", "u1"), ("value", "<i4")])  # one servo's part of a sync write of goal positions
_RESET_KEEPS = {0xFF: (), 0x01: ("id",), 0x02: ("id", "baud_rate")}  # factory reset option -> kept
_BAUD_CODES = {rate: code for code, rate in ct.BAUD_RATES.items()}
_F = ct.BY_NAME
_GOAL = _F["goal_position"]
_GOAL_VALUE = struct.Struct("<i")
_LIMITS_ADDRESS = _F["max_position_limit"].address


@functools.cache
def _live_fields(start: int, end: int) -> frozenset[str]:
    """The plant-driven registers (fields of `_LIVE`) a read of addresses ``start`` to ``end`` covers."""
    return frozenset(name for name, lo, hi in _LIVE_SPANS if lo < end and start < hi)


def _rows(indices: list[int]) -> slice | np.ndarray:
    """Table rows ``indices`` as a slice where they are consecutive (a loop reads its chain's servos in order:
    the rows are then a view, not a copy), else an index array."""
    if indices == list(range(indices[0], indices[0] + len(indices))):
        return slice(indices[0], indices[0] + len(indices))
    return np.array(indices)


def _ticks_to_rad(sign: float, offset: float, zero: int, ticks: int) -> float:
    """A goal of ``ticks`` as the joint's angle (rad): the servo's direction ``sign`` (±1), its Homing Offset and
    turns ``offset`` (ticks) and the tick at 0 rad ``zero``."""
    return sign * (ticks - offset - zero) / TICKS_PER_RAD


def _goal_position_error(table: memoryview, value: int) -> int:
    """The error number of a Goal Position write of ``value`` (ticks) to a servo's control ``table`` (0: taken):
    data range while its bus watchdog has tripped (goals are read-only then), data limit beyond its position
    limits in position mode (3)."""
    if table[98] == 0xFF:
        return ErrorCode.DATA_RANGE
    if table[11] == 3:
        highest, lowest = _POSITION_LIMITS.unpack_from(table, _LIMITS_ADDRESS)
        if not lowest <= value <= highest:
            return ErrorCode.DATA_LIMIT
    return ErrorCode.NONE


# Return Delay Time, Status Return Level, Hardware Error Status: what a Fast Sync Read's reply takes from each servo
# beside its data
_REPLY_REGISTERS = np.array([9, 68, 70])


class _FastRead:
    """A Fast Sync Read every servo of which hears the host: their table rows, the reply's layout, and what the
    servos' `_REPLY_REGISTERS` held at the last read (their bytes) and gave: None (a servo is silent) or the
    segments' error bytes and the reply's delay (s). A loop sends the same read every cycle and those registers
    seldom change: the answer is worked out again only when they did."""

    __slots__ = ("rows", "status", "registers", "answer")

    def __init__(self, rows: slice | np.ndarray, status: FastStatus) -> None:
        self.rows = rows
        self.status = status
        self.registers = b""  # none read yet: no servo has no registers
        self.answer: tuple[np.ndarray, float] | None = None


@dataclass
class ChainStats:
    """Counts of what the chain saw and did."""

    packets: int = 0  #: valid instruction packets received
    crc_errors: int = 0  #: packets received with a bad CRC
    replies: int = 0  #: status packets written (after fault injection)
    unheard: int = 0  #: packets ignored by a servo because of a baud-rate mismatch


class _Servo:
    __slots__ = ("id", "index", "table", "registered", "turn_offset", "baud")

    def __init__(self, dxl_id: int, index: int, table: memoryview) -> None:
        self.id = dxl_id
        self.index = index  # servo position in the chain = joint index in the plant
        self.table = table  # this servo's row of the chain's control-table memory
        self.table[:] = ct.initial_table()
        self.table[7] = dxl_id
        self.registered: tuple[int, bytes] | None = None
        self.turn_offset = 0
        self.baud = ct.BAUD_RATES[self.table[8]]

    def get(self, name: str) -> int:
        item = _F[name]
        return struct.unpack_from(item.fmt, self.table, item.address)[0]

    def put(self, name: str, value: int) -> None:
        item = _F[name]
        struct.pack_into(item.fmt, self.table, item.address, value)

    @property
    def return_delay(self) -> float:
        return self.table[9] * ct.RETURN_DELAY_UNIT


class DynamixelChain(PtyDevice):
    """Servos ``ids`` on one simulated bus, served at :attr:`path` (see module docstring).

    ``baud_rate`` (bit/s) sets every servo's Baud Rate register; ``settings`` maps
    control-table field names to values written to every servo at start (e.g.
    ``{"return_delay_time": 0}``); ``faults`` is a fault spec (see `faults`);
    ``adapter``: the USB-serial adapter's latency (a name or ms, see `bus_timing.parse_adapter`);
    ``sub_controller``: a board sharing the bus (module docstring); ``port_server``: the thread that serves
    its pty, shared with the robot's other buses (None: a thread of its own).
    Bad arguments raise ValueError, an unknown field name KeyError, naming it.
    """

    def __init__(self, ids: Sequence[int], plant: JointPlant | None = None, *, faults: str | FaultSpec = "",
                 baud_rate: int = 1_000_000, settings: Mapping[str, int] | None = None,
                 zero_tick: int = 2048, emulate_wire_time: bool = True,
                 adapter: str | float | Adapter = DEFAULT_ADAPTER, name: str = "ttyDXL",
                 sub_controller: ImuBoard | None = None, port_server: PortServer | None = None) -> None:
        ids = list(ids)
        if not ids or len(set(ids)) != len(ids) or not all(0 <= i <= 252 for i in ids):
            raise ValueError(f"DynamixelChain: ids must be distinct integers in 0..252, got {ids}")
        if sub_controller is not None and sub_controller.id in ids:
            raise ValueError(f"DynamixelChain: the sub-controller's id {sub_controller.id} is a servo's")
        self.sub_controller = sub_controller
        if baud_rate not in _BAUD_CODES:
            raise ValueError(f"DynamixelChain: baud_rate {baud_rate} is not an XM430 rate "
                             f"({', '.join(map(str, _BAUD_CODES))})")
        self.adapter = parse_adapter(adapter)
        self.plant: JointPlant = plant if plant is not None else ServoPlant(len(ids))
        if len(self.plant.position) < len(ids):
            raise ValueError(f"DynamixelChain: plant has {len(self.plant.position)} joints for {len(ids)} servos")
        self._faults = FaultInjector(faults, supported=SUPPORTED_FAULTS, device="Dynamixel chain")
        missing = sorted({servo for servo, _ in self._faults.spec.overloads} - set(ids))
        if missing:
            raise ValueError(f"fault spec field 'overload': no servo with id {missing[0]} on this chain")
        self.stats = ChainStats()
        self._lock = threading.Lock()
        self._zero = zero_tick
        self._emulate_wire = emulate_wire_time
        self._bus_free = -math.inf  # when the bus is next idle (monotonic s)
        now = time.monotonic()
        self._plant_time = now
        self._last_packet = now
        self._refreshed_at = -math.inf
        self._fresh: set[str] = set()  # the live registers refreshed at _refreshed_at
        # One bytearray holds every servo's table (a memoryview row each) so that a numpy view can
        # refresh the plant-driven registers of all servos in one assignment.
        memory = bytearray(len(ids) * ct.TABLE_SIZE)
        self._tables = np.frombuffer(memory, dtype=np.uint8).reshape(len(ids), ct.TABLE_SIZE)
        self._live = self._tables[:, _LIVE_START:_LIVE_END].view(_LIVE)[:, 0]  # those registers, by field
        rows = memoryview(memory)
        self._servos = [_Servo(dxl_id, index, rows[index * ct.TABLE_SIZE: (index + 1) * ct.TABLE_SIZE])
                        for index, dxl_id in enumerate(ids)]
        self._by_id: dict[int, _Servo] = {}
        self._hearing_line: int | None = -1
        self._hearing_map: dict[int, _Servo] = {}
        # (servo ids read, data length, line speed) -> the read's layout (None: not every servo hears), `_fast_answer`
        self._fast_layouts: dict[tuple[bytes, int, int | None], _FastRead | None] = {}
        self._readdress()
        self._boot = np.full(len(ids), now)
        self._sign = np.ones(len(ids))
        self._offset = np.zeros(len(ids))
        self._threshold = np.zeros(len(ids))
        self._goal = np.zeros(len(ids))
        self._armed: dict[_Servo, float] = {}
        self._shortest_watchdog = math.inf  # the shortest armed period (s): the next expiry is this after a packet
        self._reader = PacketReader()
        self._handlers: dict[int, Callable[[Packet, float, int | None], list[tuple[float, bytes]]]] = {
            Instruction.PING: self._ping,
            Instruction.READ: self._read_instruction,
            Instruction.WRITE: self._write_instruction,
            Instruction.REG_WRITE: self._reg_write,
            Instruction.ACTION: self._action,
            Instruction.FACTORY_RESET: self._factory_reset,
            Instruction.REBOOT: self._reboot_instruction,
            Instruction.CLEAR: self._clear,
            Instruction.SYNC_READ: self._sync_read,
            Instruction.FAST_SYNC_READ: self._sync_read,
            Instruction.SYNC_WRITE: self._sync_write,
            Instruction.BULK_READ: self._bulk_read,
            Instruction.FAST_BULK_READ: self._bulk_read,
            Instruction.BULK_WRITE: self._bulk_write,
        }
        config = {"baud_rate": _BAUD_CODES[baud_rate], **(settings or {})}
        for servo in self._servos:
            self._remap(servo)
            for key, value in config.items():
                self._poke(servo, key, value, now)
            if "goal_position" not in config:  # the goal starts where the joint is
                self._hold_present(servo, now)
        self._faults.start(now)
        # last: its thread calls back into this object
        self._port = PtyPort(self, name, spin=emulate_wire_time, server=port_server)

    # -- public API -------------------------------------------------------------------------------

    def register(self, dxl_id: int, name: str) -> int:
        """Current value of control-table field ``name`` of servo ``dxl_id`` (table units)."""
        with self._lock:
            servo = self._servo(dxl_id)
            if ct.field(name).address >= _LIVE_START:
                self._sync_plant(time.monotonic())
            return servo.get(name)

    def set_register(self, dxl_id: int, name: str, value: int) -> None:
        """Set a field directly, bypassing access rules (to configure the simulated servo).

        Fields computed from the plant (addresses 120-143) are overwritten at the
        next read; set the plant state instead.
        """
        with self._lock:
            self._poke(self._servo(dxl_id), name, value, time.monotonic())

    def trip(self, dxl_id: int, bits: int) -> None:
        """Raise hardware error ``bits`` (e.g. `OVERLOAD_ERROR`) on servo ``dxl_id`` now."""
        with self._lock:
            now = time.monotonic()
            self._advance(now)
            self._trip(self._servo(dxl_id), bits)

    # -- ByteDevice -------------------------------------------------------------------------------

    def on_bytes(self, data: bytes, now: float) -> list[Reply]:
        with self._lock:
            packets = self._reader.feed(data, now)
            if not packets:
                return []
            self._expire_watchdogs(now)
            line = self._port.line_speed()
            replies: list[Reply] = []
            for packet in packets:
                replies += self._handle(packet, now, line)
            return replies

    def poll(self, now: float) -> list[Reply]:
        with self._lock:
            for event in self._faults.due_events(now):
                self._expire_watchdogs(event.time)
                self._advance(event.time)
                if event.kind == "overload":
                    self._trip(self._by_id[event.arg], ct.OVERLOAD_ERROR)
                elif event.kind == "vanish":
                    self._port.vanish()
                elif event.kind == "restore":
                    self._reader.clear()
                    self._port.restore()
            self._expire_watchdogs(now)
            return []

    def next_deadline(self) -> float:
        with self._lock:
            return min(self._last_packet + self._shortest_watchdog, self._faults.next_event_time())

    # -- packet handling --------------------------------------------------------------------------

    def _servo(self, dxl_id: int) -> _Servo:
        try:
            return self._by_id[dxl_id]
        except KeyError:
            raise KeyError(f"no servo with id {dxl_id} on this chain") from None

    def _handle(self, packet: Packet, now: float, line: int | None) -> list[Reply]:
        if not packet.crc_ok:
            self.stats.crc_errors += 1
            servo = self._unicast(packet.id, line)
            if servo is None or servo.table[68] < 2:
                return []
            return self._schedule(now, packet.size, [(servo.return_delay,
                                                     encode_status(servo.id, self._error(servo, ErrorCode.CRC)))],
                                  line)
        self.stats.packets += 1
        self._last_packet = now
        handler = self._handlers.get(packet.instruction)
        if handler is None:
            servo = self._unicast(packet.id, line)
            entries = [] if servo is None else self._status(servo, ErrorCode.INSTRUCTION, level=2)
        else:
            entries = handler(packet, now, line)
        return self._schedule(now, packet.size, entries, line)

    def _readdress(self) -> None:
        """Rebuild the id lookups after an id or baud-rate change."""
        self._by_id = {servo.id: servo for servo in self._servos}
        self._hearing_line = -1
        self._fast_layouts.clear()

    def _hearing(self, line: int | None) -> dict[int, _Servo]:
        """Servos by id that can hear a host at line speed ``line`` (None: unknown, all)."""
        if line != self._hearing_line:
            self._hearing_line = line
            self._hearing_map = {s.id: s for s in self._servos if line is None or s.baud == line}
        return self._hearing_map

    def _unicast(self, dxl_id: int, line: int | None) -> _Servo | None:
        servo = self._hearing(line).get(dxl_id)
        if servo is None and dxl_id in self._by_id:
            self.stats.unheard += 1
        return servo

    def _targets(self, dxl_id: int, line: int | None) -> list[_Servo]:
        if dxl_id == BROADCAST_ID:
            hearing = self._hearing(line)
            self.stats.unheard += len(self._servos) - len(hearing)
            return list(hearing.values())
        servo = self._unicast(dxl_id, line)
        return [] if servo is None else [servo]

    def _error(self, servo: _Servo, code: int) -> int:
        return code | (ALERT if servo.table[70] else 0)

    def _status(self, servo: _Servo, code: int, params: bytes = b"", *, level: int,
                reply_id: int | None = None) -> list[tuple[float, bytes]]:
        """A one-reply list if the servo's Status Return Level allows replies of ``level``.

        ``reply_id`` is the id the instruction was addressed to, when a write may have changed it.
        """
        if servo.table[68] < level:
            return []
        reply_id = servo.id if reply_id is None else reply_id
        return [(servo.return_delay, encode_status(reply_id, self._error(servo, code), params))]

    def _schedule(self, now: float, instruction_size: int, entries: list[tuple[float, bytes]],
                  line: int | None) -> list[Reply]:
        """Due times for replies sent one after the other, each after its delay; faults applied.

        The instruction reaches the bus the adapter's ``out_s`` after the host wrote it, and once
        the bus is free (after earlier instructions and replies); with wire time every byte takes
        10 bit times (at the host's line speed ``line``, baud, as `on_bytes` read it; None: the first
        servo's); each reply reaches the host the adapter's ``in_s`` after its last byte.
        """
        byte_time = wire_time(1, line or self._servos[0].baud) if self._emulate_wire else 0.0
        t = max(now + self.adapter.out_s, self._bus_free) + instruction_size * byte_time
        replies = []
        for delay, payload in entries:
            t += delay + len(payload) * byte_time
            dropped, corrupt, extra = self._faults.reply_fate()
            if dropped:
                continue
            if corrupt:  # error, parameters or CRC: the client's CRC check catches it
                payload = self._faults.corrupt(payload, 8, len(payload))
            replies.append((t + self.adapter.in_s + extra, payload))
        self._bus_free = t
        self.stats.replies += len(replies)
        return replies

    # -- instructions ------------------------------------------------------------------------------

    def _ping(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        servos = self._targets(packet.id, line)
        if packet.id == BROADCAST_ID:
            servos.sort(key=lambda servo: servo.id)
        entries = []
        for servo in servos:
            info = _PING.pack(servo.get("model_number"), servo.get("firmware_version"))
            entries.append((servo.return_delay, encode_status(servo.id, self._error(servo, 0), info)))
        sub = self.sub_controller
        if sub is not None and packet.id in (sub.id, BROADCAST_ID):
            entries.append((sub.return_delay, encode_status(sub.id, 0, _PING.pack(0, 0))))
        return entries

    def _sub_reply(self, address: int, length: int) -> tuple[int, bytes]:
        data = self.sub_controller.read(address, length)
        return (ErrorCode.ACCESS, b"") if data is None else (ErrorCode.NONE, data)

    def _read_instruction(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        sub = self.sub_controller
        if sub is not None and packet.id == sub.id:
            if sub.status_level < 1:
                return []
            code, data = self._sub_reply(*_ADDRESS_LENGTH.unpack(packet.params)) if len(packet.params) == 4 \
                else (ErrorCode.DATA_LENGTH, b"")
            return [(sub.return_delay, encode_status(sub.id, code, data))]
        servo = self._unicast(packet.id, line)
        if servo is None:
            return []
        if len(packet.params) != 4:
            return self._status(servo, ErrorCode.DATA_LENGTH, level=1)
        address, length = _ADDRESS_LENGTH.unpack(packet.params)
        self._sync_plant(now, address, address + length)
        code, data = self._read(servo, address, length)
        return self._status(servo, code, data, level=1)

    def _write_instruction(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        entries = []
        for servo in self._targets(packet.id, line):
            code = self._write(servo, packet.params, now)
            if packet.id != BROADCAST_ID:
                entries = self._status(servo, code, level=2, reply_id=packet.id)
        return entries

    def _reg_write(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        entries = []
        for servo in self._targets(packet.id, line):
            code = self._check_write(servo, packet.params)
            if not code:
                servo.registered = (packet.params[0] | packet.params[1] << 8, packet.params[2:])
                servo.table[69] = 1
            if packet.id != BROADCAST_ID:
                entries = self._status(servo, code, level=2)
        return entries

    def _action(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        entries = []
        for servo in self._targets(packet.id, line):
            code = ErrorCode.INSTRUCTION
            if servo.registered is not None:
                address, data = servo.registered
                servo.registered = None
                servo.table[69] = 0
                code = self._write(servo, bytes((address & 0xFF, address >> 8)) + data, now)
            if packet.id != BROADCAST_ID:
                entries = self._status(servo, code, level=2, reply_id=packet.id)
        return entries

    def _factory_reset(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        option = packet.params[0] if len(packet.params) == 1 else None
        if packet.id == BROADCAST_ID and option == 0xFF:
            return []  # refused by X-series firmware 42+, without reply
        entries = []
        for servo in self._targets(packet.id, line):
            code = ErrorCode.DATA_LENGTH if option is None else (
                ErrorCode.NONE if option in _RESET_KEEPS else ErrorCode.DATA_RANGE)
            if packet.id != BROADCAST_ID:
                entries = self._status(servo, code, level=2)  # sent before the reset takes effect
            if not code:
                keep = {name: servo.get(name) for name in _RESET_KEEPS[option]}
                servo.table[:] = ct.initial_table()
                for name, value in keep.items():
                    servo.put(name, value)
                self._restart(servo, now)
        return entries

    def _reboot_instruction(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        entries = []
        for servo in self._targets(packet.id, line):
            if packet.id != BROADCAST_ID:
                entries = self._status(servo, ErrorCode.NONE, level=2)  # sent before rebooting
            servo.table[ct.EEPROM_END:] = ct.initial_table()[ct.EEPROM_END:]
            self._restart(servo, now)
        return entries

    def _clear(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        entries = []
        for servo in self._targets(packet.id, line):
            self._sync_plant(now)
            if packet.params != _CLEAR_KEY:
                code = ErrorCode.DATA_RANGE
            elif servo.table[122]:  # moving
                code = ErrorCode.RESULT_FAIL
            else:
                present = servo.get("present_position")
                servo.turn_offset -= present - present % ct.POSITION_TICKS_PER_REV
                self._remap(servo)
                self._refreshed_at = -math.inf
                code = ErrorCode.NONE
            if packet.id != BROADCAST_ID:
                entries = self._status(servo, code, level=2)
        return entries

    def _sync_read(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        if packet.id != BROADCAST_ID:
            servo = self._unicast(packet.id, line)
            return [] if servo is None else self._status(servo, ErrorCode.INSTRUCTION, level=1)
        if len(packet.params) < 5:
            return []
        address, length = _ADDRESS_LENGTH.unpack_from(packet.params)
        self._sync_plant(now, address, address + length)
        fast = packet.instruction == Instruction.FAST_SYNC_READ
        if fast:
            entries = self._fast_answer(packet.params[4:], address, length, line)
            if entries is not None:
                return entries
        requests = [(dxl_id, address, length) for dxl_id in packet.params[4:]]
        return self._answer_reads(requests, fast, line)

    def _fast_answer(self, ids: bytes, address: int, length: int, line: int | None) -> list[tuple[float, bytes]] | None:
        """The Fast Sync Read's reply when every one of ``ids`` is a servo that hears ``line`` and answers
        reads: what `_answer_reads` builds, from the table rows at once (a control loop's read, every
        cycle). None otherwise (a sub-controller, a silent or deaf servo, a bad range): `_answer_reads` then."""
        if not length or address + length > ct.TABLE_SIZE:
            return None
        key = (ids, length, line)
        if key not in self._fast_layouts:
            if len(self._fast_layouts) >= 16:  # bounded: a loop asks the same ids every cycle
                self._fast_layouts.clear()
            servos = [self._hearing(line).get(dxl_id) for dxl_id in ids]
            self._fast_layouts[key] = None if None in servos else _FastRead(
                _rows([servo.index for servo in servos]), FastStatus(ids, length))
        layout = self._fast_layouts[key]
        if layout is None:
            return None
        tables = self._tables[layout.rows]
        registers = tables.take(_REPLY_REGISTERS, axis=1).tobytes()
        if registers != layout.registers:  # seldom: the servos' registers are as the last read found them
            layout.registers = registers
            if (tables[:, 68] < 1).any():  # a Status Return Level of 0 keeps that servo silent
                layout.answer = None
            else:
                errors = np.where(tables[:, 70] != 0, ALERT, ErrorCode.NONE)  # the alert bit: Hardware Error Status
                delay = float(tables[:, 9].sum()) * ct.RETURN_DELAY_UNIT  # each servo's Return Delay Time in turn
                layout.answer = errors, delay
        if layout.answer is None:
            return None
        errors, delay = layout.answer
        return [(delay, layout.status.encode(errors, tables[:, address: address + length]))]

    def _bulk_read(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        params = packet.params
        if packet.id != BROADCAST_ID:
            servo = self._unicast(packet.id, line)
            return [] if servo is None else self._status(servo, ErrorCode.INSTRUCTION, level=1)
        if not params or len(params) % 5:
            return []
        requests = [(params[i], *_ADDRESS_LENGTH.unpack_from(params, i + 1)) for i in range(0, len(params), 5)]
        self._sync_plant(now, min(a for _, a, _ in requests), max(a + n for _, a, n in requests))
        return self._answer_reads(requests, packet.instruction == Instruction.FAST_BULK_READ, line)

    def _answer_reads(self, requests: list[tuple[int, int, int]], fast: bool,
                      line: int | None) -> list[tuple[float, bytes]]:
        entries = []
        segments = []
        delay = 0.0
        hearing = self._hearing(line)
        sub = self.sub_controller
        for dxl_id, address, length in requests:
            if sub is not None and dxl_id == sub.id and sub.status_level >= 1:
                code, data = self._sub_reply(address, length)
                if fast:
                    segments.append((code, sub.id, data))
                    delay += sub.return_delay
                else:
                    entries.append((sub.return_delay, encode_status(sub.id, code, data)))
                continue
            servo = hearing.get(dxl_id)
            if servo is None:
                self.stats.unheard += dxl_id in self._by_id
                continue
            if servo.table[68] < 1:
                continue
            code, data = self._read(servo, address, length)
            if fast:
                segments.append((self._error(servo, code), servo.id, data))
                delay += servo.return_delay
            else:
                entries.append((servo.return_delay, encode_status(servo.id, self._error(servo, code), data)))
        if fast and segments:
            entries = [(delay, encode_fast_status(segments))]
        return entries

    def _sync_write(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        params = packet.params
        if packet.id != BROADCAST_ID or len(params) < 4:
            return []
        address, length = _ADDRESS_LENGTH.unpack_from(params)
        stride = length + 1
        if length == 0 or (len(params) - 4) % stride:
            return []
        head = params[:2]
        hearing = self._hearing(line)
        if address == _GOAL.address and length == _GOAL.size:
            self._sync_write_goals(params, now, hearing)
            return []
        for i in range(4, len(params), stride):
            servo = hearing.get(params[i])
            if servo is not None:
                self._write(servo, head + params[i + 1: i + stride], now)
            else:
                self.stats.unheard += params[i] in self._by_id
        return []

    def _sync_write_goals(self, params: bytes, now: float, hearing: dict[int, _Servo]) -> None:
        """A sync write of Goal Position (a control loop's packet every cycle): what `_write` does for each
        servo (range, watchdog and limit checks, then the goal to the table and the plant), without its
        general field handling, so that the simulator's time per cycle stays small beside the bus's."""
        rows = np.frombuffer(params, dtype=_GOAL_ROW, offset=4)
        self._advance(now)
        # looked up once, not once a servo; the joints' signs and offsets as Python floats (what `item` gives)
        goals, set_goal, zero = self._goal, self.plant.set_goal, self._zero
        signs, offsets = self._sign.tolist(), self._offset.tolist()
        lowest, highest, address, position_modes = _GOAL.lo, _GOAL.hi, _GOAL.address, ct.POSITION_MODES
        for dxl_id, value in zip(rows["id"].tolist(), rows["value"].tolist(), strict=True):
            servo = hearing.get(dxl_id)
            if servo is None:
                self.stats.unheard += dxl_id in self._by_id
                continue
            table = servo.table
            if not lowest <= value <= highest or _goal_position_error(table, value):
                continue
            _GOAL_VALUE.pack_into(table, address, value)
            joint = servo.index
            goals[joint] = value
            if table[11] in position_modes:
                set_goal(joint, _ticks_to_rad(signs[joint], offsets[joint], zero, value))
        self._refreshed_at = -math.inf

    def _bulk_write(self, packet: Packet, now: float, line: int | None) -> list[tuple[float, bytes]]:
        params = packet.params
        if packet.id != BROADCAST_ID:
            return []
        i = 0
        while i + 5 <= len(params):
            length = params[i + 3] | params[i + 4] << 8
            end = i + 5 + length
            if end > len(params):
                break
            servo = self._unicast(params[i], line)
            if servo is not None:
                self._write(servo, params[i + 1: i + 3] + params[i + 5: end], now)
            i = end
        return []

    # -- control table ---------------------------------------------------------------------------

    def _read(self, servo: _Servo, address: int, length: int) -> tuple[int, bytes]:
        if length == 0 or address + length > ct.TABLE_SIZE:
            return ErrorCode.ACCESS, b""
        return ErrorCode.NONE, bytes(servo.table[address: address + length])

    def _write(self, servo: _Servo, params: bytes, now: float) -> int:
        """Write ``params`` (address LE16 + data) to ``servo``; returns the error number."""
        code = self._check_write(servo, params)
        if code:
            return code
        address = params[0] | params[1] << 8
        data = params[2:]
        fields, _ = ct.fields_in(address, address + len(data))
        self._advance(now)
        servo.table[address: address + len(data)] = data
        for item in fields:
            self._after_write(servo, item.name, now)
        return ErrorCode.NONE

    def _check_write(self, servo: _Servo, params: bytes) -> int:
        if len(params) < 3:
            return ErrorCode.DATA_LENGTH
        address = params[0] | params[1] << 8
        data = params[2:]
        end = address + len(data)
        if end > ct.TABLE_SIZE:
            return ErrorCode.ACCESS
        fields, complete = ct.fields_in(address, end)
        if not complete:
            return ErrorCode.ACCESS
        if fields[0].address != address or fields[-1].end != end:
            return ErrorCode.DATA_LENGTH
        torque_on = servo.table[64]
        for item in fields:
            if not item.writable or (item.eeprom and torque_on):
                return ErrorCode.ACCESS
            value = struct.unpack_from(item.fmt, data, item.address - address)[0]
            if not item.lo <= value <= item.hi:
                return ErrorCode.DATA_RANGE
            code = self._check_value(servo, item.name, value)
            if code:
                return code
        return ErrorCode.NONE

    def _check_value(self, servo: _Servo, name: str, value: int) -> int:
        if name == "goal_position":
            return _goal_position_error(servo.table, value)
        if name in ct.GOAL_FIELDS:
            if servo.table[98] == 0xFF:  # bus watchdog error: goals are read-only
                return ErrorCode.DATA_RANGE
            if abs(value) > servo.get({"goal_pwm": "pwm_limit", "goal_current": "current_limit",
                                       "goal_velocity": "velocity_limit"}[name]):
                return ErrorCode.DATA_LIMIT
        elif name == "operating_mode" and value not in ct.OPERATING_MODES:
            return ErrorCode.DATA_RANGE
        elif name == "bus_watchdog" and value < 0:
            return ErrorCode.DATA_RANGE
        elif name == "torque_enable" and value and servo.table[70] & servo.table[63]:
            return ErrorCode.RESULT_FAIL  # shut down: only a reboot re-enables torque
        return ErrorCode.NONE

    def _after_write(self, servo: _Servo, name: str, now: float) -> None:
        """Side effects of a field that was just written."""
        joint = servo.index
        if name == "goal_position":
            goal = servo.get("goal_position")
            self._goal[joint] = goal
            if servo.table[11] in ct.POSITION_MODES:
                self.plant.set_goal(joint, self._ticks_to_rad(servo, goal))
        elif name == "torque_enable":
            on = bool(servo.table[64])
            if on:  # as the real servo: the goal starts where the joint is
                self._hold_present(servo, now)
            self.plant.set_torque(joint, on)
            self._update_watchdog(servo)
        elif name == "bus_watchdog":
            self._update_watchdog(servo)
        elif name in ("homing_offset", "drive_mode", "moving_threshold"):
            self._remap(servo)
        elif name == "baud_rate":
            servo.baud = ct.BAUD_RATES[servo.table[8]]
            self._readdress()
        elif name == "id":
            servo.id = servo.table[7]
            self._readdress()
        if name in ("homing_offset", "drive_mode", "moving_threshold", "goal_position"):
            self._refreshed_at = -math.inf

    def _poke(self, servo: _Servo, name: str, value: int, now: float) -> None:
        item = ct.field(name)
        try:
            struct.pack_into(item.fmt, servo.table, item.address, value)
        except struct.error:
            raise ValueError(f"control-table field '{name}': value {value} does not fit "
                             f"{item.size} byte(s)") from None
        self._advance(now)
        self._after_write(servo, name, now)

    # -- plant coupling ---------------------------------------------------------------------------

    def _remap(self, servo: _Servo) -> None:
        i = servo.index
        self._sign[i] = -1.0 if servo.table[10] & 1 else 1.0
        self._offset[i] = servo.get("homing_offset") + servo.turn_offset
        self._threshold[i] = servo.get("moving_threshold")
        self._goal[i] = servo.get("goal_position")

    def _ticks_to_rad(self, servo: _Servo, ticks: int) -> float:
        i = servo.index
        # item(): Python floats, whose arithmetic costs less than numpy scalars'
        return _ticks_to_rad(self._sign.item(i), self._offset.item(i), self._zero, ticks)

    def _present_ticks(self, servo: _Servo) -> int:
        i = servo.index
        position = float(self.plant.position[i])
        return int(round(self._zero + self._sign[i] * position * TICKS_PER_RAD + self._offset[i]))

    def _hold_present(self, servo: _Servo, now: float) -> None:
        """Make the goal the present position (torque on, reboot)."""
        self._advance(now)
        ticks = self._present_ticks(servo)
        servo.put("goal_position", ticks)
        self._goal[servo.index] = ticks
        self.plant.set_goal(servo.index, self._ticks_to_rad(servo, ticks))
        self._refreshed_at = -math.inf

    def _advance(self, now: float) -> None:
        dt = now - self._plant_time
        if dt > 0.0:
            self.plant.step(dt)
            self._plant_time = now

    def _sync_plant(self, now: float, start: int = _LIVE_START, end: int = _LIVE_END) -> None:
        """Step the plant to ``now`` and write its state into every servo's live registers among addresses
        ``start`` to ``end`` (the registers a read covers: a loop reading positions each cycle does not pay
        for the current, PWM and status registers)."""
        self._advance(now)
        if self._refreshed_at != now:
            self._refreshed_at = now
            self._fresh = set()
        wanted = _live_fields(start, end) - self._fresh
        if not wanted:
            return
        if wanted & _MOTION:  # Moving Status compares the position with the goal
            wanted |= _MOTION | {"position"}
        self._fresh |= wanted
        plant = self.plant
        n = len(self._servos)
        sign = self._sign
        live = self._live
        if "position" in wanted:
            position = np.rint(self._zero + sign * plant.position[:n] * TICKS_PER_RAD + self._offset)
            live["position"] = position
        if wanted & _MOTION:
            velocity = np.rint(sign * plant.velocity[:n] / ct.VELOCITY_UNIT)
            live["velocity"] = live["velocity_trajectory"] = velocity
            moving = np.abs(velocity) > self._threshold
            live["moving"] = moving
            live["moving_status"] = (np.abs(self._goal - position) <= IN_POSITION_TICKS) & ~moving
        if wanted & {"pwm", "current"}:
            current = sign * plant.current[:n]
            live["pwm"] = np.clip(np.rint(current * (ct.PWM_FULL_SCALE / STALL_CURRENT)), -ct.PWM_FULL_SCALE,
                                  ct.PWM_FULL_SCALE)
            live["current"] = np.clip(np.rint(current / ct.CURRENT_UNIT), -32768, 32767)
        if "tick" in wanted:
            live["tick"] = ((now - self._boot) * 1000.0).astype(np.int64) % 32768
        if "position_trajectory" in wanted:
            live["position_trajectory"] = self._goal

    def _restart(self, servo: _Servo, now: float) -> None:
        """State after power-up with the table already reset: torque off, errors and registrations cleared."""
        servo.registered = None
        servo.turn_offset = 0
        self._boot[servo.index] = now
        servo.id = servo.table[7]
        servo.baud = ct.BAUD_RATES[servo.table[8]]
        self._readdress()
        self.plant.set_torque(servo.index, False)
        self._remap(servo)
        self._hold_present(servo, now)
        self._update_watchdog(servo)

    def _trip(self, servo: _Servo, bits: int) -> None:
        servo.table[70] |= bits
        if servo.table[63] & bits:
            servo.table[64] = 0
            self.plant.set_torque(servo.index, False)
            self._update_watchdog(servo)

    def _update_watchdog(self, servo: _Servo) -> None:
        period = struct.unpack_from("<b", servo.table, 98)[0]
        if servo.table[64] and period > 0:
            self._armed[servo] = period * ct.WATCHDOG_UNIT
        else:
            self._armed.pop(servo, None)
        self._shortest_watchdog = min(self._armed.values(), default=math.inf)

    def _expire_watchdogs(self, now: float) -> None:
        if self._last_packet + self._shortest_watchdog > now:  # none expired (every packet asks)
            return
        expired = sorted((self._last_packet + period, servo.index, servo)
                         for servo, period in self._armed.items() if self._last_packet + period <= now)
        for when, _, servo in expired:
            self._advance(when)
            joint = servo.index
            self.plant.set_goal(joint, float(self.plant.position[joint]))  # stop where it is
            servo.table[98] = 0xFF  # -1: Bus Watchdog Error
            del self._armed[servo]
        self._shortest_watchdog = min(self._armed.values(), default=math.inf)
