"""Replay of a motion file (BVH, or joint-trajectory CSV with its URDF) in real time.

Frames are handed out when their time comes: a frame at time t (from the first frame)
at ``start + t / speed`` on the monotonic clock; ``speed`` 0 means as fast as the reader
takes them. With ``loop`` the motion starts over after its end, time continuing (one
frame period after the last frame), so the stream's time keeps increasing; each lap
after the first is marked ``restart`` (the motion jumps back), so the analysis starts over.
A looped cycle (:mod:`livezmp.model.loop_cycle`: its last frame repeats its first) is
played on as the loop it is instead: its repeated frame once, its root carried on by each
cycle's travel, one timeline, no restart.
"""

from __future__ import annotations

import time

import numpy as np

from livezmp.errors import InputError
from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec
from livezmp.model.loop_cycle import Loop
from livezmp.sources.interface import ErrorLog, SourceFrame, SourceStats


class Pacer:
    """Real-time pacing at ``speed`` × real time (0 = no waiting)."""

    def __init__(self, speed: float, where: str):
        if not speed >= 0:
            raise InputError(f"{where}: replay speed must be ≥ 0 (0 = as fast as possible), got {speed}")
        self.speed = speed
        self._start: float | None = None

    def due(self, t: float, timeout: float) -> float | None:
        """Wait until the frame at ``t`` s (from the first frame) is due, up to ``timeout``
        s; return the monotonic time it went out, or None if it is not due yet."""
        now = time.monotonic()
        if self._start is None:
            self._start = now
        if self.speed == 0:
            return now
        wait = self._start + t / self.speed - now
        if wait > timeout:
            time.sleep(max(timeout, 0.0))
            return None
        if wait > 0:
            time.sleep(wait)
            now = time.monotonic()
        return now


class FileReplaySource:
    """Replays ``frames`` (F, nq) at ``times`` (F,) s; ``cycle`` the take's loop, over the columns of ``frames``,
    played on when ``loop``; see the module docstring."""

    def __init__(self, name: str, body: BodyModel, body_spec: BodySpec, times: np.ndarray, frames: np.ndarray,
                 speed: float = 1.0, loop: bool = False, cycle: Loop | None = None):
        if len(frames) < 2:
            raise InputError(f"{name}: need at least 2 frames to replay, got {len(frames)}")
        self.name, self.body, self.body_spec = name, body, body_spec
        self.times = np.asarray(times, dtype=float)
        self.frames = np.asarray(frames, dtype=float)
        self.nominal_dt = float((self.times[-1] - self.times[0]) / (len(self.times) - 1))
        self.period = float(self.times[-1] - self.times[0]) + self.nominal_dt  # one pass of a loop
        self.pacer, self.loop = Pacer(speed, name), loop
        self.cycle = cycle if loop else None
        self.stats, self.errors = SourceStats(), ErrorLog()
        self._k = 0
        self._closed = False

    @property
    def finished(self) -> bool:
        return self._closed or (not self.loop and self._k >= len(self.frames))

    def read(self, timeout: float) -> SourceFrame | None:
        if self.finished:
            return None
        if self.cycle is not None:
            k = self._k
            t, row, restart = k * self.nominal_dt, self.cycle.rows(self.frames, k, k + 1)[0], False
        else:
            n = len(self.frames)
            i, lap = self._k % n, self._k // n
            # each lap after the first restarts the analysis: the wrap is a jump in the motion
            t, row = float(self.times[i] - self.times[0]) + lap * self.period, self.frames[i]
            restart = i == 0 and lap > 0
        sent = self.pacer.due(t, timeout)
        if sent is None:
            return None
        self._k += 1
        self.stats.delivered += 1
        return SourceFrame(float(self.times[0]) + t, row, None, sent, restart=restart)

    def close(self) -> None:
        self._closed = True
