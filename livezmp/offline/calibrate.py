"""A subject's head-arms-trunk (HAT) or trunk parameters identified from force-plate trials.

A lower-body marker set does not see the trunk, so the table places the HAT (about half the body
mass) straight above the mid-hip. Its mass fraction and centre of mass (forward, left, up from the
mid-hip in the pelvis' heading frame) are found here by least squares on the plates: ZMP − CoP and
the CoM's horizontal acceleration against (GRF − m g) / m (weighted by h / g, in metres of ZMP),
over the complete frames. The kinematics do not depend on these parameters, so the take is analysed
once: the rest of the body's wrench is computed once, and the HAT adds a point mass moving with
the HAT frame (x, y, z, heading channels), exactly as in the body model.

The HAT sways as in analyze's default (:func:`livezmp.model.markers.hat_sway`): it follows the mid-hip below
:data:`TRUNK_FOLLOW_HZ` and sways a gain (fore-aft, lateral) times it above; the gains are fitted. The take is run
at the table's gains (so its plate delay and complete frames are analyze's) and once with the HAT's sway above
that frequency removed: base and estimator being linear in it, the two give the HAT at any gain.

The table is the prior (the HAT sway gains' is :data:`TRUNK_STEP_GAIN`, measured on trunk-marker trials), and
how strongly the fit is held to it is chosen by cross-validation on the frames being fitted. The folds respect
the gait: each trial's complete frames are cut into blocks of ``BLOCK_S`` and every other block goes to one
fold, so both folds hold both feet and every part of each stance. (The former folds, each trial's first and
second halves, put one foot's stance in one half and the other's in the other on most short trials, so a fit
on one half was scored on the other foot: ``block_s=None`` still gives them.) Given several trials of one
subject, the folds are the trials instead, each held out in turn (a subject file is for a take it was not fitted
on; the blocks of one take share what is constant over it and not the subject's). Every prior weight of
``PRIOR_WEIGHTS`` is fitted on the rest and scored on each fold, and the weight with the lower pooled held-out
error among those that beat the table every way round is used (else, or when a fold has fewer than
``MIN_FOLD_FRAMES`` frames, the table itself, an infinite weight, and the report says so). A trial whose plates'
horizontal force runs against the markers' motion is refused. Reported held-out error: fitted on the rest (its
weight chosen the same way within them: their blocks, or with several trials left, those trials) and scored on
each fold, never seen by the fit or the choice (with several trials: each trial scored with the parameters
calibrated on the others). Each parameter's uncertainty: the delete-one-block jackknife of the fit at the chosen
weight (the blocks, not the frames, are the independent samples).

A full-body or trunk marker set tracks the thorax (middle + upper trunk; head and arms tracked or placed on it), so
there the thorax is the fitted segment, the same way: its mass fraction and centre of mass (forward, left, up the
trunk from its origin at the cervicale's level, in its own tracked frame, the full rotation R: its acceleration is
a_o + R([ω̇]× + [ω]×²) r, ω in that frame, and its own rate of angular momentum about its centre of mass is the
table's inertia's, scaled with its mass), the rest of the body (scaled to the remainder of the mass) computed once,
with the table (:func:`livezmp.model.markers.thorax_table`) as the prior and the same cross-validation, jackknife
and refusals; no sway gains (the trunk's markers say where it is). Its subject file has ``trunk_fraction`` and
``trunk_offset_m`` instead of the ``hat_*`` keys, and either kind is refused with the other kind of set.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.optimize import least_squares

from livezmp.balance.plates import G, plates_floor
from livezmp.errors import InputError
from livezmp.jsonfile import write_text_atomic
from livezmp.model.anthropometry import ADULT, MAX_AGE_YEARS, BspTable, child_segments
from livezmp.model.c3d import C3dTrial
from livezmp.model.markers import (
    TRUNK_FOLLOW_HZ,
    TRUNK_STEP_GAIN,
    MarkerBodyOptions,
    body_from_markers,
    hat_table,
    sway_basis,
    thorax_table,
)
from livezmp.offline.gaitlab import LabAnalysis, LabOptions, analyse_lab_take, com_accelerations, facing, run_take
from livezmp.offline.validation import walking_axes
from livezmp.tomlfile import read_toml

ACC_WEIGHT = 0.09  # m per m/s²: a CoM acceleration error counts like the ZMP shift it causes (h / g)
# fraction, m, m, m: what subjects plausibly differ by; sway gains: no table gives them, so a weak prior that
# only holds them at the trunk-marker trials' where the data do not say otherwise
PRIOR_SD = np.array([0.05, 0.03, 0.03, 0.05, 0.5, 0.5])
PRIOR_MM = 10.0
# multiples of that prior's weight tried by the cross-validation (inf: the table, nothing fitted)
PRIOR_WEIGHTS = (0.3, 1.0, 3.0, 10.0, 30.0, np.inf)
MIN_FRAMES = 20  # complete frames a fit needs
MAX_FOLLOW_HZ = 5.0  # a subject file's hat_follow_hz: above it the sway of every step would be followed
# ... and below this (a 100 s period) it follows nothing a take holds; far lower, the follow filter's design is
# singular (2e-300 Hz: scipy's LinAlgError)
MIN_FOLLOW_HZ = 0.01
# the cross-validation's blocks, s: longer than the table's ZMP - CoP error stays correlated (its autocorrelation
# falls below 1/e within 50-100 ms on 8 of the 10 calibratable plate trials; 200-230 ms on two), shorter than a
# stance (0.5-0.7 s), so every stance spans blocks of both folds
BLOCK_S = 0.2
MIN_FOLD_FRAMES = 10  # frames each fold needs for a score (half of MIN_FRAMES: a fold is scored, not fitted alone)
# the prior's weight for the unconstrained fit (bounds only): on the very frames it is fitted on, the least error
# any HAT parameters reach on these trials, reported as their floor
FREE_WEIGHT = 1e-3
PARAMETERS = ("hat_fraction", "forward", "left", "up", "sway_fore_aft", "sway_lateral")  # theta's entries
# fraction, forward, left, up (m), sway gain fore-aft, lateral
BOUNDS = ([0.30, -0.15, -0.10, 0.10, 0.0, 0.0], [0.70, 0.15, 0.10, 0.60, 1.5, 1.5])
# a tracked thorax: theta's first four (its sway gains are not used: its markers place it)
TRUNK_PARAMETERS = ("trunk_fraction", "forward", "left", "up")
# fraction (the table: 0.31-0.32), forward, left, up the trunk from the cervicale's level (the table: 0.11-0.17 m
# below it for statures of 1.3-1.8 m), m
TRUNK_BOUNDS = ([0.15, -0.15, -0.10, -0.45, 0.0, 0.0], [0.50, 0.15, 0.10, 0.0, 1.5, 1.5])


@dataclass(frozen=True)
class Segment:
    """The segment a marker set's fit moves: its channels' prefix in the marker body (``"hat"``: a lower-body set's
    placed HAT; ``"thorax"``: a full-body or trunk set's tracked thorax), the parameters fitted (theta's first
    entries), theta's bounds, and the :class:`MarkerBodyOptions` field that sets its mass fraction."""

    name: str
    parameters: tuple[str, ...]
    bounds: tuple[list[float], list[float]]
    fraction_option: str


