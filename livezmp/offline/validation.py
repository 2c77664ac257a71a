"""Validation of a take's ZMP and centre-of-mass motion against force plates.

On a flat floor the ZMP of the whole body is the centre of pressure (CoP) the plates measure,
and the centre of mass accelerates by (GRF - m g) / m: both are independent truths for what
livezmp computes from the motion alone. Positions in metres, internal frame (z up).
"""

from __future__ import annotations

import numpy as np
from scipy.stats import t as student_t

from livezmp.balance.plates import G, lowpass
from livezmp.model.markers import sway_basis, travel_axes

MAX_LAG_S = 0.1  # s: the lag search covers ± this
# A lag is *determined* when the first and second halves of the frames give lags this close (and neither at the
# search's edge): their difference estimates the lag's own uncertainty, and one wider than the ±10 ms a lag is
# judged against cannot tell a clock offset from noise (on one stance the RMS hardly depends on the shift).
LAG_AGREE_S = 0.02
# s: the blocks a lag's uncertainty is found over (:func:`lag_uncertainty`). The ZMP − CoP error's autocorrelation
# is below zero by 0.1 s, but the lag drifts over longer stretches (a stance): with 0.1 s blocks the halves of the
# held-out walks disagreed more than the interval allowed (the p-value of their difference against it, median 0.37
# on the tuning half / 0.32 on the test half, where 0.5 is right); with 0.2 s, 0.50 / 0.53 (docs/validation.md)
LAG_BLOCK_S = 0.2
# at most this many blocks (a long take's are longer): each costs one full lag search, and 30 already put Student's t
# within 5 % of the normal's
LAG_MAX_BLOCKS = 40
LAG_CONFIDENCE = 0.95  # the two-sided level of the lag's interval
# The walk's heading at each frame (:func:`walk_heading`): its velocity low-passed below the stride (a slow walk's
# 0.7 Hz strides sway the heading by 1 deg through it), counted from half a slow walk's speed (0.4 m/s) up; slower,
# swaying or standing, the whole take's travel or the way the subject faces
HEADING_HZ = 0.5
HEADING_SPEEDS_MPS = (0.2, 0.4)


