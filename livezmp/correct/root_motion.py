"""Rotate a body's root (pelvis / floating base) about a pivot while the feet stay put.

``RootMover.apply(q, delta, w_left)`` turns a root rotation offset ``delta`` (a rotation
vector in the internal world frame, rad: roll about x, pitch about y, yaw about z) into
new channel values: the root rotates about a pivot between the hip joint centres
(``w_left`` = weight of the left hip: 1 in left stance, 0 in right stance, ½ in double
support, so the stance leg's hip does not move), its channels are re-solved from the new
pose, and each leg's correction channels are re-solved (damped Gauss-Newton) so that its
foot frames keep their world placement. For a robot with six-joint legs this is exact;
for a skeleton whose legs may only turn at the thigh, the stance foot is exact and a
swing foot keeps its place to the extent the thigh alone allows.

A mimic joint on a leg (a double knee's second joint) is no coordinate of the IK: its
column of the foot Jacobian is folded into its parent's (J_parent += m J_follower) and it is
set to m q_parent + o after every step, so the foot placed is the one the robot reaches
once the relation is imposed on its goals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial.transform import Rotation

from livezmp.correct.limits import clip
from livezmp.model.body import BodyModel
from livezmp.model.mimic import follow

_AXIS = {"X": 0, "Y": 1, "Z": 2}
MAX_IK_STEP = 0.1  # rad per Gauss-Newton iteration and joint


@dataclass
class _RootChain:
    first_joint: int  # pinocchio joint id of the first root channel
    trans_q: list[int]
    trans_axes: list[int]
    rot_q: list[int]
    rot_seq: str  # intrinsic Euler sequence, e.g. "ZXY"


def _root_chain(body: BodyModel) -> _RootChain:
    model = body.model
    chain = _RootChain(0, [], [], [], "")
    for qi in body.correction.root_channels:
        jid = next(j for j in range(1, model.njoints) if model.joints[j].idx_q == qi)
        if not chain.first_joint:
            chain.first_joint = jid
        kind = model.joints[jid].shortname().replace("JointModel", "")
        if kind[0] == "P":
            chain.trans_q.append(qi)
            chain.trans_axes.append(_AXIS[kind[1]])
        else:
            chain.rot_q.append(qi)
            chain.rot_seq += kind[1]
    return chain


def hip_axes(h_left: np.ndarray, h_right: np.ndarray) -> np.ndarray:
    """Columns: forward, the hip line (right hip → left hip), and up (world z made
    orthogonal to the hip line). A pitch about the hip line moves neither hip."""
    # |v| as np.linalg.norm computes it for a 1-D float vector (the square root of v.dot(v)), without its
    # Python-level dispatch (~1.5 us a call, two a call here)
    y = h_left - h_right
    y = y / math.sqrt(y.dot(y))
    z = np.array([0.0, 0.0, 1.0]) - y[2] * y
    z /= math.sqrt(z.dot(z))
    # y × z written out on plain floats (the same double arithmetic as numpy scalars', without their cost): np.cross
    # costs ~10 µs on 3-vectors, and this runs every live correction
    (y0, y1, y2), (z0, z1, z2) = y.tolist(), z.tolist()
    x = np.array([y1 * z2 - y2 * z1, y2 * z0 - y0 * z2, y0 * z1 - y1 * z0])
    # the columns filled in place: np.column_stack's Python-level checks were half this function's 8 us
    h = np.empty((3, 3))
    h[:, 0], h[:, 1], h[:, 2] = x, y, z
    return h


def euler_from_matrix(rotation: np.ndarray, seq: str) -> np.ndarray:
    """Intrinsic Euler angles (rad) of ``seq`` (three distinct axes, e.g. "ZXY") with
    R = R_seq[0](a) · R_seq[1](b) · R_seq[2](c), b in [−π/2, π/2]; closed form, as
    scipy's ``Rotation.as_euler`` (used within 1e-6 of gimbal lock, where it picks c = 0)."""
    i, j, k = (_AXIS[a] for a in seq)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # +1 for the cyclic orders XYZ, YZX, ZXY
    sb = s * rotation[i, k]
    if abs(sb) > 1.0 - 1e-6:
        return Rotation.from_matrix(rotation).as_euler(seq)
    return np.array([math.atan2(-s * rotation[j, k], rotation[k, k]), math.asin(sb),
                     math.atan2(-s * rotation[i, j], rotation[i, i])])


