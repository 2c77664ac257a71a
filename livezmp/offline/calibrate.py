"""A subject's head-arms-trunk (HAT) parameters identified from force-plate trials.

A lower-body marker set does not see the trunk, so the table places the HAT (about half the body
mass) straight above the mid-hip. Its mass fraction and centre of mass (forward, left, up from the
mid-hip in the pelvis' heading frame) are found here by least squares on the plates: ZMP − CoP and
the CoM's horizontal acceleration against (GRF − m g) / m (weighted by h / g, in metres of ZMP),
over the complete frames. The kinematics do not depend on these parameters, so the take is analysed
once: the rest of the body's wrench is computed once, and the HAT adds a point mass moving with
the HAT frame (x, y, z, heading channels), exactly as in the body model.

The table is the prior (the HAT sway gains' is :data:`TRUNK_SWAY_GAIN`, measured on trunk-marker trials), and
how strongly the fit is held to it is chosen by cross-validation on the frames being fitted: each trial's
complete frames are split into their first and second halves, every prior weight of ``PRIOR_WEIGHTS`` is fitted
on one half and scored on the other, and the weight with the lower mean held-out error among those that beat
the table both ways round is used (else, or when a half has fewer than ``MIN_FRAMES`` frames, the table itself,
an infinite weight). A trial whose plates' horizontal
force runs against the markers' motion is refused. Reported held-out error: fitted on one half (its weight
chosen the same way within that half's own halves) and scored on the other, never seen by the fit or the choice.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

from livezmp.balance.plates import G
from livezmp.errors import InputError
from livezmp.model.anthropometry import ADULT, MAX_AGE_YEARS, BspTable, child_segments
from livezmp.model.c3d import C3dTrial
from livezmp.model.markers import TRUNK_SWAY_GAIN, MarkerBodyOptions, body_from_markers, hat_table, sway_basis
from livezmp.offline.gaitlab import LabAnalysis, LabOptions, analyse_lab_take, com_accelerations, facing
from livezmp.offline.validation import walking_axes
from livezmp.tomlfile import read_toml

HAT = slice(6, 12)  # the HAT segment's channels: x, y, z, yaw, pitch, roll
ACC_WEIGHT = 0.09  # m per m/s²: a CoM acceleration error counts like the ZMP shift it causes (h / g)
# fraction, m, m, m: what subjects plausibly differ by; sway gains: no table gives them, so a weak prior that
# only holds them at 1 (the HAT moving with the mid-hip) where the data do not say otherwise
PRIOR_SD = np.array([0.05, 0.03, 0.03, 0.05, 0.5, 0.5])
PRIOR_MM = 10.0
# multiples of that prior's weight tried by the cross-validation (inf: the table, nothing fitted)
PRIOR_WEIGHTS = (0.3, 1.0, 3.0, 10.0, 30.0, np.inf)
MIN_FRAMES = 20  # complete frames a fit (and each part of its cross-validation) needs
# the prior's weight for the unconstrained fit (bounds only): on the very frames it is fitted on, the least error
# any HAT parameters reach on these trials, reported as their floor
FREE_WEIGHT = 1e-3
PARAMETERS = ("hat_fraction", "forward", "left", "up", "sway_fore_aft", "sway_lateral")  # theta's entries
# fraction, forward, left, up (m), sway gain fore-aft, lateral
BOUNDS = ([0.30, -0.15, -0.10, 0.10, 0.0, 0.0], [0.70, 0.15, 0.10, 0.60, 1.5, 1.5])


@dataclass(frozen=True)
class Subject:
    """HAT mass fraction of the body, its centre of mass (forward, left, up) m from the mid-hip, and how far
    it sways (fore-aft, lateral) relative to the mid-hip (:func:`livezmp.model.markers.hat_sway`); the rest of the
    body's segment table ``bsp`` ("adult", "child"; None: chosen from each file) and the subject's age, years."""

    hat_fraction: float
    hat_offset: tuple[float, float, float]
    hat_sway_gain: tuple[float, float] = TRUNK_SWAY_GAIN
    bsp: str | None = None
    age_years: float | None = None

    def marker_options(self, base: MarkerBodyOptions | None = None) -> MarkerBodyOptions:
        """``base`` with this subject's HAT; its table and age unless ``base`` asks for its own."""
        base = base or MarkerBodyOptions()
        return replace(base, hat_fraction=self.hat_fraction, hat_offset=self.hat_offset,
                       hat_sway_gain=self.hat_sway_gain, bsp=self.bsp if base.bsp == "auto" and self.bsp else base.bsp,
                       age_years=base.age_years if base.age_years is not None else self.age_years)


