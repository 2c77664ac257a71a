"""ZMP against force-plate centre of pressure on the shared C3D gait trials, step by step.

Each row adds one change to the one above, so each error source shows its share:

  0  CoM ground projection alone (no dynamics)
  1  live estimator settings (0.4 s window, 0.1 s ahead), HAT rigid on the pelvis, raw plates
  2  + HAT upright (moves with the mid-hip, turns with the pelvis' heading)
  3  + plates low-passed like the kinematics (zero-phase, at the estimator's cutoff)
  4  + symmetric estimator window for whole takes (0.8 s, 0.4 s ahead)
  5  + plates' delay behind the markers measured and undone
  6  + the placed HAT swaying TRUNK_SWAY_GAIN times the mid-hip
  7  + instead following the mid-hip below TRUNK_FOLLOW_HZ and swaying TRUNK_STEP_GAIN times it above
  8  + the segments' positions across the walk low-passed at half the cutoff (the lateral band)
                                                                   [livezmp analyze default: 4 + 5 + 7 + 8]

then the estimator's cutoff around the default (plates low-passed with it, and at a fixed 6 Hz), the trunk's
sway relative to the mid-hip on the trials whose trunk is tracked by markers (where TRUNK_SWAY_GAIN and
TRUNK_STEP_GAIN come from)
and every trial before / after it, the error split by axis, support phase and the ZMP's linear (CoM) part
with the kinematic and the plates' acceleration, the lag of the ZMP and of those linear parts (and the ZMP
with its angular-momentum part delayed), that part split per segment group and term (the ZMP's lag and RMS
with each taken out), the lateral error in single stance split into those parts with the upper body's lateral
gain onto the plates, the fore-aft swing at the step frequency split into the mid-hip's acceleration and the
upper body's and legs' motion relative to it, `livezmp calibrate`
cross-validated per trial, the plates' CoP against their own force line, and the estimator's own gain and
delay on sinusoids (why row 4 matters).
Figures: over each trial's complete frames (every loaded foot on a plate); lag > 0: the ZMP comes after
the CoP; bias: mean ZMP - CoP along the walk and to its left.

    python benchmarks/bench_forceplates.py [MORE.c3d | DIR ...] [--static WALK.c3d=STATIC.c3d ...]

Extra trials (files, or directories searched for *.c3d) get one row each with `livezmp analyze`'s
default settings, or the one line that refuses them; the median is then over every trial with
complete frames (the shared ones included). `--static` gives an extra walk (by its file name) the static
trial of its cluster set, as `livezmp analyze WALK.c3d --static STATIC.c3d` does.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import ezc3d
import numpy as np
import pinocchio as pin
from machine_load import load_averages

from livezmp.balance.plates import G, lowpass
from livezmp.balance.support import support_and_clamp
from livezmp.errors import InputError
from livezmp.estimate.estimator import EstimatorConfig
from livezmp.estimate.response import acceleration_response
from livezmp.model.c3d import read_c3d
from livezmp.model.markers import (
    TRUNK_FOLLOW_HZ,
    TRUNK_STEP_GAIN,
    TRUNK_SWAY_GAIN,
    MarkerBodyOptions,
    input_rotation,
    sway_basis,
)
from livezmp.model.static_trial import read_walk
from livezmp.offline.calibrate import BLOCK_S, calibrate
from livezmp.offline.gaitlab import (
    COP_CHECK_WEIGHT,
    LabOptions,
    analyse_lab_take,
    facing,
    may_bear_weight,
    plates_at,
)
from livezmp.offline.plausibility import WALK_COM_ACC_P99, com_accelerations, plausibility
from livezmp.offline.validation import (
    LAG_AGREE_S,
    MAX_LAG_S,
    cop_vs_zmp,
    lag_with_halves,
    path_axes,
    walking_axes,
)

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "c3d"
TRIALS = ("walk_plugingait_forceplates.c3d", "cgm24_walking01_forceplate.c3d")
LIVE = {"window_s": 0.4, "lag_s": 0.1}
RIGID = MarkerBodyOptions(hat_follows_pelvis=True, hat_sway_gain=None)
NO_SWAY = MarkerBodyOptions(hat_sway_gain=None)
CONSTANT_SWAY = MarkerBodyOptions(hat_sway_gain=TRUNK_SWAY_GAIN, hat_follow_hz=None)  # one gain at every frequency
RAW_PLATES = 1e9  # Hz: no low-pass
UNBANDED = {"lateral_cutoff_fraction": None}  # steps before the lateral band
STEPS = [
    ("1 live window, HAT rigid, raw plates", LabOptions(markers=RIGID, estimator=LIVE, plate_cutoff_hz=RAW_PLATES,
                                                         plate_delay_s=0.0, **UNBANDED)),
    ("2 + HAT upright", LabOptions(markers=NO_SWAY, estimator=LIVE, plate_cutoff_hz=RAW_PLATES, plate_delay_s=0.0,
                                   **UNBANDED)),
    ("3 + plates low-passed as kinematics", LabOptions(markers=NO_SWAY, estimator=LIVE, plate_delay_s=0.0,
                                                       **UNBANDED)),
    ("4 + symmetric window (0.8 s / 0.4 s)", LabOptions(markers=NO_SWAY, plate_delay_s=0.0, **UNBANDED)),
    ("5 + plate delay undone", LabOptions(markers=NO_SWAY, **UNBANDED)),
    ("6 + trunk sway {:.2f}/{:.2f}".format(*TRUNK_SWAY_GAIN), LabOptions(markers=CONSTANT_SWAY, **UNBANDED)),
    ("7 + follows < {:g} Hz, sways {:.2f}/{:.2f}".format(TRUNK_FOLLOW_HZ, *TRUNK_STEP_GAIN), LabOptions(**UNBANDED)),
    ("8 + lateral band (half the cutoff) [default]", LabOptions()),
]
LAG_TARGET_MS = 10.0  # ms: issue 15's target for the ZMP's lag behind the plates' CoP
CONTACT_LOAD = 0.05  # of the weight: a foot carrying more stands on the floor
UPPER = ("thorax", "headarms", "arms", "head", "upperarm", "forearm", "hand")


def _give_or_take(v: float | None, u: float | None) -> str:
    """'+V ± U' (ms) with '-' for what is None, 12 characters."""
    return f"{'-' if v is None else f'{v:+.1f}':>6s} ± {'-' if u is None else f'{u:.0f}':<3s}"


def lag(cv: dict) -> str:
    """The lag (ms), or 'n.d.' when its two halves disagree (validation.lag_with_halves)."""
    return f"{cv['lag_ms']:+7.1f}" if cv["lag_ms"] is not None else f"{'n.d.':>7s}"


def row(name: str, cv: dict, extra: str = "") -> str:
    if not cv["frames"]:
        return f"{name:40s} {'-':>6s}"
    fa, lat = cv["bias_mm"]
    return (f"{name:40s} {cv['frames']:6d} {cv['rms_mm']:7.1f} {cv['p95_mm']:7.1f} {fa:+7.1f} {lat:+7.1f} "
            f"{lag(cv)}  {extra}")


def header() -> str:
    return f"{'':40s} {'frames':>6s} {'RMS':>7s} {'p95':>7s} {'biasFA':>7s} {'biasLat':>7s} {'lag ms':>7s}"


def trial_table(path: Path) -> list[dict]:
    trial = read_c3d(path)
    print(f"\n{path.name}  ({len(trial.points)} frames at {trial.rate:g} Hz, {len(trial.plates)} plates)  mm")
    print(header())
    out = []
    final = analyse_lab_take(trial)
    r, p = final.result, final.plates
    com = cop_vs_zmp(r.com, np.ones(len(r), dtype=bool), p.cop, final.complete, r.com, 1.0 / trial.rate)
    print(row("0 CoM projection (no dynamics)", com))
    for name, opts in STEPS:
        a = analyse_lab_take(trial, opts)
        delay = a.summary["time_alignment"]
        out.append({"step": name, **a.summary["cop_vs_zmp"]})
        print(row(name, a.summary["cop_vs_zmp"], f"plate delay measured {delay['plate_delay_measured_ms']:+.1f} ms, "
                                              f"applied {delay['plate_delay_applied_ms']:+.1f} ms"))
    for hz in (4.0, 5.0, 8.0, 10.0):
        a = analyse_lab_take(trial, LabOptions(estimator={"cutoff_hz": hz}))
        print(row(f"  default but cutoff {hz:g} Hz", a.summary["cop_vs_zmp"]))
        a = analyse_lab_take(trial, LabOptions(estimator={"cutoff_hz": hz}, plate_cutoff_hz=6.0))
        print(row("  the same, plates at 6 Hz", a.summary["cop_vs_zmp"]))
    c = final.complete
    kin, plate = _accelerations(trial, final)
    p99 = [_axis_p99(x[c], r.com) for x in (plate, kin)]
    dist = np.percentile(np.linalg.norm(p.cop[c, :2] - r.com[c, :2], axis=1), 99)
    print(f"plausibility references: CoM acceleration p99 (fore-aft, lateral, vertical) m/s2: plates "
          f"{np.round(p99[0], 2).tolist()}, markers {np.round(p99[1], 2).tolist()}; CoP-CoM p99 {dist:.3f} m")
    m, acc = final.summary["mass"], final.summary["com_acc_vs_plates"]
    print(f"mass: file {m['file_kg']} kg, plates {m['plates_kg']} kg over {m['plate_cycles']} cycle(s), used "
          f"{m['used_kg']} kg ({m['source']}); CoM acceleration vs plates r = {acc['r']}, RMS {acc['rms_mps2']} m/s2")
    return out


def estimator_response(rate: float, freq: float, window: float, lag: float, cutoff: float) -> tuple[float, float]:
    """Gain and delay (ms) of the estimator's acceleration of a unit sinusoid at ``freq`` Hz."""
    gain, delay = acceleration_response(EstimatorConfig(rate_hz=rate, cutoff_hz=cutoff, window_s=window, lag_s=lag),
                                        freq)
    return gain, 1000 * delay


