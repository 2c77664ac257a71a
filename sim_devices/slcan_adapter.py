"""A simulated LAWICEL / slcan USB-CAN adapter on a pty, with simulated CAN nodes behind it.

Unmodified python-can opens it with
``can.Bus(interface="slcan", channel=adapter.path, bitrate=1_000_000)``
(pass ``sleep_after_open=0`` to skip python-can's 2 s wait). Commands are ASCII
lines ending in CR; the adapter answers CR for success and BEL for an error:

===========  ================================================================
``Sn``       bitrate n = 0..8 (10k, 20k, 50k, 100k, 125k, 250k, 500k, 800k, 1M);
             channel must be closed
``O`` / L    open the channel (``L``: listen only); needs a bitrate, closed
``C``        close the channel (always CR)
``tiiildd``  send a standard frame (3 hex id, dlc digit, data hex); reply ``z``
``Tiiiiiiiildd``  extended frame; reply ``Z``. ``r``/``R``: remote frames
``V`` / v    hardware and software version: ``V1013`` (python-can reads hw 10, sw 13)
``N``        serial number: ``NSIM1``
``F``        status flags as 2 hex digits (channel open); reading clears them
``Z0``/Z1    timestamps off/on (channel closed): 4 hex digits of ms, mod 60000
(empty)      no-op, CR
===========  ================================================================

Frames from the nodes reach the host as ``tiiildd[tttt]`` lines while the
channel is open, the bus is not off and the adapter's bitrate equals
``bus_bitrate`` (otherwise nothing is exchanged and the bus-error flag is
set). Status flag bits: 0x80 bus error, 0x20 error passive.

Faults (see `faults`): ``drop``/``corrupt``/``delay`` act on frames towards the
host (corrupt changes one data byte; frames without data are left intact),
``busoff`` episodes stop all traffic (sending answers BEL), ``vanish`` unplugs
the port; after it returns the adapter has power-cycled (closed, no bitrate).
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

from sim_devices.can_node import CanFrame, CanNode
from sim_devices.faults import FaultInjector, FaultSpec
from sim_devices.pty_port import PtyDevice, PtyPort, Reply

SUPPORTED_FAULTS = frozenset({"drop", "corrupt", "delay", "vanish", "busoff"})
BITRATES = (10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)
OK = b"\r"
ERROR = b"\a"
BUS_ERROR = 0x80
ERROR_PASSIVE = 0x20
MAX_LINE = 64  # longer than any valid command; a longer line is discarded with BEL
_HEX = "[0-9A-Fa-f]"
_FRAME = {  # command letter -> (pattern of the rest, extended, remote)
    "t": (re.compile(f"({_HEX}{{3}})([0-8])((?:{_HEX}{{2}})*)"), False, False),
    "T": (re.compile(f"({_HEX}{{8}})([0-8])((?:{_HEX}{{2}})*)"), True, False),
    "r": (re.compile(f"({_HEX}{{3}})([0-8])()"), False, True),
    "R": (re.compile(f"({_HEX}{{8}})([0-8])()"), True, True),
}


@dataclass
class AdapterStats:
    """Counts of frames through the adapter."""

    frames_from_host: int = 0  #: frames the host sent that reached the bus
    frames_to_host: int = 0  #: frames written to the host (after fault injection)
    frames_lost: int = 0  #: frames not exchanged: bus off or bitrate mismatch


def parse_frame(command: str) -> CanFrame | None:
    """The frame in a t/T/r/R command, or None if malformed."""
    pattern, extended, remote = _FRAME[command[0]]
    match = pattern.fullmatch(command, 1)
    if match is None:
        return None
    ident, dlc, data = match.groups()
    try:
        return CanFrame(int(ident, 16), bytes.fromhex(data), is_extended=extended, is_remote=remote,
                        dlc=int(dlc))
    except ValueError:  # dlc and data length disagree, or id out of range
        return None


def encode_frame(frame: CanFrame, timestamp_ms: int | None = None) -> bytes:
    """The line the adapter sends the host for ``frame``, CR included."""
    kind = ("R" if frame.is_extended else "r") if frame.is_remote else ("T" if frame.is_extended else "t")
    ident = f"{frame.arbitration_id:08X}" if frame.is_extended else f"{frame.arbitration_id:03X}"
    line = f"{kind}{ident}{frame.dlc}{frame.data.hex().upper()}"
    if timestamp_ms is not None:
        line += f"{timestamp_ms % 60000:04X}"
    return line.encode() + OK


class SlcanAdapter(PtyDevice):
    """An slcan adapter at :attr:`path` bridging the host to ``nodes`` (see module docstring).

    ``tick_period`` (s) is how often the nodes' ``tick`` runs while the channel is open.
    Node methods run on the port thread; give all nodes at construction.
    """

    def __init__(self, nodes: Sequence[CanNode] = (), *, faults: str | FaultSpec = "",
                 bus_bitrate: int = 1_000_000, tick_period: float = 1e-3, serial_number: str = "SIM1",
                 name: str = "ttySLCAN") -> None:
        if bus_bitrate not in BITRATES:
            raise ValueError(f"SlcanAdapter: bus_bitrate {bus_bitrate} is not an slcan rate "
                             f"({', '.join(map(str, BITRATES))})")
        if not tick_period > 0:
            raise ValueError(f"SlcanAdapter: tick_period must be > 0, got {tick_period}")
        self.nodes = list(nodes)
        self.bus_bitrate = bus_bitrate
        self.tick_period = tick_period
        self.serial_number = serial_number
        self.stats = AdapterStats()
        self._faults = FaultInjector(faults, supported=SUPPORTED_FAULTS, device="slcan adapter")
        self._lock = threading.Lock()
        self._line = bytearray()
        self._power_up()
        self._bus_off = False
        self._faults.start(time.monotonic())
        self._port = PtyPort(self, name)  # last: its thread calls back into this object

    # -- public API -------------------------------------------------------------------------------

    @property
    def is_open(self) -> bool:
        """True while the CAN channel is open (after O or L)."""
        return self._open

    # -- ByteDevice -------------------------------------------------------------------------------

    def on_bytes(self, data: bytes, now: float) -> list[Reply]:
        with self._lock:
            replies: list[Reply] = []
            self._line += data
            while True:
                end = self._line.find(OK)
                if end < 0:
                    if len(self._line) > MAX_LINE:
                        self._line.clear()
                        replies.append((now, ERROR))
                    return replies
                command = bytes(self._line[:end])
                del self._line[: end + 1]
                replies += self._command(command, now)

    def poll(self, now: float) -> list[Reply]:
        with self._lock:
            for event in self._faults.due_events(now):
                if event.kind == "busoff":
                    self._bus_off = True
                    self._flags |= BUS_ERROR | ERROR_PASSIVE
                elif event.kind == "busoff_end":
                    self._bus_off = False
                elif event.kind == "vanish":
                    self._port.vanish()
                elif event.kind == "restore":
                    self._line.clear()
                    self._power_up()
                    self._port.restore()
            if not self._open or now < self._next_tick:
                return []
            self._next_tick += self.tick_period
            if self._next_tick <= now:  # fell behind: keep the cadence from now, no burst
                self._next_tick = now + self.tick_period
            frames = [frame for node in self.nodes for frame in node.tick(now)]
            return self._to_host(frames, now)

    def next_deadline(self) -> float:
        with self._lock:
            tick = self._next_tick if self._open and self.nodes else math.inf
            return min(tick, self._faults.next_event_time())

    # -- internals --------------------------------------------------------------------------------

    def _power_up(self) -> None:
        self._bitrate: int | None = None
        self._open = False
        self._listen_only = False
        self._timestamps = False
        self._flags = 0
        self._opened_at = 0.0
        self._next_tick = math.inf

    def _bus_ok(self) -> bool:
        if self._bus_off or self._bitrate != self.bus_bitrate:
            self._flags |= BUS_ERROR
            return False
        return True

    def _command(self, raw: bytes, now: float) -> list[Reply]:
        try:
            command = raw.decode("ascii")
        except UnicodeDecodeError:
            return [(now, ERROR)]
        head = command[:1]
        if head in ("t", "T", "r", "R"):
            return self._transmit(command, now)
        reply = ERROR
        if command == "":
            reply = OK
        elif head == "S" and len(command) == 2 and command[1].isdigit() and int(command[1]) < len(BITRATES):
            if not self._open:
                self._bitrate = BITRATES[int(command[1])]
                reply = OK
        elif command in ("O", "L"):
            if not self._open and self._bitrate is not None:
                self._open, self._listen_only, self._opened_at = True, command == "L", now
                self._next_tick = now
                reply = OK
        elif command == "C":
            self._open = False
            self._next_tick = math.inf
            reply = OK
        elif command in ("V", "v"):
            reply = f"{command}1013".encode() + OK
        elif command == "N":
            reply = f"N{self.serial_number}".encode() + OK
        elif command == "F":
            if self._open:
                if self._bus_off:
                    self._flags |= BUS_ERROR | ERROR_PASSIVE
                reply = f"F{self._flags:02X}".encode() + OK
                self._flags = 0
        elif command in ("Z0", "Z1"):
            if not self._open:
                self._timestamps = command == "Z1"
                reply = OK
        return [(now, reply)]

    def _transmit(self, command: str, now: float) -> list[Reply]:
        frame = parse_frame(command)
        if frame is None or not self._open or self._listen_only or self._bus_off:
            if frame is not None and self._bus_off:
                self.stats.frames_lost += 1
            return [(now, ERROR)]
        ack = [(now, b"Z\r" if frame.is_extended else b"z\r")]
        if not self._bus_ok():
            self.stats.frames_lost += 1
            return ack
        self.stats.frames_from_host += 1
        answers = [reply for node in self.nodes for reply in node.on_frame(frame)]
        return ack + self._to_host(answers, now)

    def _to_host(self, frames: list[CanFrame], now: float) -> list[Reply]:
        if not frames:
            return []
        if not self._bus_ok():
            self.stats.frames_lost += len(frames)
            return []
        stamp = int((now - self._opened_at) * 1000.0) if self._timestamps else None
        replies = []
        for frame in frames:
            dropped, corrupt, extra = self._faults.reply_fate()
            if dropped:
                continue
            if corrupt and frame.data:
                frame = CanFrame(frame.arbitration_id, self._faults.corrupt(frame.data, 0, len(frame.data)),
                                 is_extended=frame.is_extended)
            replies.append((now + extra, encode_frame(frame, stamp)))
        self.stats.frames_to_host += len(replies)
        return replies