def load_subject(path: str | Path) -> Subject:
    """Read a subject file (TOML ``[subject]`` with ``hat_fraction``, ``hat_offset_m = [fwd, left, up]`` and
    optionally ``hat_sway_gain = [fore_aft, lateral]``, else :data:`TRUNK_SWAY_GAIN`; ``bsp = "adult"`` or
    ``"child"`` and ``age_years``, else the table is chosen from each file)."""
    p = Path(path)
    s = read_toml(p, "subject file").get("subject")
    if not isinstance(s, dict):
        raise InputError(f"{p}: missing [subject] table")
    f, off = s.get("hat_fraction"), s.get("hat_offset_m")
    if not isinstance(f, int | float) or not 0.0 < f < 1.0:
        raise InputError(f"{p}: subject.hat_fraction must be a number between 0 and 1, got {f!r}")
    if not (isinstance(off, list) and len(off) == 3 and all(isinstance(v, int | float) for v in off)
            and all(abs(v) < 1.5 for v in off)):
        raise InputError(f"{p}: subject.hat_offset_m must be [forward, left, up] in metres, got {off!r}")
    gain = s.get("hat_sway_gain", list(TRUNK_SWAY_GAIN))
    if not (isinstance(gain, list) and len(gain) == 2
            and all(isinstance(v, int | float) and 0 <= v <= 2 for v in gain)):
        raise InputError(f"{p}: subject.hat_sway_gain must be [fore_aft, lateral], each 0..2, got {gain!r}")
    bsp, age = s.get("bsp"), s.get("age_years")
    if bsp is not None and bsp not in ("adult", "child"):
        raise InputError(f"{p}: subject.bsp must be \"adult\" or \"child\", got {bsp!r}")
    if age is not None and not (isinstance(age, int | float) and 0 < age < MAX_AGE_YEARS):
        raise InputError(f"{p}: subject.age_years must be a number of years, got {age!r}")
    return Subject(float(f), tuple(float(v) for v in off), tuple(float(v) for v in gain), bsp,
                   None if age is None else float(age))


def write_subject(subject: Subject, path: str | Path, report: dict) -> None:
    lines = ["# livezmp subject file (livezmp calibrate)", "[subject]",
             f"hat_fraction = {subject.hat_fraction:.5f}",
             "hat_offset_m = [" + ", ".join(f"{v:.5f}" for v in subject.hat_offset) + "]  # forward, left, up",
             "hat_sway_gain = [" + ", ".join(f"{v:.4f}" for v in subject.hat_sway_gain) + "]  # fore-aft, lateral",
             *([f'bsp = "{subject.bsp}"  # the segment table the HAT was fitted with'] if subject.bsp else []),
             *([f"age_years = {subject.age_years:.3f}"] if subject.age_years is not None else []),
             "", "[calibration]"]
    for k, v in report.items():
        lines.append(f"{k} = {v!r}" if not isinstance(v, str) else f'{k} = "{v}"')
    Path(path).write_text("\n".join(lines).replace("None", '"n/a"') + "\n", encoding="utf-8")


