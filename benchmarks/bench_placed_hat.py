"""What a placed head-arms-trunk (HAT) misses, measured where the truth is known.

Every trial whose upper body is tracked by markers is analysed as it is (`analyze`'s defaults) and again with its
upper body's markers hidden (the labels the take read for the trunk, head and arms), so that the HAT is placed from
the pelvis as for a lower-body set, with the same mass and plate delay; both are scored against the plates on the
frames complete in both. Printed:

1. per trial: ZMP − CoP RMS tracked and placed (mm); the placed minus the tracked ZMP along and across the walk (RMS
   and mean, mm); how much of it the upper body's centre-of-mass path alone gives, (m_u / M) (p_placed − p_tracked)
   with p = c − z a / g its own ZMP point (the rest: its own rotations, the arms' swing);
2. predictors of the tracked upper body's path from what a lower-body set sees (the mid-hip's sway above
   :data:`TRUNK_FOLLOW_HZ`, its rate (phase), the pelvis' tilt and obliquity, the legs' centre of mass), each added
   to the HAT following the mid-hip and fitted by pooled least squares on one half of the subjects (alternate
   subjects, the file name without its trial number naming one), scored on the other half both ways round; per
   subject, fitted on its other trials; and fitted on each trial itself (the floor). Scores: the median over trials
   of the RMS ZMP error the upper body's path leaves, (m_u / M) |p_model − p_tracked| (mm);
3. the share of that error's power below 1 Hz, at the step frequency (1-2.5 Hz), at its harmonics (2.5-6 Hz);
4. how far the tracked upper body stands ahead of the placed HAT, and whether the pelvis' tilt tells it.

    python benchmarks/bench_placed_hat.py /work/extra_c3d/heldout[2-7]/*.c3d /work/extra_c3d/btk_gait/*.c3d \
        /work/extra_c3d/distinct/*.c3d

Deterministic; the machine's load changes only the time taken.
"""

from __future__ import annotations

import argparse
import re
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
from machine_load import load_averages
from scipy.stats import spearmanr

from livezmp.balance.plates import G, lowpass
from livezmp.errors import InputError
from livezmp.model.c3d import C3dTrial, read_c3d, strip_prefix
from livezmp.model.markers import TRUNK_FOLLOW_HZ, TRUNK_STEP_GAIN, sway_basis
from livezmp.offline.gaitlab import LabAnalysis, LabOptions, analyse_lab_take

# the roles of every upper-body marker livezmp reads (Plug-in Gait's full body, the trunk's tops, Helen Hayes' arms
# and head); the labels a take found for them are hidden
UPPER_ROLES = frozenset(("C7", "T10", "CLAV", "STRN", "LCLA", "RCLA", "LFHD", "RFHD", "LBHD", "RBHD", "LSHO", "RSHO",
                         "LELB", "RELB", "LWRA", "RWRA", "LWRB", "RWRB", "LFIN", "RFIN", "LWRI", "RWRI", "THEA",
                         "FHEA", "RHEA"))
UPPER_SEGMENTS = ("hat", "thorax", "headarms", "arms", "head", "upperarm", "forearm", "hand")
STEP_HZ = 1.8  # a typical step frequency (Hz), scaling the mid-hip's rate to metres
PREDICTORS = (("sway",), ("sway", "rate"), ("sway", "pelvis"), ("sway", "legs"), ("sway", "rate", "pelvis"),
              ("sway", "rate", "pelvis", "legs"))
BANDS_HZ = ((0.0, 1.0), (1.0, 2.5), (2.5, 6.0))


@dataclass
class Pair:
    """One trial tracked and placed, on the tracked take's frames ``rows`` complete in both: the ZMP − CoP (F, 2) m
    along and across the walk of each, the upper body's own ZMP point p tracked and placed, the predictors'
    contributions to it (name -> (F, 2) m, walk axes) and its part that follows the mid-hip (``base``); ``k`` the
    upper body's share of the mass."""

    name: str
    rate: float
    rows: np.ndarray
    err_tracked: np.ndarray
    err_placed: np.ndarray
    p_tracked: np.ndarray
    p_placed: np.ndarray
    base: np.ndarray
    parts: dict
    k: float
    lean_mm: float  # the tracked upper body's centre of mass ahead of the placed HAT's, mean over the take (mm)
    pelvis_pitch_deg: float  # the pelvis' median pitch (its markers' anterior tilt), deg


