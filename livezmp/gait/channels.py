"""Which rotation channel is which: body segment, side, and the anatomical axis.

A channel's axis is the world direction it rotates about in the walk's mean pose,
taken from the body model's joint axes (Pinocchio): "lateral" (left–right: flexion
and extension of the limbs, forward bending of the trunk), "vertical" (twist of the
upright trunk or of a hanging limb) or "forward" (ab/adduction, side bending). So it
does not depend on the file's Euler order or naming. In the paper's frame (y up,
walking along z) these are its X, Y and Z rotations. Two channels of one joint whose
axes are nearly parallel in the mean pose are flagged ``gimbal``: an Euler triple
near gimbal lock, where those two angles trade off and neither means much alone.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from livezmp.errors import InputError
from livezmp.model.body import BodyModel
from livezmp.model.segments import classify, tag_joints

AXES = ("lateral", "vertical", "forward")
GIMBAL_COS = np.cos(np.deg2rad(20.0))  # axes closer than 20° count as degenerate

# Robot joints are named after the motion, not the segment it moves (l_hip_pitch moves
# the thigh, l_el the forearm); first match wins, on the lower-cased name.
_ROBOT_KINDS = [
    (r"^base_", "pelvis"),
    (r"hip", "thigh"),
    (r"knee", "shank"),
    (r"ank|ankle", "foot"),
    (r"sho|shoulder", "upper_arm"),
    (r"(^|_)el($|_)|elbow", "forearm"),
    (r"wrist", "hand"),
    (r"head|neck", "head"),
    (r"waist|torso|chest|spine", "spine"),
]
_MARKER_KINDS = {"hat": "spine", "thorax": "spine", "upperarm": "upper_arm"}  # marker body segment -> kind


@dataclass(frozen=True)
class ChannelTag:
    """One rotation channel: ``name`` as in the input, its ``joint``, segment ``kind``
    and ``side`` (left, right, center), world ``axis`` (see module doc), ``gimbal`` flag."""

    name: str
    joint: str
    kind: str
    side: str
    axis: str
    gimbal: bool = False

    @property
    def key(self) -> str:
        """Skeleton-independent label, e.g. ``thigh:left:lateral``."""
        return f"{self.kind}:{self.side}:{self.axis}"


def robot_joint_kind(name: str) -> tuple[str, str]:
    """(segment kind, side) of a robot joint name such as ``l_hip_pitch``; kind "other" if unknown."""
    s = name.lower()
    side = "left" if re.search(r"(^l_|_l$|left)", s) else "right" if re.search(r"(^r_|_r$|right)", s) else "center"
    for pat, kind in _ROBOT_KINDS:
        if re.search(pat, s):
            return kind, ("center" if kind == "pelvis" else side)
    tag = classify(name)
    return (tag.kind, tag.side) if tag else ("other", side)


def _segment_of_channels(body: BodyModel, source: str) -> list[tuple[str, str, str]]:
    """(joint, kind, side) for every input channel of ``body``."""
    if body.kind == "bvh":
        joints = [n.rsplit(".", 1)[0] for n in body.channel_names]
        unique = list(dict.fromkeys(joints))
        tags = dict(zip(unique, tag_joints(unique, source=source), strict=True))
        return [(j, tags[j].kind, tags[j].side) for j in joints]
    if body.kind == "markers":  # segment names: pelvis, hat, thorax, head, thigh_l, upperarm_r, ...
        out = []
        for n in body.channel_names:
            seg = n.split(".")[0]
            kind, _, side = seg.partition("_")
            out.append((seg, _MARKER_KINDS.get(kind, kind), {"l": "left", "r": "right"}.get(side, "center")))
        return out
    return [(n, *robot_joint_kind(n)) for n in body.channel_names]


def _lateral(body: BodyModel, data: pin.Data, source: str) -> np.ndarray:
    """Unit left-minus-right hip direction on the ground plane (internal frame, z up)."""
    legs = body.correction.legs
    if not legs.get("left") or not legs.get("right"):
        raise InputError(f"{source}: body model has no left and right legs to tell left from right")
    idx_q = [j.idx_q for j in body.model.joints]
    hip = {s: data.oMi[idx_q.index(legs[s][0])].translation for s in ("left", "right")}
    d = hip["left"] - hip["right"]
    d[2] = 0.0
    n = float(np.linalg.norm(d))
    if n < 1e-9:
        raise InputError(f"{source}: left and right hips coincide; cannot find the lateral axis")
    return d / n


def tag_channels(body: BodyModel, q_mean: np.ndarray, source: str) -> list[ChannelTag]:
    """Tags of every rotation channel of ``body`` (in channel order) in the pose ``q_mean`` (SI)."""
    model, data = body.model, body.model.createData()
    pin.computeJointJacobians(model, data, q_mean)
    lateral = _lateral(body, data, source)
    up = np.array([0.0, 0.0, 1.0])
    frame = np.stack([lateral, up, np.cross(lateral, up)])
    segs = _segment_of_channels(body, source)
    out: list[ChannelTag] = []
    axes: list[np.ndarray] = []
    for i, name in enumerate(body.channel_names):
        if not body.angle_mask[i]:
            continue
        jid = model.getJointId(name)
        w = data.J[3:, model.joints[jid].idx_v]  # world-frame angular part = the joint's world axis
        axes.append(w)
        joint, kind, side = segs[i]
        out.append(ChannelTag(name, joint, kind, side, AXES[int(np.argmax(np.abs(frame @ w)))]))
    for a in range(len(out)):
        for b in range(a + 1, len(out)):
            if out[a].joint == out[b].joint and abs(float(axes[a] @ axes[b])) > GIMBAL_COS:
                out[a], out[b] = replace(out[a], gimbal=True), replace(out[b], gimbal=True)
    return out


def reference_channel(tags: list[ChannelTag], source: str) -> int:
    """Index (into ``tags``) of the thigh flexion channel that marks gait cycles: the left
    thigh's lateral-axis channel, else the right's."""
    for side in ("left", "right"):
        for i, t in enumerate(tags):
            if t.kind == "thigh" and t.side == side and t.axis == "lateral" and not t.gimbal:
                return i
    raise InputError(f"{source}: no thigh flexion channel (a thigh joint rotating about the lateral axis)")
