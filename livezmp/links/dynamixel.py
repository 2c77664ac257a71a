"""Dynamixel Protocol 2.0 servo link, through the ROBOTIS dynamixel-sdk.

    dynamixel:PATH[?baud=1000000&fast=auto&read=position&return_delay=0&watchdog=0.1&timeout=S]

One sync read per `read` of what the loop uses: Present Position of every servo
(``read=position``, 4 bytes a servo: every byte costs rate on the bus) or Present Current,
Velocity and Position (``read=state``, addresses 126-135 of the X-series control table),
or a Fast Sync Read (one status packet for all
servos: about half the bytes and one reply to parse instead of one per servo) with
``fast=1``, or by default (``fast=auto``) when every servo's firmware is 45 or later (the
X-series firmware that has it) and the installed dynamixel-sdk has it; one sync write of Goal Position per
`write_goals`. Servo ids, zero offsets, directions and ticks per revolution come from the
robot config (`ServoConfig`); currents and velocities use the XM/XH units (2.69 mA,
0.229 rpm).

`open` checks every servo answers (with the model number the robot config gives, where it gives one: a
servo that answers as another model is refused, nothing driven) and is in a position control mode, reads its position
limits (in position mode 3 a servo ignores a goal beyond them, so `write_goals` refuses
one with LinkError), sets Return Delay Time to ``return_delay`` us (default 0; 2 us units)
where it differs (an EEPROM write, so only on servos whose torque is off), arms the Bus
Watchdog (``watchdog`` s, 20 ms units; 0 leaves it off), enables torque, checks it came on
and holds the present posture.

Replies are received one status packet at a time with the sdk's packet handler, so a
lost or corrupt reply does not swallow the others: ``stats.read_errors`` counts replies
lost (``no_reply``, ``short_reply``) or rejected (``bad_crc``, ``bad_reply``), the same
unit the simulated devices' fault counters use. A plain sync read asks the servos whose
replies were lost once more (a second sync read of just them); a servo still missing, or
a lost Fast Sync Read reply, makes `read` raise `LinkReadError` and return nothing. At
`open` each read is retried up to `OPEN_TRIES` times for the servos not heard yet, so a
noisy bus opens; a servo never heard is a LinkError naming it. On a bus that loses more
than `MAX_REPLY_LOSS` of its replies (over the last `LOSS_WINDOW`) the link gives up:
`LinkUnusable`, with the measured loss (a bad cable, termination or baud rate). A status
packet with the alert bit set makes the link read that servo's Hardware Error Status,
reported in ``LinkFrame.hardware_errors``.

``timeout`` (s) bounds the wait for the replies of one transaction once the link is open;
by default three times the slowest of the good reads at the end of `open` plus 2 ms, at
least 10 ms (never more than the sdk's own: twice its USB latency timer, 16 ms, plus 2 ms, which is
what `open` waits: servos may still have their factory return delays then). A lost
reply costs the loop one timeout.

An IMU sub-controller in the robot config (``[imu]``, the OP3's OpenCR at id 200:
:mod:`.dynamixel_imu`) is read in the same transaction: the read becomes a (Fast) Bulk Read
of the servos' registers and the IMU's 12 (longer instruction, one more reply; no second
round trip through the adapter; Fast only with ``fast=1``), and the frame carries its ``imu`` (gyro and accelerometer,
base-link axes). A lost IMU reply leaves that frame without one (counted); robots without
an ``[imu]`` keep the sync read and pay nothing.

For a loop that overlaps its work with the bus: `request` sends the next read's instruction
ahead (built by the sdk once: it never changes), ``write_goals(q, request=True)`` sends the
goals and that instruction in one write (one USB transfer, one out latency), and
`prepare_goals` builds both packets ahead for `send_prepared` to send the moment a read
has verified.

The bytes each read and write put on the wire are counted from `open`'s end;
`bus_ceilings` turns them into the bus's physical ceiling (:mod:`.bus_timing`). Known limit: Protocol 2.0 has no
sequence numbers, so a reply delayed beyond the timeout that arrives during the next
transaction would be taken for that transaction's; keep the timeout above the bus's worst
reply latency.
"""

from __future__ import annotations

import math
import os
import select
import termios
import time
from collections.abc import Sequence
from contextlib import contextmanager

import numpy as np
import serial
from dynamixel_sdk import (
    BROADCAST_ID,
    COMM_RX_CORRUPT,
    COMM_RX_TIMEOUT,
    COMM_SUCCESS,
    GroupBulkRead,
    GroupSyncRead,
    GroupSyncWrite,
    PacketHandler,
    PortHandler,
)
from dynamixel_sdk.port_handler import LATENCY_TIMER

from livezmp.links.base import LinkError, LinkFrame, LinkReadError, LinkStats, LinkUnusable, PortLink
from livezmp.links.bus_timing import Adapter, BusCeiling, bulk_read_bytes, sync_read_bytes, sync_write_bytes
from livezmp.links.dynamixel_cycle_packets import FastReply, GoalPacket
from livezmp.links.dynamixel_imu import IMU_ADDRESS, IMU_LENGTH, decode_imu
from livezmp.links.reply_loss import ReplyLoss
from livezmp.model.robot_config import ImuConfig, ServoConfig