def hidden(trial: C3dTrial, lab: LabAnalysis) -> C3dTrial:
    """``trial`` with the labels its take read for the upper body, and any other of those roles' standard names (a
    shoulder marker tracks the thorax where C7 and CLAV are missing), renamed so that no role finds them."""
    gone = {label for role, label in lab.take.roles.items() if role in UPPER_ROLES}
    gone |= {x for x in trial.labels if strip_prefix(x).upper() in UPPER_ROLES}
    gone |= {x for role, labels in lab.take.mean_of.items() if role in UPPER_ROLES for x in labels}
    return replace(trial, labels=[f"hidden_{x}" if x in gone else x for x in trial.labels])


def upper_com(lab: LabAnalysis) -> tuple[np.ndarray, float]:
    """The upper body's centre of mass (F, 3) m and mass (kg) in ``lab``'s take."""
    model = lab.take.body.model
    joints = [j for j in range(1, model.njoints)
              if model.names[j].split(".")[0].split("_")[0] in UPPER_SEGMENTS and model.inertias[j].mass > 0]
    data = model.createData()
    mass = sum(model.inertias[j].mass for j in joints)
    com = []
    for q in lab.result.q:
        pin.forwardKinematics(model, data, q)
        com.append(sum(model.inertias[j].mass * data.oMi[j].act(model.inertias[j].lever) for j in joints) / mass)
    return np.array(com), mass


def _channels(lab: LabAnalysis, names: tuple[str, ...]) -> np.ndarray:
    return lab.result.q[:, [lab.take.body.channel_names.index(n) for n in names]]


def _acc(x: np.ndarray, rate: float) -> np.ndarray:
    """Second derivative (m/s², along axis 0) of ``x`` low-passed at 6 Hz (the estimator's band)."""
    return np.gradient(np.gradient(lowpass(x, rate, 6.0), 1 / rate, axis=0), 1 / rate, axis=0)


def _fast(x: np.ndarray, rate: float) -> np.ndarray:
    """The part of ``x`` above the follow frequency (as :func:`livezmp.model.markers.hat_sway` splits it)."""
    return x - lowpass(x, rate, TRUNK_FOLLOW_HZ)


def pair(path: Path) -> Pair | str:
    """The trial at ``path`` tracked and placed, or why not."""
    trial = read_c3d(path)
    full = analyse_lab_take(trial)
    if "hat" in full.take.placed or not full.complete.any():
        return "its HAT is placed, or no complete frame"
    placed = analyse_lab_take(hidden(trial, full), LabOptions(
        mass=full.summary["mass"]["used_kg"], plate_delay_s=full.summary["time_alignment"]["plate_delay_applied_ms"]
        / 1000 or None))
    if "hat" not in placed.take.placed:
        return "its upper body is still tracked with the markers hidden"
    frame_f, frame_p = (np.round(a.times * a.rate).astype(int) for a in (full, placed))
    _, i_f, i_p = np.intersect1d(frame_f, frame_p, return_indices=True)
    rows = np.zeros(len(frame_f), dtype=bool)
    rows[i_f] = (placed.complete & placed.result.has_zmp)[i_p]
    rows &= full.complete & full.result.has_zmp
    rows = rows[i_f]
    if rows.sum() < 10:
        return f"{int(rows.sum())} frames complete in both"
    rate = full.rate
    hip = _channels(full, ("pelvis.x", "pelvis.y", "pelvis.z"))[i_f]
    trend, fwd, left = sway_basis(hip)
    axes = np.stack([fwd[:2], left[:2]], axis=1)
    cu, mass_u = upper_com(full)
    ch = upper_com(placed)[0][i_p]
    cu = cu[i_f]
    height = ch[:, 2:3]  # the placed HAT's centre-of-mass height, for every model of its horizontal path

    def own(c: np.ndarray) -> np.ndarray:
        return (c[:, :2] - height / G * _acc(c, rate)[:, :2]) @ axes

    sway = hip - trend
    base = own(trend + lowpass(sway, rate, TRUNK_FOLLOW_HZ) + [0.0, 0.0, 1.0] * (ch - hip))
    mass = full.summary["mass"]["used_kg"]
    legs = (mass * full.result.com[i_f] - mass_u * cu) / (mass - mass_u)
    tilt, obliquity = (_fast(a, rate) for a in _channels(full, ("pelvis.pitch", "pelvis.roll"))[i_f].T)
    lever = float(np.median(height[:, 0] - hip[:, 2]))
    fast = _fast(sway, rate)
    parts = {"sway": fast, "rate": np.gradient(fast, 1 / rate, axis=0) / (2 * np.pi * STEP_HZ),
             "pelvis": lever * (np.outer(np.sin(tilt), fwd) - np.outer(np.sin(obliquity), left)),
             "legs": _fast(legs - trend, rate)}
    zero = own(np.zeros_like(hip))
    walk = [(a.result.zmp[i, :2] - a.plates.cop[i, :2]) @ axes for a, i in ((full, i_f), (placed, i_p))]
    return Pair(path.stem, rate, rows, walk[0], walk[1], own(cu) - base, own(ch) - base, base,
                {n: own(x) - zero for n, x in parts.items()}, mass_u / mass, 1000 * float(np.mean((cu - ch) @ fwd)),
                float(np.degrees(np.median(_channels(full, ("pelvis.pitch",))))))


