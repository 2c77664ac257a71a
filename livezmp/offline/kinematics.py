"""Rigid-body kinematics and centroidal dynamics of a body model over many frames at once.

The per-frame pipeline asks Pinocchio for one state at a time (13-20 µs a call on a
132-joint skeleton). Offline, a whole chunk of frames goes through one forward pass
instead: every quantity is an array over the chunk's frames, and each joint costs a
few numpy operations, whatever the chunk length. End to end through
:func:`livezmp.offline.batch.run_batch` that makes a take 2.5-4x faster than the same
path calling Pinocchio per frame (``benchmarks/bench_batch_kinematics.py``); the results
agree to 4e-15 m.

The pass reads the Pinocchio model's own structure (``parents``, ``jointPlacements``,
``inertias``, ``frames``) and follows Pinocchio's conventions: per joint, the spatial
velocity (ω, v) and spatial acceleration (α, a) in the joint's local frame, with v and
a taken at the joint origin, as in Pinocchio's ``data.v`` / ``data.a``; the world
placement as the world coordinates of the joint's three axes and of its origin. Joints
are one-degree-of-freedom revolute or prismatic joints along x, y, z or any fixed axis
(what :mod:`livezmp.model.bvh_body` and :mod:`livezmp.model.urdf_body` build); a model with any
other joint raises :class:`UnsupportedModel`.

Units: SI (m, rad, s, kg), world frame of the model (internal frame: z up). Arrays are
frames-first: (C, 3) vectors, (C, 3, 3) rotations for C frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from livezmp.model.body import BodyModel

# Layout of the per-joint state block Z (3, 7, C): for local axis k, Z[k, 0:4] are the k-th local
# components of ω, v, α, a, and Z[k, 4:7] the world coordinates of that axis (column k of the world
# rotation). A rotation of the local frame mixes the rows of Z the same way for all seven slots, so
# one operation moves the velocities, the accelerations and the world orientation together.
_W, _V, _AL, _AC, _E = 0, 1, 2, 3, slice(4, 7)
_AXIS_NAMES = {"X": 0, "Y": 1, "Z": 2}


class UnsupportedModel(ValueError):
    """The model has a joint the batch pass does not handle (only 1-dof revolute / prismatic ones)."""


@dataclass(frozen=True)
class _Joint:
    """One 1-dof joint, as the pass applies it: placement, then motion about/along local ``axis``."""

    index: int
    parent: int
    iq: int  # index in q, v and a
    prismatic: bool
    axis: int  # 0, 1, 2
    sign: float  # the motion is about/along sign * e_axis
    translation: np.ndarray | None  # placement translation in the parent frame (None: zero)
    rotation_t: np.ndarray | None  # transpose of the placement rotation (None: identity)
    post: np.ndarray | None  # for an axis off x/y/z: the basis B with B e_z = axis (joint frame = B-frame B^T)


@dataclass(frozen=True)
class _Body:
    joint: int
    mass: float
    lever: np.ndarray  # centre of mass in the joint frame, m
    lever_cross: np.ndarray  # (3, 3): x -> x × lever
    inertia: np.ndarray | None  # rotational inertia about the centre of mass, joint frame (None: point mass)


def _basis_with_z(u: np.ndarray) -> np.ndarray:
    """A rotation whose third column is the unit vector ``u``."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, u)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(u, x), u])


def _compile_joint(model: pin.Model, j: int) -> _Joint:
    jm = model.joints[j]
    name = jm.shortname()
    if jm.nq != 1 or jm.nv != 1:
        raise UnsupportedModel(f"joint {model.names[j]} ({name}) has {jm.nq} configuration variables")
    placement = model.jointPlacements[j]
    rot = np.array(placement.rotation)
    trans = np.array(placement.translation)
    post = None
    if name in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
        u = np.array(jm.extract().axis, dtype=float)
        u /= np.linalg.norm(u)
        big = int(np.argmax(np.abs(u)))
        if abs(u[big]) == 1.0:  # ±x, ±y or ±z: the aligned case with a sign
            axis, sign = big, float(np.sign(u[big]))
        else:
            post = _basis_with_z(u)
            rot = rot @ post
            axis, sign = 2, 1.0
        prismatic = name.startswith("JointModelPrismatic")
    elif name[:-1] in ("JointModelR", "JointModelP") and name[-1] in _AXIS_NAMES:
        axis, sign, prismatic = _AXIS_NAMES[name[-1]], 1.0, name[-2] == "P"
    else:
        raise UnsupportedModel(f"joint {model.names[j]}: type {name} is not handled by the batch pass")
    return _Joint(
        index=j, parent=int(model.parents[j]), iq=int(jm.idx_q), prismatic=prismatic, axis=axis, sign=sign,
        translation=trans if trans.any() else None,
        rotation_t=None if np.array_equal(rot, np.eye(3)) else rot.T.copy(),
        post=post,
    )


