"""A body model: a Pinocchio model in livezmp's internal frame, plus what livezmp needs
around it (input channels, feet, the joints a correction may use).

Internal frame: z up, metres, ground plane z = ground height. Every model is a chain of
one-degree-of-freedom joints, one per input channel, so ``q`` is the input channel
vector converted to SI (``q = channels * channel_scale``), ``v = dq/dt`` and
``a = d²q/dt²`` exactly: the estimator differentiates channels and the dynamics
consume the result with no further conversion. A URDF robot's floating base is six
such joints (x, y, z, then yaw, pitch, roll: R = Rz·Ry·Rx), singular only at ±90° pitch.
``world_from_input`` rotates the input's world frame (e.g. BVH y-up) into the internal one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from livezmp.model.mimic import Mimic


@dataclass
class Foot:
    """One foot. Either ``sole_local`` (k, 3) corners in the frame ``frame_id`` (robots),
    or a heel-to-toe rectangle from the ``frame_id`` (ankle) and ``toe_frame_id`` frames
    (skeletons) with the given dimensions in metres."""

    side: str
    frame_id: int
    sole_local: np.ndarray | None = None
    toe_frame_id: int | None = None
    heel_back: float = 0.0
    toe_front: float = 0.0
    width: float = 0.0
    ankle_height: float = 0.0
    toe_height: float = 0.0


@dataclass
class CorrectionJoints:
    """What a balance correction moves. ``root_channels``: q indices of the root's
    translation and rotation channels, in chain order (the root is the pelvis of a
    skeleton, the floating base of a robot); ``root_frame_id``: the frame they place.
    ``legs``: q indices each leg re-solve may change (a skeleton's thigh rotations, a
    robot's whole leg chain); ``hips``: frame of each hip joint centre (the pivot);
    ``foot_frames``: frames whose world placement each leg must keep (positions of
    the ankle and toe joints for a skeleton; the full pose of the foot for a robot)."""

    root_channels: list[int]
    root_frame_id: int
    legs: dict[str, list[int]]
    hips: dict[str, int]
    foot_frames: dict[str, list[int]]
    full_foot_pose: bool


@dataclass
class BodyModel:
    """Everything livezmp knows about a body. ``kind`` is "bvh" or "urdf"."""

    kind: str
    model: pin.Model
    point_model: pin.Model  # same kinematics, each segment a point mass (the seed's ZMP)
    channel_names: list[str]
    channel_scale: np.ndarray  # (nq,) input unit → SI
    angle_mask: np.ndarray  # (nq,) bool
    feet: dict[str, Foot]
    world_from_input: np.ndarray  # (3, 3)
    up_axis: str
    units: str
    total_mass: float
    correction: CorrectionJoints
    named_points: dict[str, int] = field(default_factory=dict)  # e.g. ankle/toe frames for checks
    base_channels: list[int] = field(default_factory=list)  # q indices of a robot's floating base
    joint_names: list[str] = field(default_factory=list)  # a robot's actuated joints (URDF names)
    mimics: tuple[Mimic, ...] = ()  # joints that follow another (indices into joint_names)
    # a robot's links whose file's inertias are placeholders (livezmp.model.placeholder_inertia), used as written
    placeholder_inertias: tuple[str, ...] = ()
    # a skeleton's: the input row's column of each channel (the part of the skeleton the model is built on,
    # livezmp.model.bvh_body.model_part); None: the input's rows are the channels
    input_columns: np.ndarray | None = None

    @property
    def nq(self) -> int:
        return self.model.nq

    def channels_to_q(self, channels: np.ndarray) -> np.ndarray:
        """Input channel values (file units, degrees) → q (m, rad)."""
        return channels * self.channel_scale

    def q_to_channels(self, q: np.ndarray) -> np.ndarray:
        """q (m, rad) → input channel values (file units, degrees): :meth:`channels_to_q` undone."""
        return q / self.channel_scale

    def input_rows(self, rows: np.ndarray) -> np.ndarray:
        """The channels (..., nq) of input rows (..., C) as a file or stream carries them (every joint of a
        skeleton)."""
        return rows if self.input_columns is None else rows[..., self.input_columns]

    def into_input(self, rows: np.ndarray, channels: np.ndarray) -> np.ndarray:
        """Input rows (F, C) with the body's channels set to ``channels`` (F, nq); the columns the body does not
        read (a skeleton's dropped joints) as ``rows`` has them."""
        if self.input_columns is None:
            return channels
        out = np.array(rows, dtype=float)
        out[:, self.input_columns] = channels
        return out

    def to_input_frame(self, p: np.ndarray) -> np.ndarray:
        """Internal-frame points (..., 3) → the input's world frame (still metres)."""
        return p @ self.world_from_input


def world_from_up_axis(up: str) -> np.ndarray:
    """Rotation (3, 3) from an input's axes whose up axis is ``up`` ("+z", "-y", ...) into the internal
    frame (z up): the axes are turned cyclically so ``up`` becomes z (y up: (x, y, z) -> (z, x, y), as for
    BVH input); a negative up axis also flips the first axis (a proper rotation)."""
    a = "xyz".index(up[-1])
    r = np.eye(3)[[(a + 1) % 3, (a + 2) % 3, a]]
    if up[0] == "-":
        r[[0, 2]] *= -1.0
    return r


def point_mass_copy(model: pin.Model) -> pin.Model:
    """The same model with every body's rotational inertia removed (point masses at the
    segment centres of mass): its centroidal dynamics give the seed paper's ZMP."""
    pm = model.copy()
    for i in range(len(pm.inertias)):
        old = pm.inertias[i]
        pm.inertias[i] = pin.Inertia(old.mass, old.lever, np.zeros((3, 3)))
    return pm


def foot_soles(body: BodyModel, data: pin.Data, place: bool = False) -> dict[str, np.ndarray]:
    """Sole corners (k, 3) of each foot in the internal world frame for the current
    ``data``: its frame placements up to date, or, with ``place``, its joint placements, from which
    the feet's frames alone are placed here (the same products as ``updateFramePlacements``, so the
    same corners bit for bit, without placing every frame of the model)."""
    if place:
        # pin.updateFramePlacement places one frame and hands it back: reading data.oMf[i] costs about 10 times
        # a frame's placement (the simulated humanoid's physics places its feet every 1 ms step)
        model = body.model

        def placed(frame: int) -> pin.SE3:
            return pin.updateFramePlacement(model, data, frame)
    else:
        placed = data.oMf.__getitem__
    out = {}
    for side, foot in body.feet.items():
        m = placed(foot.frame_id)
        if foot.sole_local is not None:
            sole = foot.sole_local.dot(m.rotation.T)  # ndarray.dot: the same product as @, less overhead
            sole += m.translation
            out[side] = sole
            continue
        # A handful of coordinates: plain floats beat numpy's per-call cost.
        ax, ay, az = m.translation.tolist()
        tx, ty, tz = placed(foot.toe_frame_id).translation.tolist()
        dx, dy = tx - ax, ty - ay
        n = math.hypot(dx, dy)
        ux, uy = (dx / n, dy / n) if n > 1e-9 else (1.0, 0.0)
        half = foot.width / 2
        wx, wy = -uy * half, ux * half
        hx, hy = ax - ux * foot.heel_back, ay - uy * foot.heel_back
        px, py = tx + ux * foot.toe_front, ty + uy * foot.toe_front
        zh, zt = az - foot.ankle_height, tz - foot.toe_height
        out[side] = np.array(
            ((hx - wx, hy - wy, zh), (px - wx, py - wy, zt), (px + wx, py + wy, zt), (hx + wx, hy + wy, zh))
        )
    return out


def soles_over(body: BodyModel, frames: np.ndarray) -> dict[str, np.ndarray]:
    """Sole corners (F, k, 3) of each foot (internal world frame, m) over F frames of raw channels (F, nq): the
    positions alone, frame by frame (no estimator: the frames as they are)."""
    model = body.model
    data = model.createData()
    out: dict[str, list[np.ndarray]] = {side: [] for side in body.feet}
    for row in frames:
        pin.framesForwardKinematics(model, data, body.channels_to_q(row))
        for side, sole in foot_soles(body, data).items():
            out[side].append(sole)
    return {side: np.array(soles) for side, soles in out.items()}


def _twist(model: pin.Model, data: pin.Data, frame_id: int) -> list[float]:
    """[vx, vy, vz, wx, wy, wz] of the frame's body, world axes: the velocity (m/s) of its point at the world
    origin, then the angular velocity (rad/s)."""
    return pin.getFrameVelocity(model, data, frame_id, pin.WORLD).vector.tolist()


def _rigid_velocities(twist: list[float], points: list) -> list[tuple[float, float, float]]:
    """Velocities (m/s, world axes) of points (world coordinates, m) moving with a body of this twist:
    v0 + ω × p. Plain floats: the points are few."""
    vx, vy, vz, wx, wy, wz = twist
    return [(vx + (wy * z - wz * y), vy + (wz * x - wx * z), vz + (wx * y - wy * x)) for x, y, z in points]


def sole_velocities(body: BodyModel, model: pin.Model, data: pin.Data, soles: dict[str, np.ndarray]) -> dict:
    """Velocity (k, 3) of each sole corner, m/s, internal world frame (``data`` must hold
    the kinematics of (q, v)). Skeleton soles: heel corners move rigidly with the ankle,
    toe corners with the toe joint, so a heel the foot rolls over stands still."""
    out = {}
    for side, foot in body.feet.items():
        corners = soles[side].tolist()
        twist = _twist(model, data, foot.frame_id)
        if foot.sole_local is not None:
            out[side] = np.array(_rigid_velocities(twist, corners))
        else:  # corners heel, toe, toe, heel
            heel = _rigid_velocities(twist, corners[::3])
            toe = _rigid_velocities(_twist(model, data, foot.toe_frame_id), corners[1:3])
            out[side] = np.array((heel[0], toe[0], toe[1], heel[1]))
    return out


def lowest_sole_points(body: BodyModel, model: pin.Model, data: pin.Data, soles: dict[str, np.ndarray],
                       belt: tuple[tuple[float, float], tuple[float, float]] | None = None,
                       ) -> dict[str, tuple[float, float]]:
    """Per foot, the height z (m, internal world frame) of its lowest sole corner (the first of equal
    ones) and that corner's horizontal speed (m/s): what contact detection needs
    (:meth:`livezmp.balance.contacts.ContactDetector.update_lowest`), without every corner's velocity. Equal to
    the lowest row of ``soles`` and of :func:`sole_velocities`; ``data`` as for that function. ``belt``: the
    (left, right) horizontal velocities (m/s) of the surface under each foot, the speed taken relative to it."""
    out = {}
    for side, foot in body.feet.items():
        corners = soles[side].tolist()
        heights = [c[2] for c in corners]
        z = min(heights)
        i = heights.index(z)
        # a skeleton's toe corners (1, 2) move with the toe joint, its heel corners with the ankle
        frame = foot.toe_frame_id if foot.sole_local is None and i in (1, 2) else foot.frame_id
        ((vx, vy, _),) = _rigid_velocities(_twist(model, data, frame), [corners[i]])
        if belt is not None:  # the stance foot rides the belt: its speed relative to it says contact
            bx, by = belt[0 if side == "left" else 1]
            vx, vy = vx - bx, vy - by
        out[side] = (z, math.hypot(vx, vy))
    return out