def subject(name: str) -> str:
    """A trial's subject: its file name without the trial number (biomechZoo's subject code before it)."""
    s = re.sub(r"^(zoo_HC\d+[A-Z]).*", r"\1", re.sub(r"[_-]?\d+$", "", name))
    return "osim" if s.startswith("osim") else s


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x * x)))


def _design(p: Pair, names: tuple[str, ...], axis: int) -> np.ndarray:
    return np.column_stack([p.parts[n][:, axis] for n in names])[p.rows]


def fit(pairs: list[Pair], names: tuple[str, ...], axis: int) -> np.ndarray:
    """Pooled least-squares coefficients of the predictors ``names`` onto the tracked path's (``axis``: 0 along the
    walk, 1 across), each trial's frames weighted by its upper body's share of the mass (as in the ZMP)."""
    x = np.vstack([p.k * _design(p, names, axis) for p in pairs])
    y = np.concatenate([p.k * p.p_tracked[p.rows, axis] for p in pairs])
    return np.linalg.lstsq(x, y, rcond=None)[0]


def left_mm(p: Pair, axis: int, names: tuple[str, ...] = (), coef: np.ndarray | None = None) -> float:
    """RMS (mm) of the ZMP error the upper body's path leaves with the model (None: the placed HAT as it is)."""
    model = p.p_placed[p.rows, axis] if coef is None else _design(p, names, axis) @ coef
    return 1000 * p.k * _rms(model - p.p_tracked[p.rows, axis])


def _zmp_rms_mm(err: np.ndarray) -> float:
    """RMS (mm) of the distance of (F, 2) errors in m."""
    return 1000 * float(np.sqrt(np.mean(np.sum(err * err, axis=1))))


def per_trial(pairs: list[Pair]) -> None:
    print(f"{'trial':30s} {'frames':>6s} {'tracked':>8s} {'placed':>7s}   placed − tracked ZMP, RMS (mean) fore-aft / "
          "lateral mm   of which not the upper body's path")
    for p in pairs:
        d = 1000 * (p.err_placed - p.err_tracked)[p.rows]
        rest = d - 1000 * p.k * (p.p_placed - p.p_tracked)[p.rows]
        cells = " / ".join(f"{_rms(d[:, a]):5.1f} ({d[:, a].mean():+5.1f})" for a in (0, 1))
        print(f"{p.name[:30]:30s} {p.rows.sum():6d} {_zmp_rms_mm(p.err_tracked[p.rows]):8.1f} "
              f"{_zmp_rms_mm(p.err_placed[p.rows]):7.1f}   {cells}   {_rms(rest[:, 0]):5.1f} / {_rms(rest[:, 1]):5.1f}")
    tracked = [_zmp_rms_mm(p.err_tracked[p.rows]) for p in pairs]
    placed = [_zmp_rms_mm(p.err_placed[p.rows]) for p in pairs]
    bias = [1000 * (p.err_placed - p.err_tracked)[p.rows, 0].mean() for p in pairs]
    print(f"median over {len(pairs)}: tracked {np.median(tracked):.1f} mm, placed {np.median(placed):.1f} mm; placed − "
          f"tracked fore-aft bias median {np.median(bias):+.1f} mm (quartiles {np.percentile(bias, 25):+.1f}, "
          f"{np.percentile(bias, 75):+.1f})")