@dataclass
class FrameMotion:
    """World placement and motion of one model frame over C frames (m, m/s, rad/s).

    ``position`` (C, 3) and ``rotation`` (C, 3, 3) place the frame; ``omega`` (C, 3) is the
    angular velocity of its joint; ``joint_origin`` (C, 3) and ``joint_velocity`` (C, 3)
    the position and velocity of the joint origin, all in world coordinates."""

    position: np.ndarray
    rotation: np.ndarray
    omega: np.ndarray
    joint_origin: np.ndarray
    joint_velocity: np.ndarray

    def point_velocity(self, points: np.ndarray) -> np.ndarray:
        """Velocity (C, k, 3), m/s, of world points (C, k, 3) rigidly attached to the frame."""
        r = points - self.joint_origin[:, None, :]
        w = self.omega[:, None, :]
        return self.joint_velocity[:, None, :] + np.cross(w, r)


@dataclass
class Dynamics:
    """Centroidal quantities over C frames, as :func:`livezmp.balance.zmp.compute_zmp` uses them.

    ``com`` (C, 3) m; ``momentum_rate`` (C, 3) N: rate of linear momentum (Pinocchio's
    ``dhg.linear``); ``moment`` (C, 3) N·m: rate of angular momentum about the CoM
    (``dhg.angular``); ``mass`` kg; ``frames`` the requested model frames."""

    com: np.ndarray
    momentum_rate: np.ndarray
    moment: np.ndarray
    mass: float
    frames: dict[int, FrameMotion]


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for (3, C) arrays."""
    return np.stack((a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]))


def _to_world(local: np.ndarray, z: np.ndarray) -> np.ndarray:
    """World coordinates (3, C) of local vectors (3, C), the joint's axes being z[:, _E] (3, 3, C)."""
    e = z[:, _E]
    return local[0] * e[0] + local[1] * e[1] + local[2] * e[2]