HAT_SEGMENT = Segment("hat", PARAMETERS, BOUNDS, "hat_fraction")
THORAX_SEGMENT = Segment("thorax", TRUNK_PARAMETERS, TRUNK_BOUNDS, "trunk_fraction")


@dataclass(frozen=True)
class Subject:
    """The fitted segment's (``segment``: ``"hat"``, a lower-body set's placed HAT, or ``"thorax"``, a full-body or
    trunk set's tracked thorax) mass fraction of the body and centre of mass (forward, left, up) m: the HAT's from
    the mid-hip in the pelvis' heading frame, the thorax' from its origin in its own frame; how far a HAT sways
    (fore-aft, lateral) relative to the mid-hip above ``hat_follow_hz`` Hz, following it below
    (:func:`livezmp.model.markers.hat_sway`); the rest of the body's segment table ``bsp`` ("adult", "child";
    None: chosen from each file) and the subject's age, years."""

    fraction: float
    offset: tuple[float, float, float]
    hat_sway_gain: tuple[float, float] = TRUNK_STEP_GAIN
    bsp: str | None = None
    age_years: float | None = None
    hat_follow_hz: float = TRUNK_FOLLOW_HZ
    segment: str = "hat"

    def marker_options(self, base: MarkerBodyOptions | None = None) -> MarkerBodyOptions:
        """``base`` with this subject's HAT or thorax; its table and age unless ``base`` asks for its own."""
        base = base or MarkerBodyOptions()
        base = replace(base, bsp=self.bsp if base.bsp == "auto" and self.bsp else base.bsp,
                       age_years=base.age_years if base.age_years is not None else self.age_years)
        if self.segment == "thorax":
            return replace(base, trunk_fraction=self.fraction, trunk_offset=self.offset)
        return replace(base, hat_fraction=self.fraction, hat_offset=self.offset, hat_sway_gain=self.hat_sway_gain,
                       hat_follow_hz=self.hat_follow_hz)

    def bvh_hat_fraction(self, where: str) -> float:
        """The HAT fraction a BVH's head, arms and trunk are rescaled to; a tracked thorax' subject (``where``: its
        file) is refused (its fraction is the thorax' alone)."""
        if self.segment != "hat":
            raise InputError(f"{where}: a tracked trunk's subject file (trunk_fraction) is for a full-body or trunk "
                             "C3D marker set; a BVH takes a placed HAT's (hat_fraction)")
        return self.fraction