@dataclass
class _Terms:
    """Per complete frame: the rest of the body's wrench for the whole mass (F (n, 3) N, moment about
    the origin (n, 3) N·m), the HAT frame's origin o, acceleration a_o, heading A and its second
    derivative B (p = o + A r, a = a_o + B r), the plates' CoP (n, 2) and acceleration (n, 3); the
    origin's straight-line trend and the walk's axes (for the sway gains: o -> trend + K (o - trend))."""

    f_rest: np.ndarray
    m_rest: np.ndarray
    o: np.ndarray
    a_o: np.ndarray
    A: np.ndarray
    B: np.ndarray
    cop: np.ndarray
    plate_acc: np.ndarray
    mass: float
    floor: float
    trend: np.ndarray
    fwd: np.ndarray
    left: np.ndarray

    def part(self, sel: np.ndarray) -> _Terms:
        """The same terms on the frames ``sel`` (boolean over this one's frames)."""
        return _Terms(**{f.name: v[sel] if isinstance(v := getattr(self, f.name), np.ndarray) and v.ndim >= 1
                         and f.name not in ("fwd", "left") else v for f in fields(self)})


def _terms(trial: C3dTrial, lab: LabAnalysis, rows: np.ndarray, markers: MarkerBodyOptions) -> _Terms:
    mass = lab.summary["mass"]["used_kg"]
    rest = body_from_markers(trial, replace(markers, total_mass=mass, hat_fraction=0.0)).body.model
    data = rest.createData()
    r = lab.result
    idx = np.flatnonzero(rows)
    f_rest, m_rest = np.empty((len(idx), 3)), np.empty((len(idx), 3))
    for k, i in enumerate(idx):
        pin.computeCentroidalMomentumTimeVariation(rest, data, r.q[i], r.v[i], r.a[i])
        f = data.dhg.linear - mass * rest.gravity.linear
        f_rest[k], m_rest[k] = f, data.dhg.angular + np.cross(data.com[0], f)
    q, v, a = r.q[idx, HAT], r.v[idx, HAT], r.a[idx, HAT]
    c, s = np.cos(q[:, 3]), np.sin(q[:, 3])
    zero, one = np.zeros_like(c), np.ones_like(c)
    A = np.stack([np.stack([c, -s, zero], -1), np.stack([s, c, zero], -1), np.stack([zero, zero, one], -1)], 1)
    d1 = np.stack([np.stack([-s, -c, zero], -1), np.stack([c, -s, zero], -1), np.stack([zero] * 3, -1)], 1)
    d2 = np.stack([np.stack([-c, s, zero], -1), np.stack([-s, -c, zero], -1), np.stack([zero] * 3, -1)], 1)
    B = a[:, 3, None, None] * d1 + (v[:, 3] ** 2)[:, None, None] * d2
    plate_acc = lab.plates.force[idx] / mass - np.array([0.0, 0.0, G])
    trend, fwd, left = sway_basis(r.q[:, HAT][:, :3], facing(lab.take))
    return _Terms(f_rest, m_rest, q[:, :3], a[:, :3], A, B, lab.plates.cop[idx, :2], plate_acc, mass,
                  lab.plates.surface_z, trend[idx], fwd, left)


