"""Gait cycles from the thigh's flexion oscillation, and the walk's frequency.

A cycle (a stride: two steps) starts each time the thigh flexion angle rises through
its mean: first found with the middle of its range, then again with the mean over the
cycles found. Hysteresis (the angle must first fall 30 % of the half-range below that
level) keeps noise from making extra crossings. Only the longest run of consecutive
plausible cycles (within ±20 % of the median cycle time) is used, so standing still,
starting and stopping at either end of a take and interruptions are left out. The
frequency is refined by fitting the reference waveform's harmonics over those whole
cycles (exact for a periodic waveform).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from livezmp.errors import InputError
from livezmp.gait import harmonics as hm

HYSTERESIS = 0.3  # fraction of the half-range the angle must fall below the middle to re-arm
REGULARITY = 0.2  # a cycle more than 20 % off the median cycle time is not steady walking
MIN_SWING = np.deg2rad(1.0)  # a thigh that swings less than this is not walking


@dataclass
class Cycles:
    """``events`` (n+1,) s: cycle start times; ``frequency`` Hz: cycles (strides) per second."""

    events: np.ndarray
    frequency: float

    @property
    def n_cycles(self) -> int:
        return len(self.events) - 1

    def window(self, t: np.ndarray) -> np.ndarray:
        """Boolean mask of the samples of ``t`` inside the whole cycles."""
        return (t >= self.events[0]) & (t <= self.events[-1])


def up_crossings(t: np.ndarray, x: np.ndarray, level: float, hysteresis: float) -> np.ndarray:
    """Times (s) where ``x`` rises through ``level`` after being below ``level - hysteresis``;
    linear interpolation between samples."""
    out = []
    armed = False
    for k in range(len(x)):
        if x[k] < level - hysteresis:
            armed = True
        elif armed and x[k] >= level and k > 0:
            x0, x1 = x[k - 1], x[k]
            out.append(t[k - 1] + (level - x0) / (x1 - x0) * (t[k] - t[k - 1]))
            armed = False
    return np.asarray(out)


def _longest_run(events: np.ndarray, min_period: float, max_period: float) -> np.ndarray:
    periods = np.diff(events)
    ok = (periods >= min_period) & (periods <= max_period)
    if ok.any():
        typical = float(np.median(periods[ok]))
        ok &= np.abs(periods - typical) <= REGULARITY * typical
    best, start = (0, 0), None
    for i, good in enumerate([*ok, False]):
        if good and start is None:
            start = i
        elif not good and start is not None:
            if i - start > best[1] - best[0]:
                best = (start, i)
            start = None
    return events[best[0] : best[1] + 1]


def max_harmonics(frequency: float, sample_rate: float, wanted: int) -> int:
    """At most ``wanted`` harmonics, all below 45 % of the sample rate."""
    return max(1, min(wanted, int(0.45 * sample_rate / frequency)))


def detect_cycles(t: np.ndarray, x: np.ndarray, what: str, harmonics: int = 5,
                  min_period: float = 0.4, max_period: float = 3.0, min_cycles: int = 2) -> Cycles:
    """Cycles of the reference angle ``x`` (rad) sampled at ``t`` (s).

    ``what`` names the file and channel for errors. Raises :class:`InputError` when
    fewer than ``min_cycles`` whole cycles are found.
    """
    lo, hi = np.percentile(x, [5, 95])
    half = (hi - lo) / 2
    if half < MIN_SWING:
        raise InputError(f"{what}: swings only {np.rad2deg(2 * half):.2f}° peak to peak: not a walk")
    events = _longest_run(up_crossings(t, x, (hi + lo) / 2, HYSTERESIS * half), min_period, max_period)
    n = max(len(events) - 1, 0)
    needed = {1: "one", 2: "two"}.get(min_cycles, str(min_cycles))
    if n < min_cycles:
        raise InputError(f"{what}: fewer than {needed} whole gait cycles ({n}); need a longer take")
    f0 = n / (events[-1] - events[0])
    inside = (t >= events[0]) & (t <= events[-1])
    tw, xw = t[inside], x[inside]
    h = max_harmonics(f0, 1.0 / float(np.median(np.diff(t))), harmonics)
    best = minimize_scalar(lambda f: float(hm.fit(tw, xw, f, h)[1][0]), bounds=(0.95 * f0, 1.05 * f0),
                           method="bounded", options={"xatol": 1e-12 * f0})
    # Cycles start where the waveform rises through its own mean: there a smooth waveform is
    # nearly straight, so the interpolated times do not depend on where the samples fall.
    mean = float(hm.fit(tw, xw, best.x, h)[0][0, 0])
    events = _longest_run(up_crossings(t, x, mean, HYSTERESIS * half), min_period, max_period)
    if len(events) < min_cycles + 1:
        raise InputError(f"{what}: fewer than {needed} whole gait cycles ({max(len(events) - 1, 0)}); "
                         "need a longer take")
    return Cycles(events, float(best.x))
