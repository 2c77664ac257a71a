"""The same BVH motion re-expressed on skeletons of other shapes, so that the truth is known:
CMU-style extra hip joints (``LHipJoint``/``RHipJoint`` between the pelvis and the thighs),
rotation-only channels below the root, other rotation and position channel orders, z up,
metres instead of centimetres, and a higher frame rate (rotations slerped). Every variant but
the resampled one places every joint exactly where the original does (up to a fixed change
of axes and unit).

BVH convention: ``CHANNELS ... Zrotation Xrotation Yrotation`` is R = Rz(a) Rx(b) Ry(c), an
intrinsic Euler sequence, scipy's uppercase "ZXY"; position channels replace the offset.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from livezmp.model.bvh import BvhJoint, BvhMotion


@dataclass
class Skeleton:
    """A motion as per-joint local placements: ``trans`` (F, J, 3) file units, ``rot`` (F, J, 4)
    quaternions (x, y, z, w); ``rot_order`` / ``pos_order``: each joint's channel letters
    ("" for none); ``has_pos``: whether a joint carries position channels."""

    names: list[str]
    parents: list[int]
    offsets: np.ndarray
    end_sites: list[np.ndarray | None]
    rot_order: list[str]
    pos_order: list[str]
    trans: np.ndarray
    rot: np.ndarray
    frame_time: float


def decompose(motion: BvhMotion) -> Skeleton:
    """Per-joint local translations and rotations of every frame of ``motion``."""
    f, n = len(motion.frames), len(motion.joints)
    trans = np.zeros((f, n, 3))
    rot = np.zeros((f, n, 4))
    rot_order, pos_order = [], []
    for i, j in enumerate(motion.joints):
        cols = {c: j.first_channel + k for k, c in enumerate(j.channels)}
        rots = [c[0] for c in j.channels if c.endswith("rotation")]
        poss = [c[0] for c in j.channels if c.endswith("position")]
        rot_order.append("".join(rots))
        pos_order.append("".join(poss))
        trans[:, i] = j.offset
        for ax, letter in enumerate("XYZ"):
            if letter in poss:
                trans[:, i, ax] = motion.frames[:, cols[f"{letter}position"]]
        if rots:
            angles = motion.frames[:, [cols[f"{a}rotation"] for a in rots]]
            rot[:, i] = Rotation.from_euler("".join(rots), angles, degrees=True).as_quat()
        else:
            rot[:, i] = [0, 0, 0, 1]
    return Skeleton([j.name for j in motion.joints], [j.parent for j in motion.joints],
                    np.array([j.offset for j in motion.joints]), [j.end_site for j in motion.joints],
                    rot_order, pos_order, trans, rot, motion.frame_time)


def compose(s: Skeleton, source: str = "<variant>") -> BvhMotion:
    """The BVH motion of ``s`` (channels in each joint's orders, positions before rotations)."""
    joints, columns, first = [], [], 0
    for i, name in enumerate(s.names):
        channels = [f"{a}position" for a in s.pos_order[i]] + [f"{a}rotation" for a in s.rot_order[i]]
        joints.append(BvhJoint(name, s.parents[i], s.offsets[i].copy(), channels, s.end_sites[i],
                               first_channel=first))
        first += len(channels)
        for a in s.pos_order[i]:
            columns.append(s.trans[:, i, "XYZ".index(a)])
        if s.rot_order[i]:
            angles = Rotation.from_quat(s.rot[:, i]).as_euler(s.rot_order[i], degrees=True)
            columns.extend(angles.T)
    for i, j in enumerate(joints):
        if j.parent >= 0:
            joints[j.parent].children.append(i)
    return BvhMotion(joints, s.frame_time, np.column_stack(columns), source)


def positions_below_root_dropped(s: Skeleton) -> Skeleton:
    """CMU-style channels: position channels on the root only (the others' are their offsets)."""
    root = 0
    if not np.ptp(s.trans[:, 0], axis=0).any() and not np.ptp(s.rot[:, 0], axis=0).any():
        root = s.parents.index(0)  # a fixed root above the moving pelvis (Bandai): the pelvis keeps them
    pos = [p if i in (0, root) else "" for i, p in enumerate(s.pos_order)]
    moving = [i for i in range(len(s.names)) if not pos[i] and np.ptp(s.trans[:, i], axis=0).max() > 0]
    if moving:
        raise ValueError(f"joint {s.names[moving[0]]} moves its position channels: not an exact re-expression")
    return replace(s, pos_order=pos)


def channel_orders(s: Skeleton, rot_order: str, pos_order: str = "XYZ") -> Skeleton:
    """Every rotation channel triple in ``rot_order`` (e.g. "ZYX"), positions in ``pos_order``."""
    return replace(s, rot_order=[rot_order if r else "" for r in s.rot_order],
                   pos_order=[pos_order if p else "" for p in s.pos_order])


def z_up(s: Skeleton) -> Skeleton:
    """The whole scene turned +90° about x (y up → z up), as exporters do it: the root's
    offset, translation and rotation turn (R' = W R), every joint below keeps its channels,
    so every joint's world placement turns with the scene."""
    w = Rotation.from_euler("x", 90, degrees=True)
    trans, rot, offsets = s.trans.copy(), s.rot.copy(), s.offsets.copy()
    trans[:, 0] = s.trans[:, 0] @ w.as_matrix().T
    rot[:, 0] = (w * Rotation.from_quat(s.rot[:, 0])).as_quat()
    offsets[0] = w.apply(s.offsets[0])
    return replace(s, offsets=offsets, trans=trans, rot=rot)


def scaled(s: Skeleton, factor: float) -> Skeleton:
    """Lengths times ``factor`` (0.01: centimetres → metres)."""
    return replace(s, offsets=factor * s.offsets, trans=factor * s.trans,
                   end_sites=[None if e is None else factor * e for e in s.end_sites])


def cmu_hip_joints(s: Skeleton, side_names: dict[str, str]) -> Skeleton:
    """Insert ``LHipJoint`` / ``RHipJoint`` (zero offset, three rotation channels, always
    zero) between each thigh (``side_names``: "L"/"R" → thigh joint name) and its parent,
    as CMU's skeletons have them."""
    names, parents = list(s.names), list(s.parents)
    offsets, ends = list(s.offsets), list(s.end_sites)
    rot_order, pos_order = list(s.rot_order), list(s.pos_order)
    trans, rot = [s.trans[:, i] for i in range(len(names))], [s.rot[:, i] for i in range(len(names))]
    order = list(range(len(names)))
    for side, thigh_name in side_names.items():
        thigh = names.index(thigh_name)
        new = len(names)
        names.append(f"{side}HipJoint")
        parents.append(parents[thigh])
        parents[thigh] = new
        offsets.append(np.zeros(3))
        ends.append(None)
        rot_order.append(rot_order[thigh] or "ZXY")
        pos_order.append("")
        trans.append(np.zeros_like(trans[thigh]))
        identity = np.zeros_like(rot[thigh])
        identity[:, 3] = 1.0
        rot.append(identity)
        order.insert(order.index(thigh), new)
    # joints in depth-first file order: each new joint sits just before its thigh
    index = {old: k for k, old in enumerate(order)}
    return Skeleton([names[o] for o in order], [-1 if parents[o] < 0 else index[parents[o]] for o in order],
                    np.array([offsets[o] for o in order]), [ends[o] for o in order],
                    [rot_order[o] for o in order], [pos_order[o] for o in order],
                    np.stack([trans[o] for o in order], axis=1), np.stack([rot[o] for o in order], axis=1),
                    s.frame_time)


def resampled(s: Skeleton, factor: int) -> Skeleton:
    """``factor`` times the frame rate: rotations slerped, translations linear."""
    f, n = s.rot.shape[:2]
    t = np.arange(f)
    tn = np.arange((f - 1) * factor + 1) / factor
    rot = np.stack([Slerp(t, Rotation.from_quat(s.rot[:, i]))(tn).as_quat() for i in range(n)], axis=1)
    trans = np.stack([[np.interp(tn, t, s.trans[:, i, a]) for a in range(3)] for i in range(n)]).transpose(2, 0, 1)
    return replace(s, trans=trans, rot=rot, frame_time=s.frame_time / factor)
