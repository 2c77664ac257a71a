"""A marker body as a kinematic chain: segment frames -> joint rotations.

The marker body (:mod:`livezmp.model.markers`) places every segment freely in the world (six
channels each: x, y, z, yaw, pitch, roll), so that soft-tissue motion cannot break a chain. A balance
correction needs a chain: rotating the pelvis must carry the trunk with it, and a thigh rotation the
rest of its leg. :func:`chain_body` gives the same segments, inertias, frames and feet hung on a tree
(pelvis the root; trunk or HAT and thighs on the pelvis, shank on thigh, foot on shank, head, upper
arms and a trunk-marker set's head-and-arms block on the thorax, forearm on upper arm, hand on
forearm), each child with six channels relative to
its parent's frame: the translation of its origin (m, parent axes, so the small joint-centre motion
of soft tissue is kept exactly) and its rotation as intrinsic Y-X-Z angles (rad: flexion about the
parent's lateral axis, then ab/adduction, then axial rotation, the joint-coordinate order of Grood &
Suntay 1983, whose middle angle stays small in walking). The pelvis keeps its world channels (yaw,
pitch, roll). The channel layout (six per segment, same order) and the frame ids are those of the
free body, so its feet, named points and correction joints carry over unchanged.

Both bodies place every segment at the same world pose: :func:`chain_frames` and :func:`free_frames`
convert one's channels into the other's, exactly.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from livezmp.model.body import BodyModel, point_mass_copy
from livezmp.model.markers import _euler_zyx

PARENT = {"hat": "pelvis", "thorax": "pelvis", "head": "thorax", "headarms": "thorax", "arms": "thorax",
          "thigh": "pelvis", "shank": "thigh", "foot": "shank",
          "upperarm": "thorax", "forearm": "upperarm", "hand": "forearm"}
_CHILD_CHANNELS = ("x", "y", "z", "flex", "abd", "rot")  # rotations about the y, x, z axes, in that order
_CHILD_JOINTS = (pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ, pin.JointModelRY, pin.JointModelRX,
                 pin.JointModelRZ)


def segment_names(body: BodyModel) -> list[str]:
    """The segments of a marker body (free or chain), in channel order (six channels each)."""
    return [n.split(".")[0] for n in body.channel_names[::6]]


def parent_of(segment: str) -> str | None:
    """The segment ``segment`` hangs from (``thigh_l`` -> ``pelvis``, ``shank_l`` -> ``thigh_l``)."""
    kind, _, side = segment.partition("_")
    if kind == "pelvis":
        return None
    parent = PARENT[kind]
    return f"{parent}_{side}" if side and parent in ("thigh", "shank", "upperarm", "forearm") else parent


def chain_body(free: BodyModel) -> BodyModel:
    """The chain form of the free marker body ``free`` (see the module docstring)."""
    names = segment_names(free)
    model = pin.Model()
    model.name = "markers-chain"
    last = {}  # segment -> its last (rotation) joint
    for seg in names:
        parent = parent_of(seg)
        if parent is None:  # the pelvis: its world channels, as in the free body
            joints = [(free.model.names[j], free.model.joints[j].extract()) for j in range(1, 7)]
            jid = 0
        else:
            joints = [(f"{seg}.{c}", jm()) for c, jm in zip(_CHILD_CHANNELS, _CHILD_JOINTS, strict=True)]
            jid = last[parent]
        for name, jm in joints:
            jid = model.addJoint(jid, jm, pin.SE3.Identity(), name)
        last[seg] = jid
    for j in range(1, free.model.njoints):
        model.inertias[j] = free.model.inertias[j]
    for f in list(free.model.frames)[1:]:  # same order: the frame ids stay those of the free body
        model.addFrame(pin.Frame(f.name, f.parentJoint, f.placement, f.type))
    angle = np.array([c not in ("x", "y", "z") for c in (n.split(".")[1] for n in model.names[1:])])
    return BodyModel(
        kind="markers", model=model, point_model=point_mass_copy(model), channel_names=list(model.names[1:]),
        channel_scale=np.ones(model.nq), angle_mask=angle, feet=free.feet, world_from_input=free.world_from_input,
        up_axis=free.up_axis, units=free.units, total_mass=free.total_mass, correction=free.correction,
        named_points=free.named_points)


def zyx_matrix(a: np.ndarray) -> np.ndarray:
    """(F, 3, 3) Rz(a0)·Ry(a1)·Rx(a2) of angles (F, 3) rad."""
    return _rz(a[:, 0]) @ _ry(a[:, 1]) @ _rx(a[:, 2])


def _rx(t):
    c, s, o, z = np.cos(t), np.sin(t), np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], 1)


def _ry(t):
    c, s, o, z = np.cos(t), np.sin(t), np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], 1)


def _rz(t):
    c, s, o, z = np.cos(t), np.sin(t), np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], 1)


def _yxz_matrix(a: np.ndarray) -> np.ndarray:
    return _ry(a[:, 0]) @ _rx(a[:, 1]) @ _rz(a[:, 2])


def _yxz_angles(r: np.ndarray) -> np.ndarray:
    # R = Ry(a)·Rx(b)·Rz(c): R[1, 2] = -sin b, R[0, 2] / R[2, 2] = tan a, R[1, 0] / R[1, 1] = tan c
    return np.column_stack([np.arctan2(r[:, 0, 2], r[:, 2, 2]), np.arcsin(np.clip(-r[:, 1, 2], -1, 1)),
                            np.arctan2(r[:, 1, 0], r[:, 1, 1])])


def world_poses(names: list[str], free: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Segment -> (origin (F, 3) m, rotation (F, 3, 3)) in the internal world frame, from free-body
    channels (F, 6 S)."""
    return {s: (free[:, 6 * i:6 * i + 3], zyx_matrix(free[:, 6 * i + 3:6 * i + 6])) for i, s in enumerate(names)}


def chain_frames(names: list[str], free: np.ndarray) -> np.ndarray:
    """Chain-body channels (F, 6 S) of the free-body channels ``free`` (same world poses)."""
    poses = world_poses(names, free)
    out = free.copy()
    for i, s in enumerate(names):
        parent = parent_of(s)
        if parent is None:
            continue
        (o, r), (po, pr) = poses[s], poses[parent]
        prt = np.transpose(pr, (0, 2, 1))
        out[:, 6 * i:6 * i + 3] = np.einsum("fij,fj->fi", prt, o - po)
        out[:, 6 * i + 3:6 * i + 6] = np.unwrap(_yxz_angles(prt @ r), axis=0)
    return out


def chain_poses(names: list[str], chain: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Segment -> (origin (F, 3) m, rotation (F, 3, 3)), internal world frame, from chain channels."""
    poses = {}
    for i, s in enumerate(names):  # parents come first
        parent = parent_of(s)
        t, a = chain[:, 6 * i:6 * i + 3], chain[:, 6 * i + 3:6 * i + 6]
        if parent is None:
            poses[s] = (t, zyx_matrix(a))
            continue
        po, pr = poses[parent]
        poses[s] = (po + np.einsum("fij,fj->fi", pr, t), pr @ _yxz_matrix(a))
    return poses


def free_frames(names: list[str], chain: np.ndarray) -> np.ndarray:
    """Free-body channels (F, 6 S) of chain channels (the inverse of :func:`chain_frames`)."""
    poses = chain_poses(names, chain)
    return np.hstack([np.hstack([o, _euler_zyx(r)]) for o, r in poses.values()])
