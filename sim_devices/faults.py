"""Fault injection for the simulated devices, from a compact spec string.

A spec is a comma-separated list of ``field=value`` items (spaces ignored)::

    drop=0.01,corrupt=0.01,delay=0.01:5ms,overload=7@2s,vanish=3s+1s,seed=1

Fields:

``drop=P``
    Each reply (status packet, or CAN frame towards the host) is lost with
    probability ``P`` in [0, 1].
``corrupt=P``
    Each reply that is not dropped has one byte changed with probability ``P``
    (which bytes are eligible is up to the device: a Dynamixel status packet's
    error/parameter/CRC bytes, so the client's CRC check fails; a CAN frame's
    data bytes).
``delay=P:T``
    Each reply that is not dropped is held back by ``T`` with probability ``P``.
``overload=ID@T``
    Servo ``ID`` reports an overload hardware error ``T`` after the device
    starts (Dynamixel only). Repeatable.
``vanish=T+D``
    The port disappears ``T`` after start and comes back ``D`` later.
    Repeatable.
``busoff=T+D``
    The CAN bus goes bus-off ``T`` after start for ``D`` (slcan only).
    Repeatable.
``seed=N``
    Seed of the random generator (default 0), so runs are reproducible.

Times are a number with unit ``s``, ``ms`` or ``us``; a bare number is seconds.
A bad spec raises `ValueError` with a one-line message naming the field.

`FaultInjector` makes the random draws and keeps `FaultCounters` of what it
actually injected, so tests can compare them with the errors a client saw.
"""

from __future__ import annotations

import dataclasses
import random
import re
from dataclasses import dataclass, field

_TIME = re.compile(r"^([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)(s|ms|us)?$")
_UNITS = {None: 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6}
ALL_FIELDS = frozenset({"drop", "corrupt", "delay", "overload", "vanish", "busoff", "seed"})


@dataclass(frozen=True)
class FaultSpec:
    """Parsed fault spec; times in seconds from device start, probabilities in [0, 1]."""

    drop: float = 0.0
    corrupt: float = 0.0
    delay_probability: float = 0.0
    delay: float = 0.0
    overloads: tuple[tuple[int, float], ...] = ()
    vanishes: tuple[tuple[float, float], ...] = ()
    bus_offs: tuple[tuple[float, float], ...] = ()
    seed: int = 0
    fields: frozenset[str] = frozenset()


@dataclass
class FaultCounters:
    """What was actually injected (counts)."""

    dropped: int = 0
    corrupted: int = 0
    delayed: int = 0
    overloads: int = 0
    vanishes: int = 0
    bus_offs: int = 0


@dataclass(frozen=True, order=True)
class FaultEvent:
    """A timed fault: ``kind`` is one of overload, vanish, restore, busoff, busoff_end."""

    time: float
    kind: str
    arg: int = field(default=0, compare=False)


def _bad(name: str, value: str, why: str) -> ValueError:
    return ValueError(f"fault spec field '{name}': {why}, got '{value}'")


def _time(name: str, text: str) -> float:
    match = _TIME.match(text)
    if not match:
        raise _bad(name, text, "expected a time such as 2s, 5ms or 500us")
    return float(match.group(1)) * _UNITS[match.group(2)]