def extra_paths(args: list[str]) -> list[Path]:
    out = []
    for a in args:
        p = Path(a)
        out += sorted(q for q in p.rglob("*") if q.suffix.lower() == ".c3d" and q.stat().st_size) if p.is_dir() else [p]
    return out


def extra_table(paths: list[Path], statics: dict[str, str]) -> dict[str, tuple]:
    """One row per extra trial at the defaults (or why it is refused); {name: (trial, analysis)} of those
    with complete frames. ``statics``: a walk's file name -> its static trial."""
    print(f"\nmore trials, `livezmp analyze` defaults  mm\n{'trial':40s} {header()[41:]}  rate, plates, marker set")
    done = {}
    for path in paths:
        try:
            trial = read_walk(path, statics.get(path.name))
            a = analyse_lab_take(trial)
        except InputError as e:
            print(f"{path.name[:40]:40s} refused: {str(e).replace(str(path) + ': ', '')[:150]}")
            continue
        cv = a.summary["cop_vs_zmp"]
        info = f"{trial.rate:g} Hz, {len(trial.plates)} plates, {a.summary['markers']['marker_set'][:28]}"
        if "labels" in a.summary["markers"]:
            info += f" (labels: {len(a.summary['markers']['labels']['aliases'])} aliases)"
        if "from_static_trial" in a.summary["markers"]:
            info += f"; {len(a.summary['markers']['from_static_trial']['landmarks'])} landmarks from its static trial"
        aside = a.summary["plates"]["set_aside"]
        info += f"; plate(s) {', '.join(str(p['plate']) for p in aside)} set aside (pulling)" if aside else ""
        if not cv["frames"]:
            why = a.summary["plates"]["no_complete_frame"]
            print(f"{path.name[:40]:40s} {0:6d}  no complete frames; {info}; {why}")
            continue
        print(row(path.name[:40], cv, info))
        done[path.name] = (trial, a)
    return done


def trunk_sway(done: dict[str, tuple]) -> None:
    """On trials whose trunk is tracked by markers: how far the centre of mass of thorax, head and arms sways
    about its straight-line trend, per unit of the mid-hip's sway (least-squares gain, fore-aft and lateral),
    and its mean offset from the mid-hip. TRUNK_SWAY_GAIN is the median of these gains (chosen as the mean of the
    first two such trials, Vicon_analysis and vicon_zerowire; the median over all four is the same, the mean is
    pulled down by sub_labels, whose trunk leans over the stance leg against its pelvis: lateral gain < 0)."""
    print("\ntrunk sway measured where the trunk is tracked (every frame of the take)")
    print(f"{'trial':34s} {'gain fore-aft':>13s} {'r':>5s} {'gain lateral':>13s} {'r':>5s}  "
          "HAT CoM from mid-hip fwd/left/up mm")
    gains, acc_gains = [], []
    for name, (_, a) in done.items():
        model = a.take.body.model
        upper = [j for j in range(1, model.njoints)
                 if model.names[j].split(".")[0].split("_")[0] in UPPER and model.inertias[j].mass > 0]
        if not upper:
            continue
        data, hip_joint = model.createData(), model.getJointId("pelvis.roll")
        com, hip = [], []
        for q in a.result.q:
            pin.forwardKinematics(model, data, q)
            com.append(sum(model.inertias[j].mass * data.oMi[j].act(model.inertias[j].lever) for j in upper)
                       / sum(model.inertias[j].mass for j in upper))
            hip.append(data.oMi[hip_joint].translation.copy())
        com, hip = np.array(com), np.array(hip)
        trend, fwd, left = sway_basis(hip)
        dh, dc = hip - trend, com - sway_basis(com)[0]
        fit = [(float((dh @ ax) @ (dc @ ax) / ((dh @ ax) @ (dh @ ax))), float(np.corrcoef(dh @ ax, dc @ ax)[0, 1]))
               for ax in (fwd, left)]
        gains.append([g for g, _ in fit])
        # the same in acceleration (6 Hz band, 0.3 s clear of the ends), what the ZMP uses: TRUNK_STEP_GAIN
        inner = slice(int(0.3 * a.rate), -int(0.3 * a.rate))
        acc = [np.gradient(np.gradient(lowpass(x, a.rate, 6.0), 1 / a.rate), 1 / a.rate)[inner]
               for x in (dh @ fwd, dc @ fwd, dh @ left, dc @ left)]
        acc_gains.append([float(acc[k] @ acc[k + 1] / (acc[k] @ acc[k])) for k in (0, 2)])
        off = com - hip
        print(f"{name[:34]:34s} {fit[0][0]:13.2f} {fit[0][1]:5.2f} {fit[1][0]:13.2f} {fit[1][1]:5.2f}  "
              f"{1000 * np.mean(off @ fwd):+.0f} / {1000 * np.mean(off @ left):+.0f} / {1000 * np.mean(off[:, 2]):.0f}"
              f"   in acceleration {acc_gains[-1][0]:.2f} / {acc_gains[-1][1]:.2f}")
    if gains:
        mean, median = np.mean(gains, axis=0), np.median(gains, axis=0)
        print(f"gain fore-aft / lateral: median {median[0]:.2f} / {median[1]:.2f}, mean {mean[0]:.2f} / {mean[1]:.2f} "
              f"(TRUNK_SWAY_GAIN = {TRUNK_SWAY_GAIN}); in acceleration median "
              "{:.2f} / {:.2f} (TRUNK_STEP_GAIN = {})".format(*np.median(acc_gains, axis=0), TRUNK_STEP_GAIN))


def sway_before_after(done: dict[str, tuple]) -> None:
    """Every trial with the placed HAT moving with the mid-hip (before) and swaying as by default (after)."""
    print("\nplaced HAT: moving with the mid-hip -> following it below {:g} Hz, swaying {:.2f}/{:.2f} above "
          "(RMS / bias fore-aft / lag)".format(TRUNK_FOLLOW_HZ, *TRUNK_STEP_GAIN))
    before, after = [], []
    for name, (trial, a) in done.items():
        cv0 = analyse_lab_take(trial, LabOptions(markers=NO_SWAY)).summary["cop_vs_zmp"]
        cv1 = a.summary["cop_vs_zmp"]
        before.append(cv0["rms_mm"])
        after.append(cv1["rms_mm"])
        print(f"{name[:34]:34s} {cv0['rms_mm']:6.1f} {cv0['bias_mm'][0]:+6.1f} {lag(cv0)}  ->  "
              f"{cv1['rms_mm']:6.1f} {cv1['bias_mm'][0]:+6.1f} {lag(cv1)}")
    print(f"median RMS over {len(after)} trials: {np.median(before):.1f} -> {np.median(after):.1f} mm")


GROUPS = ("pelvis", "hat", "thorax", "headarms", "arms", "head", "upperarm", "forearm", "hand", "thigh", "shank",
          "foot")
LATERAL_GAINS = (0.59, 0.40)  # the four tracked trunks' mean lateral sway gain, and lower
SLOW_HZ = 2.0  # Hz: below the stride's third harmonic, above its fundamental (~0.9 Hz)
MIN_SINGLE_FRAMES = 6  # scored single-stance frames a trial needs for the single-stance table


def _group_accelerations(a, dt: float) -> dict[str, np.ndarray]:
    """Each segment kind's share of the whole-body CoM acceleration (F, 3) m/s² (sum over kinds = the CoM's)."""
    model, data = a.take.body.model, a.take.body.model.createData()
    joints: dict[str, list[int]] = {}
    for j in range(1, model.njoints):
        if model.inertias[j].mass > 0:
            joints.setdefault(model.names[j].split(".")[0].split("_")[0], []).append(j)
    total = sum(model.inertias[j].mass for js in joints.values() for j in js)
    pos = {k: np.empty((len(a.result.q), 3)) for k in joints}
    for f, q in enumerate(a.result.q):
        pin.forwardKinematics(model, data, q)
        for k, js in joints.items():
            pos[k][f] = sum(model.inertias[j].mass * data.oMi[j].act(model.inertias[j].lever) for j in js) / total
    return {k: com_accelerations(v, dt) for k, v in pos.items()}