# X-series control table (ROBOTIS e-manual, Protocol 2.0): addresses and units.
MODEL_NUMBER = 0  # EEPROM, 2 bytes: what a ping answers with (1020: XM430-W350)
FIRMWARE_VERSION = 6  # EEPROM
FAST_SYNC_READ_FIRMWARE = 45  # X-series firmware with Fast Sync Read (ROBOTIS e-manual)
RETURN_DELAY_TIME = 9  # EEPROM, 2 us units
OPERATING_MODE = 11  # EEPROM
POSITION_LIMITS = 48  # EEPROM: Max Position Limit (4 bytes), Min Position Limit (4), in ticks
TORQUE_ENABLE = 64  # RAM from here on
HARDWARE_ERROR_STATUS = 70
BUS_WATCHDOG = 98  # 20 ms units, 0 off; reads -1 once it tripped
GOAL_POSITION = 116
PRESENT_STATE = 126  # Present Current (2 bytes), Present Velocity (4), Present Position (4)
PRESENT_STATE_LENGTH = 10
PRESENT_POSITION = 132
READS = {"position": (PRESENT_POSITION, 4), "state": (PRESENT_STATE, PRESENT_STATE_LENGTH)}
RETURN_DELAY_UNIT_US = 2
POSITION_MODES = {3: "position", 4: "extended position", 5: "current-based position"}
ALERT = 0x80  # status packet error bit: Hardware Error Status is not 0
# Protocol 2.0 status packet: header FF FF FD 00, id, length (2: instruction to CRC), 0x55, error, data, CRC (2).
PKT_ID, PKT_LENGTH, PKT_ERROR, PKT_DATA = 4, 5, 8, 9
VELOCITY_UNIT = 0.229 * 2.0 * math.pi / 60.0  # rad/s per unit
CURRENT_UNIT = 2.69e-3  # A per unit
WATCHDOG_UNIT = 0.020  # s per unit
WATCHDOG_MAX = 127 * WATCHDOG_UNIT
OPEN_TRIES = 8  # attempts of each read at open, for the servos not heard yet: a noisy bus still opens
MAX_REPLY_LOSS = 0.15  # share of replies lost or rejected beyond which the bus is not usable
LOSS_WINDOW = 400  # replies the loss is measured over
MIN_TIMEOUT_MS = 10.0  # the shortest reply timeout `open` chooses by itself

_STATE = np.dtype([("current", "<i2"), ("velocity", "<i4"), ("position", "<i4")])
_POSITION = np.dtype([("position", "<i4")])
_PORT_ERRORS = (serial.SerialException, OSError, termios.error)  # termios: flushing a vanished pty


class WaitingPortHandler(PortHandler):
    """The sdk's port handler, but a read that finds no bytes waits for them (select on
    the port, up to the packet's timeout) instead of polling again at once: the sdk's
    own loop spins a whole CPU core for every reply, which on a small computer is the
    core the servos' other work (and here the simulator) needs. Counts the bytes it moves."""

    bytes_out = 0
    bytes_in = 0
    _held: bytearray | None = None  # packets kept back (`held`)
    silence_limit = math.inf  # s: a longer gap between two writes may have tripped the servos' Bus Watchdog
    last_out = -math.inf  # time.monotonic() of the last bytes written
    silent_too_long = False  # a gap longer than silence_limit came before a write since it was cleared

    def readPort(self, length):
        data = self.ser.read(length)
        if not data:
            remaining_ms = self.packet_timeout - self.getTimeSinceStart()
            if remaining_ms > 0:
                select.select([self.ser.fileno()], [], [], remaining_ms / 1000.0)
                data = self.ser.read(length)
        self.bytes_in += len(data)
        return data

    def writePort(self, packet):
        if self._held is not None:
            self._held += bytes(packet)
            self.bytes_out += len(packet)
            return len(packet)
        self.stamp()
        written = self.ser.write(packet)
        self.bytes_out += written or 0
        return written

    def stamp(self) -> None:
        """Bytes go out now: note a silence before them longer than ``silence_limit``."""
        now = time.monotonic()
        if now - self.last_out > self.silence_limit:
            self.silent_too_long = True
        self.last_out = now

    def clearPort(self):
        if self._held is None:  # while packets are held, the input was cleared before the first
            super().clearPort()

    @contextmanager
    def held(self):
        """The packets sent inside are not sent: the bytearray given collects them (inside an outer
        `held`, only these)."""
        outer, self._held = self._held, bytearray()
        try:
            yield self._held
        finally:
            self._held = outer


ID_ADDRESS = 7


def find_servos(path: str, ids: Sequence[int], baud: int, tries: int = OPEN_TRIES) -> set[int]:
    """Which of ``ids`` answer on the bus at ``path`` (a sync read of their ID register, asked again
    up to ``tries`` times for the silent ones). LinkError if the port cannot be opened."""
    probe = DynamixelLink(path, [str(i) for i in ids], [ServoConfig(str(i), i) for i in ids], baud=baud)
    probe._open_port()
    heard: set[int] = set()
    try:
        for _ in range(tries):
            silent = tuple(i for i in ids if i not in heard)
            if not silent:
                break
            heard |= set(probe._transaction(ID_ADDRESS, 1, False, silent)[0])
    finally:
        probe._release()
    return heard