def _model(t: _Terms, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ZMP (n, 2) m and CoM acceleration (n, 3) m/s² for parameters (fraction, forward, left, up, sway gain
    fore-aft, lateral)."""
    f_h, r, (k_fa, k_lat) = theta[0], theta[1:4], theta[4:6]
    rest = 1.0 - f_h  # the rest's wrench was computed with no HAT, i.e. the rest carrying the whole mass
    m_h = f_h * t.mass
    k = k_fa * np.outer(t.fwd, t.fwd) + k_lat * np.outer(t.left, t.left) + np.diag([0.0, 0.0, 1.0])
    p = t.trend + (t.o - t.trend) @ k.T + t.A @ r
    acc = t.a_o @ k.T + t.B @ r - np.array([0.0, 0.0, -G])
    force = rest * t.f_rest + m_h * acc
    moment = rest * t.m_rest + m_h * np.cross(p, acc)
    z0 = t.floor
    zmp = np.column_stack([(z0 * force[:, 0] - moment[:, 1]) / force[:, 2],
                           (moment[:, 0] + z0 * force[:, 1]) / force[:, 2]])
    return zmp, force / t.mass + np.array([0.0, 0.0, -G])


def _residuals(theta: np.ndarray, terms: list[_Terms], prior: np.ndarray, weight: float) -> np.ndarray:
    out = []
    for t in terms:
        zmp, acc = _model(t, theta)
        out += [(zmp - t.cop).ravel(), ACC_WEIGHT * (acc[:, :2] - t.plate_acc[:, :2]).ravel()]
    n = sum(len(t.cop) for t in terms)
    # the table as a prior: at weight 1 a parameter PRIOR_SD away from it costs like PRIOR_MM of ZMP error on
    # every frame
    out.append(np.sqrt(weight * n) * PRIOR_MM / 1000 * (theta - prior) / PRIOR_SD)
    return np.concatenate(out)


def _rms_mm(theta: np.ndarray, terms: list[_Terms]) -> float:
    d = np.vstack([_model(t, theta)[0] - t.cop for t in terms])
    return float(1000 * np.sqrt(np.mean(np.sum(d * d, axis=1))))


def _fit(terms: list[_Terms], prior: np.ndarray, weight: float, free: np.ndarray) -> np.ndarray:
    """Least squares over the parameters ``free`` (bool (6,)); the others stay at the prior."""
    if not np.isfinite(weight):
        return prior

    def theta(x: np.ndarray) -> np.ndarray:
        out = prior.copy()
        out[free] = x
        return out

    lo, hi = (np.asarray(b)[free] for b in BOUNDS)
    x = least_squares(lambda x: _residuals(theta(x), terms, prior, weight), prior[free], bounds=(lo, hi),
                      x_scale=PRIOR_SD[free]).x
    return theta(x)


def _halves(terms: list[_Terms]) -> tuple[list[_Terms], list[_Terms]]:
    """Every trial's frames split into their first and second halves."""
    cut = [np.arange(len(t.cop)) < len(t.cop) // 2 for t in terms]
    return [t.part(c) for t, c in zip(terms, cut, strict=True)], [t.part(~c) for t, c in zip(terms, cut, strict=True)]


def _cross_validated(halves: tuple[list[_Terms], list[_Terms]], prior: np.ndarray,
                     free: np.ndarray) -> tuple[float, list[float]]:
    """The prior weight whose fits on one half score best on the other (mean RMS over both ways round) among
    those that beat the table both ways round (else the table: a fit that helps one way and not the other
    is a fit to that half's noise), and each weight's mean score (mm)."""
    if min(sum(len(t.cop) for t in half) for half in halves) < MIN_FRAMES:
        return PRIOR_WEIGHTS[-1], []
    table = [_rms_mm(prior, halves[1 - k]) for k in (0, 1)]
    folds = np.array([[_rms_mm(_fit(halves[k], prior, w, free), halves[1 - k]) for k in (0, 1)]
                      for w in PRIOR_WEIGHTS])
    score = folds.mean(axis=1)
    ok = (folds < np.array(table)).all(axis=1)
    best = int(np.flatnonzero(ok)[np.argmin(score[ok])]) if ok.any() else len(PRIOR_WEIGHTS) - 1
    return PRIOR_WEIGHTS[best], [float(v) for v in score]


def _check_agreement(trial: C3dTrial, lab: LabAnalysis, rows: np.ndarray) -> None:
    """Refuse a trial whose plates' horizontal force runs against the markers' motion (the CoM accelerations
    from both anticorrelated along the walk or across it): plates or markers are wrong there, and a fit to
    them would move the subject's parameters to make up for it."""
    kin = com_accelerations(lab.take, lab.result)[rows]
    plate = lab.plates.force[rows] / lab.summary["mass"]["used_kg"]
    for name, axis in zip(("fore-aft", "lateral"), walking_axes(lab.result.com, facing(lab.take)), strict=True):
        r = float(np.corrcoef(kin @ axis, plate @ axis)[0, 1])
        if r < 0:
            raise InputError(f"{trial.source}: the plates' {name} force runs against the markers' motion (r = "
                             f"{r:.2f} between the CoM accelerations): plates or markers are wrong; not a trial "
                             "to calibrate on")


def calibrate(trials: list[C3dTrial], opts: LabOptions | None = None,
              fit: tuple[str, ...] = PARAMETERS) -> tuple[Subject, dict]:
    """Fit the HAT parameters on ``trials`` (see the module docstring); returns the subject and a report
    (RMS ZMP − CoP with the table, fitted, fitted without the prior on the same frames (the floor of what
    these parameters can do there), and held out, mm; the prior weight chosen). ``fit``: which of
    ``PARAMETERS`` are fitted (the others keep the table's value)."""
    unknown = set(fit) - set(PARAMETERS)
    if unknown or not fit:
        raise ValueError(f"calibrate: fit takes some of {PARAMETERS}, got {fit}")
    free = np.isin(PARAMETERS, fit)
    opts = opts or LabOptions()
    # the HAT frame's origin at the mid-hip: the fit sways it (the table's sway is its prior)
    opts = replace(opts, markers=replace(opts.markers, hat_sway_gain=None))
    whole = []
    for trial in trials:
        if not trial.plates:
            raise InputError(f"{trial.source}: no force plates: nothing to calibrate against")
        lab = analyse_lab_take(trial, opts)
        if "hat.x" not in lab.take.body.channel_names:
            raise InputError(f"{trial.source}: a full-body or trunk marker set tracks the trunk: "
                             "there is no placed HAT to calibrate")
        rows = lab.complete & lab.result.has_zmp & np.isfinite(lab.plates.cop).all(axis=1)
        if rows.sum() < MIN_FRAMES:
            raise InputError(f"{trial.source}: only {int(rows.sum())} complete frames; need {MIN_FRAMES}")
        _check_agreement(trial, lab, rows)
        whole.append(_terms(trial, lab, rows, opts.markers))
        stature, bsp = lab.summary["markers"]["stature_m"], lab.summary["markers"]["bsp"]
    table = ADULT if bsp["table"] == "adult" else BspTable(child_segments(bsp["age_years"]), "child", bsp["age_years"])
    fraction, height, _ = hat_table(stature, table=table.segments)
    prior = np.array([fraction, 0.0, 0.0, height, *TRUNK_SWAY_GAIN])
    halves = _halves(whole)
    weight, scores = _cross_validated(halves, prior, free)
    fitted = _fit(whole, prior, weight, free)
    unconstrained = _fit(whole, prior, FREE_WEIGHT, free)
    held_out, weights = [], []
    for k in (0, 1):  # the held-out half sees neither the fit nor the choice of its weight
        w, _ = _cross_validated(_halves(halves[k]), prior, free)
        held_out.append(_rms_mm(_fit(halves[k], prior, w, free), halves[1 - k]))
        weights.append(w)
    report = {"trials": [t.source for t in trials], "frames": int(sum(len(t.cop) for t in whole)),
              "rms_table_mm": round(_rms_mm(prior, whole), 2), "rms_fitted_mm": round(_rms_mm(fitted, whole), 2),
              "rms_fitted_unconstrained_mm": round(_rms_mm(unconstrained, whole), 2),
              "rms_held_out_table_mm": round(float(np.mean([_rms_mm(prior, halves[1 - k]) for k in (0, 1)])), 2),
              "rms_held_out_fitted_mm": round(float(np.mean(held_out)), 2),
              "prior_weight": None if not np.isfinite(weight) else weight,
              "prior_weight_scores_mm": [round(v, 2) for v in scores],
              "held_out_prior_weights": [None if not np.isfinite(w) else w for w in weights]}
    return Subject(float(fitted[0]), tuple(float(v) for v in fitted[1:4]), tuple(float(v) for v in fitted[4:6]),
                   table.name, table.age_years), report
