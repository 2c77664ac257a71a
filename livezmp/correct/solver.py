"""Balance correction of a whole motion, offline: root (waist) rotations, smallest and
smooth, that bring the ZMP into the support polygon; legs re-solved so feet stay put.

The problem over the whole take: find root rotation offsets δ_k (rad, internal world
axes, one 3-vector per frame) minimising

    Σ_k |ZMP_k(δ) − target_k|² / σ_z²  +  Σ_k |δ_k|² / σ_δ²  +  Σ_k |δ̈_k|² / σ_a²

subject to |δ_k| ≤ max_rotation per axis, where target_k is the ZMP itself when it is
inside the polygon by at least ``margin`` and the polygon point ``margin`` inside
otherwise. ZMP_k depends on δ at neighbouring frames too, through the estimator's
velocities and accelerations, so the problem is solved for all frames at once by
Gauss-Newton: each iteration linearises ZMP_k in δ_j with
(∂ZMP/∂q, ∂ZMP/∂q̇, ∂ZMP/∂q̈ at frame k) × (the estimator's impulse response from j to k)
× (∂channels/∂δ at frame j), solves the bounded linear least-squares problem
(scipy's ``lsq_linear``) and re-analyses the corrected motion exactly with the same
analysis that ``livezmp analyze`` runs. The rate limit is applied last as a
projection; frames still outside, and frames whose correction was cut by a limit,
are reported. The seed paper's fixed-step search, for comparison, is
:func:`livezmp.correct.seed_search.seed_grid_search`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import scipy.sparse as sp
from scipy.optimize import lsq_linear
from scipy.sparse.linalg import LinearOperator

from livezmp.balance.pipeline import FrameResult, Pipeline, PipelineConfig, default_config
from livezmp.balance.support import clamp_to_polygon
from livezmp.balance.zmp import compute_zmp
from livezmp.correct.edit import apply_delta, changed_channels, foot_displacement, hold_feet
from livezmp.correct.limits import CORRECTION_CUTOFF_HZ, CorrectionLimits, inset, rate_limit, stance_weights, zmp_target
from livezmp.correct.root_motion import RootMover
from livezmp.correct.unknowns import Unknowns, per_frame
from livezmp.estimate.estimator import EstimatorConfig, StreamingEstimator
from livezmp.model.body import BodyModel
from livezmp.model.bvh import BvhMotion
from livezmp.model.bvh_body import BvhBodyOptions, body_from_bvh
from livezmp.offline.batch import analyse_frames


@dataclass
class CorrectionResult:
    """``delta`` (F, 3) rad; ``frames`` corrected raw channels (F, nq); figures for the report."""

    delta: np.ndarray
    frames: np.ndarray
    before: list[FrameResult]
    after: list[FrameResult]
    foot_displacement_m: dict[str, float]
    rate_limited_frames: list[int]
    solver_s: float
    history: list[int] = field(default_factory=list)  # frames outside after each iteration
    foot_held_frames: list[int] = field(default_factory=list)  # rotations scaled down to keep a loaded foot
    estimator: EstimatorConfig | None = None  # the settings the motion was judged with

    def report(self) -> dict:
        judged_b = [r for r in self.before if r.inside is not None]
        judged_a = [r for r in self.after if r.inside is not None]
        out_a = [r.index for r in judged_a if not r.inside]
        deg = np.degrees(self.delta)
        n = len(self.frames)
        return {
            "frames": n,
            "support_frames": len(judged_a),
            "out_of_support_before": sum(1 for r in judged_b if not r.inside),
            "out_of_support_after": len(out_a),
            "inside_fraction_before": round(np.mean([r.inside for r in judged_b]), 6) if judged_b else None,
            "inside_fraction_after": round(np.mean([r.inside for r in judged_a]), 6) if judged_a else None,
            "infeasible_frames": out_a,
            "rate_limited_frames": self.rate_limited_frames,
            "foot_held_frames": self.foot_held_frames,
            "max_root_rotation_deg": round(float(np.abs(deg).max()), 4) if n else 0.0,
            "rms_root_rotation_deg": round(float(np.sqrt(np.mean(np.sum(deg**2, axis=1)))), 4) if n else 0.0,
            "max_root_rate_deg_s": round(float(np.abs(np.diff(deg, axis=0)).max() * self._fps()), 3) if n > 1 else 0.0,
            "max_foot_displacement_mm": round(1000 * self.foot_displacement_m["stance"], 4),
            "max_swing_foot_displacement_mm": round(1000 * self.foot_displacement_m["swing"], 4),
            "solver_ms_per_frame": round(1000 * self.solver_s / max(n, 1), 4),
            "outside_after_iteration": self.history,
            "estimator": asdict(self.estimator) if self.estimator else None,
        }

    def _fps(self) -> float:
        ts = [r.t for r in self.before]
        return (len(ts) - 1) / (ts[-1] - ts[0]) if len(ts) > 1 else 0.0


def estimator_matrices(pipe: Pipeline, times: np.ndarray, edge: int) -> list[sp.csr_matrix]:
    """The estimator as three linear maps (F × F, sparse): position, velocity and
    acceleration at output frame k per unit input at frame j. The estimator is linear
    (for changes far from an angle wrap); its response is exact for inputs within
    ``edge`` frames of either end (warm-up and flush) and the steady-state kernel in
    between, truncated where it falls below 1e-7 of its peak."""
    f = len(times)
    cfg = pipe.estimator.config
    cols = sorted(set(range(min(edge, f))) | set(range(max(f - edge, 0), f)))
    est = StreamingEstimator(len(cols), np.zeros(len(cols), bool), cfg)
    resp = np.zeros((3, f, len(cols)))
    impulses = np.zeros((f, len(cols)))
    impulses[cols, np.arange(len(cols))] = 1.0
    outs = [est.step(float(times[k]), impulses[k]) for k in range(f)]
    for e in [o for o in outs if o is not None] + est.flush():
        resp[:, e.index] = [e.q, e.qd, e.qdd]
    # steady state: one impulse well after the warm-up
    lag, span = pipe.estimator.lag, 3 * cfg.window
    start = max(4 * cfg.window, int(5 * cfg.rate_hz))
    one = StreamingEstimator(1, np.zeros(1, bool), cfg)
    kernel = np.zeros((3, lag + span + 1))
    for k in range(start + span + lag + 1):
        e = one.step(k * cfg.dt, np.array([1.0 if k == start else 0.0]))
        if e is not None and start - lag <= e.index <= start + span:
            kernel[:, e.index - start + lag] = [e.q[0], e.qd[0], e.qdd[0]]
    keep = np.abs(kernel).max(axis=0) > 1e-7 * np.abs(kernel).max()
    kd = np.arange(-lag, span + 1)[keep]
    kernel = kernel[:, keep]
    mats = []
    for i in range(3):
        rows, cj, vals = [], [], []
        big = np.abs(resp[i]) > 1e-7 * max(np.abs(resp[i]).max(), 1e-300)
        r_idx, c_idx = np.nonzero(big)
        rows += r_idx.tolist()
        cj += [cols[c] for c in c_idx]
        vals += resp[i][r_idx, c_idx].tolist()
        edge_cols = set(cols)
        for j in range(f):
            if j in edge_cols:
                continue
            k = j + kd
            ok = (k >= 0) & (k < f)
            rows += k[ok].tolist()
            cj += [j] * int(ok.sum())
            vals += kernel[i][ok].tolist()
        mats.append(sp.csr_matrix((vals, (rows, cj)), shape=(f, f)))
    return mats


class _Linearisation:
    """∂ZMP_k/∂δ_j as a sparse (2F × 3F) matrix around the current correction."""

    def __init__(self, model, mover: RootMover, changed: list[int], est: list[sp.csr_matrix]):
        self.model, self.mover = model, mover
        self.data = model.createData()
        self.changed = changed
        self.est = est

    def channel_jacobians(self, q_base: np.ndarray, delta: np.ndarray, w: np.ndarray, eps: float = 1e-4,
                          block: int = 256):
        """C_j = ∂q_changed/∂δ at each frame (F, m, 3), by central differences; the six
        perturbed configurations of ``block`` frames at a time go through the legs' solve together."""
        f = len(q_base)
        out = np.zeros((f, len(self.changed), 3))
        for lo in range(0, f, block):
            js = np.arange(lo, min(lo + block, f))
            d = np.repeat(delta[js], 6, axis=0).reshape(len(js), 3, 2, 3)  # frame, axis, ±, δ
            for a in range(3):
                d[:, a, 0, a] += eps
                d[:, a, 1, a] = d[:, a, 0, a] - 2 * eps
            q = self.mover.apply_many(np.repeat(q_base[js], 6, axis=0), d.reshape(-1, 3), np.repeat(w[js], 6))
            q = q[:, self.changed].reshape(len(js), 3, 2, -1)
            out[js] = np.swapaxes((q[:, :, 0] - q[:, :, 1]) / (2 * eps), 1, 2)
        return out

    def zmp_partials(self, r: FrameResult, eps: float = 1e-6) -> tuple[np.ndarray, float] | None:
        """G (3, 2, m): ∂ZMP_xy/∂(q, q̇, q̈) of the changed channels at one analysed frame,
        and the frame's load: vertical ground force over body weight."""
        base = [r.q, r.v, r.a]
        res = compute_zmp(self.model, self.data, *base, r.ground_z)
        z0 = res.zmp
        if z0 is None:
            return None
        load = float(res.force[2] / (self.data.mass[0] * -self.model.gravity.linear[2]))
        g = np.zeros((3, 2, len(self.changed)))
        for i in range(3):
            for c, qi in enumerate(self.changed):
                args = [b.copy() for b in base]
                args[i][qi] += eps
                z = compute_zmp(self.model, self.data, *args, r.ground_z).zmp
                if z is None:
                    return None
                g[i, :, c] = (z[:2] - z0[:2]) / eps
        return g, load

    def matrix(self, results: list[FrameResult], rows: list[int], cjac: np.ndarray
               ) -> tuple[sp.csr_matrix, np.ndarray]:
        """The Jacobian rows of ``rows`` and each row's weight: the frame's load, so that
        frames near flight, where the ZMP is a ratio of small numbers, do not dominate
        the linear step (the exact cost still counts them in full)."""
        f = len(cjac)
        data, ri, ci = [], [], []
        weight = np.zeros(len(rows))
        for e in self.est:
            e.sort_indices()  # for the searchsorted look-ups of one row's entries
        for row, k in enumerate(rows):
            part = self.zmp_partials(results[k])
            if part is None:
                continue
            g, weight[row] = part[0], min(1.0, part[1])
            js = np.union1d(np.union1d(self.est[0][k].indices, self.est[1][k].indices), self.est[2][k].indices)
            c0, c1, c2 = (_row_values(e, k, js)[:, None, None] for e in self.est)
            gk = g[0] * c0 + g[1] * c1 + g[2] * c2  # (nj, 2, m)
            blocks = gk @ cjac[js]  # (nj, 2, 3)
            data.append(blocks.reshape(-1, 6))
            ri.append(np.repeat([[2 * row] * 3 + [2 * row + 1] * 3], len(js), axis=0))
            ci.append(3 * js[:, None] + np.array([0, 1, 2, 0, 1, 2]))
        if data:
            data, ri, ci = (np.concatenate(x).ravel() for x in (data, ri, ci))
        return sp.csr_matrix((data, (ri, ci)), shape=(2 * len(rows), 3 * f)), weight