class DynamixelLink(PortLink):
    """Servos ``servos[i]`` drive joints ``joint_names[i]`` (see module docstring).

    ``baud`` (bit/s), ``fast`` (Fast Sync Read; None: where every servo has it, see
    ``fast_read`` after `open`), ``read`` ("position" or "state", see `READS`),
    ``return_delay`` (us, even, 0-508), ``watchdog`` (s, 0: off), ``timeout``
    (s per transaction, None: from the reads at open), ``imu``: an IMU sub-controller on the
    bus (module docstring). Construction does no I/O; `open` does.
    """

    def __init__(self, path: str, joint_names: Sequence[str], servos: Sequence[ServoConfig], *,
                 baud: int = 1_000_000, fast: bool | None = None, read: str = "position", return_delay: int = 0,
                 watchdog: float = 0.1, timeout: float | None = None, imu: ImuConfig | None = None) -> None:
        if len(servos) != len(joint_names):
            raise ValueError(f"DynamixelLink: {len(joint_names)} joints but {len(servos)} servos")
        ids = [s.id for s in servos]
        if len(set(ids)) != len(ids) or not all(0 <= i <= 252 for i in ids):
            raise ValueError(f"DynamixelLink: servo ids must be distinct, in 0..252, got {ids}")
        if watchdog and not WATCHDOG_UNIT <= watchdog <= WATCHDOG_MAX:
            raise ValueError(f"DynamixelLink: watchdog must be 0 or {WATCHDOG_UNIT}..{WATCHDOG_MAX:.2f} s, "
                             f"got {watchdog}")
        if read not in READS:
            raise ValueError(f"DynamixelLink: read must be one of {', '.join(READS)}, got '{read}'")
        if return_delay % RETURN_DELAY_UNIT_US or not 0 <= return_delay <= 254 * RETURN_DELAY_UNIT_US:
            raise ValueError(f"DynamixelLink: return_delay must be an even number of us in 0..508, got {return_delay}")
        if imu is not None and imu.id in ids:
            raise ValueError(f"DynamixelLink: the IMU's id {imu.id} is a servo's")
        self.path = path
        self.imu = imu
        self._extra = None if imu is None else (imu.id, IMU_ADDRESS, IMU_LENGTH)  # read with the servos
        self._imu_data: bytes | None = None  # the IMU's registers from the last read
        self.joint_names = list(joint_names)
        self.read_what = read
        self.return_delay = return_delay
        self.ids = ids
        self.models = [s.model for s in servos]  # the robot config's model numbers (None: not said)
        self.baud = baud
        self.fast = fast
        self.fast_read = bool(fast)  # what `read` uses: decided at open when fast is None
        self.watchdog = watchdog
        self.timeout = timeout
        self._opening = False  # while open() configures the servos: the sdk's own timeout
        self.stats = LinkStats()
        self.loss = ReplyLoss(LOSS_WINDOW, MAX_REPLY_LOSS)
        self._run_timeout_ms: float | None = None  # the reply timeout once open
        # bytes read, reads, bytes written, writes: since open finished (a list: counted twice a cycle, where an
        # array's slice took 1 us each time)
        self._traffic = [0, 0, 0, 0]
        self._pending = False  # a `request`ed read's instruction is out, its replies not taken in
        self._requested_bytes = 0
        # (goals' sync write + next read instruction, the goals' bytes): built, not sent yet
        self._prepared: tuple[bytes | bytearray, int] | None = None
        self._instruction: bytes | None = None  # `read`'s instruction, once built
        self._fast_reply: FastReply | None = None  # `read`'s Fast Sync Read reply buffer, once made
        self._goal_packet: GoalPacket | None = None  # the goals' sync write (+ read instruction), once made
        direction = np.array([s.direction for s in servos], dtype=float)
        ticks_per_rad = np.array([s.ticks_per_rev for s in servos], dtype=float) / (2.0 * math.pi)
        self._zero = np.array([s.zero for s in servos], dtype=float)
        self._rad_per_tick = direction / ticks_per_rad
        self._ticks_per_rad = direction * ticks_per_rad
        self._rad_s_per_unit = direction * VELOCITY_UNIT
        self._amp_per_unit = direction * CURRENT_UNIT
        self._ph = PacketHandler(2.0)
        self._port: PortHandler | None = None
        self._readers: dict[tuple[int, int], GroupSyncRead] = {}
        self._present: np.ndarray | None = None  # raw ticks of the last verified read
        self._lowest = np.full(len(ids), -2.0**31)  # goal limits in ticks, from the servos at open
        self._highest = np.full(len(ids), 2.0**31 - 1)
        self._opened_pty = False  # whether the port opened was a pseudo-terminal

    @property
    def pty_ports(self) -> int:
        """1 where the port is a pseudo-terminal (a simulated bus, or a bridge such as socat or ser2net): its
        written bytes wait for a kernel worker of normal priority to reach the other end (a USB-serial
        adapter's go out in the write itself); else 0. Of an open port, what it was when opened: the loop asks
        every cycle, and following the path's links costs ~10 us."""
        return int(self._opened_pty if self._port is not None else _names_a_pty(self.path))

    # -- Link -----------------------------------------------------------------------------------

    def open(self) -> None:
        """Open the port, check and configure every servo, enable torque, hold (see module docstring)."""
        self._open_port()
        self.loss.clear()
        self._opening = True
        try:
            self._configure()
        except LinkError:
            self._release()
            raise
        finally:
            self._opening = False

    def request(self) -> None:
        """Send the next `read`'s instruction now; `read` then only receives the replies (a loop
        computes while they travel). Writing before that `read` first takes them in."""
        if self._pending or self._port is None:
            return
        port = self._port
        instruction = self._read_instruction()
        self._requested_bytes = port.bytes_out + port.bytes_in
        try:
            port.clearPort()  # as the sdk does before each instruction: no stale byte is taken for a reply
            port.writePort(instruction)
        except _PORT_ERRORS as err:
            raise LinkError(f"{self.path}: port failed: {err}") from None
        self._pending = True

    def _read_instruction(self) -> bytes:
        """The bytes of `read`'s (Fast) Sync or Bulk Read instruction, built by the sdk once: they never change."""
        if self._instruction is None:
            port = self._require_port()
            reader = self._reader(*READS[self.read_what], tuple(self.ids), self._extra)
            with port.held() as data:
                try:
                    result = _fast_tx(reader) if self.fast_read else reader.txPacket()
                finally:
                    port.is_using = False  # the replies are ours to take in `read`, whatever the sdk thinks
            port.bytes_out -= len(data)  # counted when sent
            if result != COMM_SUCCESS:
                raise LinkError(f"{self.path}: sync read not built: {self._ph.getTxRxResult(result)}")
            self._instruction = bytes(data)
        return self._instruction

    def read(self) -> LinkFrame:
        """Present position (rad), velocity (rad/s) and current (A) of every joint, verified."""
        self.stats.reads += 1
        port = self._require_port()
        sent, self._pending = self._pending, False
        before = self._requested_bytes if sent else port.bytes_out + port.bytes_in
        fields = _STATE if self.read_what == "state" else _POSITION
        try:
            if self.fast_read and self._extra is None:  # the loop's usual read: straight into a buffer
                state = self._fast_sync_read(fields, sent)
                alerted = self._fast_reply.alerted()
            else:
                errors, data = self._sync_read(*READS[self.read_what], self.fast_read,
                                               retries=0 if self.fast_read else 1, sent=sent, extra=self._extra)
                state = np.frombuffer(data, dtype=fields)
                alerted = [i for i, e in enumerate(errors) if e & ALERT]
        finally:
            self._traffic[0] += port.bytes_out + port.bytes_in - before
            self._traffic[1] += 1
        t = time.monotonic()
        alerts = {i: self._hardware_error(i) for i in alerted}
        self._present = state["position"].astype(np.int64)
        full = self.read_what == "state"
        return LinkFrame(
            t=t,
            positions=(self._present - self._zero) * self._rad_per_tick,
            velocities=state["velocity"] * self._rad_s_per_unit if full else None,
            currents=state["current"] * self._amp_per_unit if full else None,
            hardware_errors={self.joint_names[i]: bits for i, bits in alerts.items() if bits},
            imu=None if self._imu_data is None else decode_imu(self._imu_data, self.imu.axes),
        )

    def prepare_goals(self, positions: np.ndarray) -> None:
        """Build the sync write of ``positions`` (rad, checked as by `write_goals`) and the next read's
        instruction now, for `send_prepared` to send in one write (a loop builds them while it would
        otherwise sleep, so the moment a read verified costs only the write)."""
        self.prepare_ticks(self.goal_ticks(positions))

    def send_prepared(self) -> None:
        """Send what `prepare_goals` built: the goals, then the next read's instruction (`request`)."""
        if self._prepared is None:
            raise LinkError(f"{self.path}: no goals prepared")
        prepared, self._prepared = self._prepared, None
        self._send_goals(*prepared)

    def write_goals(self, positions: np.ndarray, request: bool = False) -> None:
        """Goal positions (n,) rad in ``joint_names`` order, as one sync write (with ``request``:
        and the next read's instruction, see `write_ticks`)."""
        self.write_ticks(self.goal_ticks(positions), request)

    def goal_ticks(self, positions: np.ndarray) -> np.ndarray:
        """Goal positions (n,) rad as servo ticks; LinkError (nothing sent) if one is beyond its servo's limits."""
        goals = np.asarray(positions, dtype=float)
        if goals.shape != (len(self.ids),):
            raise LinkError(f"{self.path}: write_goals needs {len(self.ids)} positions, got shape {goals.shape}")
        ticks = np.rint(self._zero + goals * self._ticks_per_rad)
        bad = ~((ticks >= self._lowest) & (ticks <= self._highest))  # also catches NaN
        if bad.any():
            i = int(np.argmax(bad))
            ends = sorted([(self._lowest[i] - self._zero[i]) * self._rad_per_tick[i],
                           (self._highest[i] - self._zero[i]) * self._rad_per_tick[i]])
            raise LinkError(f"{self.path}: goal for joint '{self.joint_names[i]}' is {float(goals[i])} rad, outside "
                            f"its servo's range [{ends[0]:.4f}, {ends[1]:.4f}] rad; nothing sent")
        return ticks.astype("<i4")

    @property
    def tick_scale(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(zero, ticks per rad, lowest, highest goal tick) of each servo, as `goal_ticks` converts and checks
        with them (set at `open`)."""
        return self._zero, self._ticks_per_rad, self._lowest, self._highest

    def prepare_ticks(self, ticks: np.ndarray) -> None:
        """`prepare_goals` of goal ``ticks`` (n,) int32 already converted and checked (`goal_ticks`)."""
        self._prepared = self._goals_packet().fill(ticks)

    @property
    def read_label(self) -> str:
        """What each `read` asks for, e.g. "fast sync read: position"."""
        kind = "bulk read" if self._extra else "sync read"
        return f"{'fast ' if self.fast_read else ''}{kind}: {self.read_what}" + (" + imu" if self._extra else "")

    def bus_ceilings(self, adapter: Adapter) -> list[BusCeiling]:
        """The bus's ceiling from the bytes a read and a write moved since `open` (the packet sizes
        when nothing was exchanged yet), the servos' return delays and ``adapter``."""
        read_bytes, reads, write_bytes, writes = self._traffic
        n, length = len(self.ids), READS[self.read_what][1]
        planned = bulk_read_bytes([length] * n + [IMU_LENGTH], self.fast_read) if self._extra else \
            sync_read_bytes(n, length, self.fast_read)
        per_read = read_bytes / reads if reads else sum(planned)
        per_write = write_bytes / writes if writes else sync_write_bytes(n, 4)
        delays = n * self.return_delay * 1e-6
        return [BusCeiling(self.baud, per_read + per_write, delays, adapter)]

    def hold(self) -> None:
        """Goals = the present positions, from a fresh read (exact ticks, no rounding)."""
        self.read()
        self.write_ticks(self._present.astype("<i4"))

    def safe_stop(self, drop_torque: bool = False) -> None:
        """Hold (or switch torque off); never raises: if the bus is gone the servos' Bus Watchdog stops them."""
        if self._port is None:
            return
        try:
            if drop_torque:
                self._write_all(TORQUE_ENABLE, 1, 0)
            else:
                self._hold_retrying()
        except LinkError:
            pass  # counted where it happened; nothing more can be sent

    # -- open -----------------------------------------------------------------------------------

    def _open_port(self) -> None:
        port = WaitingPortHandler(self.path)
        try:
            ok = port.setBaudRate(self.baud)
        except _PORT_ERRORS as err:
            raise LinkError(f"{self.path}: cannot open: {err}") from None
        if not ok:
            raise LinkError(f"{self.path}: baud rate {self.baud} is not supported by dynamixel-sdk")
        if self.fast and not hasattr(GroupSyncRead, "fastSyncRead"):
            port.closePort()
            raise LinkError(f"{self.path}: this dynamixel-sdk has no Fast Sync Read: use fast=0 or upgrade it")
        self._port = port
        self._opened_pty = _names_a_pty(self.path)
        self._readers = {}
        self._instruction = self._goal_packet = None

    def _configure(self) -> None:
        if any(m is not None for m in self.models):
            self._check_models()
        # firmware version, id, baud rate, return delay, drive mode, operating mode
        eeprom = self._read_at_open(FIRMWARE_VERSION, OPERATING_MODE - FIRMWARE_VERSION + 1)
        stride = OPERATING_MODE - FIRMWARE_VERSION + 1
        firmware, delays, modes = eeprom[0::stride], eeprom[RETURN_DELAY_TIME - FIRMWARE_VERSION::stride], \
            eeprom[OPERATING_MODE - FIRMWARE_VERSION::stride]
        if self.fast is None:
            # with an IMU sub-controller, only when asked (fast=1): whether its firmware answers a Fast Bulk
            # Read is not something the servos' firmware versions tell
            self.fast_read = hasattr(GroupSyncRead, "fastSyncRead") and min(firmware) >= FAST_SYNC_READ_FIRMWARE \
                and self._extra is None
            self._instruction = self._goal_packet = None
        limits = np.frombuffer(self._read_at_open(POSITION_LIMITS, 8), dtype="<i4").reshape(-1, 2)
        limited = np.frombuffer(modes, dtype=np.uint8) == 3
        self._highest = np.where(limited, limits[:, 0], 2.0**31 - 1)
        self._lowest = np.where(limited, limits[:, 1], -2.0**31)
        ram = self._read_at_open(TORQUE_ENABLE, 1)
        for i, (delay, mode) in enumerate(zip(delays, modes, strict=True)):
            if mode not in POSITION_MODES:
                raise LinkError(f"{self.path}: {self._who(i)} is in operating mode {mode}, not a position mode "
                                f"({', '.join(f'{k} {v}' for k, v in POSITION_MODES.items())})")
            want = self.return_delay // RETURN_DELAY_UNIT_US
            if delay != want:
                if ram[i]:
                    raise LinkError(f"{self.path}: {self._who(i)} has Return Delay Time {2 * delay} us and torque "
                                    f"on, so it cannot be set to {self.return_delay} us: switch its torque off and "
                                    "reopen")
                self._write_one(i, RETURN_DELAY_TIME, want)
        self._arm_watchdog()
        self._write_all(TORQUE_ENABLE, 1, 1)
        state = self._read_at_open(TORQUE_ENABLE, HARDWARE_ERROR_STATUS - TORQUE_ENABLE + 1)
        stride = HARDWARE_ERROR_STATUS - TORQUE_ENABLE + 1
        off = [i for i in range(len(self.ids)) if not state[i * stride]]
        if off:
            detail = ", ".join(f"{self._who(i)} (hardware error status {state[i * stride + stride - 1]:#04x})"
                               for i in off)
            raise LinkError(f"{self.path}: torque did not come on for {detail}: reboot or power-cycle the servo")
        self._hold_retrying()
        if self.imu is not None:
            self._check_imu()
        self._run_timeout_ms = self._measure_timeout() if self.timeout is None else 1e3 * self.timeout
        self._traffic[:] = [0, 0, 0, 0]

    def _check_models(self) -> None:
        """Every servo whose model the robot config gives answers with that model number; else LinkError
        naming the first that does not: the ids are another robot's (or the config another robot's), whose
        servos may turn another way, another tick per radian or another torque (nothing driven yet)."""
        models = np.frombuffer(self._read_at_open(MODEL_NUMBER, 2), dtype="<u2")
        wrong = [i for i, m in enumerate(self.models) if m is not None and models[i] != m]
        if wrong:
            i = wrong[0]
            raise LinkError(f"{self.path}: {self._who(i)} answers as Dynamixel model {models[i]}, the robot config "
                            f"says {self.models[i]} ({len(wrong)} of {len(self.ids)} servos differ): another "
                            "robot's servos on these ids, or another robot's config")

    def _arm_watchdog(self) -> None:
        """(Re)arm the servos' Bus Watchdog (``watchdog`` s; off: nothing), clearing one that tripped: a
        tripped servo takes no goal until then (Bus Watchdog(98) reads -1; XM430 e-Manual)."""
        if self.watchdog:
            port = self._require_port()
            counted = list(self._traffic)  # set-up, not the loop's cycles (the bus summary's bytes)
            self._write_all(BUS_WATCHDOG, 1, 0)  # writing 0 first clears a tripped watchdog
            self._write_all(BUS_WATCHDOG, 1, round(self.watchdog / WATCHDOG_UNIT))
            self._traffic[:] = counted
            # a margin below the servos' period: their timer starts when our bytes arrive, not when sent
            port.silence_limit = 0.9 * self.watchdog
            port.silent_too_long = False

    def _rearm_after_silence(self) -> None:
        """Before goals: if the bus was silent longer than the Bus Watchdog since it was armed (the host
        stalled: a memory lock or page-in, a bus left idle while the next one opened), the servos may have
        tripped it and would ignore these goals without a word (a sync write has no reply): clear and
        re-arm it first, and count it (``watchdog_rearmed``)."""
        port = self._port
        if port is not None and (port.silent_too_long or time.monotonic() - port.last_out > port.silence_limit):
            self.stats.count("watchdog_rearmed")
            self._arm_watchdog()

    def _check_imu(self) -> None:
        """The IMU sub-controller answers a read of its registers; LinkError naming it after OPEN_TRIES."""
        port = self._require_port()
        for _ in range(OPEN_TRIES):
            try:
                _, result, error = self._ph.readTxRx(port, self.imu.id, IMU_ADDRESS, IMU_LENGTH)
            except _PORT_ERRORS as err:
                raise LinkError(f"{self.path}: port failed: {err}") from None
            finally:
                port.is_using = False
            if result == COMM_SUCCESS and not error & 0x7F:
                return
            self._lost_reply(result)
        raise LinkError(f"{self.path}: the IMU sub-controller (id {self.imu.id}, the robot config's [imu]) does not "
                        f"answer a read of its registers {IMU_ADDRESS}-{IMU_ADDRESS + IMU_LENGTH - 1} "
                        f"({OPEN_TRIES} tries)")

    def _measure_timeout(self) -> float:
        """The reply timeout (ms) for the run: 3x the slowest of a few good reads, plus 2 ms, at most the sdk's."""
        port = self._require_port()
        took = []
        for _ in range(OPEN_TRIES):
            start = time.perf_counter()
            try:
                self._sync_read(*READS[self.read_what], self.fast_read, extra=self._extra)
            except LinkReadError:
                continue
            took.append(1e3 * (time.perf_counter() - start))
            if len(took) == 3:
                break
        sdk = 2.0 * LATENCY_TIMER + 2.0 + port.tx_time_per_byte * 1000
        # at least 10 ms: a late reply counted as lost would count towards MAX_REPLY_LOSS on a busy host
        return min(max(3.0 * max(took, default=sdk) + 2.0, MIN_TIMEOUT_MS), sdk)

    def _hold_retrying(self) -> None:
        """`hold`, retrying reads that fail (a lost reply should not leave the servos on their old goals)."""
        for _ in range(OPEN_TRIES):
            try:
                self.hold()
                return
            except LinkReadError:
                continue
        raise LinkError(f"{self.path}: could not read the servos to hold them after {OPEN_TRIES} tries")

    def _read_at_open(self, address: int, length: int) -> bytes:
        """One sync read of every servo, retried; the data in joint order. LinkError after OPEN_TRIES."""
        try:
            return self._sync_read(address, length, fast=False, retries=OPEN_TRIES - 1)[1]
        except LinkReadError as err:
            raise LinkError(f"{err} ({OPEN_TRIES} tries; check power, ids, baud rate and Status Return Level)") \
                from None

    # -- bus transactions -----------------------------------------------------------------------

    def _reader(self, address: int, length: int, ids: tuple[int, ...],
                extra: tuple[int, int, int] | None = None) -> GroupSyncRead | GroupBulkRead:
        """The sync read of ``ids``, or with ``extra`` (id, address, length) the bulk read of both."""
        key = (address, length, ids, extra)
        reader = self._readers.get(key)
        if reader is None:
            if extra is None:
                reader = GroupSyncRead(self._port, self._ph, address, length)
                for dxl_id in ids:
                    reader.addParam(dxl_id)
            else:
                reader = GroupBulkRead(self._port, self._ph)
                for dxl_id in ids:
                    reader.addParam(dxl_id, address, length)
                reader.addParam(*extra)
            self._readers[key] = reader
        return reader

    def _sync_read(self, address: int, length: int, fast: bool, retries: int = 0,
                   sent: bool = False, extra: tuple[int, int, int] | None = None) -> tuple[list[int], bytes]:
        """(status error byte per servo, data of every servo concatenated), in joint order; the servos
        whose replies were lost asked again up to ``retries`` times (``sent``: the first instruction
        went out already, by `request`). ``extra`` (id, address, length): a device read in the first
        transaction too (a bulk read), its data left in ``_imu_data`` (None when lost). LinkReadError
        if some servos stay silent, LinkUnusable when the bus loses too many replies."""
        replies: dict[int, tuple[int, bytes]] = {}
        failures: dict[str, int] = {}
        missing = tuple(self.ids)
        self._imu_data = None
        for attempt in range(1 + retries):
            first = extra if attempt == 0 else None
            got, lost = self._transaction(address, length, fast, missing, sent=sent and attempt == 0, extra=first)
            if first is not None and first[0] in got:
                self._imu_data = got.pop(first[0])[1]
            replies.update(got)
            for kind, count in lost.items():
                failures[kind] = failures.get(kind, 0) + count
            self.loss.add(1 if fast else len(missing) + (first is not None), sum(lost.values()))
            missing = tuple(i for i in self.ids if i not in replies)
            if not missing:
                break
        if failures:
            self.stats.read_errors += sum(failures.values())
            for kind, count in failures.items():
                self.stats.errors_by_kind[kind] = self.stats.errors_by_kind.get(kind, 0) + count
        if self.loss.exceeded():
            raise LinkUnusable(f"{self.path}: {self.loss.describe()}: check the cable, its termination and the baud "
                               "rate")
        if missing:
            who = [self._who(self.ids.index(i)) for i in missing]
            detail = ", ".join(who[:4]) + (f" and {len(who) - 4} more" if len(who) > 4 else "")
            raise LinkReadError(f"{self.path}: sync read failed: {', '.join(f'{n} {k}' for k, n in failures.items())}"
                                f"; nothing usable from {detail}")
        return [replies[i][0] for i in self.ids], b"".join(replies[i][1] for i in self.ids)

    def _fast_sync_read(self, fields: np.dtype, sent: bool) -> np.ndarray:
        """`read`'s Fast Sync Read (``sent``: its instruction is out already, by `request`): the
        servos' records (error, id, ``fields``, crc) in joint order, a view over the receive
        buffer valid until the next read. LinkReadError when the reply is lost or rejected,
        LinkUnusable when the bus loses too many (as `_sync_read`)."""
        port = self._require_port()
        reply = self._fast_reply
        if reply is None or reply.records_dtype.names[2:-1] != fields.names:
            reply = self._fast_reply = FastReply(self.ids, fields)
        try:
            if not sent:
                port.clearPort()
                port.writePort(self._read_instruction())
            # the wait starts now: a `request`ed read's reply may have been waiting for a whole cycle
            timeout_ms = self._run_timeout_ms or 2.0 * LATENCY_TIMER + 2.0
            failure, got = reply.receive(port.ser.fileno(), timeout_ms / 1e3)
        except _PORT_ERRORS as err:
            raise LinkError(f"{self.path}: port failed: {err}") from None
        port.bytes_in += got
        self.loss.add(1, failure is not None)
        if failure is not None:
            self.stats.read_errors += 1
            self.stats.count(failure)
        if self.loss.exceeded():
            raise LinkUnusable(f"{self.path}: {self.loss.describe()}: check the cable, its termination and the baud "
                               "rate")
        if failure is not None:
            raise LinkReadError(f"{self.path}: fast sync read failed: 1 {failure}; nothing usable from any servo")
        return reply.records

    def _transaction(self, address: int, length: int, fast: bool, ids: tuple[int, ...], sent: bool = False,
                     extra: tuple[int, int, int] | None = None) -> tuple[dict[int, tuple[int, bytes]], dict[str, int]]:
        """One (Fast) Sync Read of ``ids``, or Bulk Read with ``extra`` (``sent``: its instruction is out
        already): (the replies by id, the lost or rejected ones by kind)."""
        port = self._require_port()
        reader = self._reader(address, length, ids, extra)
        try:
            if not sent:
                result = _fast_tx(reader) if fast else reader.txPacket()
                if result != COMM_SUCCESS:
                    raise LinkError(f"{self.path}: sync read not sent: {self._ph.getTxRxResult(result)}")
            if sent or (self._run_timeout_ms is not None and not self._opening):
                # the wait starts now: a `request`ed read's replies may have been waiting for a whole cycle
                port.setPacketTimeoutMillis(self._run_timeout_ms or 2.0 * LATENCY_TIMER + 2.0)
            requests = [(i, length) for i in ids] + ([] if extra is None else [(extra[0], extra[2])])
            return self._receive_fast(requests) if fast else self._receive_each(requests)
        except _PORT_ERRORS as err:
            raise LinkError(f"{self.path}: port failed: {err}") from None
        finally:
            port.is_using = False  # the sdk leaves it set when an exception cuts a transaction short

    def _receive_each(self, requests: list[tuple[int, int]]) -> tuple[dict[int, tuple[int, bytes]], dict[str, int]]:
        """One status packet per device of ``requests`` (id, data length), in any order, until all
        are in or the timeout passed."""
        port, ph = self._port, self._ph
        expected = len(requests)
        wanted = dict(requests)
        replies: dict[int, tuple[int, bytes]] = {}
        failures: dict[str, int] = {}
        while len(replies) + sum(failures.values()) < expected:
            packet, result = ph.rxPacket(port, False)
            if result == COMM_SUCCESS:
                # Un-stuffed by the sdk: the length field is exact, the list may run on past the CRC.
                # a good reply's length field counts instruction, error, data and CRC
                dxl_id = packet[PKT_ID]
                length = wanted.get(dxl_id, -9)
                if dxl_id not in replies and not packet[PKT_ERROR] & 0x7F \
                        and packet[PKT_LENGTH] | packet[PKT_LENGTH + 1] << 8 == length + 4:
                    replies[dxl_id] = (packet[PKT_ERROR], bytes(packet[PKT_DATA: PKT_DATA + length]))
                else:
                    failures["bad_reply"] = failures.get("bad_reply", 0) + 1
            elif result == COMM_RX_CORRUPT and not port.isPacketTimeout():
                failures["bad_crc"] = failures.get("bad_crc", 0) + 1  # framing intact: the next reply follows
            else:
                kind = "no_reply" if result == COMM_RX_TIMEOUT else "short_reply"
                failures[kind] = failures.get(kind, 0) + expected - len(replies) - sum(failures.values())
        return replies, failures

    def _receive_fast(self, requests: list[tuple[int, int]]) -> tuple[dict[int, tuple[int, bytes]], dict[str, int]]:
        """The one Fast Sync/Bulk Read status packet: (error, id, data, crc) per device of ``requests``
        (id, data length), in instruction order."""
        total = sum(length + 4 for _, length in requests)
        data, result, _ = self._ph.fastSyncReadRx(self._port, BROADCAST_ID, total)
        if result != COMM_SUCCESS:
            return {}, {"no_reply" if result == COMM_RX_TIMEOUT else "bad_crc": 1}
        if len(data) != total:
            return {}, {"short_reply": 1}
        replies = {}
        at = 0
        for dxl_id, length in requests:
            error = data[at]
            if data[at + 1] != dxl_id:
                return {}, {"short_reply": 1}
            if error & 0x7F:
                return {}, {"bad_reply": 1}
            replies[dxl_id] = (error, bytes(data[at + 2: at + 2 + length]))
            at += length + 4
        return replies, {}

    def _hardware_error(self, i: int) -> int:
        """Hardware Error Status of servo ``i`` (its status packet had the alert bit)."""
        try:
            value, result, error = self._ph.read1ByteTxRx(self._port, self.ids[i], HARDWARE_ERROR_STATUS)
        except _PORT_ERRORS as err:
            raise LinkError(f"{self.path}: port failed: {err}") from None
        if result != COMM_SUCCESS:
            self._lost_reply(result)
            raise LinkReadError(f"{self.path}: {self._who(i)} raised its alert bit, and reading its hardware error "
                                f"status failed: {self._ph.getTxRxResult(result)}")
        return value

    def _lost_reply(self, result: int) -> None:
        """Count the status packet of a unicast transaction that ended with ``result`` as lost or rejected."""
        self.stats.read_errors += 1
        self.stats.count("no_reply" if result == COMM_RX_TIMEOUT else "bad_crc")

    def write_ticks(self, ticks: np.ndarray, request: bool = False) -> None:
        """Goal ticks (n,) int32 from `goal_ticks`, as one sync write; with ``request``, the next
        read's instruction (`request`) goes out with it, in the same write to the port. Goals
        `prepare_goals` built and not sent are dropped: they share the packet's buffer, and these are newer."""
        self._prepared = None
        payload, goal_bytes = self._goals_packet().fill(ticks)
        self._send_goals(payload if request else payload[:goal_bytes], goal_bytes)

    def _goals_packet(self) -> GoalPacket:
        """The goals' sync write with the next read's instruction behind it, laid out once."""
        if self._goal_packet is None:
            self._require_port()
            self._goal_packet = GoalPacket(self.ids, GOAL_POSITION, self._read_instruction())
        return self._goal_packet

    def _send_goals(self, payload: bytes | bytearray, goal_bytes: int) -> None:
        """Write ``payload``: a sync write of goals (its first ``goal_bytes``) and, when it holds more, the
        next read's instruction (that read is then pending, as after `request`), in one write to the port.
        Sending clears the port's input: the replies of a pending read are taken in (and dropped) first."""
        port = self._require_port()
        if self._pending:
            try:
                self.read()
            except LinkReadError:
                pass  # counted; the write goes on
        self._rearm_after_silence()
        self.stats.writes += 1
        try:
            port.clearPort()
            port.stamp()
            port.ser.write(payload)
        except _PORT_ERRORS as err:
            self.stats.write_errors += 1
            raise LinkError(f"{self.path}: port failed: {err}") from None
        port.bytes_out += goal_bytes
        self._traffic[2] += goal_bytes
        self._traffic[3] += 1
        if len(payload) > goal_bytes:
            self._requested_bytes = port.bytes_out + port.bytes_in
            port.bytes_out += len(payload) - goal_bytes
            self._pending = True

    def _write_all(self, address: int, size: int, value: int) -> None:
        """The same value to every servo, one sync write (no reply)."""
        writer = GroupSyncWrite(self._require_port(), self._ph, address, size)
        raw = value.to_bytes(size, "little", signed=value < 0)
        for dxl_id in self.ids:
            writer.addParam(dxl_id, raw)
        self._send(writer)

    def _write_one(self, i: int, address: int, value: int) -> None:
        """One byte to servo ``i``, acknowledged; retried when the acknowledgement is lost (writing is idempotent)."""
        port = self._require_port()
        for _ in range(OPEN_TRIES):
            try:
                result, error = self._ph.write1ByteTxRx(port, self.ids[i], address, value)
            except _PORT_ERRORS as err:
                raise LinkError(f"{self.path}: port failed: {err}") from None
            if result == COMM_SUCCESS:
                break
            self._lost_reply(result)
        else:
            self.stats.write_errors += 1
            raise LinkError(f"{self.path}: writing address {address} of {self._who(i)}: no valid answer in "
                            f"{OPEN_TRIES} tries")
        if error:
            self.stats.write_errors += 1
            raise LinkError(f"{self.path}: writing address {address} of {self._who(i)} failed: error {error:#04x}")

    def _send(self, writer: GroupSyncWrite) -> None:
        port = self._require_port()
        self.stats.writes += 1
        before = port.bytes_out
        try:
            result = writer.txPacket()
            self._traffic[2] += port.bytes_out - before
            self._traffic[3] += 1
        except _PORT_ERRORS as err:
            self.stats.write_errors += 1
            raise LinkError(f"{self.path}: port failed: {err}") from None
        finally:
            port.is_using = False
        if result != COMM_SUCCESS:
            self.stats.write_errors += 1
            raise LinkError(f"{self.path}: sync write not sent: {self._ph.getTxRxResult(result)}")

    # -- helpers --------------------------------------------------------------------------------

    def _require_port(self) -> PortHandler:
        if self._port is None:
            raise LinkError(f"{self.path}: link is not open")
        return self._port

    def _release(self) -> None:
        self._pending = False
        self._prepared = None
        port, self._port = self._port, None
        if port is not None:
            try:
                port.closePort()
            except _PORT_ERRORS:
                pass  # already gone

    def _who(self, i: int) -> str:
        return f"servo {self.ids[i]} ({self.joint_names[i]})"


def _names_a_pty(path: str) -> bool:
    """Whether ``path`` leads (through its links) to a pseudo-terminal."""
    return os.path.realpath(path).startswith("/dev/pts/")


def _fast_tx(reader: GroupSyncRead | GroupBulkRead) -> int:
    """Send a Fast Sync Read or Fast Bulk Read instruction."""
    return reader.fastBulkReadTxPacket() if isinstance(reader, GroupBulkRead) else reader.fastSyncReadTxPacket()