def lateral_sources(done: dict[str, tuple]) -> None:
    """Where the markers' lateral CoM acceleration departs from the plates' (GRF_lat / m), over complete frames:
    the residual (kinematic - plates) SD; each segment kind's share of the kinematic acceleration (SD, and its
    correlation with the residual); the pelvis points' own lateral acceleration (markers low-passed at 6 Hz like
    the kinematics): SD and the least-squares gain onto the plates'; the RMS with the placed HAT's lateral
    sway gain lowered (LATERAL_GAINS)."""
    print("\nlateral CoM acceleration, markers vs plates (complete frames), m/s2: SD, r with the residual "
          "(kin - plates); pelvis points: SD, r with the plates, gain onto the plates")
    for name, (trial, a) in done.items():
        r, p, dt = a.result, a.plates, 1.0 / trial.rate
        rows = _scored(a)
        _, left = walking_axes(r.com)
        plate = (p.force[rows] / a.summary["mass"]["used_kg"]) @ left
        res = com_accelerations(r.com, dt)[rows] @ left - plate
        groups = _group_accelerations(a, dt)
        shares = " ".join(f"{k} {np.std(v[rows] @ left):.2f}/{np.corrcoef(v[rows] @ left, res)[0, 1]:+.2f}"
                          for k, v in sorted(groups.items(), key=lambda kv: GROUPS.index(kv[0])))
        _, r_in = input_rotation(trial)
        span = slice(a.take.first_frame, a.take.first_frame + len(r.com))

        def lat(x: np.ndarray, rate: float = trial.rate, rows: np.ndarray = rows,
                left: np.ndarray = left) -> np.ndarray:
            return com_accelerations(lowpass(x, rate, 6.0), 1.0 / rate)[rows] @ left

        hips = a.take.centres["hip"]
        points = {"mid-hip": lat((hips["left"] + hips["right"]) / 2)}
        for label, roles in (("mid-ASIS", ("LASI", "RASI")), ("mid-PSIS", ("LPSI", "RPSI")), ("sacrum", ("SACR",))):
            xs = [trial.marker(a.take.roles.get(k) or "") for k in roles]
            if all(x is not None and np.isfinite(x[span]).all() for x in xs):
                points[label] = lat(np.mean([x[span] @ r_in.T for x in xs], axis=0))
        pts = " ".join(f"{k} {np.std(v):.2f}/{np.corrcoef(v, plate)[0, 1]:+.2f}/{(v @ plate) / (v @ v):.2f}"
                       for k, v in points.items())
        gains = [analyse_lab_take(trial, LabOptions(markers=MarkerBodyOptions(hat_sway_gain=(TRUNK_SWAY_GAIN[0], g))))
                 .summary["cop_vs_zmp"]["rms_mm"] for g in LATERAL_GAINS] if "hat" in groups else []
        print(f"{name[:34]:34s} plates {np.std(plate):.2f} residual {np.std(res):.2f} | {shares} | {pts} | RMS "
              f"{a.summary['cop_vs_zmp']['rms_mm']:.1f}" + "".join(f", lateral sway {g}: {v:.1f}"
                                                                   for g, v in zip(LATERAL_GAINS, gains, strict=False)))


def _hat_kind(groups: dict[str, np.ndarray]) -> str:
    """How a body's head, arms and trunk are modelled, from its segment kinds: placed on the pelvis, the trunk
    tracked with head and arms placed on it, or every segment tracked."""
    return "placed HAT" if "hat" in groups else "trunk + placed" if {"headarms", "arms"} & set(groups) else "tracked"


def single_stance_lateral(done: dict[str, tuple]) -> None:
    """The lateral error in single stance, signed outward (towards the stance foot's outside), mean over the
    scored single-stance frames: ZMP - CoP split exactly into the model's angular-momentum part (ZMP minus the
    linear part with the kinematic acceleration), the acceleration part (the linear part, kinematic minus the
    plates' acceleration) and the plates' force line through the model's CoM minus the CoP (mm); the lateral CoM
    acceleration outward, kinematic / plates / kinematic low-passed at SLOW_HZ over the whole take (m/s2: a mean
    the low-pass leaves is at the stride frequency, not marker shake); and the gain k on the upper body's share
    of the kinematic lateral acceleration that best matches the plates' (plates ~ kin + (k - 1) upper, over the
    scored frames). Medians of k per way the head, arms and trunk are modelled (:func:`_hat_kind`)."""
    print(f"\nlateral error in single stance, outward: ZMP - CoP = angular-momentum part + acceleration part + force "
          f"line - CoP (mm); lateral CoM acceleration outward kin / plates / kin below {SLOW_HZ:g} Hz (m/s2); upper "
          "body's gain k onto the plates")
    ks: dict[str, list[float]] = {}
    for name, (trial, a) in done.items():
        r, rows, dt = a.result, _scored(a), 1.0 / trial.rate
        single = rows & (r.support < 2)  # SUPPORT_LABELS: 0 left, 1 right
        if single.sum() < MIN_SINGLE_FRAMES:
            continue
        _, left = path_axes(r.com, trial.rate, facing(a.take))
        out = np.where(r.support == 0, 1.0, -1.0)[single]
        lin, lin_plates = _linear_parts(trial, a)
        zmp, cop = r.zmp[:, :2], a.plates.cop[:, :2]
        parts = [zmp - cop, zmp - lin, lin - lin_plates, lin_plates - cop]
        mm = " ".join(f"{1000 * np.mean(_along(p[single], left[single]) * out):+6.1f}" for p in parts)
        kin_acc, plate_acc = _accelerations(trial, a)
        kin, plates = (_along(x[:, :2], left) for x in (kin_acc, plate_acc))
        slow = _along(lowpass(kin_acc[:, :2], trial.rate, SLOW_HZ), left)
        acc = " / ".join(f"{np.mean(x[single] * out):+.2f}" for x in (kin, plates, slow))
        groups = _group_accelerations(a, dt)
        upper = _along(sum(v for k, v in groups.items() if k in UPPER + ("hat",))[:, :2], left)[rows]
        k = 1 - ((kin - plates)[rows] @ upper) / (upper @ upper)
        ks.setdefault(_hat_kind(groups), []).append(k)
        print(f"{name[:34]:34s} {int(single.sum()):4d} fr {100 * single.sum() / rows.sum():3.0f} % | {mm} | {acc} | "
              f"k {k:4.2f} ({_hat_kind(groups)})")
    print("  upper body's gain k, median (quartiles): " + "; ".join(
        f"{kind} {np.median(v):.2f} ({np.percentile(v, 25):.2f}-{np.percentile(v, 75):.2f}, {len(v)} trials)"
        for kind, v in ks.items()))