def walking_axes(com: np.ndarray, facing: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unit horizontal (3,) fore-aft (the CoM's net travel; when it barely moves, ``facing`` (horizontal: the way
    the subject faces), else +x) and lateral (left of it) directions."""
    return travel_axes(com[-1, :2] - com[0, :2], facing)


def _slow_velocity(origin: np.ndarray, rate: float) -> np.ndarray:
    """(F, 3) m/s horizontal velocity of ``origin`` (F, 3) m at ``rate`` Hz, low-passed at ``HEADING_HZ``."""
    vel = np.gradient(lowpass(origin, rate, HEADING_HZ), 1.0 / rate, axis=0)
    vel[:, 2] = 0.0
    return vel


def walk_heading(origin: np.ndarray, rate: float, facing: np.ndarray | None = None) -> np.ndarray:
    """(F, 3) unit horizontal axis (internal frame) along which a walk whose point ``origin`` (F, 3) m at
    ``rate`` Hz heads at each frame: its velocity low-passed at ``HEADING_HZ`` (below the stride, so that the
    lateral sway does not swing it) where it moves faster than ``HEADING_SPEEDS_MPS``' upper end, the whole
    take's travel (:func:`sway_basis`; standing: the way it faces) below the lower, blended between. An axis, not
    a direction: it points along the take's travel (:func:`path_axes` turns it the way the walk goes)."""
    _, fwd, _ = sway_basis(origin, facing)
    vel = _slow_velocity(origin, rate)
    speed = np.linalg.norm(vel, axis=1, keepdims=True)
    lo, hi = HEADING_SPEEDS_MPS
    w = np.clip((speed - lo) / (hi - lo), 0.0, 1.0)
    w = w * w * (3 - 2 * w)  # smoothstep: no kink where the walk starts to count
    # a heading against the take's travel is the same axis: blended with the travel it must not cancel it
    local = vel / np.maximum(speed, 1e-9) * np.sign(vel @ fwd + 1e-12)[:, None]
    d = w * local + (1 - w) * fwd
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def path_axes(com: np.ndarray, rate: float, facing: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unit horizontal fore-aft and lateral (left of it) axes (F, 3 each, internal frame) that follow the path of
    a walk whose centre of mass ``com`` (F, 3) m at ``rate`` Hz turns: at each frame :func:`walk_heading`, pointed
    the way the CoM moves where it moves faster than ``HEADING_SPEEDS_MPS``' lower end (a walk that turns back
    turns its fore-aft with it). On a straight walk they are :func:`walking_axes`' to within the heading's sway;
    on a turn those, the net travel's, would put half of a 90 deg turn's fore-aft offset into the lateral."""
    axis = walk_heading(com, rate, facing)
    vel = _slow_velocity(com, rate)
    back = (np.linalg.norm(vel, axis=1) > HEADING_SPEEDS_MPS[0]) & (np.einsum("ij,ij->i", axis, vel) < 0)
    fwd = np.where(back[:, None], -axis, axis)
    return fwd, np.stack([-fwd[:, 1], fwd[:, 0], np.zeros(len(fwd))], axis=1)


def _errors(a: np.ndarray, b: np.ndarray, rows: np.ndarray, shift: int) -> np.ndarray:
    """a(t + shift frames) − b(t) over the rows where both are valid."""
    idx = np.flatnonzero(rows)
    idx = idx[(idx + shift >= 0) & (idx + shift < len(a))]
    d = a[idx + shift] - b[idx]
    return d[np.isfinite(d).all(axis=1)]


def best_lag(a: np.ndarray, b: np.ndarray, rows: np.ndarray, dt: float) -> float | None:
    """The shift (s) of signal ``a`` (N, k) that minimises its RMS distance to ``b`` (N, k) over ``rows``,
    refined between frames by a parabola; positive: ``a`` lags (comes after) ``b``."""
    k = int(round(MAX_LAG_S / dt))
    shifts = np.arange(-k, k + 1)
    rms = np.array([np.sqrt(np.mean(np.sum(e * e, axis=1))) if len(e := _errors(a, b, rows, s)) else np.inf
                    for s in shifts])
    if not np.isfinite(rms).any():
        return None
    i = int(np.argmin(rms))
    frac = 0.0
    if 0 < i < len(rms) - 1 and np.isfinite(rms[i - 1 : i + 2]).all():
        a, b, c = rms[i - 1 : i + 2]
        den = a - 2 * b + c
        frac = 0.5 * (a - c) / den if den > 0 else 0.0
    return float((shifts[i] + frac) * dt)


def lag_with_halves(a: np.ndarray, b: np.ndarray, rows: np.ndarray,
                    dt: float) -> tuple[float | None, bool, list]:
    """:func:`best_lag` over ``rows`` (s), whether it is determined (see ``LAG_AGREE_S``), and the lags over
    the first and second halves of ``rows`` (s, None where there is none)."""
    idx = np.flatnonzero(rows)
    halves = []
    for part in (idx[: len(idx) // 2], idx[len(idx) // 2 :]):
        sel = np.zeros(len(rows), dtype=bool)
        sel[part] = True
        halves.append(best_lag(a, b, sel, dt) if len(part) else None)
    lag = best_lag(a, b, rows, dt)
    edge = MAX_LAG_S - dt / 2
    ok = (lag is not None and all(h is not None and abs(h) < edge for h in halves)
          and abs(halves[0] - halves[1]) <= LAG_AGREE_S)
    return lag, ok, halves


def lag_uncertainty(a: np.ndarray, b: np.ndarray, rows: np.ndarray, dt: float) -> float | None:
    """Half-width (s) of the ``LAG_CONFIDENCE`` interval of :func:`best_lag` over ``rows``: a delete-one-block
    jackknife over consecutive ``LAG_BLOCK_S`` blocks of ``rows`` (at most ``LAG_MAX_BLOCKS``; Efron & Tibshirani
    1993, *An Introduction to the Bootstrap*, ch. 11: blocks keep the error's own correlation inside them) with
    Student's t at one fewer degrees of freedom than blocks. A flat RMS curve, or parts of the take that want
    different shifts (a single stance: early stance later, late stance earlier), give a wide one. None with fewer
    than two blocks or where a block's removal leaves no lag."""
    idx = np.flatnonzero(rows)
    n = min(int(round(len(idx) * dt / LAG_BLOCK_S)), LAG_MAX_BLOCKS)
    if n < 2:
        return None
    lags = []
    for part in np.array_split(idx, n):
        rest = rows.copy()
        rest[part] = False
        lags.append(best_lag(a, b, rest, dt))
    if any(v is None for v in lags):
        return None
    lags = np.array(lags)
    se = np.sqrt((n - 1) / n * np.sum((lags - lags.mean()) ** 2))
    return float(student_t.ppf(0.5 + LAG_CONFIDENCE / 2, n - 1) * se)


def ms(v: float | None) -> float | None:
    """Seconds (or None) as milliseconds rounded to 0.1 ms, for summaries."""
    return None if v is None else round(1000 * v, 1)


def cop_vs_zmp(zmp: np.ndarray, has_zmp: np.ndarray, cop: np.ndarray, complete: np.ndarray, com: np.ndarray,
               dt: float, facing: np.ndarray | None = None, clock_uncertainty_s: float = 0.0) -> dict:
    """ZMP against plate CoP over the complete frames that have a ZMP: count, RMS, p95 and max of the
    horizontal distance (mm), mean ZMP − CoP along the walking direction and to its left at each frame
    (:func:`path_axes`: on a turning walk the axes turn with the path) (mm), and
    the lag (ms, see :func:`best_lag`; reported, not applied; None when not determined, see
    :func:`lag_with_halves`), the lag over all those frames whether determined or not, its uncertainty (ms,
    the half-width of its 95 % interval: :func:`lag_uncertainty` and, root-sum-square, ``clock_uncertainty_s``,
    that of a plate delay applied to ``cop``, whose error the lag takes on whole; None with under two blocks)
    and the lags over the first and second halves of those frames (ms)."""
    rows = complete & has_zmp & np.isfinite(cop).all(axis=1)
    d = zmp[rows, :2] - cop[rows, :2]
    if not len(d):
        return {"frames": 0, "rms_mm": None, "p95_mm": None, "max_mm": None, "bias_mm": None, "lag_ms": None,
                "lag_estimate_ms": None, "lag_uncertainty_ms": None, "lag_halves_ms": None}
    dist = np.hypot(d[:, 0], d[:, 1])
    fwd, left = (ax[rows, :2] for ax in path_axes(com, 1.0 / dt, facing))
    shown = np.where(has_zmp[:, None], zmp, np.nan)[:, :2]
    lag, determined, halves = lag_with_halves(shown, cop[:, :2], rows, dt)
    own = lag_uncertainty(shown, cop[:, :2], rows, dt)
    return {
        "frames": int(rows.sum()),
        "rms_mm": round(1000 * float(np.sqrt(np.mean(dist ** 2))), 2),
        "p95_mm": round(1000 * float(np.percentile(dist, 95)), 2),
        "max_mm": round(1000 * float(dist.max()), 2),
        "bias_mm": [round(1000 * float(np.mean(np.einsum("ij,ij->i", d, ax))), 2) for ax in (fwd, left)],
        "lag_ms": ms(lag) if determined else None,
        "lag_estimate_ms": ms(lag),
        "lag_uncertainty_ms": None if own is None else ms(float(np.hypot(own, clock_uncertainty_s))),
        "lag_halves_ms": [ms(h) for h in halves],
    }


def plate_delay(com_acc: np.ndarray, plate_acc: np.ndarray, rows: np.ndarray,
                dt: float) -> tuple[float | None, bool, list, float | None]:
    """How late (s) the plates' acceleration (GRF − m g) / m (N, 3) comes after the kinematic CoM
    acceleration (N, 3) over ``rows``: the plates' clock against the markers'. Both sides measure the
    whole body's acceleration, so a shift between them is timing, not the body model. Also whether it is
    determined (:func:`lag_with_halves`), the delays over the two halves of ``rows`` (s) and the half-width of
    its 95 % interval (s, :func:`lag_uncertainty`)."""
    lag, determined, halves = lag_with_halves(com_acc, plate_acc, rows, dt)
    return ((None if lag is None else -lag), determined, [None if h is None else -h for h in halves],
            lag_uncertainty(com_acc, plate_acc, rows, dt))


def com_acc_vs_plates(com_acc: np.ndarray, force: np.ndarray, mass: float, complete: np.ndarray) -> dict:
    """The CoM acceleration from the kinematics (F, 3) against (GRF − m g) / m from the plates over the
    complete frames: Pearson r and RMS difference (m/s²) per axis x, y, z (internal frame)."""
    rows = complete & np.isfinite(com_acc).all(axis=1)
    if rows.sum() < 3:
        return {"frames": int(rows.sum()), "r": None, "rms_mps2": None}
    plates = force[rows] / mass - np.array([0.0, 0.0, G])
    kin = com_acc[rows]
    r = [float(np.corrcoef(kin[:, k], plates[:, k])[0, 1]) if kin[:, k].std() > 0 and plates[:, k].std() > 0
         else None for k in range(3)]
    rms = np.sqrt(np.mean((kin - plates) ** 2, axis=0))
    return {"frames": int(rows.sum()), "r": [None if v is None else round(v, 4) for v in r],
            "rms_mps2": [round(float(v), 4) for v in rms]}


def force_line_offset(point: np.ndarray, com: np.ndarray, force: np.ndarray, surface_z: float) -> np.ndarray:
    """(N, 2) m: how far ``point`` (N, 3) lies, horizontally, from where the line of ``force`` (N, 3) N through
    the centre of mass ``com`` (N, 3) meets the floor at height ``surface_z`` (m): point − (com − h F_h / F_z).
    For the plates' CoP and ground reaction through the true CoM this is the whole body's rate of change of
    angular momentum about its CoM over F_z (Newton–Euler: the CoP is off the force line only by that), through
    a model's CoM that plus where the model misplaces the CoM; for the ZMP and m (a + g) from the kinematics it
    is the model's own segments' rate. NaN where F_z ≤ 0."""
    fz = np.where(force[:, 2] > 0, force[:, 2], np.nan)
    h = com[:, 2] - surface_z
    return point[:, :2] - (com[:, :2] - h[:, None] * force[:, :2] / fz[:, None])


def stance_gap(offset: np.ndarray, stance: np.ndarray, axes: tuple[np.ndarray, np.ndarray],
               min_frames: int) -> list[float] | None:
    """Half the difference (m, [fore-aft, lateral] along ``axes``) between the mean ``offset`` (N, 2) m over
    the frames standing on the left foot and over those on the right (``stance``: 0 left, 1 right, else
    neither); laterally positive: out towards the stance foot. None with fewer than ``min_frames`` a side.
    Laterally it is the part of the body's roll (angular momentum about the walk) that turns with the stance,
    F_z times the offset: a trunk leaning over the stance leg and back puts the CoP outside the force line in
    every stance."""
    means = []
    for side in (0, 1):
        rows = (stance == side) & np.isfinite(offset).all(axis=1)
        if rows.sum() < min_frames:
            return None
        means.append(offset[rows].mean(axis=0))
    half = (means[0] - means[1]) / 2
    return [float(half @ axes[0][:2]), float(half @ axes[1][:2])]


def cop_vs_force_line(cop: np.ndarray, zmp: np.ndarray, com: np.ndarray, plate_force: np.ndarray,
                      kin_force: np.ndarray, surface_z: float, stance: np.ndarray, rows: np.ndarray,
                      axes: tuple[np.ndarray, np.ndarray], min_frames: int) -> dict:
    """The plates' CoP against their own force line (:func:`force_line_offset`: the plates' CoP and ground
    reaction ``plate_force`` (N, 3) N through the markers' CoM ``com`` (N, 3) m) beside the ZMP against the
    kinematics' (``kin_force`` = m (a + g), N): RMS over ``rows`` (mm, [fore-aft, lateral] along ``axes``) and
    :func:`stance_gap` over those of them in single support (``stance`` 0 left, 1 right; mm). Both measure the
    body's rate of change of angular momentum, the plates the subject's (through the marker body's CoM) and the
    ZMP the marker body's: a plates' lateral offset or stance gap the ZMP lacks is roll or lean the marker body
    does not have (an upright, placed trunk cannot lean over the stance leg), and no CoM acceleration closes it."""
    single = rows & np.isin(stance, (0, 1))
    out = {"frames": int(rows.sum()), "single_support_frames": int(single.sum())}
    for name, point, force in (("plates", cop, plate_force), ("zmp", zmp, kin_force)):
        off = force_line_offset(point, com, force, surface_z)
        ok = rows & np.isfinite(off).all(axis=1)
        rms = [np.sqrt(np.mean((off[ok] @ ax[:2]) ** 2)) if ok.any() else None for ax in axes]
        gap = stance_gap(off, np.where(ok & single, stance, -1), axes, min_frames)
        out[f"{name}_rms_mm"] = [None if v is None else round(1000 * float(v), 1) for v in rms]
        out[f"{name}_stance_gap_mm"] = None if gap is None else [round(1000 * v, 1) for v in gap]
    return out
