"""Force plates: unloaded offsets, the plates' signals at the marker frames, combined centre of
pressure, and the frames where the plates saw the whole body.

Frames: the internal one (z up, metres). The centre of pressure (CoP) is where the combined
ground reaction's moment has no horizontal component, on the plates' top surface; on a flat
floor it is the ZMP the motion implies.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import butter, sosfiltfilt

from livezmp.errors import InputError
from livezmp.model.c3d import C3dTrial, PlateRecord
from livezmp.model.marker_map import MarkerMap
from livezmp.model.markers import input_rotation

QUIET_WINDOW_S = 0.1  # s: an unloaded stretch this long gives a plate's offset
QUIET_STD_N = 3.0  # N: vertical force this steady (std) is "quiet"
UNLOADED_MAX_N = 100.0  # N: a quiet stretch above this is someone standing, not an offset
# N: a plate cannot pull a foot down; an offset-free vertical force whose mean over QUIET_WINDOW_S goes below -this
# (ten times the quiet noise) is a drifting or faulty plate, set aside (a foot on it is off the plates). The mean,
# not the low-passed force: the low-pass rings below zero after a short hard stance (a running step, 1750 N over
# 0.25 s, -44 N at 4.9 Hz: AnyBody's SlowRun had both its plates set aside)
PULL_N = 10 * QUIET_STD_N
# N: an offset-free vertical force whose mean over QUIET_WINDOW_S goes above this carries no person (two tonnes-force:
# 8 body weights of a 250 kg subject, where drop landings peak at 5-8 and running at 2.5-3): a channel scale or unit
# wrong, set aside as a pulling plate is (channels 1e30 times too large had their plate's offset read as a load)
OVERLOAD_N = 20_000.0
CONTACT_MARGIN_M = 0.02  # m: a sole corner this close outside a plate's outline still counts as on it
G = 9.81
# m: stepped-on plates' surfaces further apart in height than this are not one floor (a stair's step is 150-200 mm;
# the plates of the trials read so far lie within 3 mm of each other)
LEVEL_M = 0.05
# deg: a stepped-on plate whose surface (the plane of its corners) leans further than this from level is a ramp's or a
# slope's, no level floor (FH Campus Wien's ramp plates in fhstp/autoSIM lean 9.9 deg; every other plate stepped on
# in the 269 of the trials read so far lies within 0.8 deg of it: docs/validation.md, held-out round 6)
MAX_TILT_DEG = 2.0
STANDING_S = 1.5  # s: plates loaded this long without a break are stood on, not walked over
# a foot stands still (stance, :func:`raised_by`) while its ankle centre moves slower than this horizontally, for at
# least STILL_S: a walking stance's ankle holds still 0.3-0.4 s, a swing moves it at 1-5 m/s
STILL_MPS = 0.15
STILL_S = 0.1
# stance-frame mass: at least this many frames carried whole, and at least this part of the frames with the feet on
# the plates (fewer: the plates miss the load in most of them, e.g. a plate set aside)
STANCE_MIN_FRAMES = 10
STANCE_MIN_KEPT = 0.5
UP = np.array([0.0, 0.0, 1.0])


@dataclass
class PlateFrames:
    """The plates at the marker frames (F rows), internal frame. ``force`` (F, 3) N, summed over
    plates; ``cop`` (F, 3) m, NaN where the vertical force is below ``min_fz``; ``outlines``
    [(4, 3)] m; ``offsets`` per plate (force N, moment N·m) removed, or None when the plate never
    rested unloaded."""

    force: np.ndarray
    moment: np.ndarray  # (F, 3) N·m about the world origin
    cop: np.ndarray
    outlines: list[np.ndarray]
    offsets: list[tuple[np.ndarray, np.ndarray] | None]
    surface_z: float
    set_aside: list[dict] = field(default_factory=list)  # {plate (1-based), min_fz_n or max_fz_n, reason}: not used
    # each plate used (the order of ``outlines``): its number (1-based) and its own CoP (F, 3) m, NaN below min_fz
    used: list[int] = field(default_factory=list)
    plate_cop: list[np.ndarray] = field(default_factory=list)
    plate_fz: list[np.ndarray] = field(default_factory=list)  # (F,) N, each plate used


def plates_floor(trial: C3dTrial, mmap: MarkerMap | None = None) -> float | None:
    """Height (m, internal frame) of the trial's plates' surface (the mean of their corners): the floor;
    None without plates. ``mmap``: the trial's marker map, if it needs one. Raises InputError when the plates
    stepped on (vertical force varying by more than ``UNLOADED_MAX_N``) lie more than ``LEVEL_M`` apart in height:
    a stair's or a step's plates are no one floor for the ZMP (pyCGM's Movement_trial: plates 0-584 mm up); or when
    one of them leans more than ``MAX_TILT_DEG`` from level (:func:`plate_tilt_deg`): a ramp's (fhstp/autoSIM's
    FH Campus Wien walks up two plates leaning 9.9 deg, 86 mm apart in height: "a stair or a step" before)."""
    if not trial.plates:
        return None
    r_in = input_rotation(trial, mmap)[1]
    heights = np.array([(p.corners @ r_in.T)[:, 2].mean() for p in trial.plates])
    stepped = np.array([len(p.force) > 0 and np.ptp(p.force @ r_in[2]) > UNLOADED_MAX_N for p in trial.plates])
    on = np.flatnonzero(stepped) if stepped.any() else np.arange(len(heights))
    tilts = {k: plate_tilt_deg(trial.plates[k].corners @ r_in.T) for k in on}
    leaning = [k for k in on if tilts[k] > MAX_TILT_DEG]
    if leaning:
        raise InputError(f"{trial.source}: force plate{'s' if len(leaning) > 1 else ''} stepped on "
                         f"{', '.join(str(k + 1) for k in leaning)} lean{'' if len(leaning) > 1 else 's'} "
                         f"{', '.join(f'{tilts[k]:.1f}' for k in leaning)} deg from level: a ramp or a slope, and "
                         f"the ZMP needs one level floor")
    if np.ptp(heights[on]) > LEVEL_M:
        mm = ", ".join(f"{1000 * (heights[k] - heights[on].min()):.0f}" for k in on)
        raise InputError(f"{trial.source}: the force plates stepped on are not one level floor (plates "
                         f"{', '.join(str(k + 1) for k in on)} at {mm} mm): a stair or a step, and the ZMP needs "
                         f"one floor")
    return float(heights.mean())


def plate_tilt_deg(corners: np.ndarray) -> float:
    """How far (deg) the plane of a plate's ``corners`` (4, 3), internal frame (z up), leans from level: the angle
    between its normal (the cross product of its diagonals) and the vertical, either way up."""
    normal = np.cross(corners[2] - corners[0], corners[3] - corners[1])
    return float(np.degrees(np.arccos(min(1.0, abs(normal[2]) / np.linalg.norm(normal)))))


def raised_by(ankles: list[np.ndarray], outlines: list[np.ndarray], rate: float) -> float:
    """How far (m) the plates stand above the floor the feet stand on off them: the median height of the stances
    (runs of at least ``STILL_S`` with an ankle centre slower than ``STILL_MPS``; each its median) whose ankle lies
    over a plate's ``outlines`` (k, 3) less that of those off the plates, when more than ``LEVEL_M`` and the stances
    of each kind lie within ``LEVEL_M`` of each other (two floors, each level); else 0: one level floor, a stair or
    a slope (AnyBody's SpecialFeatures: stances over its plates 77-589 mm up), or no stance on or off the plates.
    ``ankles``: each foot's ankle centre (F, 3) m, internal frame, at ``rate`` Hz. Qualisys' ClinicalGait walks
    (held-out round 4) step 86-88 mm up onto their two plates and down off them, the pelvis rising 80 mm with
    them: plates standing on the lab's floor, not let into it."""
    n = max(2, round(STILL_S * rate))
    heights: dict[bool, list[float]] = {True: [], False: []}
    for a in ankles:
        still = np.linalg.norm(np.gradient(a[:, :2], 1.0 / rate, axis=0), axis=1) < STILL_MPS
        edges = np.flatnonzero(np.diff(np.concatenate([[0], still.astype(int), [0]])))
        for i, j in zip(edges[::2], edges[1::2], strict=True):
            if j - i >= n:
                mid = np.median(a[i:j], axis=0)
                heights[any(_inside(mid, o, 0.0) for o in outlines)].append(float(mid[2]))
    if not heights[True] or not heights[False] or max(np.ptp(h) for h in heights.values()) > LEVEL_M:
        return 0.0
    step = float(np.median(heights[True]) - np.median(heights[False]))
    return step if step > LEVEL_M else 0.0


def unloaded_offset(plate: PlateRecord, analog_rate: float,
                    up: np.ndarray = UP) -> tuple[np.ndarray, np.ndarray] | None:
    """The plate's reading at rest: mean force (3,) N and moment (3,) N·m. Over the samples the file names
    unloaded (FORCE_PLATFORM:ZERO, ``plate.zero``; from its first sample that is not blank, an exact zero) when the
    vertical force is steady there (std < ``QUIET_STD_N``), no ``QUIET_WINDOW_S`` stretch reads more than
    ``PULL_N`` below it (else the range held a load) and one reads more than ``UNLOADED_MAX_N`` above it (the plate
    is stepped on); otherwise over its quietest
    unloaded stretch (``QUIET_WINDOW_S`` long, vertical force std < ``QUIET_STD_N``, |mean| <
    ``UNLOADED_MAX_N``, the smallest |mean| among those); None when there is none (loaded all along). ``up`` (3,):
    the vertical in the file's axes (a y-up lab's is its y: its z force is a horizontal one, quiet under load).

    The ZERO range comes first because an amplifier's offset can exceed ``UNLOADED_MAX_N``: c3d.org's TYPE-3
    sample reads -80, -212 and -181 N on three unloaded plates, which the quiet-stretch rule kept as "loaded" and
    then set aside as pulling."""
    n = max(2, round(QUIET_WINDOW_S * analog_rate))
    fz = plate.force @ up
    starts = np.arange(0, max(len(fz) - n + 1, 0), max(1, n // 4))
    windows = fz[starts[:, None] + np.arange(n)]
    mean, std = windows.mean(axis=1), windows.std(axis=1)
    if plate.zero is not None and len(mean):
        a, b = plate.zero
        # blank samples (exact zeros) before the plate's first reading are padding, not a reading: Innovative Sports
        # Training's c3d.org sample reads 21 N unloaded after a blank frame, AnyBody's GaitUniMiami -103 N after
        # 0.1 s of them; the range is read from the first sample that is not blank
        a += int(np.argmax(fz[a:b] != 0.0)) if fz[a:b].any() else b - a
        base = fz[a:b].mean() if b > a else 0.0
        # unloaded there: steady, nothing reads a pull below it, and someone stands on the plate later (one stood
        # on all along, ZERO range included, would lose the weight)
        if b > a and fz[a:b].std() < QUIET_STD_N and base - PULL_N <= mean.min() \
                and mean.max() > base + UNLOADED_MAX_N:
            return plate.force[a:b].mean(axis=0), plate.moment[a:b].mean(axis=0)
    ok = (std < QUIET_STD_N) & (np.abs(mean) < UNLOADED_MAX_N)
    if not ok.any():
        return None
    k = starts[np.flatnonzero(ok)[np.argmin(np.abs(mean[ok]))]]
    return plate.force[k:k + n].mean(axis=0), plate.moment[k:k + n].mean(axis=0)


def lowpass(x: np.ndarray, rate: float, cutoff_hz: float | None) -> np.ndarray:
    """Zero-phase 4th-order Butterworth low-pass along axis 0 (time; ``rate`` Hz samples, no time shift), in
    ``x``'s units; ``cutoff_hz`` (Hz) None, at or above Nyquist, or under 16 samples: ``x`` as is."""
    if cutoff_hz is None or cutoff_hz >= rate / 2 or len(x) < 16:
        return x
    sos = butter(2, cutoff_hz, fs=rate, output="sos")  # 2nd order, run forward and back: 4th
    return sosfiltfilt(sos, x, axis=0)


def cutoff_for_gain(freq_hz: float, gain: float) -> float:
    """The cutoff (Hz) at which :func:`lowpass` (|H(f)| = 1 / (1 + (f / cutoff)^4)) keeps ``gain`` (0-1) of a
    sinusoid of ``freq_hz`` Hz."""
    return freq_hz / (1.0 / gain - 1.0) ** 0.25


def lowpass_reach_s(cutoff_hz: float, outside: float = 0.05) -> float:
    """How far (s) :func:`lowpass` at ``cutoff_hz`` reaches: the time from a sample beyond which its impulse
    response keeps less than ``outside`` of its absolute weight on either side (0.078 s at 4.93 Hz for 5 %). A
    low-passed plate reading at a frame mixes in the readings that far away."""
    rate = 200.0 * cutoff_hz  # samples fine enough that the answer does not depend on them (< 1 ms)
    n = int(4 * rate / cutoff_hz)
    impulse = np.zeros(2 * n + 1)
    impulse[n] = 1.0
    weight = np.abs(lowpass(impulse, rate, cutoff_hz))
    beyond = 1.0 - np.cumsum(weight[n:]) / weight.sum() - 0.5 * (1.0 - weight[n] / weight.sum())
    within = np.flatnonzero(beyond < outside)
    return float((within[0] if len(within) else n) / rate)


def plate_frames(plates: list[PlateRecord], analog_rate: float, rate: float, frames: np.ndarray,
                 world_from_input: np.ndarray, cutoff_hz: float | None, min_fz: float = 20.0,
                 shift_s: float = 0.0) -> PlateFrames:
    """The plates' combined wrench and CoP at marker frames ``frames`` (C3D frame indices), offsets
    removed, low-passed (zero phase) at ``cutoff_hz`` before the CoP is formed.

    Analog sample k is at time k / analog_rate, marker frame i at i / rate (the C3D convention: a
    frame's first analog sample is simultaneous with it); ``shift_s`` samples the plates that much
    later (time alignment). A plate whose vertical force, averaged over ``QUIET_WINDOW_S``, goes below
    ``-PULL_N`` or above ``OVERLOAD_N`` is set aside: not summed, and its outline left out of ``outlines``."""
    r = world_from_input
    force = np.zeros((len(plates[0].force) if plates else 0, 3))
    moment = np.zeros_like(force)
    offsets, outlines, aside, used, own = [], [], [], [], []
    for k, p in enumerate(plates):
        off = unloaded_offset(p, analog_rate, r[2])
        offsets.append(off)
        f, mom = p.force, p.moment
        if off is not None:
            f, mom = f - off[0], mom - off[1]
        window = max(1, round(QUIET_WINDOW_S * analog_rate))
        low, high = _lowest_mean(f @ r[2], window), -_lowest_mean(-(f @ r[2]), window)
        if low < -PULL_N or high > OVERLOAD_N:
            aside.append(_set_aside(k + 1, low, high))
            continue
        f, mom, c = f @ r.T, mom @ r.T, r @ p.centre
        force += f
        moment += mom + np.cross(c, f)  # about the world origin
        outlines.append(p.corners @ r.T)
        used.append(k + 1)
        own.append(np.hstack([f, mom + np.cross(c, f)]))
    surface = float(np.mean([(p.corners @ r.T)[:, 2].mean() for p in plates])) if plates else 0.0
    t = (np.asarray(frames, dtype=float) / rate + shift_s) * analog_rate

    def at_frames(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Wrench (S, 6) low-passed, at the marker frames: force (F, 3), moment (F, 3)."""
        w = lowpass(w, analog_rate, cutoff_hz)
        idx = np.clip(t, 0, len(w) - 1)
        lo = np.floor(idx).astype(int)
        hi = np.minimum(lo + 1, len(w) - 1)
        frac = (idx - lo)[:, None]
        at = w[lo] * (1 - frac) + w[hi] * frac
        return at[:, :3], at[:, 3:]

    fr, mo = at_frames(np.hstack([force, moment]))
    each = [at_frames(w) for w in own]
    return PlateFrames(fr, mo, _cop(fr, mo, surface, min_fz), outlines, offsets, surface, aside, used,
                       [_cop(f, m, surface, min_fz) for f, m in each], [f[:, 2] for f, _ in each])


def _set_aside(plate: int, low: float, high: float) -> dict:
    """A plate set aside (1-based ``plate``), its lowest and highest vertical force means ``low``, ``high`` (N) and
    why in words."""
    if low < -PULL_N:
        return {"plate": plate, "min_fz_n": round(low, 1),
                "reason": f"its vertical force reaches {low:.0f} N (a plate cannot pull; drifting or faulty)"}
    return {"plate": plate, "max_fz_n": float(f"{high:.4g}"),
            "reason": f"its vertical force reaches {high:.3g} N, more than any person's {OVERLOAD_N:.0f} N (a channel "
                      "scale or unit wrong?)"}


def _lowest_mean(x: np.ndarray, n: int) -> float:
    """The lowest mean of ``n`` consecutive samples of ``x`` (of all of them when fewer); 0 when empty."""
    if len(x) == 0:
        return 0.0
    if len(x) <= n:
        return float(x.mean())
    c = np.concatenate([[0.0], np.cumsum(x)])
    return float(((c[n:] - c[:-n]) / n).min())


def _cop(force: np.ndarray, moment: np.ndarray, surface: float, min_fz: float) -> np.ndarray:
    """(F, 3) m: where ``force`` (F, 3) N with ``moment`` (F, 3) N·m about the world origin meets the plane at height
    ``surface``; NaN where the vertical force is at most ``min_fz`` N."""
    cop = np.full_like(force, np.nan)
    ok = force[:, 2] > min_fz
    cop[ok, 0] = (surface * force[ok, 0] - moment[ok, 1]) / force[ok, 2]
    cop[ok, 1] = (moment[ok, 0] + surface * force[ok, 1]) / force[ok, 2]
    cop[ok, 2] = surface
    return cop


def _outside(points: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """(...,) m: how far horizontal ``points`` (..., 3) lie outside the convex ``outline`` (k, 3), or each outside
    its own (..., k, 3): the largest signed distance to the outline's edge lines (negative inside; off a corner, a
    lower bound of the distance)."""
    a = outline[..., :2]
    e = np.roll(a, -1, axis=-2) - a
    n = np.stack([e[..., 1], -e[..., 0]], axis=-1) / np.linalg.norm(e, axis=-1, keepdims=True)
    inward = np.sum((a.mean(axis=-2, keepdims=True) - a) * n, axis=-1, keepdims=True) > 0
    n = np.where(inward, -n, n)  # outward normals
    return np.max(np.sum((points[..., None, :2] - a) * n, axis=-1), axis=-1)


def _inside(points: np.ndarray, outline: np.ndarray, margin: float) -> np.ndarray:
    """(..., ) whether horizontal ``points`` (..., 3) lie in the convex ``outline`` (4, 3) grown by ``margin``."""
    return _outside(points, outline) <= margin


def complete_frames(soles: dict[str, np.ndarray], in_contact: dict[str, np.ndarray], outlines: list[np.ndarray],
                    loaded: np.ndarray, margin: float = CONTACT_MARGIN_M) -> np.ndarray:
    """(F,) frames where some foot is in contact, the plates are loaded, and every foot in contact
    has all its sole corners (``soles`` {side: (F, k, 3)}) on some plate: there the plates measured
    the whole ground reaction."""
    complete = loaded.copy()
    any_contact = np.zeros_like(loaded)
    for side, sole in soles.items():
        on = np.zeros(sole.shape[:2], dtype=bool)
        for o in outlines:
            on |= _inside(sole, o, margin)
        complete &= ~in_contact[side] | on.all(axis=1)
        any_contact |= in_contact[side]
    return complete & any_contact


def cop_on_feet(plates: PlateFrames, soles: dict[str, np.ndarray], in_contact: dict[str, np.ndarray],
                min_fz: float, margin: float = CONTACT_MARGIN_M) -> list[dict]:
    """A check of each plate's reading that does not need the ZMP: a plate's own CoP lies under the foot standing on
    it. Per plate used, over the frames where one foot in contact (``in_contact`` {side: (F,)}) has all its sole
    corners (``soles`` {side: (F, k, 3)} m) on it, no other foot in contact touches it and it carries more than
    ``min_fz`` N: ``{plate (1-based), frames, on_foot}``, the part of those frames whose plate CoP lies in that sole
    grown by ``margin``, and ``off_p95_mm``, the 95th percentile of how far it lies outside the sole (0 inside). A
    plate read with wrong corners, ORIGIN, axes or channels puts its CoP off the foot."""
    out = []
    for n, outline, cop, fz in zip(plates.used, plates.outlines, plates.plate_cop, plates.plate_fz, strict=True):
        corners_on = {s: _inside(sole, outline, margin) & in_contact[s][:, None] for s, sole in soles.items()}
        on = {s: c.all(axis=1) for s, c in corners_on.items()}
        touch = {s: c.any(axis=1) for s, c in corners_on.items()}
        off = np.zeros(len(fz))
        rows = np.zeros(len(fz), dtype=bool)
        for s in soles:
            alone = on[s] & (fz > min_fz) & np.isfinite(cop).all(axis=1)
            for other in soles:
                alone &= (other == s) | ~touch[other]
            rows |= alone
            off[alone] = np.maximum(_outside(cop[alone], soles[s][alone]), 0.0)
        if rows.any():
            out.append({"plate": n, "frames": int(rows.sum()), "on_foot": round(float(np.mean(off[rows] <= margin)), 3),
                        "off_p95_mm": round(1000 * float(np.percentile(off[rows], 95)), 1)})
    return out


def gait_cycles(strikes: dict[str, list[float]]) -> list[tuple[float, float]]:
    """(start, end) s of every whole gait cycle: one foot strike to the same foot's next."""
    out = []
    for times in strikes.values():
        t = sorted(times)
        out += list(zip(t[:-1], t[1:], strict=True))
    return out


def plate_mass(fz: np.ndarray, times: np.ndarray, complete: np.ndarray, cycles: list[tuple[float, float]],
               min_complete: float = 0.95) -> tuple[float | None, int]:
    """Body mass (kg) from the plates: mean vertical force over whole gait cycles ÷ g (over a cycle the
    centre of mass returns to its height, so its mean vertical acceleration is zero). Only cycles
    whose frames are at least ``min_complete`` complete count (their complete frames are averaged).
    Returns (mass or None, cycles used)."""
    total, n, used = 0.0, 0, 0
    for a, b in cycles:
        rows = (times >= a) & (times < b)
        if rows.sum() < 3 or complete[rows].mean() < min_complete:
            continue
        total += float(fz[rows & complete].sum())
        n += int((rows & complete).sum())
        used += 1
    return (total / n / G if n else None), used


def stance_mass(fz: np.ndarray, acc_z: np.ndarray, feet_on: np.ndarray,
                seen: float) -> tuple[float | None, int, int]:
    """Body mass (kg) from frames where every foot that may bear weight is on a plate (``feet_on`` (F,)): there
    the plates carry the whole body, F_z = m (g + a_z), with ``acc_z`` (F,) m/s² the CoM's vertical acceleration
    from the kinematics (which does not depend on the mass). A ratio of sums, m = Σ F_z / Σ (g + a_z): Σ a_z dt is
    the CoM's vertical velocity change, which the kinematics give to a few cm/s against g × the time summed (several
    m/s), while one frame's a_z (a smoothed second derivative) misses part of the step's, so F_z / (g + a_z) frame
    by frame scatters by ±25 % (c3d.org sub_labels, sample14). Summed over the frames complete at that mass, where
    the plates carry at least ``seen`` of m (g + a_z) (below it part of the load stands off the plates: the frames
    the comparison leaves out too), found by iterating from all of them: each pass drops frames that carry too
    little, so m only rises, until none is dropped. None unless ``STANCE_MIN_FRAMES`` frames remain and they are
    at least ``STANCE_MIN_KEPT`` of the feet-on frames (a load missed by less than 1 - ``seen`` over most of them
    looks like a lighter body and is not found). Returns (mass or None, frames summed, feet-on frames)."""
    rows = feet_on & (G + acc_z > 0.5 * G)  # a hop or a fall gives a quotient of nothing
    if rows.sum() < STANCE_MIN_FRAMES:
        return None, 0, int(rows.sum())
    keep = rows
    while True:
        mass = float(fz[keep].sum() / (G + acc_z[keep]).sum())
        kept = rows & (fz > seen * mass * (G + acc_z))
        if mass <= 0 or kept.sum() == keep.sum() or kept.sum() < STANCE_MIN_FRAMES:
            break
        keep = kept
    ok = mass > 0 and kept.sum() == keep.sum() and kept.sum() >= STANCE_MIN_KEPT * rows.sum()
    return (mass if ok else None), int(kept.sum()), int(rows.sum())


def standing_span(times: np.ndarray, complete: np.ndarray, strikes: list[float] = (),
                  min_s: float = STANDING_S) -> list[tuple[float, float]]:
    """[(start, end)] s: every run of complete frames without a break that lasts ``min_s`` or more (longer than any
    walking stance: someone standing or swaying on the plates, whose mean vertical force over it is the weight as
    over a gait cycle) and has no foot strike (``strikes``, s) inside it; [] when there is none. A break (a frame not
    complete: a foot off the plates) ends a run: two steps on the plates with a step off between them are not
    standing; nor is a walk over adjoining plates, which strikes them (its mean force is not the weight)."""
    idx = np.flatnonzero(complete)
    runs = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if len(idx) else []
    spans = [(float(times[r[0]]), float(np.nextafter(times[r[-1]], np.inf))) for r in runs
             if times[r[-1]] - times[r[0]] >= min_s]
    return [(a, b) for a, b in spans if not any(a < t < b for t in strikes)]