def _along(d: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(n,) horizontal differences ``d`` (n, 2) along each row's ``axis`` (n, 3)."""
    return np.einsum("ij,ij->i", d, axis[:, :2])


def _rms(d: np.ndarray, axes: tuple[np.ndarray, np.ndarray]) -> str:
    """'total (fore-aft / lateral)' RMS in mm of horizontal differences ``d`` (n, 2), along each row's ``axes``
    (fore-aft, lateral: (n, 3) each, `path_axes`)."""
    fa, lat = (1000 * np.sqrt(np.mean(_along(d, ax) ** 2)) for ax in axes)
    return f"{1000 * np.sqrt(np.mean(np.sum(d * d, axis=1))):5.1f} ({fa:5.1f}/{lat:5.1f})"


def _scored(a) -> np.ndarray:
    """(F,) the frames the comparison scores: complete, with a ZMP and a plate CoP."""
    return a.complete & a.result.has_zmp & np.isfinite(a.plates.cop).all(axis=1)


def _lag_cell(lag: float | None, determined: bool) -> str:
    """A lag (s) as a table cell in ms; ? = not determined, n/a = none."""
    return "n/a" if lag is None else f"{1000 * lag:+.1f}{'' if determined else '?'}"


def _delayed(x: np.ndarray, t: np.ndarray, delay: float) -> np.ndarray:
    """(F, k) columns ``x`` at times ``t`` (s) delayed by ``delay`` s (linear interpolation, held at the ends)."""
    return np.column_stack([np.interp(t - delay, t, col) for col in x.T])


def _accelerations(trial, a) -> tuple[np.ndarray, np.ndarray]:
    """(F, 3) the CoM's acceleration from the kinematics and from the plates ((GRF - m g) / m), m/s2."""
    return (com_accelerations(a.result.com, 1.0 / trial.rate),
            a.plates.force / a.summary["mass"]["used_kg"] - [0.0, 0.0, G])


def _axis_p99(acc: np.ndarray, com: np.ndarray) -> list[float]:
    """p99 of |acc| (N, 3) m/s2 along the walk of ``com`` (F, 3) (fore-aft, lateral; walking_axes) and vertical."""
    fwd, left = walking_axes(com)
    return [float(np.percentile(np.abs(acc @ ax), 99)) for ax in (fwd, left, np.array([0.0, 0.0, 1.0]))]


def _linear_parts(trial, a) -> list[np.ndarray]:
    """(F, 2) the ZMP's linear part, CoM - h a / (a_z + g), with the kinematic and with the plates' CoM
    acceleration (:func:`_accelerations`), m."""
    com, h = a.result.com, a.result.com[:, 2:] - a.plates.surface_z
    with np.errstate(divide="ignore", invalid="ignore"):  # the plates' part off the plates (a_z = -g): inf, unused
        return [com[:, :2] - h * x[:, :2] / (x[:, 2:] + G) for x in _accelerations(trial, a)]


def error_sources(done: dict[str, tuple]) -> None:
    """Per trial: the error split by axis (fore-aft and lateral along the path at each frame, `path_axes`) and
    support phase; the ZMP's linear part (CoM - h a / (a_z + g))
    with the kinematic CoM acceleration and with the plates' (GRF / m: what the plates say the same CoM
    term is); the lateral CoM acceleration's spread, kinematics vs plates."""
    print("\nerror sources over complete frames, mm: total (fore-aft / lateral)")
    print(f"{'trial':34s} {'ZMP':>19s} {'single support':>19s} {'double':>19s} {'linear, kin. acc':>19s} "
          f"{'linear, plate acc':>19s}  lat. acc SD kin/plates m/s2")
    for name, (trial, a) in done.items():
        r, p = a.result, a.plates
        rows = _scored(a)
        axes = tuple(ax[rows] for ax in path_axes(r.com, trial.rate, facing(a.take)))
        cop = p.cop[rows, :2]
        loaded = [may_bear_weight(sole, p.surface_z, 1.0 / trial.rate)[rows] for sole in r.soles.values()]
        double = loaded[0] & loaded[1]
        acc, plate_acc = (x[rows] for x in _accelerations(trial, a))
        lin = [x[rows] for x in _linear_parts(trial, a)]
        d = r.zmp[rows, :2] - cop
        single_axes, double_axes = (tuple(ax[k] for ax in axes) for k in (~double, double))
        parts = [_rms(d, axes), _rms(d[~double], single_axes) if (~double).any() else f"{'-':>19s}",
                 _rms(d[double], double_axes) if double.any() else f"{'-':>19s}", _rms(lin[0] - cop, axes),
                 _rms(lin[1] - cop, axes)]
        sd = [float(np.std(_along(x[:, :2], axes[1]))) for x in (acc, plate_acc)]
        print(f"{name[:34]:34s} " + " ".join(parts) + f"  {sd[0]:.2f} / {sd[1]:.2f}")


def lag_split(done: dict[str, tuple]) -> None:
    """Where the ZMP's lead on the CoP comes from: the lag (ms, + = after the CoP, as ``lag_ms``; ? = not
    determined) of the ZMP, of its linear part with the kinematic CoM acceleration and with the plates' (the
    rest of the ZMP is the segments' angular momentum term), and the ZMP's RMS with that rest delayed."""
    delays = (0.0, 0.01, 0.02)
    print("\nlag split over complete frames: ZMP, linear part (kinematic / plate acceleration) lag ms; ZMP RMS mm "
          "with its angular-momentum part delayed " + " / ".join(f"{1000 * d:.0f}" for d in delays) + " ms")
    for name, (trial, a) in done.items():
        r, p, dt = a.result, a.plates, 1.0 / trial.rate
        rows = _scored(a)
        lin = _linear_parts(trial, a)
        zmp = np.where(r.has_zmp[:, None], r.zmp[:, :2], np.nan)
        lags = []
        for x in (zmp, *lin):
            lag, ok, _ = lag_with_halves(x, p.cop[:, :2], rows, dt)
            lags.append(_lag_cell(lag, ok))
        rest, t = np.nan_to_num(zmp - lin[0]), np.arange(len(zmp)) * dt
        rms = []
        for d in delays:
            late = lin[0] + _delayed(rest, t, d)
            e = (late - p.cop[:, :2])[rows]
            rms.append(f"{1000 * np.sqrt(np.mean(np.sum(e * e, axis=1))):.1f}")
        print(f"{name[:34]:34s} {lags[0]:>7s} {lags[1]:>7s} {lags[2]:>7s}   " + " / ".join(rms))


def bias_and_lead(done: dict[str, tuple]) -> None:
    """How much of the fore-aft bias is the ZMP's lead: the CoP travels forward through each stance, so a ZMP
    that runs a time ``lag`` ahead of it sits ``-lag`` times the CoP's mean fore-aft speed in front. Per trial:
    the fore-aft bias (mm, as ``bias_mm``: along the path at each frame), the lag (ms, ? = not determined), the
    CoP's mean fore-aft speed over scored frames whose neighbours are scored (m/s), the bias the lead alone gives,
    and the bias left with the ZMP moved back by its lag (interpolated between frames)."""
    print("\nfore-aft bias and the lead: bias mm, lag ms, CoP fore-aft speed m/s, -lag x speed mm, bias with the "
          "ZMP shifted by its lag mm")
    cols = []
    for name, (trial, a) in done.items():
        r, p, dt = a.result, a.plates, 1.0 / trial.rate
        rows = _scored(a)
        zmp = np.where(r.has_zmp[:, None], r.zmp[:, :2], np.nan)
        lag, ok, _ = lag_with_halves(zmp, p.cop[:, :2], rows, dt)
        if lag is None:
            continue
        fwd = path_axes(r.com, trial.rate, facing(a.take))[0]
        t = np.arange(len(zmp)) * dt
        bias = 1000 * float(np.mean(_along(zmp[rows] - p.cop[rows, :2], fwd[rows])))
        moved = _delayed(np.nan_to_num(zmp), t, -lag)  # ZMP(t + lag): where it stood lag later
        left = 1000 * float(np.mean(_along(moved[rows] - p.cop[rows, :2], fwd[rows])))
        mid = np.flatnonzero(rows[1:-1] & rows[:-2] & rows[2:]) + 1
        speed = (float(np.mean(_along(p.cop[mid + 1, :2] - p.cop[mid - 1, :2], fwd[mid])) / (2 * dt)) if len(mid)
                 else np.nan)
        cols.append((bias, -1000 * lag * speed, left, ok))
        print(f"{name[:34]:34s} {bias:+7.1f} {_lag_cell(lag, ok):>7s} {speed:6.2f} {-1000 * lag * speed:+7.1f} "
              f"{left:+7.1f}")
    det = np.array([c[:3] for c in cols if c[3]])
    if len(det) > 2:
        print(f"over the {len(det)} trials with the lag determined: median bias {np.median(det[:, 0]):+.1f} mm, "
              f"lead's part {np.median(det[:, 1]):+.1f}, left at the lag {np.median(det[:, 2]):+.1f}; "
              f"|bias| <= 10 mm on {int((abs(det[:, 0]) <= 10).sum())}, at the lag on "
              f"{int((abs(det[:, 2]) <= 10).sum())}; r(bias, lead's part) "
              f"{np.corrcoef(det[:, 0], det[:, 1])[0, 1]:.2f}")


AM_GROUPS = {"foot": "feet", "shank": "shanks", "thigh": "thighs", "pelvis": "pelvis"}  # any other kind: "upper"
STANCE_TERMS = ("foot rot", "shank mass", "thigh mass")  # the stance leg's terms shown on their own
# s: a mass wobbling on its bone at f_n Hz with damping ratio zeta lags it at step frequencies by 2 zeta / (2 pi f_n),
# 10 ms at 16 Hz and zeta = 0.5 (soft tissue resonates at heel strike: Wakeling, Liphardt & Nigg 2003, J Biomech
# 36:1761); the "stance late" column delays the whole stance leg's part by this much, more than its wobbling share
WOBBLE_DELAY_S = 0.01
# the stance leg's part scaled by this instead of taken out (the "st.x" column): of a sweep 0-1 by 0.25 the one
# gain that moved the lag toward 0 on the tuning and both held-out sets, RMS within 0.5 mm over the sets' own
# trials (heel-strike round); no physical quantity stands behind it (docs/validation.md), so it is shown, not used
STANCE_GAIN = 0.75
BEFORE_STRIKE_S = 0.1  # the end of single support shown on its own line: where the ZMP's error starts to grow


def _am_parts(a) -> dict[str, np.ndarray]:
    """The ZMP's angular-momentum part (the ZMP minus c - h F_xy / F_z with the model's own F) split per segment
    and term, each (F, 2) m: "<segment> rot", the segment's own rotation R (I alpha + w x I w), and "<segment>
    mass", its mass moving about the whole CoM, m_i (c_i - c) x a_i; their moments about the CoM (N m, world
    frame) divided by F_z as ``balance.zmp`` does (x: -L'_y / F_z, y: L'_x / F_z), so they sum to that part."""
    r, model = a.result, a.take.body.model
    data = model.createData()
    bodies = [j for j in range(1, model.njoints) if model.inertias[j].mass > 0]
    rot, mass = (np.zeros((len(r.q), len(bodies), 3)) for _ in range(2))
    fz = np.empty(len(r.q))
    for f in range(len(r.q)):
        pin.computeCentroidalMomentumTimeVariation(model, data, r.q[f], r.v[f], r.a[f])
        c = data.com[0]
        fz[f] = data.dhg.linear[2] - data.mass[0] * model.gravity.linear[2]
        for k, j in enumerate(bodies):
            inertia, v = model.inertias[j], data.v[j]
            rate = data.oMi[j].act(inertia * data.a[j] + v.cross(inertia * v))  # momentum's rate, about the origin
            mass[f, k] = np.cross(data.oMi[j].act(inertia.lever) - c, rate.linear)
            rot[f, k] = rate.angular - np.cross(c, rate.linear) - mass[f, k]
    return {f"{model.names[j].split('.')[0]} {term}": np.column_stack([-x[:, k, 1], x[:, k, 0]]) / fz[:, None]
            for term, x in (("rot", rot), ("mass", mass)) for k, j in enumerate(bodies)}


def _am_columns(a, loaded: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """:func:`_am_parts` summed per segment group, per leg by its support that frame (a leg whose sole may bear
    weight is a stance leg, else the swing leg), the stance leg's STANCE_TERMS, and per term over every segment
    ("rot", "mass"), each (F, 2) m."""
    cols: dict[str, np.ndarray] = {}

    def add(col: str, x: np.ndarray) -> None:
        cols[col] = cols.get(col, 0.0) + x

    for key, x in _am_parts(a).items():
        seg, term = key.split()
        kind, _, side = seg.partition("_")
        add(AM_GROUPS.get(kind, "upper"), x)
        add(term, x)
        if side:
            on = loaded["left" if side == "l" else "right"][:, None]
            add("stance leg", np.where(on, x, 0.0))
            add("swing leg", np.where(on, 0.0, x))
            if f"{kind} {term}" in STANCE_TERMS:
                add(f"stance {kind} {term}", np.where(on, x, 0.0))
    return cols


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in ``mask`` (F,)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[::2], edges[1::2], strict=True))


