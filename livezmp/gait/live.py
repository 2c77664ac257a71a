"""Live gait estimate for the monitor: stride frequency, cadence, and per-channel DC and
amplitude over the last few cycles, updated frame by frame.

Per frame the cost is O(channels) and the memory is a fixed number of per-cycle sums,
whatever the session length. Cycles are marked as in :mod:`.cycles` (the reference
channel, normally a thigh's flexion angle, rising through its running mean with
hysteresis), but the running mean is an exponential average, so no history is kept.
Per completed cycle we keep the sample count and the sums of x and x² (about the
cycle's first sample, to avoid cancellation); DC is the pooled mean and amplitude
√2 × the pooled RMS about it, which is a sinusoid's amplitude. Angles are unwrapped
frame to frame, so a channel passing ±π does not jump.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from livezmp.errors import InputError
from livezmp.gait.cycles import HYSTERESIS


@dataclass(frozen=True)
class GaitLiveState:
    """At time ``t`` (s): ``stride_frequency`` Hz (gait cycles/s), ``cadence`` steps/min,
    ``dc`` (C,) rad in [−π, π) and ``amplitude`` (C,) rad, over the last ``n_cycles`` cycles."""

    t: float
    stride_frequency: float
    cadence: float
    dc: np.ndarray
    amplitude: np.ndarray
    n_cycles: int


@dataclass
class _Cycle:
    start: float
    count: int
    shift: np.ndarray
    s1: np.ndarray
    s2: np.ndarray


class GaitLiveEstimator:
    """Streaming gait estimator over ``n_channels`` angle channels (rad); ``ref`` is the
    index of the reference (thigh flexion) channel. ``cycles`` is how many recent cycles
    the estimate covers; a gap longer than ``max_period`` s between cycle starts (the
    subject stopped) clears it. ``tau`` s is the time constant of the running mean."""

    def __init__(self, n_channels: int, ref: int, cycles: int = 3, min_period: float = 0.4,
                 max_period: float = 3.0, tau: float = 2.0):
        if not 0 <= ref < n_channels:
            raise InputError(f"gait live: reference channel {ref} out of range 0..{n_channels - 1}")
        if cycles < 1 or not 0 < min_period < max_period or tau <= 0:
            raise InputError("gait live: need cycles ≥ 1, 0 < min_period < max_period, tau > 0")
        self.n, self.ref, self.min_period, self.max_period, self.tau = n_channels, ref, min_period, max_period, tau
        self._done: deque[_Cycle] = deque(maxlen=cycles)
        self._cur: _Cycle | None = None
        self._raw = self._unwrapped = None
        self._t = self._level = self._spread = self._prev_r = None
        self._armed = False
        self._state: GaitLiveState | None = None

    def _unwrap(self, x: np.ndarray) -> np.ndarray:
        if self._raw is None:
            self._unwrapped = x.copy()
        else:
            self._unwrapped = self._unwrapped + (x - self._raw + np.pi) % (2 * np.pi) - np.pi
        self._raw = x.copy()
        return self._unwrapped

    def _crossing(self, t: float, r: float) -> float | None:
        """Time of an upward crossing of the running mean by the reference, if this frame has one."""
        if self._level is None:
            self._level, self._spread, self._prev_r = r, 0.0, r
            return None
        a = min(1.0, (t - self._t) / self.tau)
        self._level += a * (r - self._level)
        self._spread += a * (abs(r - self._level) - self._spread)
        h = HYSTERESIS * self._spread * np.pi / 2  # spread = mean |deviation| = 2A/π for a sinusoid
        hit = None
        if self._spread > 1e-6 and r < self._level - h:
            self._armed = True
        elif self._armed and r >= self._level > self._prev_r:
            hit = self._t + (self._level - self._prev_r) / (r - self._prev_r) * (t - self._t)
            self._armed = False
        self._prev_r = r
        return hit

    def _close(self, at: float) -> None:
        cur = self._cur
        if cur is not None and cur.count > 0 and self.min_period <= at - cur.start <= self.max_period:
            self._done.append(cur)
        elif cur is not None:
            self._done.clear()

    def _estimate(self, t: float) -> GaitLiveState:
        count = sum(c.count for c in self._done)
        mean = sum(c.shift * c.count + c.s1 for c in self._done) / count
        # pooled second moment about the pooled mean, from each cycle's sums about its own shift
        m2 = sum(c.s2 + 2 * (c.shift - mean) * c.s1 + c.count * (c.shift - mean) ** 2 for c in self._done) / count
        period = (self._cur.start - self._done[0].start) / len(self._done)
        f = 1.0 / period
        dc = (mean + np.pi) % (2 * np.pi) - np.pi
        return GaitLiveState(t, f, 120.0 * f, dc, np.sqrt(2 * np.maximum(m2, 0.0)), len(self._done))

    def update(self, t: float, channels: np.ndarray) -> GaitLiveState | None:
        """Feed one frame (``t`` s, ``channels`` (C,) rad); returns the latest estimate, or
        None while fewer than one whole cycle has been seen since walking (re)started."""
        x = np.asarray(channels, dtype=float)
        if x.shape != (self.n,):
            raise InputError(f"gait live: frame has shape {x.shape}, expected ({self.n},)")
        if self._t is not None and t <= self._t:
            raise InputError(f"gait live: time went from {self._t} to {t}; it must increase")
        x = self._unwrap(x)
        hit = self._crossing(t, float(x[self.ref]))
        if hit is not None:
            self._close(hit)
            self._cur = _Cycle(hit, 0, x.copy(), np.zeros(self.n), np.zeros(self.n))
            self._state = self._estimate(t) if self._done else None
        elif self._cur is not None and t - self._cur.start > self.max_period:
            self._done.clear()
            self._cur, self._state = None, None
        if self._cur is not None:
            d = x - self._cur.shift
            self._cur.count += 1
            self._cur.s1 += d
            self._cur.s2 += d * d
        self._t = t
        return self._state