class RootMover:
    """Applies root rotation offsets to configurations of ``body`` (see module docstring)."""

    def __init__(self, body: BodyModel, ik_iterations: int = 10, ik_tolerance: float = 1e-7):
        self.body = body
        self.model = body.model
        self.data = body.model.createData()
        self.chain = _root_chain(body)
        self.ik_iterations = ik_iterations
        self.ik_tolerance = ik_tolerance
        self._foot_error = 0.0
        self._unchecked: tuple[np.ndarray, list[dict[str, list[pin.SE3]]]] | None = None  # see last_foot_error
        base = len(body.base_channels)
        # channel (follower, parent, multiplier, offset) of every mimic joint
        self.mimics = [(base + m.joint, base + m.parent, m.multiplier, m.offset) for m in body.mimics]
        followers = {f for f, *_ in self.mimics}
        self.free = {s: [c for c in cols if c not in followers] for s, cols in body.correction.legs.items()}
        # per leg: (column in free, follower channel, multiplier) of the followers of the leg's own coordinates
        self.folds = {s: [(free.index(p), f, m) for f, p, m, _ in self.mimics if p in free]
                      for s, free in self.free.items()}

    @property
    def last_foot_error(self) -> float:
        """The largest foot position error (m) the last :meth:`apply`, :meth:`apply_many` or :meth:`place_feet` left
        (over its configurations). Found when asked (its forward kinematics cost a live correction ~10 %)."""
        if self._unchecked is not None:
            q, targets = self._unchecked
            self._unchecked = None
            self._foot_error = float(self._foot_errors(q, targets).max(initial=0.0))
        return self._foot_error

    def _follow(self, q: np.ndarray) -> None:
        """Each mimic joint's channel of ``q`` (..., nq; in place) set from its parent's."""
        if self.mimics:
            base = len(self.body.base_channels)
            q[..., base:] = follow(q[..., base:], self.body.mimics)

    def _fk(self, q: np.ndarray) -> None:
        pin.framesForwardKinematics(self.model, self.data, q)

    def _root_parent(self) -> pin.SE3:
        j = self.chain.first_joint
        return self.data.oMi[self.model.parents[j]] * self.model.jointPlacements[j]

    def set_root_pose(self, q: np.ndarray, pose: pin.SE3) -> None:
        """Write the root channels of ``q`` (in place) so that the root frame has ``pose``;
        ``q`` must be the configuration of the last forward-kinematics call."""
        local = self._root_parent().actInv(pose)
        c = self.chain
        for qi, ax in zip(c.trans_q, c.trans_axes, strict=True):
            q[qi] = local.translation[ax]
        angles = euler_from_matrix(local.rotation, c.rot_seq)
        old = q[c.rot_q]
        q[c.rot_q] = old + (angles - old + np.pi) % (2 * np.pi) - np.pi  # nearest to the old values

    def foot_targets(self) -> dict[str, list[pin.SE3]]:
        """Each side's foot frames' world poses (m, internal frame) at the last forward-kinematics call."""
        return {s: [self.data.oMf[f].copy() for f in fs] for s, fs in self.body.correction.foot_frames.items()}

    def apply(self, q: np.ndarray, delta: np.ndarray, w_left: float,
              leg_start: np.ndarray | None = None, shift: np.ndarray | None = None) -> np.ndarray:
        """New configuration for root rotation offset ``delta`` (rad, hip axes) about the
        pivot ``w_left`` · left hip + (1 − w_left) · right hip; feet kept in place.
        ``leg_start`` (nq,): offsets added to the leg channels of ``q`` as the IK's starting
        point (a warm start from the last solution: the IK then needs one or two iterations);
        the solution is the same to the IK tolerance. ``shift`` (3,): m (internal world frame) the root is then
        moved by, the legs carrying it over the feet (the online corrector's legs strategy)."""
        return self.apply_many(np.asarray(q, dtype=float)[None], np.asarray(delta, dtype=float)[None],
                               np.array([w_left]), None if leg_start is None else np.asarray(leg_start)[None],
                               None if shift is None else np.asarray(shift, dtype=float)[None])[0]

    def apply_many(self, q: np.ndarray, delta: np.ndarray, w_left: np.ndarray,
                   leg_start: np.ndarray | None = None, shift: np.ndarray | None = None) -> np.ndarray:
        """:meth:`apply` to N configurations at once: ``q`` (N, nq), ``delta`` (N, 3), ``w_left``
        (N,), ``leg_start`` (N, nq) or None, ``shift`` (N, 3) or None; the legs' Gauss-Newton steps of all N are
        solved as one stacked system, each configuration and leg stopping as :meth:`apply` does.
        ``last_foot_error`` is then the largest over the N."""
        q_new = np.array(q, dtype=float)
        corr = self.body.correction
        targets = []
        for n, qn in enumerate(q_new):
            self._fk(qn)
            targets.append(self.foot_targets())
            h_left = self.data.oMf[corr.hips["left"]].translation
            h_right = self.data.oMf[corr.hips["right"]].translation
            pivot = w_left[n] * h_left + (1.0 - w_left[n]) * h_right
            root = self.data.oMf[corr.root_frame_id]
            r = pin.exp3(hip_axes(h_left, h_right) @ delta[n])
            moved = pivot + r @ (root.translation - pivot)
            self.set_root_pose(qn, pin.SE3(r @ root.rotation, moved if shift is None else moved + shift[n]))
        if leg_start is not None:
            for cols in corr.legs.values():
                q_new[:, cols] += leg_start[:, cols]
        self._solve_legs(q_new, targets)
        return q_new

    def feet_of(self, q: np.ndarray) -> dict[str, list[pin.SE3]]:
        """The world placements of each foot's frames (``correction.foot_frames``) in the configuration ``q``."""
        self._fk(np.asarray(q, dtype=float))
        return self.foot_targets()

    def place_feet(self, start: np.ndarray, targets: dict[str, list[pin.SE3]]) -> np.ndarray:
        """``start`` (nq) with its legs re-solved so that each foot's frames have the placements ``targets``
        (`feet_of`: the feet of a configuration asked for), the base where ``start`` has it and every mimic joint
        following its parent: the configuration the robot reaches when asked for those feet (to the IK's
        tolerance; ``last_foot_error``: m)."""
        q = np.array(start, dtype=float)[None]
        self._solve_legs(q, [targets])
        return q[0]

    def _residual(self, frames: list[int], targets: list[pin.SE3]) -> np.ndarray:
        if self.body.correction.full_foot_pose:
            return np.concatenate([pin.log6(self.data.oMf[f].actInv(t)).vector for f, t in zip(frames, targets,
                                                                                                  strict=True)])
        return np.concatenate([t.translation - self.data.oMf[f].translation for f, t in zip(frames, targets,
                                                                                           strict=True)])

    def _jacobian(self, side: str, frame: int, ref: pin.ReferenceFrame, rows: int) -> np.ndarray:
        """(rows, free coordinates of the leg): ``frame``'s Jacobian over the leg's own coordinates, each
        follower's column folded into its parent's; ``data`` must hold the joint Jacobians."""
        full = pin.getFrameJacobian(self.model, self.data, frame, ref)[:rows]
        jac = full[:, self.free[side]]
        for k, f, m in self.folds[side]:
            jac[:, k] += m * full[:, f]
        return jac

    def _solve_legs(self, q: np.ndarray, targets: list[dict[str, list[pin.SE3]]]) -> None:
        """Damped Gauss-Newton on each leg's channels of the N configurations ``q`` (N, nq, in
        place), the legs side by side (each leg moves only its own feet, so one Jacobian
        evaluation per iteration serves both) and the steps of every configuration's legs of one
        size solved as one stacked system (each is its own system: the same values as one at a
        time); `last_foot_error` then tells how close each came."""
        corr = self.body.correction
        full = corr.full_foot_pose
        ref = pin.LOCAL if full else pin.LOCAL_WORLD_ALIGNED
        rows = 6 if full else 3
        sides = list(corr.legs)
        self._follow(q)
        pending = np.ones((len(q), len(sides)), dtype=bool)
        for _ in range(self.ik_iterations):
            # legs of one shape (rows, free coordinates) -> their (configuration, side), Jacobian and error
            work: dict[tuple[int, int], tuple[list[tuple[int, str]], list[np.ndarray], list[np.ndarray]]] = {}
            for n in np.nonzero(pending.any(axis=1))[0]:
                pin.computeJointJacobians(self.model, self.data, q[n])
                pin.updateFramePlacements(self.model, self.data)
                for i, side in enumerate(sides):
                    if not pending[n, i]:
                        continue
                    frames = corr.foot_frames[side]
                    e = self._residual(frames, targets[n][side])
                    if np.abs(e).max() < self.ik_tolerance:
                        pending[n, i] = False
                        continue
                    jac = np.concatenate([self._jacobian(side, f, ref, rows) for f in frames])
                    owners, jacs, errs = work.setdefault(jac.shape, ([], [], []))
                    owners.append((n, side))
                    jacs.append(jac)
                    errs.append(e)
            for (_, k), (owners, jacs, errs) in work.items():
                jac, e = np.array(jacs), np.array(errs)
                jt = np.swapaxes(jac, 1, 2)
                # damped, and every step bounded, so a leg that cannot reach exactly (a thigh alone
                # moving ankle and toe) settles at the nearby least-squares pose instead of
                # swinging to another branch; a robot's six-joint leg reaches exactly: damp lightly
                jtj = jt @ jac
                damping = (1e-6 if full else 1e-3) * np.trace(jtj, axis1=1, axis2=2) / k + 1e-12
                step = np.linalg.solve(jtj + damping[:, None, None] * np.eye(k), (jt @ e[:, :, None]))[..., 0]
                for (n, side), s in zip(owners, clip(step, -MAX_IK_STEP, MAX_IK_STEP), strict=True):
                    q[n, self.free[side]] += s
            self._follow(q)
            if not pending.any():
                break
        self._unchecked = (q.copy(), targets)

    def _foot_errors(self, q: np.ndarray, targets: list[dict[str, list[pin.SE3]]]) -> np.ndarray:
        """(N,) each configuration's largest foot position error (m) against its ``targets``."""
        rows = 6 if self.body.correction.full_foot_pose else 3
        e = []
        for n in range(len(q)):
            self._fk(q[n])
            e.append(np.concatenate([self._residual(frames, targets[n][side])
                                     for side, frames in self.body.correction.foot_frames.items()]))
        return np.linalg.norm(np.reshape(e, (len(q), -1, rows))[:, :, :3], axis=2).max(axis=1, initial=0.0)