SUBJECT_KEYS = {"hat_fraction", "hat_offset_m", "hat_sway_gain", "hat_follow_hz", "bsp", "age_years"}
TRUNK_KEYS = {"trunk_fraction", "trunk_offset_m", "bsp", "age_years"}  # a tracked thorax' subject file


def _is_number(value: object) -> bool:
    """A TOML number: an integer or a float (TOML's ``true`` is a Python int, and no number)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def _bounded(p: Path, key: str, value: object, segment: Segment, index: int, what: str) -> float:
    """``value``, the subject file's ``key`` (``what``: its part), checked to be a number within what calibrate fits
    for ``segment`` (its bounds' entry ``index``): values outside them, which no fit gives (a HAT of 99.999 % of
    the body, a centre of mass 1.4 m off the trunk), would be analysed without a word."""
    lo, hi = segment.bounds[0][index], segment.bounds[1][index]
    if not (_is_number(value) and lo <= value <= hi):
        raise InputError(f"{p}: subject.{key}{what} must be a number from {lo:g} to {hi:g} (the range calibrate "
                         f"fits), got {value!r}")
    return float(value)


def _bounded_list(p: Path, key: str, value: object, segment: Segment, first: int,
                  names: tuple[str, ...]) -> tuple[float, ...]:
    """The list ``value`` of the subject file's ``key``, one number per name of ``names``, each checked as
    :func:`_bounded` does from the bounds' entry ``first`` on."""
    if not (isinstance(value, list) and len(value) == len(names)):
        raise InputError(f"{p}: subject.{key} must be [{', '.join(names)}], got {value!r}")
    return tuple(_bounded(p, key, v, segment, first + i, f"[{i}] ({name})") for i, (v, name) in
                 enumerate(zip(value, names, strict=True)))


def load_subject(path: str | Path) -> Subject:
    """Read a subject file (TOML ``[subject]`` with ``hat_fraction``, ``hat_offset_m = [fwd, left, up]`` and
    optionally ``hat_sway_gain = [fore_aft, lateral]``, else :data:`TRUNK_STEP_GAIN`, the sway above
    ``hat_follow_hz`` (Hz, else :data:`TRUNK_FOLLOW_HZ`: a file written before it was, whose gains were fitted
    at every frequency, is read with it too); ``bsp = "adult"`` or ``"child"`` and ``age_years``, else the table
    is chosen from each file). A tracked thorax' file (a full-body or trunk set's) has ``trunk_fraction`` and
    ``trunk_offset_m = [fwd, left, up]`` (its own frame, from its origin) instead of the ``hat_*`` keys."""
    p = Path(path)
    s = read_toml(p, "subject file").get("subject")
    if not isinstance(s, dict):
        raise InputError(f"{p}: missing [subject] table")
    trunk = "trunk_fraction" in s or "trunk_offset_m" in s
    keys, prefix = (TRUNK_KEYS, "trunk") if trunk else (SUBJECT_KEYS, "hat")
    unknown = set(s) - keys  # a misspelt key, ignored, would leave the table's value in its place
    if unknown:
        raise InputError(f"{p}: subject.{sorted(unknown)[0]}: unknown key ({', '.join(sorted(keys))})"
                         + ("; a subject file is a tracked trunk's (trunk_*) or a placed HAT's (hat_*), not both"
                            if trunk and unknown & SUBJECT_KEYS else ""))
    segment = THORAX_SEGMENT if trunk else HAT_SEGMENT
    f = _bounded(p, f"{prefix}_fraction", s.get(f"{prefix}_fraction"), segment, 0, "")
    off = _bounded_list(p, f"{prefix}_offset_m", s.get(f"{prefix}_offset_m"), segment, 1, ("forward", "left", "up"))
    gain = _bounded_list(p, "hat_sway_gain", s.get("hat_sway_gain", list(TRUNK_STEP_GAIN)), segment, 4,
                         ("fore_aft", "lateral"))
    follow = s.get("hat_follow_hz", TRUNK_FOLLOW_HZ)
    if not (_is_number(follow) and MIN_FOLLOW_HZ <= follow <= MAX_FOLLOW_HZ):
        raise InputError(f"{p}: subject.hat_follow_hz must be a frequency in Hz, {MIN_FOLLOW_HZ:g} to "
                         f"{MAX_FOLLOW_HZ:g}, got {follow!r}")
    bsp, age = s.get("bsp"), s.get("age_years")
    if bsp is not None and bsp not in ("adult", "child"):
        raise InputError(f"{p}: subject.bsp must be \"adult\" or \"child\", got {bsp!r}")
    if age is not None and not (_is_number(age) and 0 < age < MAX_AGE_YEARS):
        raise InputError(f"{p}: subject.age_years must be a number of years, got {age!r}")
    return Subject(f, off, gain, bsp,
                   None if age is None else float(age), float(follow), "thorax" if trunk else "hat")


