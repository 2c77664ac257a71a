"""The one interface every frame source offers, and the small records it hands out.

A source delivers the input frames of one body, in order: :meth:`Source.read` returns a
:class:`SourceFrame` ``(t, channels, contacts)`` or None when nothing came within the
timeout; :attr:`Source.finished` turns true when no frame will ever come again (a file
played to its end). Faults of the link (bad packets, a dropped connection) never raise:
they are counted in :class:`SourceStats` and reported, rate-limited, through the
source's :class:`ErrorLog`, from which the monitor records them as device errors.

Adapting a servo link (``dynamixel:``, ``can:``, ``fw:``) is a class with these
attributes whose ``read`` polls the bus once per period and converts the present
positions to the body's channels (base channels first for a robot), with the foot
sensors, if any, as ``contacts``.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import asdict, dataclass
from typing import Protocol

import numpy as np

from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec


@dataclass(frozen=True)
class SourceFrame:
    """One input frame: ``t`` s on the source's clock (strictly increasing);
    ``channels`` (nq,) raw values in the body's channel order and the input's units
    (BVH: file length unit and degrees; robot: m and rad); ``contacts`` (left, right)
    from foot sensors, None to detect them; ``received`` ``time.monotonic()`` s at arrival;
    ``latency`` s from the source's own timestamp to arrival, when its clock can be
    related to this machine's (an LSL stream), else None; ``cop`` (3,) m the force plates'
    measured centre of pressure in the input's world frame (NaN when the plates are
    unloaded), None for a source without plates;
    ``restart``: the source's timeline starts over here (a looped file wrapped, a stream
    resynchronised), so the analysis restarts its estimator; ``gravity`` (3,) m/s² gravity in
    the input's frame when the ground is not level (a live loop's IMU estimate, replayed), else None."""

    t: float
    channels: np.ndarray
    contacts: tuple[bool, bool] | None = None
    received: float = 0.0
    latency: float | None = None
    cop: np.ndarray | None = None
    restart: bool = False
    gravity: np.ndarray | None = None


@dataclass
class SourceStats:
    """Counters of one source. ``delivered``: frames handed out. Dropped input:
    ``malformed`` (fails the frame schema, wrong channel count, non-finite value, time
    not increasing), ``oversized`` (longer than the limit), ``duplicate`` (a sequence
    number already seen), ``late`` (older than one already delivered: out of order),
    ``rejected`` (sender not on the allowlist), ``overflow`` (arrived while the reader's
    bounded queue was full), ``jumps`` (sequence or time jumped too far ahead). ``lost``:
    sequence numbers skipped and never delivered in order. ``resyncs``: times the source
    moved onto a new timeline (see :mod:`livezmp.sources.udp`). ``reconnects``:
    connections re-opened. ``disconnected``: reads that found a servo link's port gone (at its
    polling rate: 100 a second while it is gone). ``bad_markers``: capture frames kept with markers (or solved
    segments) left out that were infinite or beyond :data:`~livezmp.checks.MAX_COORDINATE_M` of the origin (a C3D reader
    refuses such a file). ``kernel_drops``: datagrams the kernel dropped before the source read them (its
    receive buffer full: the reader fell behind), counted where Linux offers it (``SO_RXQ_OVFL``) on a UDP source;
    None where not counted (other sources, other systems). They never arrived, so they are not among the dropped;
    a frame stream's sequence numbers count them in ``lost`` too."""

    delivered: int = 0
    malformed: int = 0
    oversized: int = 0
    duplicate: int = 0
    late: int = 0
    rejected: int = 0
    overflow: int = 0
    lost: int = 0
    jumps: int = 0
    resyncs: int = 0
    reconnects: int = 0
    disconnected: int = 0
    bad_markers: int = 0
    kernel_drops: int | None = None

    def as_dict(self) -> dict[str, int | None]:
        return asdict(self)

    @property
    def dropped(self) -> int:
        """Packets or lines received and thrown away."""
        return (self.malformed + self.oversized + self.duplicate + self.late + self.rejected + self.overflow
                + self.jumps)


@dataclass(frozen=True)
class DeviceError:
    """A fault of the source: ``wall`` time.time() s of the first occurrence, ``kind``
    (a :class:`SourceStats` field name or "disconnected"), ``message`` one line, ``count``
    occurrences folded into this report."""

    wall: float
    kind: str
    message: str
    count: int = 1


class ErrorLog:
    """Faults waiting to be recorded: at most one report per kind every ``interval`` s;
    repeats within the interval are folded into the next report of that kind (or into
    one made by :meth:`drain` once the interval has passed); at most ``maxlen`` reports
    wait. A flood of bad packets so costs O(1) memory and a few records per second."""

    def __init__(self, interval: float = 1.0, maxlen: int = 64):
        self.interval = interval
        self._out: deque[DeviceError] = deque(maxlen=maxlen)
        self._last: dict[str, float] = {}
        self._folded: dict[str, tuple[int, str]] = {}

    def report(self, kind: str, message: str, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        last = self._last.get(kind)
        if last is not None and now - last < self.interval:
            self._folded[kind] = (self._folded.get(kind, (0, ""))[0] + 1, message)
            return
        self._last[kind] = now
        count = 1 + self._folded.pop(kind, (0, ""))[0]
        self._out.append(DeviceError(time.time(), kind, message, count))

    def drain(self, now: float | None = None) -> list[DeviceError]:
        """The reports since the last call, oldest first, with folded repeats whose
        interval has passed reported under their latest message."""
        now = time.monotonic() if now is None else now
        for kind in [k for k, last in self._last.items() if now - last >= self.interval and k in self._folded]:
            count, message = self._folded.pop(kind)
            self._last[kind] = now
            self._out.append(DeviceError(time.time(), kind, message, count))
        out = list(self._out)
        self._out.clear()
        return out


class Source(Protocol):
    """Where frames come from (see the module docstring). ``name`` is shown to the
    operator; ``nominal_dt`` s is the expected frame period, None if unknown."""

    name: str
    body: BodyModel
    body_spec: BodySpec
    nominal_dt: float | None
    stats: SourceStats
    errors: ErrorLog

    @property
    def finished(self) -> bool: ...

    def read(self, timeout: float) -> SourceFrame | None:
        """The next frame, or None if none arrived within ``timeout`` s."""

    def close(self) -> None: ...
