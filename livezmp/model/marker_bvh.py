"""A marker body's chain written as BVH: one joint per segment, named as common skeletons name them
(Hips, Spine, Head, LeftUpLeg, LeftLeg, LeftFoot, LeftArm, LeftForeArm, LeftHand, ...).

Every joint has position channels (the chain keeps each joint centre's small per-frame offset in its
parent, so a fixed OFFSET would move the segments) then rotation channels: the pelvis' Z, Y, X (yaw,
pitch, roll), the others' Y, X, Z (flexion, ab/adduction, axial rotation), as in
:mod:`livezmp.model.marker_chain`, so the BVH places every segment exactly where the chain does, in the
C3D's own world frame. OFFSET is the median offset; the feet's End Site is the toe marker; other leaf
segments' End Site is twice their centre of mass from the joint. Analysed as a BVH, the segments take
the BVH table's masses (a lower-body set's placed HAT becomes one trunk segment).
"""

from __future__ import annotations

import numpy as np

from livezmp.model.body import BodyModel
from livezmp.model.bvh import BvhJoint, BvhMotion
from livezmp.model.marker_chain import parent_of, segment_names, zyx_matrix
from livezmp.model.markers import _euler_zyx

BVH_NAMES = {"pelvis": "Hips", "hat": "Spine", "thorax": "Spine", "head": "Head", "thigh": "UpLeg", "shank": "Leg",
             "foot": "Foot", "upperarm": "Arm", "forearm": "ForeArm", "hand": "Hand"}
_SIDES = {"l": "Left", "r": "Right"}
UNITS = ("cm", 100.0)  # written in centimetres: 6 decimals are 0.1 µm
_ROOT = ["Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation"]
_CHILD = ["Xposition", "Yposition", "Zposition", "Yrotation", "Xrotation", "Zrotation"]


def bvh_name(segment: str) -> str:
    """``thigh_l`` -> ``LeftUpLeg``, ``pelvis`` -> ``Hips``."""
    kind, _, side = segment.partition("_")
    return _SIDES.get(side, "") + BVH_NAMES[kind]


def _end_site(body: BodyModel, segment: str, index: int) -> np.ndarray | None:
    kind, _, side = segment.partition("_")
    if kind == "foot":
        toe = body.named_points[f"{'left' if side == 'l' else 'right'}_toe"]
        return body.model.frames[toe].placement.translation.copy()
    lever = body.model.inertias[6 * index + 6].lever
    return 2.0 * lever if np.linalg.norm(lever) > 1e-6 else None


def chain_to_bvh(body: BodyModel, chain: np.ndarray, frame_time: float, source: str) -> BvhMotion:
    """The BVH of a marker body's chain channels ``chain`` (F, 6 S) (see the module docstring); ``body`` the
    marker body (free or chain: the same inertias and frames)."""
    names = segment_names(body)
    scale = UNITS[1]
    r_in = body.world_from_input
    joints: list[BvhJoint] = []
    columns = []
    for i, seg in enumerate(names):
        parent = parent_of(seg)
        t, a = chain[:, 6 * i:6 * i + 3], chain[:, 6 * i + 3:6 * i + 6]
        if parent is None:  # into the input's world frame
            t = t @ r_in
            rot = np.degrees(_euler_zyx(r_in.T @ zyx_matrix(a)))
        else:
            rot = np.degrees(np.unwrap(a, axis=0))
        columns += [scale * t, rot]
        has_children = any(parent_of(s) == seg for s in names)
        end = None if has_children else _end_site(body, seg, i)
        joints.append(BvhJoint(bvh_name(seg), -1 if parent is None else names.index(parent),
                               scale * np.median(t, axis=0), list(_ROOT if parent is None else _CHILD),
                               None if end is None else scale * end))
    for k, j in enumerate(joints):
        j.first_channel = 6 * k
        if j.parent >= 0:
            joints[j.parent].children.append(k)
    return BvhMotion(joints, frame_time, np.hstack(columns), source)