def write_subject(subject: Subject, path: str | Path, report: dict) -> None:
    offset = "[" + ", ".join(f"{v:.5f}" for v in subject.offset) + "]"
    segment = ([f"trunk_fraction = {subject.fraction:.5f}  # the tracked thorax (middle + upper trunk)",
                f"trunk_offset_m = {offset}  # forward, left, up the trunk, its own frame, from its origin"]
               if subject.segment == "thorax" else
               [f"hat_fraction = {subject.fraction:.5f}", f"hat_offset_m = {offset}  # forward, left, up",
                "hat_sway_gain = [" + ", ".join(f"{v:.4f}" for v in subject.hat_sway_gain) + "]  # fore-aft, lateral",
                f"hat_follow_hz = {subject.hat_follow_hz:g}  # the HAT follows the mid-hip below, sways the gains "
                "above"])
    lines = ["# livezmp subject file (livezmp calibrate)", "[subject]", *segment,
             *([f'bsp = "{subject.bsp}"  # the segment table the fit used'] if subject.bsp else []),
             *([f"age_years = {subject.age_years:.3f}"] if subject.age_years is not None else []),
             "", "[calibration]"]
    for k, v in report.items():
        # texts as JSON strings, which TOML reads as they are (a note's apostrophe, a path's quote)
        text = isinstance(v, str) or (isinstance(v, list) and all(isinstance(x, str) for x in v))
        lines.append(f"{k} = {json.dumps(v)}" if text else f"{k} = {str(v).lower()}" if isinstance(v, bool)
                     else f"{k} = {v!r}")
    write_text_atomic("\n".join(lines).replace("None", '"n/a"') + "\n", path)


@dataclass
class _Terms:
    """Per complete frame: the rest of the body's wrench for the whole mass (F (n, 3) N, moment about
    the origin (n, 3) N·m), the fitted segment's origin o, acceleration a_o, rotation A and its second
    derivative B (p = o + A r, a = a_o + B r) and its own rate of angular momentum about its centre of mass per kg
    of it (``spin`` (n, 3) N·m/kg), the plates' CoP (n, 2) and acceleration (n, 3); the origin without its sway
    above the follow frequency (base, a_base; a tracked thorax': its origin) and the walk's axes (for the sway
    gains: o -> base + K (o - base)); the frames' times (n,) s; the ``segment`` fitted."""

    f_rest: np.ndarray
    m_rest: np.ndarray
    o: np.ndarray
    a_o: np.ndarray
    A: np.ndarray
    B: np.ndarray
    spin: np.ndarray
    cop: np.ndarray
    plate_acc: np.ndarray
    mass: float
    floor: float
    base: np.ndarray
    a_base: np.ndarray
    fwd: np.ndarray
    left: np.ndarray
    times: np.ndarray
    segment: Segment = HAT_SEGMENT

    def part(self, sel: np.ndarray) -> _Terms:
        """The same terms on the frames ``sel`` (boolean over this one's frames)."""
        return _Terms(**{f.name: v[sel] if isinstance(v := getattr(self, f.name), np.ndarray) and v.ndim >= 1
                         and f.name not in ("fwd", "left") else v for f in fields(self)})