def _probability(name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise _bad(name, text, "expected a probability in [0, 1]") from None
    if not 0.0 <= value <= 1.0:
        raise _bad(name, text, "expected a probability in [0, 1]")
    return value


def _episode(name: str, text: str) -> tuple[float, float]:
    start, plus, length = text.partition("+")
    if not plus:
        raise _bad(name, text, "expected START+DURATION such as 3s+1s")
    return _time(name, start), _time(name, length)


def parse_faults(spec: str) -> FaultSpec:
    """Parse a fault spec string (see module docstring); '' means no faults."""
    values: dict[str, object] = {}
    overloads: list[tuple[int, float]] = []
    vanishes: list[tuple[float, float]] = []
    bus_offs: list[tuple[float, float]] = []
    seen: set[str] = set()
    for item in spec.replace(" ", "").split(","):
        if not item:
            continue
        name, eq, text = item.partition("=")
        if not eq or name not in ALL_FIELDS:
            raise ValueError(f"fault spec item '{item}': expected one of {', '.join(sorted(ALL_FIELDS))}"
                             " as field=value")
        if name in seen and name not in ("overload", "vanish", "busoff"):
            raise _bad(name, text, "given twice")
        seen.add(name)
        if name in ("drop", "corrupt"):
            values[name] = _probability(name, text)
        elif name == "delay":
            probability, colon, amount = text.partition(":")
            if not colon:
                raise _bad(name, text, "expected PROBABILITY:TIME such as 0.01:5ms")
            values["delay_probability"] = _probability(name, probability)
            values["delay"] = _time(name, amount)
        elif name == "overload":
            servo, at, when = text.partition("@")
            if not at or not servo.isdigit() or not 0 <= int(servo) <= 252:
                raise _bad(name, text, "expected ID@TIME with ID in 0..252, such as 7@2s")
            overloads.append((int(servo), _time(name, when)))
        elif name == "vanish":
            vanishes.append(_episode(name, text))
        elif name == "busoff":
            bus_offs.append(_episode(name, text))
        else:
            if not text.isdigit():
                raise _bad(name, text, "expected a non-negative integer")
            values["seed"] = int(text)
    return FaultSpec(overloads=tuple(overloads), vanishes=tuple(vanishes), bus_offs=tuple(bus_offs),
                     fields=frozenset(seen), **values)  # type: ignore[arg-type]


_UNHARMED = (False, False, 0.0)  # a reply's fate on a bus without reply faults: delivered whole, on time


class FaultInjector:
    """Random draws and timed events for one device, with counters of what was injected.

    ``supported`` names the spec fields the device implements; any other field in
    the spec is a ValueError naming it and ``device``.
    """

    def __init__(self, spec: FaultSpec | str, *, supported: frozenset[str], device: str) -> None:
        self.spec = parse_faults(spec) if isinstance(spec, str) else spec
        unsupported = sorted(self.spec.fields - supported - {"seed"})
        if unsupported:
            raise ValueError(f"fault spec field '{unsupported[0]}' does not apply to the {device}")
        self.counters = FaultCounters()
        self._rng = random.Random(self.spec.seed)
        events = [FaultEvent(t, "overload", servo) for servo, t in self.spec.overloads]
        for start, length in self.spec.vanishes:
            events += [FaultEvent(start, "vanish"), FaultEvent(start + length, "restore")]
        for start, length in self.spec.bus_offs:
            events += [FaultEvent(start, "busoff"), FaultEvent(start + length, "busoff_end")]
        self._events = sorted(events)
        self._next = 0
        self._start = 0.0
        self._next_time = self._event_time()
        # whether a reply's fate takes a draw: without, every reply of a clean bus is unharmed at once
        self._harms_replies = bool(self.spec.drop or self.spec.corrupt or self.spec.delay_probability)

    def start(self, now: float) -> None:
        """Set the time origin (monotonic s) of the timed events."""
        self._start = now
        self._next_time = self._event_time()

    def next_event_time(self) -> float:
        """Monotonic time (s) of the next timed event, or inf (kept: a device's port asks at every wake-up)."""
        return self._next_time

    def _event_time(self) -> float:
        if self._next < len(self._events):
            return self._start + self._events[self._next].time
        return float("inf")

    def due_events(self, now: float) -> list[FaultEvent]:
        """Timed events due by ``now``, in order, with absolute monotonic times; counts them."""
        due = []
        while self._next < len(self._events) and self._start + self._events[self._next].time <= now:
            event = self._events[self._next]
            self._next += 1
            due.append(dataclasses.replace(event, time=self._start + event.time))
            if event.kind == "overload":
                self.counters.overloads += 1
            elif event.kind == "vanish":
                self.counters.vanishes += 1
            elif event.kind == "busoff":
                self.counters.bus_offs += 1
        self._next_time = self._event_time()
        return due

    def reply_fate(self) -> tuple[bool, bool, float]:
        """Draw the fate of one reply: (dropped, corrupt, extra delay in s); counts what it draws."""
        if not self._harms_replies:
            return _UNHARMED
        spec = self.spec
        if spec.drop and self._rng.random() < spec.drop:
            self.counters.dropped += 1
            return True, False, 0.0
        corrupt = bool(spec.corrupt) and self._rng.random() < spec.corrupt
        delay = spec.delay if spec.delay_probability and self._rng.random() < spec.delay_probability else 0.0
        if delay:
            self.counters.delayed += 1
        return False, corrupt, delay

    def corrupt(self, data: bytes, start: int, stop: int) -> bytes:
        """Return ``data`` with one byte in ``data[start:stop]`` changed; counts it."""
        index = self._rng.randrange(start, stop)
        out = bytearray(data)
        out[index] ^= self._rng.randrange(1, 256)
        self.counters.corrupted += 1
        return bytes(out)
