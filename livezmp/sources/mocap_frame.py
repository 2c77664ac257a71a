"""What a live capture system hands over per frame: labelled markers and force plates.

The capture sources (``lsl://``, ``qtm://``, ``natnet://``) produce :class:`MocapFrame`
records in the stream's own axes (its up axis named), converted to SI units at the edge:
marker positions and centres of pressure in metres, forces in newtons, moments in
newton-metres. What turns markers into a body (the marker body model) comes after this.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from livezmp.sources.interface import ErrorLog, SourceStats

UP_AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
MIN_LOAD_N = 20.0  # N: plates carrying less are unloaded (no CoP), as in the C3D analysis


def _empty3() -> np.ndarray:
    return np.zeros((0, 3))


@dataclass(frozen=True)
class PlateSamples:
    """Force plates of one frame, in the stream's axes: ``names`` (p,); ``force`` (p, 3) N
    exerted on each plate; ``moment`` (p, 3) N·m about the plate's origin as the stream
    gives it; ``cop`` (p, 3) m, the centre of pressure (NaN when the plate is unloaded)."""

    names: tuple[str, ...] = ()
    force: np.ndarray = field(default_factory=_empty3)
    moment: np.ndarray = field(default_factory=_empty3)
    cop: np.ndarray = field(default_factory=_empty3)

    def __len__(self) -> int:
        return len(self.names)

    def combined_cop(self, up: np.ndarray, min_force: float = MIN_LOAD_N) -> np.ndarray:
        """(3,) m the centre of pressure of all plates together, in the stream's axes: each plate's CoP
        weighted by its force along ``up`` (3,) (unit vector; either sign convention of the force);
        exact for plates whose surfaces lie in one plane. NaN when they carry less than ``min_force`` N."""
        load = np.abs(self.force @ up)
        ok = np.isfinite(self.cop).all(axis=1) & (load > 0)
        total = float(load[ok].sum())
        if total < min_force:
            return np.full(3, np.nan)
        return (load[ok, None] * self.cop[ok]).sum(axis=0) / total


@dataclass(frozen=True)
class SegmentPoses:
    """Rigid bodies / skeleton segments the capture system solved, in the stream's axes: ``names``
    (s,), ``position`` (s, 3) m, ``rotation`` (s, 3, 3) (columns: the segment's axes), ``tracked`` (s,)."""

    names: tuple[str, ...] = ()
    position: np.ndarray = field(default_factory=_empty3)
    rotation: np.ndarray = field(default_factory=lambda: np.zeros((0, 3, 3)))
    tracked: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __len__(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class MocapFrame:
    """One capture frame. ``t`` s on the source's own clock (LSL: the sample's timestamp
    mapped onto this machine's LSL clock with the stream's clock offset; QTM: the frame
    timestamp; NatNet: the frame timestamp); ``received`` ``time.monotonic()`` s at arrival;
    ``frame`` the source's frame number (-1 when it has none); ``labels`` (n,) marker names;
    ``markers`` (n, 3) m in the stream's axes, NaN where a marker is occluded; ``up`` the
    stream's up axis ("+z", "+y", ...); ``plates`` the force plates (empty without);
    ``latency`` s from the source's timestamp to ``received`` when the source's clock can
    be related to this machine's (LSL), else None; ``segments`` the rigid bodies and skeleton
    segments the system solved (empty without); ``restart``: the stream's timeline starts over
    here (connected anew, or resynchronised: :class:`~livezmp.sources.udp.Timeline`)."""

    t: float
    received: float
    frame: int
    labels: tuple[str, ...]
    markers: np.ndarray
    up: str
    plates: PlateSamples = field(default_factory=PlateSamples)
    latency: float | None = None
    segments: SegmentPoses = field(default_factory=SegmentPoses)
    restart: bool = False

    def marker(self, label: str) -> np.ndarray:
        """Position (3,) m of the marker ``label``; KeyError if the stream has no such label."""
        return self.markers[self.labels.index(label)]


def parse_up_axis(text: str, where: str) -> str:
    """``"Z"``, ``"+Z"``, ``"-y"`` ... → the canonical form ("+z"); ValueError naming ``where``."""
    s = text.strip().lower()
    s = s if s[:1] in "+-" else "+" + s
    if s not in UP_AXES:
        raise ValueError(f"{where}: up axis {text!r} is not one of x, y, z (with an optional sign)")
    return s


class MocapSource(Protocol):
    """A live capture stream (``lsl://``, ``qtm://``, ``natnet://``): ``name`` shown to the
    operator; ``nominal_dt`` s the stream's frame period as the stream states it; ``up`` its up
    axis and ``labels`` its marker labels as the stream states them at connection;
    ``stats``/``errors`` as every source's (:mod:`livezmp.sources.interface`)."""

    name: str
    nominal_dt: float
    up: str
    labels: tuple[str, ...]
    stats: SourceStats
    errors: ErrorLog

    @property
    def finished(self) -> bool: ...

    def read(self, timeout: float) -> MocapFrame | None:
        """The next frame in order, or None if none arrived within ``timeout`` s."""

    def close(self) -> None: ...


class FrameQueue:
    """Frames handed from a client's receiving thread to the reader: at most ``maxlen``
    wait; one arriving when full is counted in ``stats.overflow`` and thrown away (the
    newest is dropped, so what is delivered stays in order)."""

    def __init__(self, stats: SourceStats, maxlen: int = 4096):
        self.stats, self.maxlen = stats, maxlen
        self._q: deque[MocapFrame] = deque()
        self._cv = threading.Condition()

    def put(self, frame: MocapFrame) -> None:
        with self._cv:
            if len(self._q) >= self.maxlen:
                self.stats.overflow += 1
                return
            self._q.append(frame)
            self._cv.notify()

    def get(self, timeout: float) -> MocapFrame | None:
        with self._cv:
            if not self._q:
                self._cv.wait(timeout)
            return self._q.popleft() if self._q else None