def _terms(trial: C3dTrial, lab: LabAnalysis, rows: np.ndarray, opts: LabOptions,
           segment: Segment = HAT_SEGMENT) -> _Terms:
    """The terms on the frames ``rows`` of ``lab``, ``trial`` analysed with ``opts`` (a HAT swaying
    ``opts.markers.hat_sway_gain`` above ``hat_follow_hz``), for the fitted ``segment``."""
    mass = lab.summary["mass"]["used_kg"]
    markers = opts.markers
    rest = body_from_markers(trial, replace(markers, total_mass=mass, **{segment.fraction_option: 0.0})).body.model
    data = rest.createData()
    model = lab.take.body.model  # the table's body: the segment's rotation, velocity and inertia
    mdata = model.createData()
    joint = model.getJointId(f"{segment.name}.roll")  # its last channel: the joint frame is the segment's
    inertia = model.inertias[joint]
    per_kg = inertia.inertia / inertia.mass  # about its centre of mass, its frame
    channels = [lab.take.body.channel_names.index(f"{segment.name}.{c}") for c in ("x", "y", "z")]
    r = lab.result
    idx = np.flatnonzero(rows)
    f_rest, m_rest, spin = np.empty((len(idx), 3)), np.empty((len(idx), 3)), np.empty((len(idx), 3))
    A, B = np.empty((len(idx), 3, 3)), np.empty((len(idx), 3, 3))
    for k, i in enumerate(idx):
        pin.computeCentroidalMomentumTimeVariation(rest, data, r.q[i], r.v[i], r.a[i])
        f = data.dhg.linear - mass * rest.gravity.linear
        f_rest[k], m_rest[k] = f, data.dhg.angular + np.cross(data.com[0], f)
        pin.forwardKinematics(model, mdata, r.q[i], r.v[i], r.a[i])
        w, dw = mdata.v[joint].angular, mdata.a[joint].angular  # its own frame
        A[k] = mdata.oMi[joint].rotation
        B[k] = A[k] @ (pin.skew(dw) + pin.skew(w) @ pin.skew(w))
        spin[k] = A[k] @ (per_kg @ dw + np.cross(w, per_kg @ w))
    o, a_o = r.q[idx][:, channels], r.a[idx][:, channels]
    plate_acc = lab.plates.force[idx] / mass - np.array([0.0, 0.0, G])
    base, a_base, fwd, left = o, a_o, np.zeros(3), np.zeros(3)  # a tracked thorax does not sway: its markers place it
    if segment is HAT_SEGMENT:
        # the HAT with no sway above the follow frequency, through the same pipeline: the swayed HAT minus it is the
        # gains times the sway, as are their estimated accelerations (hat_sway and the estimator are linear in it)
        still = run_take(trial, replace(opts, markers=replace(markers, hat_sway_gain=(0.0, 0.0))), mass,
                         plates_floor(trial, markers.marker_map))[3]
        base, a_base = still.q[idx][:, channels], still.a[idx][:, channels]
        _, fwd, left = sway_basis(still.q[:, channels], facing(lab.take))
        k_fa, k_lat = markers.hat_sway_gain
        unscale = np.outer(fwd, fwd) / k_fa + np.outer(left, left) / k_lat + np.diag([0.0, 0.0, 1.0])
        o, a_o = base + (o - base) @ unscale.T, a_base + (a_o - a_base) @ unscale.T  # gains 1
    return _Terms(f_rest, m_rest, o, a_o, A, B, spin, lab.plates.cop[idx, :2], plate_acc, mass,
                  lab.plates.surface_z, base, a_base, fwd, left, lab.times[idx], segment)