class BatchKinematics:
    """The forward pass of one Pinocchio model (its bodies and the frames in ``frame_ids``)."""

    def __init__(self, model: pin.Model, frame_ids: list[int]):
        self.model = model
        self.frame_ids = list(frame_ids)
        bodies = [j for j in range(1, model.njoints) if model.inertias[j].mass > 0.0]
        needed = set()
        for j in bodies + [model.frames[f].parentJoint for f in self.frame_ids]:
            while j > 0 and j not in needed:
                needed.add(j)
                j = model.parents[j]
        self.joints = [_compile_joint(model, j) for j in sorted(needed)]
        self.bodies: dict[int, _Body] = {}
        for j in bodies:
            inertia = model.inertias[j]
            lever = np.array(inertia.lever)
            rot = np.array(inertia.inertia)
            self.bodies[j] = _Body(j, float(inertia.mass), lever, -pin.skew(lever), rot if rot.any() else None)
        self.mass = float(sum(b.mass for b in self.bodies.values()))
        self._children = {0: 0} | {j.index: 0 for j in self.joints}
        for j in self.joints:
            self._children[j.parent] += 1
        revolute = [j for j in self.joints if not j.prismatic]
        self._revolute = [j.iq for j in revolute]
        self._trig_row = {j.index: r for r, j in enumerate(revolute)}
        self._frames_at: dict[int, list[int]] = {}
        for f in self.frame_ids:
            self._frames_at.setdefault(model.frames[f].parentJoint, []).append(f)

    def dynamics(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> Dynamics:
        """CoM, centroidal momentum rate and frame motions for the states q, v, a of C frames.

        The states are channel-major, (nq, C): row i is channel i over the frames (m or rad,
        per s, per s²)."""
        n = q.shape[1]
        # all the trigonometry at once: it is the largest single cost of the pass
        cos, sin = np.cos(q[self._revolute]), np.sin(q[self._revolute])
        root = np.zeros((3, 7, n))
        for k in range(3):
            root[k, 4 + k] = 1.0
        state = {0: (root, np.zeros((3, n)))}
        pending = dict(self._children)
        mc = np.zeros((3, n))  # Σ m c
        mcdd = np.zeros((3, n))  # Σ m c̈
        ang = np.zeros((3, n))  # Σ m c × c̈ + Σ (I α + ω × I ω) in world axes
        frames: dict[int, FrameMotion] = {}
        for jt in self.joints:
            trig = None if jt.prismatic else (cos[self._trig_row[jt.index]], sin[self._trig_row[jt.index]])
            z, o = _joint_step(jt, *state[jt.parent], q[jt.iq], v[jt.iq], a[jt.iq], trig, pending[jt.parent] == 1)
            body = self.bodies.get(jt.index)
            if body is not None:
                c, cdd, spin = _body_terms(body, z, o)
                mc += body.mass * c
                m_cdd = body.mass * cdd
                mcdd += m_cdd
                ang += _cross(c, m_cdd)
                if spin is not None:
                    ang += spin
            for f in self._frames_at.get(jt.index, ()):
                frames[f] = self._frame_motion(f, z, o)
            if self._children[jt.index]:
                state[jt.index] = (z, o)
            pending[jt.parent] -= 1
            if pending[jt.parent] == 0:
                del state[jt.parent]
        com = mc / self.mass
        moment = ang - _cross(com, mcdd)
        return Dynamics(com.T, mcdd.T, moment.T, self.mass, frames)

    def _frame_motion(self, frame_id: int, z: np.ndarray, o: np.ndarray) -> FrameMotion:
        placement = self.model.frames[frame_id].placement
        e = z[:, _E]
        pos = o + np.tensordot(np.array(placement.translation), e, 1)
        rot = np.tensordot(np.array(placement.rotation).T, e, 1)  # rot[k] = world column k
        return FrameMotion(pos.T, rot.transpose(2, 1, 0), _to_world(z[:, _W], z).T, o.T, _to_world(z[:, _V], z).T)


def _joint_step(jt: _Joint, z: np.ndarray, o: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray,
                trig: tuple[np.ndarray, np.ndarray] | None, reuse: bool) -> tuple[np.ndarray, np.ndarray]:
    """The joint's state block Z (3, 7, C) and world origin (3, C) from its parent's ``z`` and ``o``;
    ``trig`` is (cos q, sin q) for a revolute joint. ``reuse``: the parent's block is not needed
    any more and may be overwritten (most joints have one child: this saves a copy per joint)."""
    if not reuse:
        z = z.copy()
    if jt.translation is not None:
        t = jt.translation
        # v += ω × t and a += α × t (spatial quantities moved to the new origin)
        z[:, _V:_AC + 1:2] += np.tensordot(-pin.skew(t), z[:, _W:_AL + 1:2], 1)
        o = o + np.tensordot(t, z[:, _E], 1)
    if jt.rotation_t is not None:
        z = np.tensordot(jt.rotation_t, z, 1)
    k = jt.axis
    a, b = (k + 1) % 3, (k + 2) % 3
    sqd = qd if jt.sign == 1.0 else -qd
    sqdd = qdd if jt.sign == 1.0 else -qdd
    if jt.prismatic:
        sq = q if jt.sign == 1.0 else -q
        # the origin moves by x = sq e_k: v += ω × x and a += α × x; then the joint's own rate and its
        # Coriolis term ω × ẋ
        z[a, _V:_AC + 1:2] += z[b, _W:_AL + 1:2] * sq
        z[b, _V:_AC + 1:2] -= z[a, _W:_AL + 1:2] * sq
        z[k, _V] += sqd
        z[a, _AC] += z[b, _W] * sqd
        z[b, _AC] -= z[a, _W] * sqd
        z[k, _AC] += sqdd
        o = o + z[k, _E] * sq
    else:
        c, s = trig[0], (trig[1] if jt.sign == 1.0 else -trig[1])
        old_a = z[a].copy()
        z[a] *= c
        z[a] += z[b] * s
        z[b] *= c
        z[b] -= old_a * s
        z[k, _W] += sqd
        # Coriolis: (ω, v) × (sign e_k q̇) added to (α, a)
        z[a, _AL:_AC + 1] += z[b, _W:_V + 1] * sqd
        z[b, _AL:_AC + 1] -= z[a, _W:_V + 1] * sqd
        z[k, _AL] += sqdd
    if jt.post is not None:
        z = np.tensordot(jt.post, z, 1)
    return z, o


def _body_terms(body: _Body, z: np.ndarray, o: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """World CoM (3, C), its acceleration (3, C), and the body's own rate of angular momentum
    I α + ω × I ω in world axes (None for a point mass)."""
    w, v, al, ac = z[:, _W], z[:, _V], z[:, _AL], z[:, _AC]
    lx = body.lever_cross
    vel = v + lx @ w  # velocity of the CoM, local axes
    cdd_local = ac + lx @ al + _cross(w, vel)
    c = o + np.tensordot(body.lever, z[:, _E], 1)
    cdd = _to_world(cdd_local, z)
    if body.inertia is None:
        return c, cdd, None
    spin = body.inertia @ al + _cross(w, body.inertia @ w)
    return c, cdd, _to_world(spin, z)


def body_frame_ids(body: BodyModel) -> list[int]:
    """The model frames the feet are built from."""
    ids = []
    for foot in body.feet.values():
        ids.append(foot.frame_id)
        if foot.sole_local is None:
            ids.append(foot.toe_frame_id)
    return ids


def batch_soles(body: BodyModel, frames: dict[int, FrameMotion]) -> dict[str, np.ndarray]:
    """Sole corners (C, k, 3) of each foot, internal world frame, m: :func:`livezmp.model.body.foot_soles`
    over C frames."""
    out = {}
    for side, foot in body.feet.items():
        m = frames[foot.frame_id]
        if foot.sole_local is not None:
            out[side] = np.einsum("kj,cij->cki", foot.sole_local, m.rotation) + m.position[:, None, :]
            continue
        a = m.position
        t = frames[foot.toe_frame_id].position
        d = t[:, :2] - a[:, :2]
        n = np.hypot(d[:, 0], d[:, 1])
        far = n > 1e-9
        u = np.where(far[:, None], d / np.where(far, n, 1.0)[:, None], np.array([1.0, 0.0]))
        w = np.stack([-u[:, 1], u[:, 0]], axis=1) * (foot.width / 2)
        heel = a[:, :2] - u * foot.heel_back
        tip = t[:, :2] + u * foot.toe_front
        zh, zt = a[:, 2] - foot.ankle_height, t[:, 2] - foot.toe_height
        sole = np.empty((len(a), 4, 3))
        sole[:, 0, :2], sole[:, 1, :2], sole[:, 2, :2], sole[:, 3, :2] = heel - w, tip - w, tip + w, heel + w
        sole[:, [0, 3], 2] = zh[:, None]
        sole[:, [1, 2], 2] = zt[:, None]
        out[side] = sole
    return out


def batch_sole_velocities(body: BodyModel, frames: dict[int, FrameMotion],
                          soles: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Velocity (C, k, 3) of each sole corner, m/s: :func:`livezmp.model.body.sole_velocities` over C frames
    (a skeleton's heel corners move with the ankle, its toe corners with the toe joint)."""
    out = {}
    for side, foot in body.feet.items():
        sole = soles[side]
        if foot.sole_local is not None:
            out[side] = frames[foot.frame_id].point_velocity(sole)
            continue
        vel = np.empty_like(sole)
        vel[:, [0, 3]] = frames[foot.frame_id].point_velocity(sole[:, [0, 3]])
        vel[:, [1, 2]] = frames[foot.toe_frame_id].point_velocity(sole[:, [1, 2]])
        out[side] = vel
    return out