def _double_halves(both: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each run of double-support frames ``both`` (F,) split at its middle: (after heel strike, before toe-off)."""
    early = np.zeros_like(both)
    for start, stop in runs(both):
        early[start:(start + stop) // 2] = True
    return early, both & ~early


def _before_strikes(both: np.ndarray, n: int) -> np.ndarray:
    """(F,) the ``n`` frames before each run of double-support frames ``both`` (F,): single support's end, just
    before the heel strike."""
    late = np.zeros_like(both)
    for start, _ in runs(both):
        late[max(0, start - n):start] = True
    return late & ~both


def am_split(done: dict[str, tuple]) -> None:
    """Which segments make the ZMP's lead: its lag (ms, as :func:`lag_split`; ? = not determined) and RMS against
    the CoP (mm) with one column of :func:`_am_columns` taken out ("stance late": the stance leg's part delayed by
    WOBBLE_DELAY_S instead, "st.x": scaled by STANCE_GAIN instead), per trial; then the medians over the
    trials (the lag's over those where it is determined) and the RMS medians in single support, in its last
    BEFORE_STRIKE_S (before heel strike) and in each double support's first half (after heel strike) and second
    half (before toe-off)."""
    order = ("ZMP", *dict.fromkeys(AM_GROUPS.values()), "upper", "swing leg", "stance leg",
             *(f"stance {t}" for t in STANCE_TERMS), "stance late", "stance gain", "rot", "mass")
    print("\nangular-momentum part by segment group: ZMP lag ms / RMS mm with that group's part taken out "
          "(rot: every segment's own rotation, mass: every mass about the CoM)")
    short = {"stance leg": "stance", "swing leg": "swing", "stance late": "st.+10ms",
             "stance gain": f"st.x{STANCE_GAIN:g}", **{f"stance {t}": "st." + t for t in STANCE_TERMS}}
    print(f"{'trial':26s} " + " ".join(f"{k if k == 'ZMP' else '-' + short.get(k, k):>12s}" for k in order))
    lags, rms = ({k: [] for k in order} for _ in range(2))
    phases = {p: {k: [] for k in order} for p in ("single support", "before heel strike", "after heel strike",
                                                  "before toe-off")}
    for name, (trial, a) in done.items():
        r, p, dt = a.result, a.plates, 1.0 / trial.rate
        rows = _scored(a)
        loaded = {s: may_bear_weight(sole, p.surface_z, dt) for s, sole in r.soles.items()}
        both = rows & loaded["left"] & loaded["right"]
        zmp = np.where(r.has_zmp[:, None], r.zmp[:, :2], np.nan)
        cols, t = _am_columns(a, loaded), a.times
        stance = np.nan_to_num(cols["stance leg"])
        cols["stance late"] = stance - _delayed(stance, t, WOBBLE_DELAY_S)
        cols["stance gain"] = (1.0 - STANCE_GAIN) * stance
        late = rows & _before_strikes(both, round(BEFORE_STRIKE_S / dt))
        cells = []
        for k in order:
            x = zmp - cols[k] if k in cols else zmp
            lag, ok, _ = lag_with_halves(x, p.cop[:, :2], rows, dt)
            e = np.sum((x - p.cop[:, :2]) ** 2, axis=1)
            rms[k].append(1000 * np.sqrt(np.mean(e[rows])))
            for phase, m in zip(phases.values(), (rows & ~both, late, *_double_halves(both)), strict=True):
                phase[k] += [1000 * np.sqrt(np.mean(e[m]))] if m.any() else []
            lags[k] += [1000 * lag] if lag is not None and ok else []
            cells.append(f"{_lag_cell(lag, ok)}/{rms[k][-1]:.1f}")
        print(f"{name[:26]:26s} " + " ".join(f"{c:>12s}" for c in cells))
    for label, lg, rm in (("median", lags, rms), *((p, None, v) for p, v in phases.items())):
        print(f"{label:26s} " + " ".join(f"{(f'{np.median(lg[k]):+.1f}/' if lg and lg[k] else '')}"
                                          f"{np.median(rm[k]) if rm[k] else np.nan:.1f}".rjust(12) for k in order))


LEG_KINDS = ("thigh", "shank", "foot")
MIN_STEPS = 1.4  # complete frames spanning fewer steps do not pin a step-frequency phasor down


def _step_phasors(series: dict[str, np.ndarray], t: np.ndarray, rows: np.ndarray, f: float) -> dict[str, complex]:
    """Each series' complex amplitude at ``f`` Hz over ``rows`` (least squares with an offset, a linear trend and
    the second harmonic beside it): amplitude abs(), phase angle() (a lead is positive)."""
    w = 2 * np.pi * f * t
    basis = np.column_stack([np.ones_like(t), t - t[rows].mean(), np.cos(w), np.sin(w), np.cos(2 * w), np.sin(2 * w)])
    return {k: complex(c[2], -c[3]) for k, v in series.items()
            for c in [np.linalg.lstsq(basis[rows], v[rows], rcond=None)[0]]}


def swing_at_step_frequency(done: dict[str, tuple]) -> None:
    """The fore-aft swing at the step frequency, split where it comes from: the body's acceleration is the mid-hip's
    (what the pelvis markers give) plus the placed or tracked upper body's and the legs' motion relative to it (each
    a share of the whole mass), against the plates' F_x / m; and the CoP's swing about the CoM against the ZMP's
    (amplitude ratio; the ZMP's lead in ms). Trials whose complete frames span at least MIN_STEPS steps."""
    print(f"\nfore-aft at the step frequency (complete frames spanning >= {MIN_STEPS} steps): acceleration amplitude "
          "m/s2 @ phase deg vs the plates'; CoP-CoM / ZMP-CoM amplitude, ZMP lead ms")
    print(f"{'trial':34s} {'f Hz':>5s} {'steps':>5s} {'mid-hip':>11s} {'upper rel.':>11s} {'legs rel.':>11s} "
          f"{'kinematic':>11s} {'plates':>6s}   CoP/ZMP  lead")
    for name, (trial, a) in done.items():
        r, p, dt = a.result, a.plates, 1.0 / trial.rate
        rows = _scored(a)
        fwd, _ = walking_axes(r.com, facing(a.take))
        shares = {k: v @ fwd for k, v in _group_accelerations(a, dt).items()}
        mid_hip = com_accelerations(r.q[:, :3], dt) @ fwd  # the pelvis' origin: its first three channels
        model = a.take.body.model
        masses: dict[str, float] = {}
        for j in range(1, model.njoints):
            kind = model.names[j].split(".")[0].split("_")[0]
            masses[kind] = masses.get(kind, 0.0) + model.inertias[j].mass
        total = sum(masses.values())
        legs = sum(shares[k] - masses[k] / total * mid_hip for k in LEG_KINDS)
        upper = sum(shares[k] - masses[k] / total * mid_hip for k in shares if k not in LEG_KINDS)
        kin = sum(shares.values())
        spectrum = np.abs(np.fft.rfft(kin - kin.mean(), 8 * len(kin)))
        freq = np.fft.rfftfreq(8 * len(kin), dt)
        band = (freq > 1.0) & (freq < 3.5)
        f = float(freq[band][np.argmax(spectrum[band])])
        steps = (a.times[rows][-1] - a.times[rows][0]) * f if rows.any() else 0.0
        if steps < MIN_STEPS:
            continue
        swing = {"zmp": np.where(r.has_zmp, (r.zmp[:, :2] - r.com[:, :2]) @ fwd[:2], 0.0),
                 "cop": np.where(rows, (p.cop[:, :2] - r.com[:, :2]) @ fwd[:2], 0.0)}
        ph = _step_phasors({"mid-hip": mid_hip, "upper": upper, "legs": legs, "kin": kin,
                            "plates": (p.force / a.summary["mass"]["used_kg"]) @ fwd, **swing}, a.times, rows, f)
        ref = ph["plates"]
        cells = " ".join(f"{abs(ph[k]):5.2f}@{np.degrees(np.angle(ph[k] / ref)):+4.0f}"
                         for k in ("mid-hip", "upper", "legs", "kin"))
        lead = 1000 * np.angle(ph["zmp"] / ph["cop"]) / (2 * np.pi * f)
        print(f"{name[:34]:34s} {f:5.2f} {steps:5.1f} {cells} {abs(ref):6.2f}   {abs(ph['cop']) / abs(ph['zmp']):5.2f} "
              f"{lead:+5.0f}")


def foot_frame(done: dict[str, tuple]) -> None:
    """CoP and ZMP in the stance foot's frame over single-support complete frames: along the foot from the heel
    (0) to the toe (1) by the sole model's corners, and sideways from its heel-toe line (mm, + left). A plate
    whose origin or corners were misplaced puts the CoP off the foot; a CoP that stays put over a stance is a
    plate that does not see the roll-over; a ZMP off the foot while the CoP is on it is the kinematics."""
    print("\nCoP / ZMP in the stance foot (single support): along heel 0 -> toe 1, min..max (mean); sideways mean mm")
    for name, (trial, a) in done.items():
        r, p = a.result, a.plates
        rows = _scored(a)
        fwd, _ = walking_axes(r.com)
        load = {s: may_bear_weight(sole, p.surface_z, 1.0 / trial.rate) for s, sole in r.soles.items()}
        cells = []
        for side, other in (("left", "right"), ("right", "left")):
            sel = rows & load[side] & ~load[other]
            if sel.sum() < 3:
                continue
            sole = r.soles[side][sel][:, :, :2]
            along = sole @ fwd[:2]
            n = np.arange(len(sole))
            heel, toe = sole[n, np.argmin(along, axis=1)], sole[n, np.argmax(along, axis=1)]
            length = np.linalg.norm(toe - heel, axis=1)
            ax = (toe - heel) / length[:, None]
            lat = np.column_stack([-ax[:, 1], ax[:, 0]])
            parts = []
            for x in (p.cop[sel, :2], r.zmp[sel, :2]):
                u = np.sum((x - heel) * ax, axis=1) / length
                w = 1000 * np.mean(np.sum((x - (heel + toe) / 2) * lat, axis=1))
                parts.append(f"{u.min():+.2f}..{u.max():+.2f} ({u.mean():+.2f}) {w:+4.0f}")
            cells.append(f"{side[0]} {int(sel.sum()):3d} fr: CoP {parts[0]}, ZMP {parts[1]}")
        print(f"{name[:34]:34s} " + " | ".join(cells))


def _feet_loaded(trial, a) -> dict[str, np.ndarray]:
    """{side: (F,) bool}: the feet the plates load, from their raw forces (no low-pass: it spreads a heel strike
    over the frames before it) at the applied plate delay, each plate's load given to the foot whose sole centre
    lies nearest its own CoP; a foot carrying more than CONTACT_LOAD of the weight is loaded."""
    shift = a.summary["time_alignment"]["plate_delay_applied_ms"] / 1000
    raw = plates_at(trial, a.take, a.times, None, shift)
    centres = {s: sole[:, :, :2].mean(axis=1) for s, sole in a.result.soles.items()}
    load = {s: np.zeros(len(a.times)) for s in centres}
    for cop, fz in zip(raw.plate_cop, raw.plate_fz, strict=True):
        seen = np.isfinite(cop).all(axis=1) & (fz > 0)
        dist = {s: np.linalg.norm(c - np.nan_to_num(cop[:, :2]), axis=1) for s, c in centres.items()}
        nearest_left = dist["left"] <= dist["right"]
        load["left"] += np.where(seen & nearest_left, fz, 0.0)
        load["right"] += np.where(seen & ~nearest_left, fz, 0.0)
    weight = a.summary["mass"]["used_kg"] * G
    return {s: x > CONTACT_LOAD * weight for s, x in load.items()}


def support_check(done: dict[str, tuple]) -> None:
    """livezmp's support against the plates over the complete frames: its feet in contact (from the markers) against
    the feet the raw plates load (:func:`_feet_loaded`): frames agreeing, frames missing a loaded foot, frames with a
    foot the plates do not load (a toe touching at push-off bounds the support too); and the plates' CoP inside
    livezmp's own support polygon, beside the ZMP (inside_fraction's test) on the same frames."""
    print(f"\nsupport against the plates (complete frames; a foot loaded above {100 * CONTACT_LOAD:g} % of the "
          "weight): frames, feet agree %, missed, extra | plate CoP inside livezmp's support % | ZMP inside %")
    totals = np.zeros(4)
    inside = []
    for name, (trial, a) in done.items():
        r = a.result
        rows = np.flatnonzero(a.complete & r.judged & np.isfinite(a.plates.cop).all(axis=1))
        if not len(rows):
            continue
        loaded = _feet_loaded(trial, a)
        labels = r.labels[rows]
        ours = {"left": np.isin(labels, ("left", "double")), "right": np.isin(labels, ("right", "double"))}
        missed = np.zeros(len(rows), dtype=bool)
        extra = np.zeros(len(rows), dtype=bool)
        for s in ours:
            missed |= loaded[s][rows] & ~ours[s]
            extra |= ours[s] & ~loaded[s][rows]
        cop_in = np.mean([support_and_clamp(r.soles["left"][i][:, :2], r.soles["right"][i][:, :2], r.labels[i],
                                            a.plates.cop[i, :2])[1].margin >= 0 for i in rows])
        zmp_in = float(np.mean(r.inside[rows]))
        totals += (len(rows), np.sum(~missed & ~extra), missed.sum(), extra.sum())
        inside.append((cop_in, zmp_in))
        print(f"{name[:34]:34s} {len(rows):5d} {100 * np.mean(~missed & ~extra):6.1f} {missed.sum():4d} "
              f"{extra.sum():4d} | {100 * cop_in:6.1f} | {100 * zmp_in:6.1f}")
    med = np.median(inside, axis=0)
    print(f"{'all':34s} {int(totals[0]):5d} {100 * totals[1] / totals[0]:6.1f} {int(totals[2]):4d} {int(totals[3]):4d}"
          f" | {100 * med[0]:6.1f} | {100 * med[1]:6.1f}  (inside: median over trials)")


def plausibility_check(done: dict[str, tuple]) -> None:
    """The plausibility verdict's inputs per trial: the markers' CoM acceleration p99 over the whole take (what a
    take is judged by), the plates' over the complete frames (both along the take's net travel, as the verdict),
    and the verdict; then the largest of each over the trials (the references are the tuning trials' largest)."""
    print(f"\nplausibility: CoM acceleration p99 m/s2 (fore-aft, lateral, vertical), references {WALK_COM_ACC_P99}")
    print(f"{'trial':34s} {'markers, whole take':>22s} {'plates, complete':>22s}  verdict")
    marks, plates = [], []
    for name, (trial, a) in done.items():
        r = a.result
        v = plausibility(r.com, r.zmp, r.has_zmp, 1.0 / a.rate)
        p99 = _axis_p99(_accelerations(trial, a)[1][a.complete], r.com) if a.complete.sum() >= 20 else [np.nan] * 3
        marks.append(v["com_acc_p99_mps2"])
        plates.append(p99)
        cells = ["/".join(f"{x:.2f}" for x in row) for row in (v["com_acc_p99_mps2"], p99)]
        print(f"{name[:34]:34s} {cells[0]:>22s} {cells[1]:>22s}  {v['verdict'][:60]}")
    most = ["/".join(f"{x:.2f}" for x in np.nanmax(np.array(v), axis=0)) for v in (marks, plates)]
    print(f"{'largest':34s} {most[0]:>22s} {most[1]:>22s}")


def plate_check(done: dict[str, tuple]) -> None:
    """Each plate read on its own, independent of the ZMP: `livezmp analyze`'s check that its CoP lies under the foot
    standing on it (summary cop_under_foot), and how far that CoP travels along the walk while the plate carries a
    quarter of the weight or more (a stance rolls it 15-25 cm from heel to toe; a plate whose moments are not read
    keeps it near its centre)."""
    print("\nplates read alone: CoP under the foot on it (frames, % on the foot, p95 mm off); CoP travel along the "
          "walk p5..p95 mm")
    for name, (_, a) in done.items():
        p = a.plates
        fwd, _ = walking_axes(a.result.com, facing(a.take))
        checks = {c["plate"]: c for c in a.summary["cop_under_foot"]["plates"]}
        cells = []
        for n, cop, fz in zip(p.used, p.plate_cop, p.plate_fz, strict=True):
            rows = (fz > COP_CHECK_WEIGHT * a.summary["mass"]["used_kg"] * G) & np.isfinite(cop).all(axis=1)
            if not rows.any():
                continue
            along = 1000 * cop[rows, :2] @ fwd[:2]
            c = checks.get(n)
            check = f"{c['frames']:3d} fr {100 * c['on_foot']:3.0f} % {c['off_p95_mm']:3.0f}" if c else f"{'-':>17s}"
            cells.append(f"p{n} {check}, travel {np.percentile(along, 95) - np.percentile(along, 5):3.0f}")
        print(f"{name[:34]:34s} " + " | ".join(cells))


def force_line(done: dict[str, tuple]) -> None:
    """The plates against their own force (`livezmp analyze`'s summary cop_vs_force_line): over complete frames,
    how far the plates' CoP lies from the line of their own force through the markers' CoM (RMS; and over single
    support half the difference between left and right stances, laterally + out towards the stance foot), beside
    the ZMP's offset from its own (kinematic) force line, and the ZMP - CoP lateral RMS. Off its force line a CoP
    says the body's angular momentum changes; the markers' segments say how much of that they carry."""
    print("\nthe plates' CoP against their own force line (complete frames), mm: RMS fore-aft / lateral, stance gap "
          "(single support) fore-aft / lateral | the ZMP's, from the markers | ZMP - CoP lateral RMS")
    for name, (_, a) in done.items():
        c = a.summary["cop_vs_force_line"]
        r, p = a.result, a.plates
        rows = _scored(a)
        _, left = walking_axes(r.com, facing(a.take))
        lat = 1000 * np.sqrt(np.mean(((r.zmp[rows, :2] - p.cop[rows, :2]) @ left[:2]) ** 2))

        def cells(kind: str, c: dict = c) -> str:
            rms, gap = c[f"{kind}_rms_mm"], c[f"{kind}_stance_gap_mm"]
            return (" ".join(f"{v:5.1f}" if v is not None else f"{'-':>5s}" for v in rms) + "  "
                    + (" ".join(f"{v:+6.1f}" for v in gap) if gap else f"{'-':>6s} {'-':>6s}"))
        print(f"{name[:34]:34s} {c['frames']:4d} fr  plates {cells('plates')} | ZMP {cells('zmp')} | {lat:5.1f}")


def cutoff_sweep(done: dict[str, tuple]) -> None:
    """`livezmp analyze` defaults on every trial but the estimator's cutoff (the plates low-passed with it)."""
    cutoffs = (4.0, 5.0, 6.0, 8.0)
    print("\nZMP vs CoP RMS (mm) by the estimator's cutoff, every trial (6 Hz: the default)")
    print(f"{'trial':34s} {'rate':>5s} " + " ".join(f"{c:5.0f} Hz" for c in cutoffs))
    table = []
    for name, (trial, a) in done.items():
        cvs = [a.summary["cop_vs_zmp"] if c == a.config.estimator.cutoff_hz else
               analyse_lab_take(trial, LabOptions(estimator={"cutoff_hz": c})).summary["cop_vs_zmp"] for c in cutoffs]
        rms = [np.nan if cv["rms_mm"] is None else cv["rms_mm"] for cv in cvs]  # None: no complete frame
        table.append(rms)
        print(f"{name[:34]:34s} {trial.rate:5.0f} " + " ".join(f"{x:8.1f}" for x in rms))
    print(f"{'median':40s} " + " ".join(f"{x:8.1f}" for x in np.nanmedian(table, axis=0)))


def _rms_by_shift(a: np.ndarray, b: np.ndarray, rows: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """RMS (mm) of a(t + shift frames) - b(t) over ``rows``, per shift."""
    idx = np.flatnonzero(rows)
    out = []
    for s in shifts:
        i = idx[(idx + s >= 0) & (idx + s < len(a))]
        d = a[i + s] - b[i]
        d = d[np.isfinite(d).all(axis=1)]
        out.append(1000 * np.sqrt(np.mean(np.sum(d * d, axis=1))) if len(d) else np.nan)
    return np.array(out)


def _lag_verdict(cv: dict) -> str:
    """Where a determined lag lies against the ±10 ms target, its uncertainty counted: 'within', 'beyond' (by
    more than its uncertainty) or 'undecided' (beyond, but within its uncertainty of it); '' when not determined."""
    if cv["lag_ms"] is None:
        return ""
    if abs(cv["lag_ms"]) <= LAG_TARGET_MS:
        return "within"
    u = cv["lag_uncertainty_ms"]
    return "beyond" if u is not None and abs(cv["lag_ms"]) - u > LAG_TARGET_MS else "undecided"


def lag_conditioning(done: dict[str, tuple], figures: Path | None) -> None:
    """Whether each trial's ZMP-CoP lag and plate delay are determined: the same estimate over the first and
    second halves of the complete frames (validation.LAG_AGREE_S), each with the half-width of its 95 %
    interval (validation.lag_uncertainty; the lag's includes the applied delay's), and where the determined lags
    lie against the ±10 ms target; with ``figures``, the ZMP-CoP RMS against the shift, whole and per half
    (lag_conditioning.png)."""
    print(f"\nlag and plate delay: whole ± 95 % half-width / first half / second half (ms), determined when the "
          f"halves agree within {1000 * LAG_AGREE_S:.0f} ms; the plate delay is applied only where determined")
    print(f"{'trial':34s} {'ZMP-CoP lag':>30s} {'plate delay (applied)':>38s}  RMS at lag 0 / at best shift mm; "
          f"against ±{LAG_TARGET_MS:g} ms")
    curves, verdicts = {}, []
    for name, (trial, a) in done.items():
        cv, ta = a.summary["cop_vs_zmp"], a.summary["time_alignment"]
        r, p = a.result, a.plates
        rows = _scored(a)
        zmp = np.where(r.has_zmp[:, None], r.zmp, np.nan)[:, :2]
        k = int(round(MAX_LAG_S * trial.rate))
        shifts = np.arange(-k, k + 1)
        idx = np.flatnonzero(rows)
        parts = [rows] + [np.isin(np.arange(len(rows)), part) for part in (idx[: len(idx) // 2], idx[len(idx) // 2 :])]
        curves[name] = (1000 * shifts / trial.rate, [_rms_by_shift(zmp, p.cop[:, :2], x, shifts) for x in parts])
        verdicts.append(_lag_verdict(cv))
        print(f"{name[:34]:34s} {_give_or_take(cv['lag_estimate_ms'], cv['lag_uncertainty_ms'])} / "
              + " / ".join(f"{v:+.0f}" if v is not None else "-" for v in cv["lag_halves_ms"])
              + f" {'yes' if cv['lag_ms'] is not None else 'no':>4s}   "
              f"{_give_or_take(ta['plate_delay_measured_ms'], ta['plate_delay_uncertainty_ms'])} / "
              + " / ".join(f"{v:+.0f}" if v is not None else "-" for v in ta["plate_delay_halves_ms"])
              + f" {'yes' if ta['plate_delay_determined'] else 'no':>4s} ({ta['plate_delay_applied_ms']:+.0f})  "
              f"{curves[name][1][0][k]:6.1f} / {np.nanmin(curves[name][1][0]):6.1f}; {verdicts[-1]}")
    print(f"determined lags: {verdicts.count('within')} within ±{LAG_TARGET_MS:g} ms, {verdicts.count('beyond')} "
          f"beyond it by more than their uncertainty, {verdicts.count('undecided')} beyond it within their "
          f"uncertainty; {verdicts.count('')} not determined")
    if figures is None:
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = len(curves)
    fig, axes = plt.subplots((n + 3) // 4, 4, figsize=(13, 2.6 * ((n + 3) // 4)), squeeze=False)
    for ax, (name, (t, (w, h1, h2))) in zip(axes.ravel(), curves.items(), strict=False):
        ax.plot(t, w, "k", lw=2, label="all complete frames")
        ax.plot(t, h1, "C0", label="first half")
        ax.plot(t, h2, "C1", label="second half")
        for c, col in ((w, "k"), (h1, "C0"), (h2, "C1")):
            ax.axvline(t[np.nanargmin(c)], color=col, ls=":", lw=1)
        ax.axvspan(-10, 10, color="0.9", zorder=0)
        ax.set_title(name.replace("sample_", "").replace(".c3d", "")[:30], fontsize=9)
        ax.set_xlabel("shift of the ZMP, ms")
        ax.set_ylabel("RMS ZMP - CoP, mm")
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    figures.mkdir(parents=True, exist_ok=True)
    fig.savefig(figures / "lag_conditioning.png", dpi=90)
    print(f"wrote {figures / 'lag_conditioning.png'}")


def _axis_map(z: np.ndarray, c: np.ndarray, offset: bool, gain: bool) -> np.ndarray:
    """Per axis (fore-aft, lateral): gain g and offset b (2, 2) of c = g z + b by least squares (g = 1 or b = 0
    when not fitted); ``z`` ZMP - CoM, ``c`` CoP - CoM (n, 2), m."""
    out = np.array([[1.0, 0.0], [1.0, 0.0]])
    for k in (0, 1):
        if gain and offset:
            out[k] = np.linalg.lstsq(np.column_stack([z[:, k], np.ones(len(z))]), c[:, k], rcond=None)[0]
        elif gain:
            out[k, 0] = z[:, k] @ c[:, k] / (z[:, k] @ z[:, k])
        else:
            out[k, 1] = np.mean(c[:, k] - z[:, k])
    return out


def _mapped_rms(z: np.ndarray, c: np.ndarray, coef: np.ndarray) -> float:
    d = z * coef[:, 0] + coef[:, 1] - c
    return float(1000 * np.sqrt(np.mean(np.sum(d * d, axis=1))))


SUBSETS = {"offset fa+lat": ("forward", "left"), "offset fa": ("forward",), "sway": ("sway_fore_aft", "sway_lateral"),
           "fraction+offset": ("hat_fraction", "forward", "left"),
           "offset+sway": ("forward", "left", "sway_fore_aft", "sway_lateral")}


def calibration_subsets(done: dict[str, tuple]) -> None:
    """`livezmp calibrate` fitting only some of the HAT's parameters (the others at the table), held out as in
    the calibration table, on the trials it accepts (a tracked thorax: all its parameters only); and each fit
    without the prior on its own frames."""
    print("\ncalibrated with fewer parameters: held out (fit on every other 0.2 s block, scored on the others) / "
          "unconstrained on its own frames, mm")
    print(f"{'trial':34s} {'table':>6s} {'all six':>13s} " + " ".join(f"{k:>15s}" for k in SUBSETS))
    for name, (trial, _) in done.items():
        cells = []
        for fit in (None, *SUBSETS.values()):
            try:
                _, rep = calibrate([trial], fit=fit)
            except InputError:
                break
            except ValueError:  # a HAT's subset, the trial's thorax tracked
                cells.append("-")
                continue
            cells.append(f"{rep['rms_held_out_fitted_mm']:6.1f} / {rep['rms_fitted_unconstrained_mm']:4.1f}")
        if cells:
            print(f"{name[:34]:34s} {rep['rms_held_out_table_mm']:6.1f} {cells[0]:>13s} "
                  + " ".join(f"{c:>15s}" for c in cells[1:]))


def calibration_floor(done: dict[str, tuple]) -> None:
    """What simple per-subject constants could do, at best: the ZMP mapped onto the plate CoP (both relative to
    the CoM's ground point, along and across the walk) by a constant offset (the bias), by a gain per axis on
    the dynamic term ZMP - CoM, and by both (4 numbers), fitted on the very frames they are scored on (an
    oracle), the same fitted on one half of the complete frames and scored on the other, and fitted on every
    other BLOCK_S block and scored on the others (calibrate's folds)."""
    print("\nfloor of per-subject constants: ZMP - CoP RMS mm after the best map of (ZMP - CoM) onto (CoP - CoM), "
          f"in-sample (oracle) / held out: fit on one half, score the other / fit on every other {BLOCK_S:g} s block, "
          "score the others")
    print(f"{'trial':34s} {'default':>7s} {'offset':>23s} {'gain per axis':>23s} {'gain+offset':>23s}")
    cols = {k: [] for k in ("default", "offset", "gain", "both")}
    for name, (_, a) in done.items():
        r, p = a.result, a.plates
        rows = _scored(a)
        fwd, left = walking_axes(r.com)
        axes = np.array([fwd[:2], left[:2]]).T
        z, c = (r.zmp[rows, :2] - r.com[rows, :2]) @ axes, (p.cop[rows, :2] - r.com[rows, :2]) @ axes
        half = np.arange(len(z)) >= len(z) // 2
        t = a.times[rows]
        odd = np.floor((t - t[0]) / BLOCK_S).astype(int) % 2 == 1
        cells = [f"{a.summary['cop_vs_zmp']['rms_mm']:7.1f}"]
        cols["default"].append(a.summary["cop_vs_zmp"]["rms_mm"])
        for key, offset, gain in (("offset", True, False), ("gain", False, True), ("both", True, True)):
            oracle = _mapped_rms(z, c, _axis_map(z, c, offset, gain))
            held = []
            for fold in (half, odd):
                sq = [_mapped_rms(z[b], c[b], _axis_map(z[f], c[f], offset, gain)) ** 2 * b.sum()
                      for f, b in ((fold, ~fold), (~fold, fold)) if f.any() and b.any()]
                held.append(float(np.sqrt(sum(sq) / len(z))))
            cols[key].append((oracle, *held))
            cells.append(f"{oracle:7.1f} {held[0]:7.1f} {held[1]:7.1f}")
        print(f"{name[:34]:34s} " + " ".join(cells))
    med = [f"{np.median(cols['default']):7.1f}"] + [
        " ".join(f"{np.median([v[i] for v in cols[k]]):7.1f}" for i in range(3)) for k in ("offset", "gain", "both")]
    print(f"{'median':34s} " + " ".join(med))


def calibration_table(done: dict[str, tuple]) -> None:
    """`livezmp calibrate` on each trial alone, cross-validated on every other BLOCK_S block of its complete
    frames, and (the former folds, beside) on their first and second halves."""
    print(f"\ncalibrated subject, each trial alone; held out = fitted on one fold (prior weight chosen within it), "
          f"scored on the other; folds: every other {BLOCK_S:g} s block (blocks), or the first and second halves of "
          "the complete frames (halves, as before) (mm)")
    print(f"{'trial':34s} {'frames':>6s} {'table':>7s} {'fitted':>7s} {'held-out table':>15s} {'halves':>7s} "
          f"{'blocks':>7s}  weight (all / held-out folds); segment (hat, thorax); fraction, CoM fwd/left/up mm, a "
          "HAT's sway gain fore-aft/lateral above the follow frequency (± jackknife SD); table: analyze's default")
    table, halves, blocks, every, off_default = [], [], [], [], []
    for name, (trial, a) in done.items():
        try:
            _, old = calibrate([trial], block_s=None)
            subject, rep = calibrate([trial])
        except InputError as e:
            print(f"{name[:34]:34s} not calibrated: {str(e).split(': ', 1)[-1][:110]}")
            every.append(a.summary["cop_vs_zmp"]["rms_mm"])
            continue
        table.append(rep["rms_held_out_table_mm"])
        off_default.append(abs(rep["rms_table_mm"] - a.summary["cop_vs_zmp"]["rms_mm"]))
        halves.append(old["rms_held_out_fitted_mm"])
        blocks.append(rep["rms_held_out_fitted_mm"])
        every.append(rep["rms_held_out_fitted_mm"])
        w = ", ".join("table" if v is None else f"{v:g}" for v in [rep["prior_weight"], *rep["held_out_prior_weights"]])
        theta = [subject.fraction, *subject.offset, *subject.hat_sway_gain][:len(rep["parameter_sd"])]
        scale = [1, 1000, 1000, 1000, 1, 1]
        fit = ", ".join(f"{v * k:.3g}±{e * k:.2g}" for v, e, k in zip(theta, rep["parameter_sd"], scale, strict=False))
        print(f"{name[:34]:34s} {rep['frames']:6d} {rep['rms_table_mm']:7.1f} {rep['rms_fitted_mm']:7.1f} "
              f"{rep['rms_held_out_table_mm']:15.1f} {old['rms_held_out_fitted_mm']:7.1f} "
              f"{rep['rms_held_out_fitted_mm']:7.1f}  {w}; {subject.segment}; "
              f"{'table kept' if rep['table_kept'] else fit}")
    if blocks:
        print(f"median held-out RMS over the {len(blocks)} calibrated trials: table {np.median(table):.1f} mm, "
              f"calibrated with halves {np.median(halves):.1f} mm, with blocks {np.median(blocks):.1f} mm; over all "
              f"{len(every)} (the others at their default): {np.median(every):.1f} mm; the table column is analyze's "
              f"default (largest difference {max(off_default):.2f} mm)")


def _subject_names(path: str) -> tuple[str, ...]:
    """The file's SUBJECTS:NAMES (empty when it names none)."""
    groups = ezc3d.c3d(str(path), extract_forceplat_data=False)["parameters"]
    return tuple(n.strip() for n in groups.get("SUBJECTS", {}).get("NAMES", {}).get("value", []) if n.strip())


def calibration_across_trials(done: dict[str, tuple]) -> None:
    """Trials naming the same subject (SUBJECTS:NAMES): calibrated on one (when calibrate accepts it), scored with
    `analyze --subject` on each other, the table (analyze's default) beside."""
    print("\ncalibrated on one trial, scored on another trial of the same subject (SUBJECTS:NAMES), ZMP - CoP RMS mm")
    groups: dict[tuple[str, ...], list[str]] = {}
    for name, (trial, _) in done.items():
        if names := _subject_names(trial.source):
            groups.setdefault(names, []).append(name)
    for names, members in groups.items():
        for src in members if len(members) > 1 else []:
            try:
                subject, _ = calibrate([done[src][0]])
            except InputError as e:
                print(f"{src[:34]:34s} not calibrated: {str(e).split(': ', 1)[-1][:90]}")
                continue
            for dst in (m for m in members if m != src):
                trial, a = done[dst]
                cal = analyse_lab_take(trial, LabOptions(markers=subject.marker_options()))
                print(f"{src[:34]:34s} -> {dst[:34]:34s} table {a.summary['cop_vs_zmp']['rms_mm']:6.1f}  calibrated "
                      f"{cal.summary['cop_vs_zmp']['rms_mm']:6.1f}  (subject {'/'.join(names)})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("more", nargs="*", help="more C3D trials, or directories holding them")
    ap.add_argument("--figures", type=Path, help="write the figures (docs/validation/) into this directory")
    ap.add_argument("--static", action="append", default=[], metavar="WALK.c3d=STATIC.c3d",
                    help="an extra walk's static trial (the walk by its file name or path; repeatable)")
    args = ap.parse_args()
    statics = {Path(walk).name: static for walk, _, static in (s.partition("=") for s in args.static)}
    t0 = time.perf_counter()
    print(f"load average {load_averages(' ')}")
    results = {name: trial_table(DATA / name) for name in TRIALS}
    print("\nmedian RMS over the trials per step (mm):")
    for k, (name, _) in enumerate(STEPS):
        print(f"  {name:40s} {np.median([results[t][k]['rms_mm'] for t in TRIALS]):7.1f}")
    done = {name: (trial, analyse_lab_take(trial)) for name in TRIALS for trial in [read_c3d(DATA / name)]}
    if args.more:
        done |= extra_table(extra_paths(args.more), statics)
        rms = [a.summary["cop_vs_zmp"]["rms_mm"] for _, a in done.values()]
        print(f"median RMS over all {len(rms)} trials with complete frames (defaults): {np.median(rms):.1f} mm")
    trunk_sway(done)
    sway_before_after(done)
    error_sources(done)
    lag_split(done)
    bias_and_lead(done)
    am_split(done)
    lateral_sources(done)
    single_stance_lateral(done)
    swing_at_step_frequency(done)
    foot_frame(done)
    plate_check(done)
    support_check(done)
    plausibility_check(done)
    force_line(done)
    if args.more:
        cutoff_sweep(done)
    lag_conditioning(done, args.figures)
    calibration_table(done)
    calibration_across_trials(done)
    calibration_subsets(done)
    calibration_floor(done)
    print("\nestimator acceleration of a sinusoid, cutoff 6 Hz: gain / delay (ms)")
    print(f"{'rate Hz':>8s} {'freq Hz':>8s} {'live 0.4/0.1 s':>18s} {'lab 0.8/0.4 s':>18s}")
    for rate in (50.0, 100.0, 240.0):
        for f in (1.0, 2.0, 4.0):
            live = estimator_response(rate, f, 0.4, 0.1, 6.0)
            lab = estimator_response(rate, f, 0.8, 0.4, 6.0)
            print(f"{rate:8.0f} {f:8.1f} {live[0]:9.3f} {live[1]:+7.1f} {lab[0]:9.3f} {lab[1]:+7.1f}")
    print(f"\n({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    main()
