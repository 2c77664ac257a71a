"""Body model of a BVH skeleton on Pinocchio.

Each rotation channel becomes a revolute joint and each position channel a prismatic
joint, in the file's channel order; a joint's position channels replace its offset. Only the
joints that carry a segment's mass, each foot's toe (the sole's front) and the joints leading to
them are built (:func:`model_part`): face, finger and toe-tip subtrees carry no mass in the table,
and are dropped (their offsets still shape the segments they hang from, as in the whole file).
Segment masses, centres of mass and radii of gyration come from de Leva (1996), see
:mod:`livezmp.model.anthropometry`; stature is estimated from the leg bones (thigh + shank
≈ 49.2 % of stature in de Leva's table). The input's world frame is rotated into the
internal z-up frame at the root.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from livezmp.errors import InputError
from livezmp.model.anthropometry import DE_LEVA_MALE
from livezmp.model.body import BodyModel, CorrectionJoints, Foot, point_mass_copy
from livezmp.model.bvh import (
    HUMAN_STATURE_M,
    MAX_CHANNELS,
    UNIT_SCALES,
    BvhJoint,
    BvhMotion,
    BvhPart,
    detect_length_unit,
    skeleton_part,
)
from livezmp.model.segments import SegmentTag, tag_joints

# input world → internal z-up: for y-up, internal (x, y, z) = input (z, x, y)
WORLD_FROM_INPUT = {
    "y": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),
    "z": np.eye(3),
}
_AXES = {"X": 0, "Y": 1, "Z": 2}
_NEXT = {"upper_arm": "forearm", "forearm": "hand", "thigh": "shank", "shank": "foot", "foot": "toe"}
_TRUNK = ("pelvis", "spine", "neck", "head")
DEFAULT_MASS = 70.0  # kg, when nothing gives the body's mass
CALIBRATION_S = 2.0  # s of motion that calibrate the feet
LEG_FRACTION_OF_STATURE = (422.2 + 434.0) / 1741  # de Leva thigh + shank over stature


@dataclass(frozen=True)
class BvhBodyOptions:
    """Options for :func:`body_from_bvh`. Lengths in metres, mass in kg.

    Foot dimensions default to fractions of the estimated stature (``None``)."""

    total_mass: float = DEFAULT_MASS
    units: str | None = None  # 'm', 'cm', 'mm', 'in'; None = detect
    up_axis: str | None = None  # 'y' or 'z'; None = detect
    mapping: dict[str, SegmentTag] | None = None
    sole_width: float | None = None
    heel_back: float | None = None
    toe_front: float | None = None
    hat_fraction: float | None = None  # head, arms and trunk above the lower trunk, of total mass (subject file)


def _rot_to(d: np.ndarray) -> np.ndarray:
    """A rotation whose z axis points along ``d``."""
    z = d / np.linalg.norm(d)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _segment_vector(motion: BvhMotion, tags: list[SegmentTag], i: int, scale: float) -> np.ndarray:
    """Bone vector (metres, joint-local) of the segment joint ``i`` owns; zero if none."""
    j = motion.joints[i]
    kind = tags[i].kind
    kids = j.children
    if kind in _TRUNK:
        cont = [c for c in kids if tags[c].kind in _TRUNK]
        kids = cont or kids
    elif kind in _NEXT:
        cont = [c for c in kids if tags[c].kind == _NEXT[kind]]
        kids = cont or kids
    if kids:
        vecs = [motion.joints[c].offset for c in kids]
        return scale * max(vecs, key=lambda v: float(np.linalg.norm(v)))
    if j.end_site is not None:
        return scale * j.end_site
    return np.zeros(3)


_BELOW_HAT = ("lower_trunk", "thigh", "shank", "foot")


def _mass_table(tags: list[SegmentTag], joints: list[BvhJoint],
                hat_fraction: float | None = None) -> dict[int, tuple[str, float, bool]]:
    """joint index → (de Leva kind, mass fraction, proximal-is-up) for every massive joint;
    fractions renormalised so that a skeleton missing segments (no arms, say) keeps its
    total mass. ``hat_fraction``: the head, arms and trunk above the lower trunk together weigh
    this part of the body (a subject file's), the other segments the rest, each group keeping its
    proportions."""
    out = _raw_mass_table(tags, joints)
    total = sum(f for _, f, _ in out.values())
    out = {i: (k, f / total, up) for i, (k, f, up) in out.items()}
    hat = sum(f for k, f, _ in out.values() if k not in _BELOW_HAT)
    if hat_fraction is None or not 0.0 < hat < 1.0:
        return out
    scale = {True: (1.0 - hat_fraction) / (1.0 - hat), False: hat_fraction / hat}
    return {i: (k, f * scale[k in _BELOW_HAT], up) for i, (k, f, up) in out.items()}


def _raw_mass_table(tags: list[SegmentTag], joints: list[BvhJoint]) -> dict[int, tuple[str, float, bool]]:
    out: dict[int, tuple[str, float, bool]] = {}
    limb = {"upper_arm", "forearm", "hand", "thigh", "shank", "foot"}
    for i, t in enumerate(tags):
        if t.kind in limb:
            kind = {"upper_arm": "upper_arm", "forearm": "forearm", "hand": "hand",
                    "thigh": "thigh", "shank": "shank", "foot": "foot"}[t.kind]
            out[i] = (kind, DE_LEVA_MALE[kind].mass_fraction, False)
        elif t.kind == "head":
            out[i] = ("head", DE_LEVA_MALE["head"].mass_fraction, True)
    pelvis = [i for i, t in enumerate(tags) if t.kind == "pelvis"][0]
    spine: list[int] = []
    k = pelvis
    while True:  # walk up the trunk from the pelvis
        nxt = [c for c in joints[k].children if tags[c].kind == "spine"]
        if not nxt:
            break
        k = nxt[0]
        spine.append(k)
    lpt, mpt, upt = (DE_LEVA_MALE[n].mass_fraction for n in ("lower_trunk", "middle_trunk", "upper_trunk"))
    if not spine:
        out[pelvis] = ("middle_trunk", lpt + mpt + upt, True)
        return out
    out[pelvis] = ("lower_trunk", lpt, True)
    if len(spine) == 1:
        out[spine[0]] = ("middle_trunk", mpt + upt, True)
        return out
    for s in spine[:-1]:
        out[s] = ("middle_trunk", mpt / (len(spine) - 1), True)
    out[spine[-1]] = ("upper_trunk", upt, True)
    return out


def _toe(joints: list[BvhJoint], tags: list[SegmentTag], foot: int) -> int | None:
    """The toe joint of the foot joint ``foot`` (its first toe child; the sole reaches to it), if any."""
    return next((c for c in joints[foot].children if tags[c].kind == "toe"), None)


def model_part(joints: list[BvhJoint], tags: list[SegmentTag], source: str = "") -> BvhPart:
    """The part of a skeleton (tagged ``tags``) its body model is built on: the joints carrying a segment's mass,
    each foot's toe and the joints leading to them; the subtrees below which no segment has mass (a face, fingers,
    toe tips) are dropped. A skeleton of up to :data:`~livezmp.model.bvh.MAX_JOINTS` joints may carry more than
    :data:`~livezmp.model.bvh.MAX_CHANNELS` channels; its part may not (the model's data grows as the cube)."""
    feet = [i for i, t in enumerate(tags) if t.kind == "foot"]
    toes = {toe for toe in (_toe(joints, tags, f) for f in feet) if toe is not None}
    part = skeleton_part(joints, set(_raw_mass_table(tags, joints)) | toes)
    if len(part.columns) > MAX_CHANNELS:
        raise InputError(f"{source}: {len(part.columns)} channels carry or lead to a segment's mass, more than the "
                         f"{MAX_CHANNELS} this tool analyses")
    return part


def _placing_joint(joints: list[BvhJoint], pelvis: int, source: str) -> int:
    """The joint whose position and rotation channels place the body (what a correction moves): the pelvis, or
    when it has no position channels the nearest joint above it with both (Reallusion's CC_Base_BoneRoot above
    CC_Base_Hip, whose rotations then follow it)."""
    i = pelvis
    while i >= 0:
        kinds = {c[1:] for c in joints[i].channels}
        if kinds == {"position", "rotation"}:
            return i
        if i == pelvis and "position" in kinds:
            break
        i = joints[i].parent
    raise InputError(f"{source}: the pelvis joint {joints[pelvis].name} needs position and rotation channels")


def _stature(motion: BvhMotion, tags: list[SegmentTag], scale: float) -> float:
    legs = []
    for side in ("left", "right"):
        shank = next(i for i, t in enumerate(tags) if t.kind == "shank" and t.side == side)
        foot = next(i for i, t in enumerate(tags) if t.kind == "foot" and t.side == side)
        legs.append(np.linalg.norm(motion.joints[shank].offset) + np.linalg.norm(motion.joints[foot].offset))
    leg = scale * float(np.mean(legs))
    if leg <= 0:
        raise InputError(f"{motion.source}: leg bones have zero length; cannot scale the body")
    return leg / LEG_FRACTION_OF_STATURE


def _check_given_unit(motion: BvhMotion, tags: list[SegmentTag], units: str) -> None:
    """Refuse a ``--units`` that makes the skeleton no human's (its estimated stature outside
    :data:`HUMAN_STATURE_M`): a Bandai walk in cm read as mm was a 1.7 cm body, its accelerations a hundredth of a
    walk's, judged "plausible for walking" with every frame inside (exit 0)."""
    stature = _stature(motion, tags, UNIT_SCALES[units])
    lo, hi = HUMAN_STATURE_M
    if not lo <= stature <= hi:
        try:
            hint = f"; the skeleton's size reads as {detect_length_unit(_stature(motion, tags, 1.0))}"
        except InputError:
            hint = ""
        raise InputError(f"{motion.source}: --units {units} makes the skeleton's estimated stature {stature:.3g} m "
                         f"(from its thigh and shank bones), no human's ({lo:g}-{hi:g} m){hint}")


def _build(motion: BvhMotion, part: BvhPart, tags: list[SegmentTag], scale: float, world_from_input: np.ndarray,
           opts: BvhBodyOptions) -> tuple[pin.Model, dict[int, int], list[int]]:
    """Model of ``part`` + frame id of each of its joints (by file index) + per-channel q index. The segments'
    shapes come from the whole skeleton: a hand's from its fingers' offsets, whether or not they are built."""
    model = pin.Model()
    model.name = "bvh"
    frames: dict[int, int] = {}
    q_index: list[int] = []
    anchor: dict[int, tuple[int, pin.SE3]] = {}  # (pin joint, placement in it) of each BVH joint built
    stature = _stature(motion, tags, scale)
    masses = _mass_table(tags, motion.joints, opts.hat_fraction)
    for i in part.kept:
        j = motion.joints[i]
        pos_axes = [_AXES[c[0]] for c in j.channels if c.endswith("position")]
        seen_rot = False
        for c in j.channels:
            if c.endswith("rotation"):
                seen_rot = True
            elif seen_rot:
                raise InputError(f"{motion.source}: joint {j.name}: position channels after rotation "
                                 "channels are not supported")
        off = scale * j.offset.copy()
        off[pos_axes] = 0.0
        if j.parent < 0:
            parent_joint, place = 0, pin.SE3(world_from_input, world_from_input @ off)
        else:
            parent_joint, pplace = anchor[j.parent]
            place = pplace * pin.SE3(np.eye(3), off)
        for c in j.channels:
            ax = _AXES[c[0]]
            jm = [pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ][ax]() if c.endswith("position") \
                else [pin.JointModelRX, pin.JointModelRY, pin.JointModelRZ][ax]()
            parent_joint = model.addJoint(parent_joint, jm, place, f"{j.name}.{c}")
            q_index.append(model.joints[parent_joint].idx_q)
            place = pin.SE3.Identity()
        anchor[i] = (parent_joint, place)
        frames[i] = model.addFrame(pin.Frame(j.name, parent_joint, place, pin.FrameType.OP_FRAME))
        if j.end_site is not None:
            site = place * pin.SE3(np.eye(3), scale * j.end_site)
            model.addFrame(pin.Frame(f"{j.name}.end", parent_joint, site, pin.FrameType.OP_FRAME))
        if i in masses:
            kind, frac, prox_up = masses[i]
            par = DE_LEVA_MALE[kind]
            d = _segment_vector(motion, tags, i, scale)
            length = float(np.linalg.norm(d))
            if length < 1e-6:  # leaf segment: continue the parent bone's direction
                d_par = scale * j.offset
                nd = float(np.linalg.norm(d_par))
                direction = d_par / nd if nd > 1e-9 else np.array([0.0, 0.0, 1.0])
                length = par.length_fraction * stature
                d = direction * length
            com_frac = (1.0 - par.com_fraction) if prox_up else par.com_fraction
            m = opts.total_mass * frac
            rs, rt, rl = (g * length for g in par.gyration)
            rot = _rot_to(d)
            inertia = rot @ np.diag([m * rs * rs, m * rt * rt, m * rl * rl]) @ rot.T
            model.appendBodyToJoint(parent_joint, pin.Inertia(m, com_frac * d, inertia), place)
    return model, frames, q_index


def _detect_up(motion: BvhMotion, part: BvhPart, tags: list[SegmentTag], scale: float, opts: BvhBodyOptions) -> str:
    """The axis along which the head is above the feet in the first frame, or where that pose cannot tell (lying,
    upside down: a keyframed take may open with a tumble) in the skeleton's zero pose, its offsets alone (which the
    exporters write standing; not every skeleton's is, and then the file is refused)."""
    model, frames, _ = _build(motion, part, tags, scale, np.eye(3), opts)
    data = model.createData()
    head_kind = "head" if any(t.kind == "head" for t in tags) else "pelvis"
    first = _channel_scale(part.joints, scale) * motion.frames[0, part.columns]
    seen = []
    for q in (first, np.zeros_like(first)):
        pin.framesForwardKinematics(model, data, q)
        pos = lambda kind: np.mean([data.oMf[frames[i]].translation for i, t in enumerate(tags) if t.kind == kind], 0)  # noqa: E731
        v = pos(head_kind) - pos("foot")
        ax = int(np.argmax(np.abs(v)))
        if ax in (1, 2) and v[ax] > 0:
            return "yz"[ax - 1]
        seen.append(np.round(v, 3))
    raise InputError(f"{motion.source}: cannot tell the up axis (head-to-feet vector {seen[0]} in the first frame, "
                     f"{seen[1]} in the skeleton's zero pose); give --up")


def _channel_scale(joints: list[BvhJoint], scale: float) -> np.ndarray:
    return np.array([scale if c.endswith("position") else np.pi / 180 for j in joints for c in j.channels])


def _calibrate_heels(model: pin.Model, feet: dict[str, Foot], qs: np.ndarray, stature: float) -> None:
    """Set each foot's ankle height so that the sole is flat when the foot is.

    Skeletons put the ankle and toe joints at different heights above the sole. Over the
    given frames (the first seconds of the take) each foot's lowest ankle and lowest toe
    heights are where it stood flat; their difference (the median over both feet,
    bounded to 0–10 % of stature) is the ankle's height above the toe joint's."""
    data = model.createData()
    low = {s: [np.inf, np.inf] for s in feet}
    for q in qs:
        pin.framesForwardKinematics(model, data, q)
        for s, f in feet.items():
            low[s][0] = min(low[s][0], data.oMf[f.frame_id].translation[2])
            low[s][1] = min(low[s][1], data.oMf[f.toe_frame_id].translation[2])
    rise = float(np.clip(np.median([a - t for a, t in low.values()]), 0.0, 0.1 * stature))
    for f in feet.values():
        f.ankle_height = f.toe_height + rise


def body_from_bvh(motion: BvhMotion, opts: BvhBodyOptions | None = None) -> BodyModel:
    """Build the body model of ``motion``'s skeleton (see module docstring)."""
    opts = opts or BvhBodyOptions()
    if opts.total_mass <= 0:
        raise InputError(f"total mass must be positive, got {opts.total_mass}")
    tags = tag_joints([j.name for j in motion.joints], opts.mapping, motion.source)
    part = model_part(motion.joints, tags, motion.source)
    units = opts.units or detect_length_unit(_stature(motion, tags, 1.0), motion.source)
    if units not in UNIT_SCALES:
        raise InputError(f"unknown length unit {units!r} (one of {', '.join(UNIT_SCALES)})")
    scale = UNIT_SCALES[units]
    if opts.units:
        _check_given_unit(motion, tags, opts.units)
    up = opts.up_axis or _detect_up(motion, part, tags, scale, opts)
    if up not in WORLD_FROM_INPUT:
        raise InputError(f"unsupported up axis {up!r} (y or z)")
    r_in = WORLD_FROM_INPUT[up]
    model, frames, q_index = _build(motion, part, tags, scale, r_in, opts)
    if q_index != list(range(model.nq)):
        raise AssertionError("channel order and q order must agree")
    stature = _stature(motion, tags, scale)
    feet = {}
    named = {}
    for side in ("left", "right"):
        fi = next(i for i, t in enumerate(tags) if t.kind == "foot" and t.side == side)
        toe = _toe(motion.joints, tags, fi)
        if toe is not None:
            toe_frame = frames[toe]
            tj = motion.joints[toe]
            tip = scale * float(np.linalg.norm(tj.end_site)) if tj.end_site is not None else 0.0
        else:
            toe_frame = model.getFrameId(f"{motion.joints[fi].name}.end") if motion.joints[fi].end_site is not None \
                else frames[fi]
            tip = 0.0
        foot_len = 0.148 * stature  # de Leva foot length / stature
        feet[side] = Foot(
            side, frames[fi], toe_frame_id=toe_frame,
            heel_back=opts.heel_back if opts.heel_back is not None else 0.25 * foot_len,
            toe_front=opts.toe_front if opts.toe_front is not None else (tip if tip > 0.01 else 0.2 * foot_len),
            width=opts.sole_width if opts.sole_width is not None else 0.055 * stature,
            toe_height=0.015 * stature,
        )
        named[f"{side}_ankle"] = frames[fi]
        named[f"{side}_toe"] = toe_frame
    scales = _channel_scale(part.joints, scale)
    calib = motion.frames[: max(1, round(CALIBRATION_S / motion.frame_time))]
    _calibrate_heels(model, feet, calib[:, part.columns] * scales, stature)
    pelvis = next(i for i, t in enumerate(tags) if t.kind == "pelvis")
    root = _placing_joint(motion.joints, pelvis, motion.source)
    pj = part.joint(root)
    legs, hips = {}, {}
    for side in ("left", "right"):
        th = next(i for i, t in enumerate(tags) if t.kind == "thigh" and t.side == side)
        tj = part.joint(th)
        legs[side] = [tj.first_channel + k for k, c in enumerate(tj.channels) if c.endswith("rotation")]
        hips[side] = frames[th]
    correction = CorrectionJoints(
        root_channels=list(range(pj.first_channel, pj.first_channel + len(pj.channels))),
        root_frame_id=frames[root], legs=legs, hips=hips,
        foot_frames={s: [named[f"{s}_ankle"], named[f"{s}_toe"]] for s in ("left", "right")},
        full_foot_pose=False,
    )
    names = [f"{j.name}.{c}" for j in part.joints for c in j.channels]
    return BodyModel(
        kind="bvh", model=model, point_model=point_mass_copy(model), channel_names=names,
        channel_scale=scales,
        angle_mask=np.array([n.endswith("rotation") for n in names]),
        feet=feet, world_from_input=r_in, up_axis=up, units=units, total_mass=opts.total_mass,
        correction=correction, named_points=named, input_columns=part.columns,
    )