def predictor_table(pairs: list[Pair]) -> None:
    subjects = sorted({subject(p.name) for p in pairs})
    half = [[p for p in pairs if subjects.index(subject(p.name)) % 2 == h] for h in (0, 1)]
    by_subject = {s: [p for p in pairs if subject(p.name) == s] for s in subjects}
    print(f"\nthe upper body's path predicted from the pelvis: ZMP error left, median mm (halves of {len(half[0])} / "
          f"{len(half[1])} trials, {len(subjects)} subjects); the placed HAT sways {TRUNK_STEP_GAIN} above "
          f"{TRUNK_FOLLOW_HZ:g} Hz")
    several = [p for group in by_subject.values() if len(group) > 1 for p in group]
    print("the placed HAT on the walks of subjects with several: " + " / ".join(
        f"{np.median([left_mm(p, axis) for p in several]):.1f}" for axis in (0, 1)) + f" mm ({len(several)} walks)")
    print(f"{'predictors':24s} axis  {'placed HAT':>10s}  {'fitted on the other half':>24s}  "
          f"{'subject, other trials':>21s}  {'floor (each trial)':>18s}  coefficients (half 0; half 1)")
    for names in PREDICTORS:
        for axis, what in enumerate(("f-a", "lat")):
            coef = [fit(h, names, axis) for h in half]
            held = [np.median([left_mm(p, axis, names, coef[1 - h]) for p in half[h]]) for h in (0, 1)]
            table = [np.median([left_mm(p, axis) for p in half[h]]) for h in (0, 1)]
            cross = [left_mm(p, axis, names, fit([q for q in group if q is not p], names, axis))
                     for group in by_subject.values() if len(group) > 1 for p in group]
            floor = np.median([left_mm(p, axis, names, fit([p], names, axis)) for p in pairs])
            print(f"{'+'.join(names):24s} {what:4s}  {table[0]:4.1f}/{table[1]:4.1f}  {held[0]:11.1f} / {held[1]:4.1f}"
                  f"         {np.median(cross):12.1f}  {floor:18.1f}  {np.round(coef[0], 2)}; {np.round(coef[1], 2)}")


def lean(pairs: list[Pair]) -> None:
    """Whether the pelvis' tilt tells how far the upper body stands ahead of the placed HAT: Spearman's r, and a line
    fitted on each half of the subjects scored on the other (median |residual|, mm of the upper body's CoM)."""
    subjects = sorted({subject(p.name) for p in pairs})
    h = np.array([subjects.index(subject(p.name)) % 2 for p in pairs])
    x, y = np.array([p.pelvis_pitch_deg for p in pairs]), np.array([p.lean_mm for p in pairs])
    print(f"\nthe upper body's centre of mass ahead of the placed HAT: median {np.median(y):+.1f} mm (quartiles "
          f"{np.percentile(y, 25):+.1f}, {np.percentile(y, 75):+.1f}); against the pelvis' pitch r = "
          f"{spearmanr(x, y).statistic:.2f}")
    for k in (0, 1):
        line = np.polyfit(x[h == k], y[h == k], 1)
        other = y[h != k]
        by_line = np.median(np.abs(other - np.polyval(line, x[h != k])))
        by_median = np.median(np.abs(other - np.median(y[h == k])))
        print(f"  fitted on half {k}: {line[0]:+.2f} mm/deg; on the other half |lean| median "
              f"{np.median(np.abs(other)):.1f} mm, less the line {by_line:.1f}, less its own median {by_median:.1f}")


def spectrum(pairs: list[Pair]) -> None:
    print("\nthe placed HAT's error against the tracked path (every frame in both), median share of its power")
    for axis, what in enumerate(("fore-aft", "lateral")):
        shares = []
        for p in pairs:
            e = p.p_placed[:, axis] - p.p_tracked[:, axis]
            power = np.abs(np.fft.rfft(e - e.mean())) ** 2
            f = np.fft.rfftfreq(len(e), 1 / p.rate)
            shares.append([power[(f >= lo) & (f < hi)].sum() / power.sum() for lo, hi in BANDS_HZ])
        print(f"  {what:8s} " + ", ".join(f"{lo:g}-{hi:g} Hz {s:.2f}" for (lo, hi), s in
                                       zip(BANDS_HZ, np.median(shares, axis=0), strict=True)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("trials", nargs="+", type=Path, help="C3D trials (those whose upper body is tracked are used)")
    args = ap.parse_args()
    t0 = time.process_time()
    print(f"load average {load_averages(' ')}")
    pairs = []
    for path in args.trials:
        try:
            got = pair(path)
        except InputError as e:
            got = "refused: " + str(e).split(": ", 1)[-1][:80]
        if isinstance(got, str):
            print(f"{path.name[:40]:40s} not used: {got}")
        elif not got.name.startswith("osim_jog"):  # a run: no HAT model of walking is meant for it
            pairs.append(got)
    per_trial(pairs)
    predictor_table(pairs)
    spectrum(pairs)
    lean(pairs)
    print(f"({time.process_time() - t0:.1f} s of CPU)")


if __name__ == "__main__":
    main()
