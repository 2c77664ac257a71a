"""What a correction may do and aims for, shared by the offline solver and the online
corrector: rotation and rate limits, the ZMP target inside the polygon, the stance pivot."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # a type only: this module stays light for the command line's defaults
    from livezmp.balance.pipeline import FrameResult


# The correction solves all of a take's frames together (one Levenberg-Marquardt loop whose steps are
# kept by the whole take's cost: chunks would not give the same rotations), so a take is in memory
# whole. Measured (benchmarks/bench_correct_memory.py, fresh-process peak RSS, Bandai skeleton): ~640 MiB
# whatever the length plus 20-42 KiB a frame; from the upper figure a 4 GiB worker holds ~84 000 frames.
# Longer takes are refused (docs/archive.md, Limits): split them.
MAX_CORRECT_FRAMES = 80_000


def clip(x: np.ndarray, lower, upper) -> np.ndarray:
    """``np.clip(x, lower, upper)`` (NaN kept, the same values bit for bit) without its Python wrapper: the live
    loop's goal limiter and online corrector run it every cycle or correction, and the wrapper was more than half
    its cost (2.5 against 1.1 us on a 3-vector)."""
    return np.minimum(np.maximum(x, lower), upper)


@dataclass(frozen=True)
class CorrectionLimits:
    """Limits and weights. Angles in degrees, rates in degrees per second, lengths in m."""

    max_rotation_deg: tuple[float, float, float] = (15.0, 15.0, 10.0)  # about x, y, z (internal)
    max_rate_deg_s: float = 120.0
    margin_m: float = 0.005  # aim this far inside the polygon
    zmp_tolerance_m: float = 0.001  # σ_z
    rotation_scale_deg: float = 20.0  # σ_δ: how much a degree of rotation costs
    accel_scale_deg_s2: float = 3000.0  # σ_a: how much rotational acceleration costs
    iterations: int = 30
    # the search stops after ``patience`` Gauss-Newton iterations without ``progress`` (a fraction) fewer frames
    # outside than the best so far: the take is not being corrected (video2bvh_cxk: 14 iterations at 267-310 of
    # 900 frames outside, then the easing, 491 s CPU; now 7 and no easing, 61 s). The walks that are corrected
    # (Bandai's 24, two held-out) went on after at most 4 such, and every new best of theirs was at least 13 %
    # fewer (walk_active_003: 37 → 32; walk_exhausted_004: 1, 4, 3, 2, 2, then 0 outside)
    patience: int = 6
    progress: float = 0.05
    foot_hold_m: float = 0.0006  # how far a weight-bearing foot may move (the promise is 1 mm)


# The estimator cutoff (Hz) a correction judges the motion with, whatever its frame rate: a file's
# default (window 0.4 s, lag 0.1 s), so that `analyze` of the corrected file reads what the correction
# saw. Not a stream's per-rate default (3.0 Hz at 30 Hz, which keeps unknown noise out of a live
# reading): the correction edits the motion, so it needs the ZMP of the motion as it is. Behind a low
# cutoff a rotation's acceleration is halved and spread over a window twice as long, so the solver
# needs larger rotations for the same ZMP shift and reaches its limits (walk_active_001 at 30 Hz: 119
# of 207 frames left outside, rotations at 15°, at 3.0 Hz; none, 5.65° at 6 Hz).
CORRECTION_CUTOFF_HZ = 6.0  # the value of estimate.estimator.FILE_CUTOFF_HZ, not imported: scipy (0.3 s)


def correction_cutoff(cutoff_hz: float | None) -> float:
    """The estimator cutoff (Hz) of a correction: ``cutoff_hz`` (``--cutoff-hz``) if given, else
    :data:`CORRECTION_CUTOFF_HZ`."""
    return CORRECTION_CUTOFF_HZ if cutoff_hz is None else cutoff_hz


def stance_weights(results: list[FrameResult], ramp_frames: int) -> np.ndarray:
    """Weight of the left hip as the rotation pivot per frame (1 left stance, 0 right,
    ½ double/none), smoothed over ``ramp_frames`` so the pivot never jumps."""
    raw = np.array([{"left": 1.0, "right": 0.0}.get(r.support, 0.5) for r in results])
    if ramp_frames <= 1 or len(raw) < 2:
        return raw
    kernel = np.hanning(ramp_frames + 2)[1:-1]
    kernel /= kernel.sum()
    pad = ramp_frames
    padded = np.concatenate([np.full(pad, raw[0]), raw, np.full(pad, raw[-1])])
    return np.convolve(padded, kernel, mode="same")[pad:-pad]


def inset(p: np.ndarray, poly: np.ndarray, margin: float) -> np.ndarray:
    """``p`` (on or in the polygon) moved up to ``margin`` toward the polygon's centre."""
    d = poly.mean(axis=0) - p
    n = np.linalg.norm(d)
    return p + d / n * min(margin, n) if n > 1e-12 and len(poly) > 2 else p


def zmp_target(r: FrameResult, margin: float) -> np.ndarray | None:
    """The ZMP target (2,) for a frame that is outside or within ``margin`` of the edge."""
    if r.zmp is None or r.margin is None or r.margin >= margin:
        return None
    return inset(r.clamped[:2] if not r.inside else r.zmp[:2], r.polygon, margin)


def rate_limit(delta: np.ndarray, max_step: float, periodic: bool = False) -> tuple[np.ndarray, list[int]]:
    """Project ``delta`` (F, 3) so no frame-to-frame step exceeds ``max_step`` (rad),
    moving values toward zero; ``periodic``: the last frame is followed by the first (a
    loop's). Returns the result and the frames changed."""
    out = delta.copy()
    changed = set()
    pairs = [(k - 1, k) for k in range(1, len(out))] + ([(len(out) - 1, 0)] if periodic and len(out) > 1 else [])
    for _ in range(len(out)):
        moved = False
        for before, k in pairs:
            step = out[k] - out[before]
            bad = np.abs(step) > max_step + 1e-12
            if bad.any():
                # shrink the larger-magnitude end toward the other
                for a in np.nonzero(bad)[0]:
                    hi = k if abs(out[k, a]) > abs(out[before, a]) else before
                    lo = before if hi == k else k
                    out[hi, a] = out[lo, a] + np.sign(out[hi, a] - out[lo, a]) * max_step
                    changed.add(hi)
                moved = True
        if not moved:
            break
    return out, sorted(changed)