def _model(t: _Terms, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ZMP (n, 2) m and CoM acceleration (n, 3) m/s² for parameters (fraction, forward, left, up, sway gain
    fore-aft, lateral; a tracked thorax' gains do nothing, its base being its origin)."""
    f_h, r, (k_fa, k_lat) = theta[0], theta[1:4], theta[4:6]
    rest = 1.0 - f_h  # the rest's wrench was computed with no segment mass, i.e. the rest carrying the whole mass
    m_h = f_h * t.mass
    k = k_fa * np.outer(t.fwd, t.fwd) + k_lat * np.outer(t.left, t.left) + np.diag([0.0, 0.0, 1.0])
    p = t.base + (t.o - t.base) @ k.T + t.A @ r
    acc = t.a_base + (t.a_o - t.a_base) @ k.T + t.B @ r - np.array([0.0, 0.0, -G])
    force = rest * t.f_rest + m_h * acc
    moment = rest * t.m_rest + m_h * (np.cross(p, acc) + t.spin)
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


def _sq_mm(theta: np.ndarray, terms: list[_Terms]) -> tuple[float, int]:
    """Sum of squared ZMP − CoP distances (mm²) and the frame count, so that folds pool."""
    d = np.vstack([_model(t, theta)[0] - t.cop for t in terms])
    return float(1e6 * np.sum(d * d)), len(d)


def _rms_mm(theta: np.ndarray, terms: list[_Terms]) -> float:
    sq, n = _sq_mm(theta, terms)
    return float(np.sqrt(sq / n))


def _fit(terms: list[_Terms], prior: np.ndarray, weight: float, free: np.ndarray) -> np.ndarray:
    """Least squares over the parameters ``free`` (bool (6,)); the others stay at the prior."""
    if not np.isfinite(weight):
        return prior

    def theta(x: np.ndarray) -> np.ndarray:
        out = prior.copy()
        out[free] = x
        return out

    lo, hi = (np.asarray(b)[free] for b in terms[0].segment.bounds)
    x = least_squares(lambda x: _residuals(theta(x), terms, prior, weight), prior[free], bounds=(lo, hi),
                      x_scale=PRIOR_SD[free]).x
    return theta(x)


def _blocks(t: _Terms, block_s: float | None) -> np.ndarray:
    """Each frame's block (0, 1, ... over the blocks present): ``block_s`` long from the first frame, or for
    None the first and second halves of the frames."""
    if not len(t.times):  # a fold that took none of this trial's frames (all of them lie in one block)
        return np.zeros(0, dtype=int)
    if block_s is None:
        return (np.arange(len(t.cop)) >= len(t.cop) // 2).astype(int)
    return np.unique(np.floor((t.times - t.times[0]) / block_s).astype(int), return_inverse=True)[1]


Folds = list[tuple[list[_Terms], list[_Terms]]]


def _folds(terms: list[_Terms], block_s: float | None) -> Folds:
    """(fitted, held-out) splits: with several trials each trial held out in turn, the others fitted; with one,
    two splits of its frames, every other block in one fold.

    A subject file is for a take it was not fitted on. Blocks of the same takes share what is constant over a take
    and not of the subject (the markers' placement that day, a plate's offset), so a fit to that passes the
    blocks' test; a trial held out does not share it. On lower-body subjects with 2-5 walks, each walk analysed
    with the others' calibration: blocks 26.0 -> trials 23.9 mm median over 7 tuning walks (Sydney, FMC), 29.2 ->
    28.4 over 10 test walks (La Trobe, Padova, Kory; table 26.0 and 36.9; docs/validation.md, "placed HAT")."""
    if len(terms) > 1:
        return [(terms[:i] + terms[i + 1:], [t]) for i, t in enumerate(terms)]
    odd = [_blocks(t, block_s) % 2 == 1 for t in terms]
    return [([t.part(o != k) for t, o in zip(terms, odd, strict=True)],
             [t.part(o == k) for t, o in zip(terms, odd, strict=True)]) for k in (False, True)]


def _cross_validated(terms: list[_Terms], prior: np.ndarray, free: np.ndarray,
                     block_s: float | None) -> tuple[float, list[float]]:
    """The prior weight whose fits on one fold score best on the other (pooled RMS over every way round) among
    those that beat the table every way round (else the table: a fit that helps one way and not another
    is a fit to that fold's noise), and each weight's pooled score (mm). Folds: :func:`_folds`."""
    folds = _folds(terms, block_s)
    if min(sum(len(t.cop) for t in part) for fold in folds for part in fold) < MIN_FOLD_FRAMES:
        return PRIOR_WEIGHTS[-1], []
    table = np.array([_sq_mm(prior, held) for _, held in folds])
    scores = np.array([[_sq_mm(_fit(fitted, prior, w, free), held) for fitted, held in folds]
                       for w in PRIOR_WEIGHTS])  # (weights, folds, (sum of squares, frames))
    pooled = np.sqrt(scores[..., 0].sum(axis=1) / scores[..., 1].sum(axis=1))
    ok = (scores[..., 0] < table[:, 0]).all(axis=1)
    best = int(np.flatnonzero(ok)[np.argmin(pooled[ok])]) if ok.any() else len(PRIOR_WEIGHTS) - 1
    return PRIOR_WEIGHTS[best], [float(v) for v in pooled]


def _pooled(splits: Folds, prior: np.ndarray, free: np.ndarray,
            block_s: float | None) -> tuple[float, float, list[float]]:
    """Pooled RMS (mm) over (fitted, held-out) ``splits`` of the table and of the calibration (fitted on each
    split's first part with the prior weight its own cross-validation chose, scored on its second), and those
    weights."""
    table = calibrated = frames = 0.0
    weights = []
    for fitted, held in splits:
        w, _ = _cross_validated(fitted, prior, free, block_s)
        sq, n = _sq_mm(_fit(fitted, prior, w, free), held)
        table, calibrated, frames = table + _sq_mm(prior, held)[0], calibrated + sq, frames + n
        weights.append(w)
    return float(np.sqrt(table / frames)), float(np.sqrt(calibrated / frames)), weights


def _jackknife_sd(terms: list[_Terms], prior: np.ndarray, weight: float, free: np.ndarray,
                  block_s: float) -> np.ndarray | None:
    """Each parameter's standard error by the delete-one-block jackknife (None with fewer than 3 blocks)."""
    labels = [_blocks(t, block_s) for t in terms]
    fits = []
    for k, lab in enumerate(labels):
        for b in range(int(lab.max()) + 1):
            fits.append(_fit([t.part(lab != b) if j == k else t for j, t in enumerate(terms)], prior, weight, free))
    if len(fits) < 3:
        return None
    fits = np.array(fits)
    return np.sqrt((len(fits) - 1) / len(fits) * np.sum((fits - fits.mean(axis=0)) ** 2, axis=0))


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


def _segment(lab: LabAnalysis, source: str, segments: list[Segment]) -> Segment:
    """The segment ``lab``'s marker set lets the fit move (a placed HAT or a tracked thorax); the same as the
    other trials' (``segments``), else refused: one subject file describes one kind of marker set."""
    names = lab.take.body.channel_names
    segment = HAT_SEGMENT if "hat.x" in names else THORAX_SEGMENT if "thorax.x" in names else None
    if segment is None:
        raise InputError(f"{source}: neither a placed head-arms-trunk nor a tracked thorax: nothing to calibrate")
    if segments and segment is not segments[0]:
        kind = "places the HAT" if segment is HAT_SEGMENT else "tracks the trunk"
        raise InputError(f"{source}: its marker set {kind}, the other trials' does not: calibrate one kind of marker "
                         "set at a time")
    return segment


def _prior(segment: Segment, stature: float, table: BspTable) -> np.ndarray:
    """theta at the segment table ``table`` for a subject of ``stature`` m (a placed HAT's sway gains
    :data:`TRUNK_STEP_GAIN`; a tracked thorax' gains do nothing)."""
    if segment is HAT_SEGMENT:
        fraction, com, _ = hat_table(stature, table=table.segments)
        return np.array([fraction, *com, *TRUNK_STEP_GAIN])
    fraction, com = thorax_table(stature, table.segments)
    return np.array([fraction, *com, *TRUNK_STEP_GAIN])


def calibrate(trials: list[C3dTrial], opts: LabOptions | None = None,
              fit: tuple[str, ...] | None = None, block_s: float | None = BLOCK_S) -> tuple[Subject, dict]:
    """Fit the HAT's (a lower-body set) or the thorax' (a full-body or trunk set) parameters on ``trials`` (see the
    module docstring); returns the subject and a report
    (RMS ZMP − CoP with the table, fitted, fitted without the prior on the same frames (the floor of what
    these parameters can do there), and held out, mm; whether the table was kept, the prior weight chosen;
    each parameter's standard error; with several trials, each scored with the others' calibration).
    A HAT follows the mid-hip below ``opts.markers.hat_follow_hz`` (default :data:`TRUNK_FOLLOW_HZ`).
    ``fit``: which of the segment's parameters (``PARAMETERS``, ``TRUNK_PARAMETERS``; None: all) are fitted (the
    others keep the table's value); ``block_s``: the cross-validation's block length, s (None: the halves of each
    trial's frames, as before)."""
    opts = opts or LabOptions()
    follow = opts.markers.hat_follow_hz
    # analysed as analyze's default (the table's HAT and sway, the prior), so the plate delay and complete frames
    # are analyze's
    opts = replace(opts, markers=replace(opts.markers, hat_sway_gain=TRUNK_STEP_GAIN))
    whole, segments, mass_notes = [], [], []
    for trial in trials:
        if not trial.plates:
            raise InputError(f"{trial.source}: no force plates: nothing to calibrate against")
        lab = analyse_lab_take(trial, opts)
        if "note" in lab.summary["mass"]:
            mass_notes.append(f"{trial.source}: {lab.summary['mass']['note']}")
        segments.append(_segment(lab, trial.source, segments))
        rows = lab.complete & lab.result.has_zmp & np.isfinite(lab.plates.cop).all(axis=1)
        if rows.sum() < MIN_FRAMES:
            raise InputError(f"{trial.source}: only {int(rows.sum())} complete frames; need {MIN_FRAMES}")
        _check_agreement(trial, lab, rows)
        if segments[0] is HAT_SEGMENT and follow is None:
            raise ValueError("calibrate: the HAT's sway is fitted above a follow frequency; hat_follow_hz is None")
        whole.append(_terms(trial, lab, rows, opts, segments[0]))
        stature, bsp = lab.summary["markers"]["stature_m"], lab.summary["markers"]["bsp"]
    segment = segments[0]
    fit = segment.parameters if fit is None else fit
    if set(fit) - set(segment.parameters) or not fit:
        raise ValueError(f"calibrate: fit takes some of {segment.parameters}, got {fit}")
    n = len(segment.parameters)
    free = np.array([p in fit for p in segment.parameters] + [False] * (len(PARAMETERS) - n))  # over theta
    table = ADULT if bsp["table"] == "adult" else BspTable(child_segments(bsp["age_years"]), "child", bsp["age_years"])
    prior = _prior(segment, stature, table)
    weight, scores = _cross_validated(whole, prior, free, block_s)
    fitted = _fit(whole, prior, weight, free)
    unconstrained = _fit(whole, prior, FREE_WEIGHT, free)
    held_table, held_fitted, weights = _pooled(_folds(whole, block_s), prior, free, block_s)
    kept = not np.isfinite(weight)
    sd = None if kept else _jackknife_sd(whole, prior, weight, free, BLOCK_S)
    report = {"trials": [t.source for t in trials], "frames": int(sum(len(t.cop) for t in whole)),
              "segment": segment.name,
              "folds": "each trial held out" if len(whole) > 1 else "halves" if block_s is None
              else f"every other {block_s:g} s block",
              "rms_table_mm": round(_rms_mm(prior, whole), 2), "rms_fitted_mm": round(_rms_mm(fitted, whole), 2),
              "rms_fitted_unconstrained_mm": round(_rms_mm(unconstrained, whole), 2),
              "rms_held_out_table_mm": round(held_table, 2), "rms_held_out_fitted_mm": round(held_fitted, 2),
              "table_kept": bool(kept),
              "prior_weight": None if kept else weight,
              "prior_weight_scores_mm": [round(v, 2) for v in scores],
              "held_out_prior_weights": [None if not np.isfinite(w) else w for w in weights],
              "parameters": list(segment.parameters),
              # the table kept: nothing was measured, its spread is the prior's between-subject one
              "parameter_sd": [round(float(v), 5) for v in (PRIOR_SD if sd is None else sd)[:n]],
              "parameter_sd_from": "the table's assumed spread (nothing fitted)" if sd is None
              else "jackknife over the blocks",
              "mass_notes": mass_notes}
    if len(whole) > 1:
        # the held-out figures are then each trial scored with the parameters calibrated on the others (_folds)
        report.update(rms_other_trials_table_mm=round(held_table, 2), rms_other_trials_fitted_mm=round(held_fitted, 2))
    if segment is THORAX_SEGMENT:
        return Subject(float(fitted[0]), tuple(float(v) for v in fitted[1:4]), bsp=table.name,
                       age_years=table.age_years, segment=segment.name), report
    return Subject(float(fitted[0]), tuple(float(v) for v in fitted[1:4]), tuple(float(v) for v in fitted[4:6]),
                   table.name, table.age_years, follow), report