def _row_values(e: sp.csr_matrix, k: int, js: np.ndarray) -> np.ndarray:
    """Entries (k, js) of ``e`` (sorted indices), zero where not stored."""
    idx, val = e.indices[e.indptr[k]:e.indptr[k + 1]], e.data[e.indptr[k]:e.indptr[k + 1]]
    if not len(idx):
        return np.zeros(len(js))
    pos = np.minimum(np.searchsorted(idx, js), len(idx) - 1)
    return np.where(idx[pos] == js, val[pos], 0.0)


def _solve_step(current, judged, jall, zall, load, delta, mu, limits, reg_size, reg_acc, bounds, dt,
                previous) -> np.ndarray:
    """One damped linearised step over the unknown rotations ``delta`` (each after its ``previous``, −1 for none).
    ZMP rows are active for frames short of the margin; frames that the predicted step would push short of it join
    the active set, and so do frame-to-frame steps beyond the rate limit (held at the limit by stiff rows), in up
    to five rounds, so a correction neither trades one frame for another nor jerks."""
    f = len(delta)
    x0 = delta.ravel()
    active = {i for i, k in enumerate(judged) if zmp_target(current[k], limits.margin_m) is not None}
    hold: dict[int, np.ndarray] = {}
    rate: dict[int, float] = {}  # flat index of δ_k,a (k with a previous) → signed step to hold
    max_step = np.radians(limits.max_rate_deg_s) * dt
    stiff = 100.0 / max_step
    trust = sp.eye(3 * f, format="csr") * np.sqrt(mu) / np.radians(limits.rotation_scale_deg)
    x = x0
    for _ in range(5):
        idx = sorted(active | set(hold))
        tgt = np.array([zmp_target(current[judged[i]], limits.margin_m) if i in active else hold[i] for i in idx])
        rows = np.ravel([[2 * i, 2 * i + 1] for i in idx])
        wrow = np.repeat(load[idx], 2)
        jz = sp.diags(wrow) @ jall[rows]
        rhs = jz @ x0 - wrow * (zall[idx] - tgt).ravel() / limits.zmp_tolerance_m
        keys = sorted(rate)
        pairs = np.ravel([[c, 3 * previous[c // 3] + c % 3] for c in keys])
        steps = sp.csr_matrix((np.tile([stiff, -stiff], len(keys)), (np.repeat(np.arange(len(keys)), 2), pairs)),
                              shape=(len(keys), 3 * f))
        a = sp.csr_array(sp.vstack([jz, reg_size, reg_acc, trust, steps]))
        b = np.concatenate([rhs, np.zeros(3 * f), np.zeros(reg_acc.shape[0]), trust @ x0,
                            stiff * np.array([rate[c] for c in keys])])
        # as an operator with the transpose built once (the sparse matrix itself would be
        # transposed anew for each of the solver's thousands of products; same arithmetic)
        at = a.T
        op = LinearOperator(a.shape, matvec=a.__matmul__, rmatvec=at.__matmul__, dtype=float)
        x = lsq_linear(op, b, bounds=bounds, method="trf", lsmr_tol="auto", max_iter=200).x
        pred = zall + (jall @ (x - x0)).reshape(-1, 2) * limits.zmp_tolerance_m
        grew = False
        for i, k in enumerate(judged):
            if i in active or i in hold:
                continue
            c = clamp_to_polygon(pred[i], current[k].polygon)
            if c.margin < limits.margin_m:
                # let it move, but no further than the margin: aim at the predicted point
                # brought back inside
                hold[i] = inset(c.point, current[k].polygon, limits.margin_m)
                grew = True
        after = np.nonzero(previous >= 0)[0]
        inc = x.reshape(f, 3)[after] - x.reshape(f, 3)[previous[after]]
        for k, a in zip(*np.nonzero(np.abs(inc) > max_step * 1.001), strict=True):
            if 3 * after[k] + a not in rate:
                rate[3 * after[k] + a] = float(np.sign(inc[k, a]) * max_step)
                grew = True
        if not grew:
            break
    return x.reshape(f, 3)


def _cost(results: list[FrameResult], delta: np.ndarray, limits: CorrectionLimits, reg_size, reg_acc,
          judged: np.ndarray) -> float:
    """The exact objective: per ``judged`` frame, the distance short of ``margin`` inside, times
    the frame's load (a moment about the polygon edge, which stays finite where the ZMP, a
    ratio, runs off near flight), squared; plus the regularisers (of the unknowns ``delta``)."""
    short = np.array([max(0.0, limits.margin_m - r.margin) * min(1.0, max(r.load, 0.0))
                      for r in results if r.margin is not None and judged[r.index]])
    x = delta.ravel()
    return float(np.sum((short / limits.zmp_tolerance_m) ** 2) + np.sum((reg_size @ x) ** 2)
                 + np.sum((reg_acc @ x) ** 2))


def _rotation_bounds(limits: CorrectionLimits, w: np.ndarray, supports: list[str], body: BodyModel,
                     q_base: np.ndarray, unk: Unknowns) -> tuple[np.ndarray, np.ndarray]:
    """Bounds on each unknown δ: the tightest of its analysed frames'. Roll about the pivot P
    lifts or lowers each hip by |h − P|·δ, yaw moves it fore and aft; where the legs may only turn at the thigh (a
    skeleton) a hip that moves along the leg moves its foot. So for every foot bearing
    weight (per the support label) roll and yaw are bounded to keep it within
    ``limits.foot_hold_m`` to first order (the final correction is checked on the feet
    themselves: :func:`livezmp.correct.edit.hold_feet`); the pivot weight ``w`` (of the
    left hip) sets |h − P|."""
    hi = np.tile(np.radians(limits.max_rotation_deg), (len(w), 1))
    if not body.correction.full_foot_pose:
        import pinocchio as pin

        data = body.model.createData()
        hips = body.correction.hips
        for k in range(len(w)):
            loaded = {"left": ["left"], "right": ["right"], "double": ["left", "right"]}.get(supports[k], [])
            lever = max([(1 - w[k]) if s == "left" else w[k] for s in loaded], default=0.0)
            if lever < 1e-9:
                continue
            pin.framesForwardKinematics(body.model, data, q_base[k])
            width = np.linalg.norm(data.oMf[hips["left"]].translation - data.oMf[hips["right"]].translation)
            hi[k, [0, 2]] = np.minimum(hi[k, [0, 2]], limits.foot_hold_m / (width * lever))
    tightest = np.full((unk.count, 3), np.inf)
    np.minimum.at(tightest, unk.index, hi)
    return -tightest.ravel(), tightest.ravel()


def _ease_contact_flips(delta, current, cost, held, analyse, limits, apply, regs, half_width, unk):
    """Last resort for frames pushed out by a contact that changed: at touchdown a
    corrected swing foot whose estimated speed lands a hair on the other side of a
    contact threshold turns double support into single, a jump no gradient sees. For
    each such frame outside, try small smooth changes of the correction around it (a
    fade toward zero, and bumps of ±0.25° on each axis) and keep the first that leaves
    fewer frames outside at no higher cost. ``delta`` and the changes are of the unknowns ``unk``."""
    f = len(delta)
    for r in list(current):
        k = r.index
        if (r.inside is not False or not unk.judged[k]
                or (r.support in ("left", "double"), r.support in ("right", "double")) == held[k]):
            continue
        at, weight = unk.near(k, half_width)
        bump = np.zeros(f)
        bump[at] = weight
        candidates = [delta * (1 - (1 - keep) * bump)[:, None] for keep in (0.5, 0.0)]
        for axis in range(3):
            for sign in (1, -1):
                step = np.zeros((f, 3))
                step[:, axis] = sign * np.radians(0.25) * bump
                candidates.append(delta + step)
        for cand in candidates:
            fr, cand = apply(cand)
            trial = analyse(fr)
            trial_cost = _cost(trial, cand, limits, *regs, unk.judged)
            if _outside(trial, unk) < _outside(current, unk) and trial_cost <= 1.5 * cost:
                delta, current, cost = cand, trial, trial_cost
                break
    return delta, current, cost


def _outside(results: list[FrameResult], unk: Unknowns) -> int:
    """Judged frames whose ZMP is outside the support polygon."""
    return sum(1 for r in results if r.inside is False and unk.judged[r.index])


def _own(results: list[FrameResult], unk: Unknowns) -> list[FrameResult]:
    """The judged frames' results, numbered from the first judged frame."""
    first = int(np.argmax(unk.judged))
    return [replace(r, index=r.index - first) if first else r for r in results if unk.judged[r.index]]


def _stalled(phase: list[int], patience: int, progress: float) -> bool:
    """Whether the last ``patience`` iterations of a phase (``phase``: frames outside after each) failed to leave
    fewer outside than the best before them by the fraction ``progress``: the steps still lower the cost, but they
    trade frames outside for others, or win back a frame or two of hundreds."""
    return len(phase) > patience and min(phase[-patience:]) >= min(phase[:-patience]) * (1.0 - progress)


def correct_motion(body: BodyModel, times: np.ndarray, frames: np.ndarray, config: PipelineConfig,
                   limits: CorrectionLimits | None = None, nominal_dt: float | None = None,
                   progress: Callable[[str], None] | None = None,
                   unknowns: Unknowns | None = None) -> CorrectionResult:
    """Correct a whole take (raw channels ``frames`` (F, nq) at ``times``); see module docstring.
    ``progress(message)`` is told each stage and solver iteration (a long take takes a while). ``unknowns``: which
    rotation each frame takes and which frames are judged (:mod:`livezmp.correct.unknowns`; default one per frame,
    all judged); the result holds the judged frames only."""
    limits = limits or CorrectionLimits()
    unk = unknowns or per_frame(len(frames))
    tell = progress or (lambda message: None)
    t0 = time.perf_counter()
    dt = nominal_dt or float(np.median(np.diff(times)))

    def analyse(fr: np.ndarray, contacts=None) -> list[FrameResult]:
        return analyse_frames(Pipeline(body, config, dt), times, fr, contacts)

    tell(f"analysing {int(unk.judged.sum())} frames")
    before = analyse(frames)
    tell(f"{_outside(before, unk)} frames outside the support polygon; solving")
    # while solving, the feet keep the contacts detected on the original motion: the
    # corrected motion moves a swing foot by millimetres, which must not flip a contact
    # (and with it the polygon) from one trial to the next; the final check re-detects
    held = [(r.support in ("left", "double"), r.support in ("right", "double")) for r in before]
    pipe = Pipeline(body, config, dt)
    model = pipe.model
    mover = RootMover(body)
    changed = changed_channels(body)
    first = unk.first_frames()
    w = stance_weights(before, max(1, round(0.1 / dt)))[first][unk.index]  # a loop's copies pivot alike
    lin = None  # the estimator's linear maps: built when a frame needs moving (a minute on a long or fast take)
    pick = unk.selection()
    q_base = np.array([body.channels_to_q(fr) for fr in frames])
    reg_size = sp.eye(3 * unk.count, format="csr") / np.radians(limits.rotation_scale_deg)
    reg_acc = unk.second_difference(dt) / np.radians(limits.accel_scale_deg_s2)
    bounds = _rotation_bounds(limits, w, [r.support for r in before], body, q_base, unk)
    delta = np.zeros((unk.count, 3))
    current = before
    cost = _cost(current, delta, limits, reg_size, reg_acc, unk.judged)
    history = []
    mu = 1.0
    # phase 1 with the original contacts held; phase 2 (a few iterations) re-detects them,
    # as `livezmp analyze` will, to settle the frames where a moved swing foot changes them
    stalled = False
    for contacts, iterations in ((held, limits.iterations), (None, 5)):
        if stalled:
            break  # the take cannot be corrected within the limits: no more searching, only the final checks
        if contacts is None:
            current = analyse(apply_delta(mover, body, frames, unk.expand(delta), w))
            cost = _cost(current, delta, limits, reg_size, reg_acc, unk.judged)
        phase: list[int] = []
        for _ in range(iterations):
            judged = [k for k, r in enumerate(current) if r.margin is not None and unk.judged[k]]
            if not any(zmp_target(current[k], limits.margin_m) is not None for k in judged):
                break
            if lin is None:
                edge = 3 * pipe.estimator.config.window + pipe.estimator.lag
                lin = _Linearisation(model, mover, changed, estimator_matrices(pipe, times, edge))
            cjac = lin.channel_jacobians(q_base, unk.expand(delta), w)
            jmat, load = lin.matrix(current, judged, cjac)
            jall = (jmat @ pick / limits.zmp_tolerance_m).tocsr()
            zall = np.array([current[k].zmp[:2] for k in judged])
            accepted = False
            for _attempt in range(6):  # Levenberg-Marquardt: damp the step until the exact cost drops
                cand = _solve_step(current, judged, jall, zall, load, delta, mu, limits, reg_size, reg_acc,
                                   bounds, dt, unk.previous())
                trial = analyse(apply_delta(mover, body, frames, unk.expand(cand), w), contacts)
                trial_cost = _cost(trial, cand, limits, reg_size, reg_acc, unk.judged)
                if trial_cost < cost:
                    delta, current, cost, accepted = cand, trial, trial_cost, True
                    mu = max(mu / 3, 1e-3)
                    break
                mu *= 10
            history.append(_outside(current, unk))
            phase.append(history[-1])
            tell(f"iteration {len(history)}: {history[-1]} frames outside")
            if not accepted or history[-1] == 0:
                break
            if stalled := _stalled(phase, limits.patience, limits.progress):
                tell(f"frames outside not {100 * limits.progress:g} % fewer in {limits.patience} iterations: "
                     "stopping the search")
                break
    tell("final check" if stalled else "easing contact changes, final check")
    if not stalled:
        delta, current, cost = _ease_contact_flips(delta, current, cost, held, analyse, limits,
                                                   lambda d: (apply_delta(mover, body, frames, unk.expand(d), w), d),
                                                   (reg_size, reg_acc), max(1, round(0.3 / dt)), unk)
    supports = [r.support for r in before]
    held_feet: set[int] = set()
    for _ in range(3):  # both only shrink rotations; the feet are checked last
        delta, limited = rate_limit(delta, np.radians(limits.max_rate_deg_s) * dt, unk.periodic)
        delta, held = hold_feet(mover, body, frames[first], delta, w[first], [supports[k] for k in first],
                                limits.foot_hold_m)
        held_feet.update(held)
        if not held:
            break
    corrected = apply_delta(mover, body, frames, unk.expand(delta), w)
    after = analyse(corrected)
    solver_s = time.perf_counter() - t0
    own = unk.judged
    feet = foot_displacement(body, frames[own], corrected[own], [s for s, j in zip(supports, own, strict=True) if j])
    return CorrectionResult(unk.expand(delta)[own], corrected[own], _own(before, unk), _own(after, unk), feet,
                            limited, solver_s, history, sorted(held_feet), config.estimator)


def correct_bvh(motion: BvhMotion, total_mass: float = 70.0, mode: str = "full",
                limits: CorrectionLimits | None = None) -> tuple[BvhMotion, CorrectionResult]:
    """A balance-corrected copy of a BVH motion (same hierarchy, frame count and time; the joints its model drops
    as they were), and what the correction did."""
    body = body_from_bvh(motion, BvhBodyOptions(total_mass=total_mass))
    times = np.arange(len(motion.frames)) * motion.frame_time
    result = correct_motion(body, times, body.input_rows(motion.frames),
                            default_config(body, motion.fps, mode, cutoff_hz=CORRECTION_CUTOFF_HZ), limits,
                            nominal_dt=motion.frame_time)
    return replace(motion, frames=body.into_input(motion.frames, result.frames)), result
