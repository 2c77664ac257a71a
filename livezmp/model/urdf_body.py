"""Body model of a URDF robot on Pinocchio: a six-joint floating base, then the URDF.

Masses and inertias come from the URDF's ``<inertial>`` tags. Feet and soles come from
the robot config (:mod:`livezmp.model.robot_config`); without one, the feet are the two
lowest leaf links in the zero pose (left = +y) and each sole a box under the link's
centre of mass: ``sole_length`` × ``sole_width``, ``sole_drop`` below the link origin,
by default 0.5 × / 0.28 × / 0.12 × the hip-to-foot height.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from livezmp.errors import InputError
from livezmp.model.body import BodyModel, CorrectionJoints, Foot, point_mass_copy
from livezmp.model.robot_config import RobotConfig, find_robot_config, load_robot_config

BASE_JOINTS = (
    ("base_x", pin.JointModelPX), ("base_y", pin.JointModelPY), ("base_z", pin.JointModelPZ),
    ("base_yaw", pin.JointModelRZ), ("base_pitch", pin.JointModelRY), ("base_roll", pin.JointModelRX),
)


@dataclass(frozen=True)
class UrdfBodyOptions:
    config: str | None = None  # robot config path; None = look beside the URDF / built-in
    sole_length: float | None = None
    sole_width: float | None = None
    sole_drop: float | None = None


def _load_fixed(path: Path) -> pin.Model:
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        raise InputError(f"{path}: cannot read URDF: {e}") from None
    if root.tag != "robot":
        raise InputError(f"{path}: not a URDF (root element <{root.tag}>)")
    if root.find("./link/inertial") is None:
        raise InputError(f"{path}: URDF has no <inertial> on any link; masses are needed for the ZMP")
    for j in root.findall("joint"):
        if j.get("type") not in ("revolute", "prismatic", "fixed"):
            raise InputError(f"{path}: joint {j.get('name')}: type {j.get('type')!r} not supported "
                             "(revolute, prismatic, fixed)")
    try:
        return pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as e:
        raise InputError(f"{path}: Pinocchio cannot load it: {str(e).splitlines()[0]}") from None


def _with_base(fixed: pin.Model) -> pin.Model:
    base = pin.Model()
    j = 0
    for name, jm in BASE_JOINTS:
        j = base.addJoint(j, jm(), pin.SE3.Identity(), name)
    f = base.addFrame(pin.Frame("base_attach", j, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    model = pin.appendModel(base, fixed, f, pin.SE3.Identity())
    model.name = fixed.name
    return model


def _chain(model: pin.Model, frame_id: int) -> list[int]:
    """Actuated joint ids from the base to the frame's joint (excluding the base joints)."""
    out = []
    j = model.frames[frame_id].parentJoint
    while j > len(BASE_JOINTS):
        out.append(j)
        j = model.parents[j]
    return out[::-1]


def _default_feet(model: pin.Model, data: pin.Data, path: Path) -> dict[str, int]:
    """The two lowest leaf links in the zero pose: left has the larger y."""
    children = {j: 0 for j in range(model.njoints)}
    for j in range(1, model.njoints):
        children[model.parents[j]] += 1
    leaves = [f for f in range(model.nframes)
              if model.frames[f].type == pin.FrameType.BODY and children[model.frames[f].parentJoint] == 0
              and model.frames[f].parentJoint > len(BASE_JOINTS)]
    if len(leaves) < 2:
        raise InputError(f"{path}: cannot find two feet (leaf links); give a robot config with [feet]")
    leaves.sort(key=lambda f: data.oMf[f].translation[2])
    a, b = leaves[0], leaves[1]
    if data.oMf[a].translation[1] < data.oMf[b].translation[1]:
        a, b = b, a
    return {"left": a, "right": b}


def _box(length: float, width: float, center: np.ndarray) -> np.ndarray:
    dx, dy = length / 2, width / 2
    return center + np.array([[-dx, -dy, 0.0], [dx, -dy, 0.0], [dx, dy, 0.0], [-dx, dy, 0.0]])


def body_from_urdf(path: str | Path, opts: UrdfBodyOptions | None = None) -> BodyModel:
    """Build the body model of a URDF robot (see module docstring)."""
    opts = opts or UrdfBodyOptions()
    path = Path(path)
    fixed = _load_fixed(path)
    model = _with_base(fixed)
    cfg: RobotConfig = load_robot_config(opts.config) if opts.config else find_robot_config(path, fixed.name)
    data = model.createData()
    q0 = np.zeros(model.nq)
    pin.framesForwardKinematics(model, data, q0)
    feet_frames: dict[str, int] = {}
    for side, f in cfg.feet.items():
        if not model.existFrame(f["link"]):
            raise InputError(f"{cfg.source}: [feet.{side}] link {f['link']!r} is not in {path}")
        feet_frames[side] = model.getFrameId(f["link"])
    if len(feet_frames) < 2:
        feet_frames = {**_default_feet(model, data, path), **feet_frames}
    hip_h = float(np.mean([data.oMi[_chain(model, f)[0]].translation[2] - data.oMf[f].translation[2]
                           for f in feet_frames.values()]))
    feet = {}
    for side, fid in feet_frames.items():
        spec = cfg.feet.get(side, {})
        if "sole" in spec:
            sole = spec["sole"]
        else:
            box = spec.get("box", {})
            com = model.inertias[model.frames[fid].parentJoint].lever
            placement = model.frames[fid].placement
            com_in_link = placement.actInv(com) if np.any(com) else np.zeros(3)
            drop = opts.sole_drop if opts.sole_drop is not None else 0.12 * hip_h
            center = np.asarray(box.get("center", [com_in_link[0], com_in_link[1], -drop]), dtype=float)
            sole = _box(box.get("length", opts.sole_length or 0.5 * hip_h),
                        box.get("width", opts.sole_width or 0.28 * hip_h), center)
        feet[side] = Foot(side, fid, sole_local=sole)
    names = [model.names[j] for j in range(1, model.njoints)]
    jid = {n: model.getJointId(n) for n in names}
    legs = {}
    for side, fid in feet_frames.items():
        chain = [model.names[j] for j in _chain(model, fid)]
        wanted = cfg.legs.get(side, chain)
        for n in wanted:
            if n not in jid:
                raise InputError(f"{cfg.source}: correction leg joint {n!r} is not in {path}")
        legs[side] = [model.joints[jid[n]].idx_q for n in wanted]
    hips = {s: model.getFrameId(model.names[_chain(model, f)[0]]) for s, f in feet_frames.items()}
    named = {f"{s}_foot": f for s, f in feet_frames.items()}
    return BodyModel(
        kind="urdf", model=model, point_model=point_mass_copy(model), channel_names=names,
        channel_scale=np.ones(model.nq),
        angle_mask=np.array([not model.joints[jid[n]].shortname().startswith("JointModelP") for n in names]),
        feet=feet, world_from_input=np.eye(3), up_axis="z", units="m",
        total_mass=float(pin.computeTotalMass(model)),
        correction=CorrectionJoints(list(range(len(BASE_JOINTS))), model.getFrameId("base_attach"), legs, hips,
                                    {s: [f] for s, f in feet_frames.items()}, full_foot_pose=True),
        named_points=named, base_channels=list(range(6)),
        joint_names=names[6:],
    )
