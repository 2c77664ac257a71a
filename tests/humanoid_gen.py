"""Humanoid URDFs generated from livezmp_mini with other joint and link names (Poppy-style: ``l_hip_y``,
``l_knee_y``, ``abs``-free), another joint order in the file and other proportions: robots the
scenarios have never seen, to show they find their limbs from the kinematic tree."""

from __future__ import annotations

import random
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from livezmp.model.demo_robot import demo_robot_path

RENAME = {"hip_yaw": "hip_z", "hip_roll": "hip_x", "hip_pitch": "hip_y", "knee": "knee_y", "ank_pitch": "ankle_y",
          "ank_roll": "ankle_x", "sho_pitch": "shoulder_y", "sho_roll": "arm_x", "el": "elbow_y"}


def joint_name(op3_name: str) -> str:
    """The generated robot's name for the mini's joint ``op3_name`` (e.g. l_hip_pitch -> l_hip_y)."""
    side, _, rest = op3_name.partition("_")
    if side in ("l", "r") and rest in RENAME:
        return f"{side}_{RENAME[rest]}"
    return {"head_pan": "head_z", "head_tilt": "head_y"}[op3_name]


def _scale_xyz(element: ET.Element, factor: tuple[float, float, float]) -> None:
    xyz = [float(v) * f for v, f in zip(element.get("xyz", "0 0 0").split(), factor, strict=True)]
    element.set("xyz", " ".join(f"{v:.6g}" for v in xyz))


def generate_humanoid(path: Path, scale: float = 1.0, leg_scale: float = 1.0, seed: int = 0) -> Path:
    """Write the generated humanoid to ``path``: every length times ``scale`` (legs' vertical lengths
    times ``leg_scale`` more), masses times scale^3, inertias times scale^5, joints renamed, links
    renamed, joints shuffled in the file (seed)."""
    tree = ET.parse(demo_robot_path())
    robot = tree.getroot()
    robot.set("name", f"generated_{seed}")
    links = {link.get("name"): f"seg{k:02d}" for k, link in enumerate(robot.findall("link"))}
    for link in robot.findall("link"):
        link.set("name", links[link.get("name")])
        inertial = link.find("inertial")
        if inertial is not None:
            _scale_xyz(inertial.find("origin"), (scale,) * 3)
            mass = inertial.find("mass")
            mass.set("value", f"{float(mass.get('value')) * scale ** 3:.6g}")
            inertia = inertial.find("inertia")
            for key, value in inertia.attrib.items():
                inertia.set(key, f"{float(value) * scale ** 5:.6g}")
    joints = robot.findall("joint")
    for joint in joints:
        name = joint.get("name")
        leg = any(part in name for part in ("hip", "knee", "ank"))
        _scale_xyz(joint.find("origin"), (scale, scale, scale * (leg_scale if leg else 1.0)))
        joint.set("name", joint_name(name))
        joint.find("parent").set("link", links[joint.find("parent").get("link")])
        joint.find("child").set("link", links[joint.find("child").get("link")])
        robot.remove(joint)
    random.Random(seed).shuffle(joints)
    robot.extend(joints)
    tree.write(path)
    return path


# -- humanoids built from a spec: leg and arm joint orders, axes, frames, names, extras ---------------------

AXES = {"yaw": (0.0, 0.0, 1.0), "roll": (1.0, 0.0, 0.0), "pitch": (0.0, 1.0, 0.0)}
# role -> name, per naming convention ({s}: l/r, {S}: L/R, {side}: left/right); roles not listed: "{s}_{role}"
CONVENTIONS = {
    "op3": {"hip_yaw": "{s}_hip_yaw", "hip_roll": "{s}_hip_roll", "hip_pitch": "{s}_hip_pitch", "knee": "{s}_knee",
            "ank_pitch": "{s}_ank_pitch", "ank_roll": "{s}_ank_roll", "sho_pitch": "{s}_sho_pitch",
            "sho_roll": "{s}_sho_roll", "arm_yaw": "{s}_arm_yaw", "el": "{s}_el", "head": "head_pan"},
    "poppy": {"hip_yaw": "{s}_hip_z", "hip_roll": "{s}_hip_x", "hip_pitch": "{s}_hip_y", "knee": "{s}_knee_y",
              "ank_pitch": "{s}_ankle_y", "ank_roll": "{s}_ankle_x", "sho_pitch": "{s}_shoulder_y",
              "sho_roll": "{s}_shoulder_x", "arm_yaw": "{s}_arm_z", "el": "{s}_elbow_y", "waist_yaw": "abs_z",
              "waist_pitch": "abs_y", "head": "head_z"},
    "nao": {"hip_yaw": "{S}HipYaw", "hip_roll": "{S}HipRoll", "hip_pitch": "{S}HipPitch", "knee": "{S}KneePitch",
            "ank_pitch": "{S}AnklePitch", "ank_roll": "{S}AnkleRoll", "sho_pitch": "{S}ShoulderPitch",
            "sho_roll": "{S}ShoulderRoll", "arm_yaw": "{S}ElbowYaw", "el": "{S}ElbowRoll", "waist_yaw": "TorsoYaw",
            "waist_pitch": "TorsoPitch", "head": "HeadYaw"},
    "darwin": {"hip_yaw": "j_pelvis_{s}", "hip_roll": "j_thigh1_{s}", "hip_pitch": "j_thigh2_{s}",
               "knee": "j_tibia_{s}", "ank_pitch": "j_ankle1_{s}", "ank_roll": "j_ankle2_{s}",
               "sho_pitch": "j_shoulder_{s}", "sho_roll": "j_high_arm_{s}", "arm_yaw": "j_mid_arm_{s}",
               "el": "j_low_arm_{s}", "head": "j_pan"},
}


@dataclass(frozen=True)
class HumanoidSpec:
    """A humanoid to generate: ``height`` (m, sole to head top), ``mass`` (kg); ``hip`` the hip joints from the
    pelvis down (``y`` yaw, ``r`` roll, ``p`` pitch: "yrp" is OP3's, "rp" a 5-DOF leg), ``ankle`` likewise;
    ``arm`` the arm joints from the trunk (``p``/``r`` shoulder pitch/roll, ``y`` upper-arm yaw, ``e`` elbow; ""
    none); ``waist`` joints between pelvis and torso (``y``, ``p``), ``torso_root``: the torso is the root link
    (the waist then sits above the legs' chains); ``flip``: share of joints whose axis is given negated;
    ``frames``: "aligned" link frames, "pitch_z" (leg links rotated so the pitch axis is local z) or "random";
    ``names``: a `CONVENTIONS` key or "numbered" (joint_1...); ``limits``: "wide", "tight" (what standing needs and
    a little), "absent" (no <limit> on any joint) or "zero" (lower = upper = 0 on every joint: Z-Bot2's CAD
    export); ``continuous``: head and upper-arm yaw continuous;
    ``grippers``: a two-finger gripper on each hand, one finger mimicking the other (multiplier -1);
    ``double_knee``: each knee split in two pitch joints 0.04 heights apart (a kid-size linkage), the lower
    (``knee2``) mimicking the upper with multiplier 1; ``double_shoulder``: each arm's first joint followed,
    0.04 heights lower, by a second about the same axis (``sho2``) mimicking it with multiplier 1; ``extras``:
    camera, IMU and sole frames as fixed massless links, and a massless root link; ``root``: the root link's name,
    its frame at its centre of mass or (``root_at_ground``) on the ground between the feet; ``robot_name`` (default
    humanoid_SEED); ``foot``: "box", "mesh" or "none" collision, or "split": two boxes, the foot's front and rear
    halves, on one plane (ergoCub's), or cylinders or spheres (`_foot_rounds`);
    as published files write them (held-out real robots): ``placeholders``, how the extras' massless links are
    written: "" without <inertial>, "zero_mass" mass 0 with a small inertia (Bolt's feet), "point_mass" 1e-4 kg
    with a zero inertia (Talos', Wolfgang's sensor frames); ``fixed_axis_zero``: fixed joints with
    <axis xyz="0 0 0"/> (Unitree H1's logo, NAO's effectors); ``odd_inertias``: the head a point mass with a
    2.4e-35 product of inertia (iCub's), the torso's moments (a, a, 3a) breaking the triangle inequality
    (Darwin-OP's neck, Romeo's shoulder); ``fixed_finger``: with grippers, the mimicking finger fixed, its <mimic>
    kept (Talos' reduced model); ``facing``: the way the robot faces in its file, "x" (REP 103), "-y" (Poppy's)
    or "-x" (iCub's); ``upside_down``: the robot then turned half a turn about x, standing on its head in its
    file (K-Scale's GPR); ``lying``: "x" or "-x", the robot then laid down in its file with its legs along that axis
    (a quarter turn about y; WATonomous' humanoid V1 lies so); ``odd_limits``: the left knee's tight limits
    mirrored, so it flexes only forward (Poppy's file), and the elbows' leaving out their zero (NAO's elbow roll,
    −1.54..−0.03 rad); ``inertia_scale``: the torso's inertia written this many times too large (1e6: kg mm^2 as
    kg m^2; Darwin-OP's file);
    ``shoulder_tilt``: the shoulder pitch's axis turned about the forward axis (rad; Unitree H1's 0.44);
    ``hip_tilt``: the hip pitch's likewise (Fourier GR2's 0.52); ``torso_com``: the torso's centre of mass
    height as a share of ``height`` (0.72; NimbRo-OP2X's upper body has its CoM 65 mm above its hips);
    ``ankle_range``: the ankle pitch limited to ± this (rad; 0: as ``limits`` says; Romeo's −0.52..0.79);
    ``arms_forward``: the arms held straight forward in the zero posture (NAO's), the shoulder roll then about the
    vertical axis and the upper-arm yaw a twist about the forward axis, at the elbow (NAO's elbow yaw);
    ``cleats``: each foot ends in four cleats, massless leaf links fixed at its sole's corners, on a plane turned
    this angle (rad) toes up from level in the zero posture, the right foot's also rolled a tenth of it, its
    outer edge up (Wolfgang-OP's: 15° and 1.3°);
    ``foot_frames``: a force sensor's and an end effector's frame as fixed massless links at each sole's centre,
    so each foot ends in several leaves at one height (JVRC-1's, XBot-L's); ``parallel_legs``: a massless copy
    of each leg below its hip roll, thigh and shank pitch and ankle roll joints ending in a foot-plane link at
    the sole (NimbRo-OP2X's parallel-linkage model, beside its serial legs);
    ``root_joint``: with ``extras``, the joint from the massless root link to the robot, "fixed" or "floating"
    (HighTorque's Hi: a ``world`` link and a floating joint, as MuJoCo conversions write the free base);
    ``sole_on_ankle``: the sides ("l", "r") whose foot's collision geometry the file gives the link between the
    ankle's joints (they meet at one point) instead of the foot link (Fourier GR3's right foot);
    ``trunk_mass``: the torso's and head's masses times this before the whole is scaled to ``mass`` (with ``arm``
    "" and ``torso_com`` near the hips' 0.54, a legs-only robot whose light trunk is a short lever: Alexbotmini's);
    ``seed``: the file's link and joint order, flipped axes, random frames."""

    height: float = 0.5
    mass: float = 3.0
    hip: str = "yrp"
    ankle: str = "pr"
    arm: str = "pre"
    waist: str = ""
    torso_root: bool = False
    flip: float = 0.0
    frames: str = "aligned"
    names: str = "op3"
    limits: str = "wide"
    continuous: bool = False
    grippers: bool = False
    double_knee: bool = False
    double_shoulder: bool = False
    extras: bool = False
    foot: str = "box"
    root: str = "base_link"
    root_at_ground: bool = False
    robot_name: str = ""
    placeholders: str = ""
    fixed_axis_zero: bool = False
    odd_inertias: bool = False
    fixed_finger: bool = False
    facing: str = "x"
    upside_down: bool = False
    lying: str = ""
    odd_limits: bool = False
    inertia_scale: float = 1.0
    shoulder_tilt: float = 0.0
    hip_tilt: float = 0.0
    torso_com: float = 0.72
    ankle_range: float = 0.0
    arms_forward: bool = False
    cleats: float = 0.0
    foot_frames: bool = False
    parallel_legs: bool = False
    root_joint: str = "fixed"
    trunk_mass: float = 1.0
    sole_on_ankle: str = ""
    seed: int = 0


ROLE_OF = {"y": "yaw", "r": "roll", "p": "pitch"}
FACING = {"x": 0.0, "-y": -np.pi / 2, "-x": np.pi}  # the yaw (rad) that turns a robot facing +x to face so
ARM_ROLE = {"p": ("sho_pitch", "pitch"), "r": ("sho_roll", "roll"), "y": ("arm_yaw", "yaw"), "e": ("el", "pitch")}


def _rot(rpy) -> np.ndarray:
    return pin.rpy.rpyToMatrix(*map(float, rpy))


def _fmt(v) -> str:
    return " ".join(f"{float(x):.9g}" for x in v)


class _Builder:
    """Links and joints in world coordinates in the zero posture; written with per-link frames."""

    def __init__(self, spec: HumanoidSpec):
        self.spec, self.rng = spec, random.Random(spec.seed)
        self.links: dict[str, dict] = {}
        self.joints: list[dict] = []
        self.count = 0

    def link(self, role: str, mass: float, com, size, frame: np.ndarray | None = None) -> str:
        name = f"link_{len(self.links) + 1}" if self.spec.names == "numbered" else role
        h = self.spec.height
        self.links[role] = {"name": name, "mass": mass, "com": np.asarray(com, float) * h,
                            "size": np.asarray(size, float) * h, "R": frame if frame is not None else np.eye(3)}
        return role

    def joint(self, role: str, side: str, parent: str, child: str, at, axis: str | None, kind: str = "revolute",
              **extra) -> None:
        self.count += 1
        convention = CONVENTIONS.get(self.spec.names, {})
        pattern = convention.get(role, "{s}_" + role if side else role)
        name = (f"joint_{self.count}" if self.spec.names == "numbered" else
                pattern.format(s=side, S=side.upper(), side={"l": "left", "r": "right"}.get(side, "")))
        sign = -1.0 if axis and self.rng.random() < self.spec.flip else 1.0
        self.joints.append({"name": name, "role": role, "side": side, "parent": parent, "child": child,
                            "at": np.asarray(at, float) * self.spec.height, "kind": kind,
                            "axis": None if axis is None else sign * np.array(AXES[axis]) @ self.tilt(role).T,
                            **extra})

    def tilt(self, role: str) -> np.ndarray:
        """The turn of a joint's axis from its world axis: the shoulder pitch's ``shoulder_tilt``, the hip
        pitch's ``hip_tilt``, about x."""
        return _rot(({"sho_pitch": self.spec.shoulder_tilt, "hip_pitch": self.spec.hip_tilt}.get(role, 0.0), 0.0, 0.0))

    def frame(self, leg: bool) -> np.ndarray | None:
        if self.spec.frames == "pitch_z" and leg:
            return _rot((-np.pi / 2, 0.0, 0.0))  # local z = world y (the pitch axis), local y = world -z
        if self.spec.frames == "random":
            return _rot([self.rng.uniform(-np.pi, np.pi) for _ in range(3)])
        return None


def _limits(spec: HumanoidSpec, role: str, side: str, axis: np.ndarray) -> tuple[float, float] | None:
    """(lower, upper) rad: wide ±2.8; tight: the standing posture's range (knee bent 0-1.4 rad forward of its
    axis sign, hips and ankles ±0.7, rolls ±0.35, arms ±1.2); ``odd_limits``: see `HumanoidSpec`."""
    if spec.odd_limits and role == "el":
        return (-1.54, -0.03)
    if spec.ankle_range and role == "ank_pitch":
        return (-spec.ankle_range, spec.ankle_range)
    if spec.limits == "absent":
        return None
    if spec.limits == "wide":
        return (-2.8, 2.8)
    if spec.limits == "zero":
        return (0.0, 0.0)
    if role == "knee":
        return (0.0, 1.4) if (axis[1] > 0) != (spec.odd_limits and side == "l") else (-1.4, 0.0)
    if role in ("hip_roll", "ank_roll", "hip_yaw"):
        return (-0.35, 0.35)
    return (-0.7, 0.7) if role in ("hip_pitch", "ank_pitch") else (-1.2, 1.2)


def _build(spec: HumanoidSpec) -> _Builder:
    b = _Builder(spec)
    trunk = b.link("torso", 0.30 * spec.trunk_mass, (0.0, 0.0, spec.torso_com), (0.12, 0.2, 0.24))
    pelvis = b.link("pelvis", 0.10, (0.0, 0.0, 0.58), (0.1, 0.16, 0.06)) if spec.waist else trunk
    if spec.waist:  # the chain from pelvis up to torso (or down, when the torso is the root)
        chain = [pelvis] + [b.link(f"waist_{k}", 0.01, (0.0, 0.0, 0.6), (0.04, 0.04, 0.02))
                            for k in range(len(spec.waist) - 1)] + [trunk]
        if spec.torso_root:
            chain = chain[::-1]
        for k, axis in enumerate(spec.waist):
            b.joint(f"waist_{ROLE_OF[axis]}", "", chain[k], chain[k + 1], (0.0, 0.0, 0.6), ROLE_OF[axis])
    head = b.link("head", 0.07 * spec.trunk_mass, (0.0, 0.0, 0.93), (0.1, 0.1, 0.12))
    b.joint("head", "", trunk, head, (0.0, 0.0, 0.86), "yaw", "continuous" if spec.continuous else "revolute")
    for s, y in (("l", 1.0), ("r", -1.0)):
        w = 0.055 * y
        parent = pelvis
        hips = list(spec.hip)
        for k, axis in enumerate(hips):
            last = k == len(hips) - 1
            above_thigh = parent
            child = (b.link(f"{s}_thigh", 0.09, (0.0, w, 0.42), (0.06, 0.06, 0.24), b.frame(True)) if last else
                     b.link(f"{s}_hip{k}", 0.01, (0.0, w, 0.54), (0.03, 0.03, 0.03), b.frame(True)))
            b.joint(f"hip_{ROLE_OF[axis]}", s, parent, child, (0.0, w, 0.54), ROLE_OF[axis])
            parent = child
        shank = b.link(f"{s}_shank", 0.05, (0.0, w, 0.18), (0.05, 0.05, 0.24), b.frame(True))
        if spec.double_knee:
            link = b.link(f"{s}_kneecap", 0.01, (0.0, w, 0.30), (0.03, 0.03, 0.04), b.frame(True))
            b.joint("knee", s, parent, link, (0.0, w, 0.32), "pitch")
            b.joint("knee2", s, link, shank, (0.0, w, 0.28), "pitch", mimic=b.joints[-1]["name"], multiplier=1.0)
        else:
            b.joint("knee", s, parent, shank, (0.0, w, 0.30), "pitch")
        parent = shank
        for k, axis in enumerate(spec.ankle):
            last = k == len(spec.ankle) - 1
            child = (b.link(f"{s}_foot", 0.025, (0.02, w, 0.03), (0.16, 0.08, 0.03), b.frame(True)) if last else
                     b.link(f"{s}_ankle{k}", 0.005, (0.0, w, 0.06), (0.02, 0.02, 0.02), b.frame(True)))
            b.joint(f"ank_{ROLE_OF[axis]}", s, parent, child, (0.0, w, 0.06), ROLE_OF[axis])
            parent = child
        if spec.cleats:
            roll = spec.cleats / 10 if s == "r" else 0.0
            for x, dy in ((-0.055, -0.035), (-0.055, 0.035), (0.095, -0.035), (0.095, 0.035)):
                at = (x, w + dy, (x + 0.055) * np.tan(spec.cleats) - dy * np.tan(roll))
                cleat = b.link(f"{s}_cleat_{'bf'[x > 0]}{'rl'[dy > 0]}", 0.0, at, (0.0, 0.0, 0.0))
                b.joint(f"cleat_{'bf'[x > 0]}{'rl'[dy > 0]}", s, parent, cleat, at, None, "fixed")
        if spec.extras:
            b.link(f"{s}_sole", 0.0, (0.02, w, 0.0), (0.0, 0.0, 0.0))
            b.joint("sole", s, parent, f"{s}_sole", (0.02, w, 0.0), None, "fixed")
        if spec.parallel_legs:
            ghost = above_thigh
            for role, at, axis in (("thigh", 0.54, "pitch"), ("shank", 0.30, "pitch"), ("foot", 0.06, "roll")):
                link = b.link(f"{s}_parallel_{role}", 0.0, (0.0, w, at), (0.0, 0.0, 0.0))
                b.joint(f"parallel_{role}", s, ghost, link, (0.0, w, at), axis)
                ghost = link
            b.link(f"{s}_parallel_plane", 0.0, (0.02, w, 0.0), (0.0, 0.0, 0.0))
            b.joint("parallel_plane", s, ghost, f"{s}_parallel_plane", (0.02, w, 0.0), None, "fixed")
        for frame in ("ft_sensor", "end_effector") if spec.foot_frames else ():
            b.link(f"{s}_{frame}", 0.0, (0.02, w, 0.0), (0.0, 0.0, 0.0))
            b.joint(f"{frame}_fixed", s, parent, f"{s}_{frame}", (0.02, w, 0.0), None, "fixed")
        parent, shoulder = trunk, (0.0, 0.12 * y, 0.82)
        # arms forward: each point of the hanging arm turned 90° about y around the shoulder, boxes with it
        point = (lambda p: (0.82 - p[2], p[1], 0.82)) if spec.arms_forward else tuple
        box = (lambda d: (d[2], d[1], d[0])) if spec.arms_forward else tuple
        for k, a in enumerate(spec.arm):
            role, axis = ARM_ROLE[a]
            if spec.arms_forward:
                axis = {"roll": "yaw", "yaw": "roll"}.get(axis, axis) if a != "e" else axis
            at = point((0.0, 0.12 * y, 0.68) if a == "e" or (a == "y" and spec.arms_forward) else shoulder)
            last = k == len(spec.arm) - 1
            com, size = ((0.0, 0.12 * y, 0.62), (0.04, 0.04, 0.13)) if last else \
                ((0.0, 0.12 * y, 0.75), (0.04, 0.04, 0.14))
            com, size = point(com), box(size)
            child = b.link(f"{s}_arm{k}", 0.03 if last or a == "e" else 0.01, com, size, b.frame(False))
            b.joint(role, s, parent, child, at, axis, "continuous" if spec.continuous and a == "y" else "revolute")
            parent = child
            if spec.double_shoulder and k == 0:
                link = b.link(f"{s}_arm{k}b", 0.01, (0.0, 0.12 * y, 0.77), (0.03, 0.03, 0.03), b.frame(False))
                b.joint("sho2", s, parent, link, (0.0, 0.12 * y, 0.78), axis, mimic=b.joints[-1]["name"],
                        multiplier=1.0)
                parent = link
        if spec.grippers and spec.arm:
            for k, finger in enumerate((0.01, -0.01)):
                tip = b.link(f"{s}_finger{k}", 0.002, (0.0, 0.12 * y + finger, 0.54), (0.01, 0.01, 0.03))
                b.joint(f"finger{k}", s, parent, tip, (0.0, 0.12 * y + finger, 0.56), "roll",
                        "fixed" if k and spec.fixed_finger else "revolute",
                        mimic=b.joints[-1]["name"] if k else None, multiplier=-1.0)
    if spec.extras:
        for role, parent, at in (("camera", head, (0.05, 0.0, 0.95)), ("imu", trunk, (0.0, 0.0, 0.7))):
            b.link(role, 0.0, at, (0.0, 0.0, 0.0))
            b.joint(f"{role}_fixed", "", parent, role, at, None, "fixed")
        b.link("dummy_root", 0.0, (0.0, 0.0, 0.58), (0.0, 0.0, 0.0))
        b.joint(f"root_{spec.root_joint}", "", "dummy_root", pelvis if not spec.torso_root else trunk,
                (0.0, 0.0, 0.58), None, spec.root_joint)
    total = sum(v["mass"] for v in b.links.values())
    for v in b.links.values():
        v["mass"] *= spec.mass / total
    # the robot turned about z in its root's frame (then about y, lying, and x, upside down), boxes with it
    turn = (_rot((np.pi if spec.upside_down else 0.0, {"x": -np.pi / 2, "-x": np.pi / 2}.get(spec.lying, 0.0), 0.0))
            @ _rot((0.0, 0.0, FACING[spec.facing])))
    for v in b.links.values():
        v["com"], v["size"] = turn @ v["com"], np.abs(turn) @ v["size"]
    for j in b.joints:
        j["at"] = turn @ j["at"]
        if j["axis"] is not None:  # limits as the robot's own axes give them (a knee flexes backward)
            j["own_axis"], j["axis"] = j["axis"], turn @ j["axis"]
    return b


def _foot_boxes(spec: HumanoidSpec, com: np.ndarray, size: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """(centre, size) world, m, of a foot's collision boxes: one, or (``foot="split"``) its front and rear halves
    (ergoCub's)."""
    if spec.foot != "split":
        return [(com, size)]
    long = int(np.argmax(size[:2]))  # the foot's length: along x, or y for a robot facing -y in its file
    half = size.copy()
    half[long] /= 2
    step = np.eye(3)[long] * half[long] / 2
    return [(com + step, half), (com - step, half)]


ROUND_FEET = ("cylinder", "cylinders", "ball", "balls")


def _foot_rounds(spec: HumanoidSpec, com: np.ndarray, size: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, tuple]]:
    """(centre (3,) world m, the shape's world rotation (3, 3), (tag, attributes)) of each collision primitive of a
    foot whose box would be ``size`` (3,) at ``com``, its bottom where the box's is: ``foot`` "cylinder", one lying
    along the foot, as long, as thick as it is high; "cylinders", two such, a quarter of its width either side of
    its middle (Fourier GR1T2's); "balls", four spheres as thick inside its bottom's corners (Unitree G1's); "ball",
    one under its middle (a ball foot)."""
    long = int(np.argmax(size[:2]))  # the foot's length: along x, or y for a robot facing -y in its file
    across = 1 - long
    r = size[2] / 2
    along = _rot((0.0, np.pi / 2, 0.0)) if long == 0 else _rot((-np.pi / 2, 0.0, 0.0))  # a cylinder's z along it
    cylinder = ("cylinder", {"radius": f"{r:.9g}", "length": f"{size[long]:.9g}"})
    ball = ("sphere", {"radius": f"{r:.9g}"})
    if spec.foot == "cylinder":
        return [(com, along, cylinder)]
    if spec.foot == "cylinders":
        return [(com + k * size[across] / 4 * np.eye(3)[across], along, cylinder) for k in (-1.0, 1.0)]
    if spec.foot == "ball":
        return [(com, np.eye(3), ball)]
    return [(com + a * (size[long] / 2 - r) * np.eye(3)[long] + b * (size[across] / 2 - r) * np.eye(3)[across],
             np.eye(3), ball) for a in (-1.0, 1.0) for b in (-1.0, 1.0)]


def _write(b: _Builder, path: Path) -> Path:
    spec = b.spec
    robot = ET.Element("robot", name=spec.robot_name or f"humanoid_{spec.seed}")
    root_role = "dummy_root" if spec.extras else ("torso" if spec.torso_root or not spec.waist else "pelvis")
    names = {role: v["name"] for role, v in b.links.items()}
    names[root_role] = spec.root if spec.names != "numbered" else names[root_role]
    origin_of = {root_role: np.zeros(3) if spec.root_at_ground else b.links[root_role]["com"]}
    for j in b.joints:
        origin_of[j["child"]] = j["at"]
    elements, links = [], {}
    for role, v in b.links.items():
        link = ET.Element("link", name=names[role])
        R, p = v["R"], origin_of[role]
        if v["mass"] > 0 or spec.placeholders:
            placeholder = {"zero_mass": 0.0, "point_mass": 1e-4}.get(spec.placeholders) if v["mass"] == 0 else None
            inertial = ET.SubElement(link, "inertial")
            ET.SubElement(inertial, "origin", xyz=_fmt(R.T @ (v["com"] - p)), rpy="0 0 0")
            ET.SubElement(inertial, "mass", value=f"{v['mass'] if placeholder is None else placeholder:.9g}")
            dx, dy, dz = v["size"]
            inertia = R.T @ np.diag([dy * dy + dz * dz, dx * dx + dz * dz, dx * dx + dy * dy]) @ R * v["mass"] / 12
            if placeholder is not None:
                inertia = np.diag([5.7e-7, 8.4e-7, 5.3e-7] if spec.placeholders == "zero_mass" else [0.0] * 3)
            elif spec.odd_inertias and role in ("head", "torso"):
                inertia = (np.array([[0.0, 0.0, 2.40741e-35], [0.0, 0.0, 0.0], [2.40741e-35, 0.0, 0.0]])
                           if role == "head" else np.diag([1.0, 1.0, 3.0]) * inertia[0, 0])
            if role == "torso":
                inertia = inertia * spec.inertia_scale
            ET.SubElement(inertial, "inertia", **{k: f"{inertia[i, j]:.9g}" for k, (i, j) in zip(
                ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)),
                strict=True)})
        links[role] = link
        elements.append(link)
    for role, v in b.links.items():
        if not role.endswith("_foot"):
            continue
        # the link that carries the foot's collision geometry: the foot's, or the one between its ankle's joints
        holder = f"{role[0]}_ankle0" if role[0] in spec.sole_on_ankle and f"{role[0]}_ankle0" in links else role
        link, R, p = links[holder], b.links[holder]["R"], origin_of[holder]
        if spec.foot in ROUND_FEET:
            for centre, turn, shape in _foot_rounds(spec, v["com"], v["size"]):
                collision = ET.SubElement(link, "collision")
                ET.SubElement(collision, "origin", xyz=_fmt(R.T @ (centre - p)),
                              rpy=_fmt(pin.rpy.matrixToRpy(R.T @ turn)))
                ET.SubElement(ET.SubElement(collision, "geometry"), *shape)
        elif spec.foot != "none":
            for centre, size in _foot_boxes(spec, v["com"], v["size"]):
                collision = ET.SubElement(link, "collision")
                ET.SubElement(collision, "origin", xyz=_fmt(R.T @ (centre - p)), rpy=_fmt(pin.rpy.matrixToRpy(R.T)))
                geometry = ET.SubElement(collision, "geometry")
                if spec.foot == "mesh":
                    ET.SubElement(geometry, "mesh", filename=f"package://humanoid/meshes/{names[role]}.stl")
                else:
                    ET.SubElement(geometry, "box", size=_fmt(size))
    for j in b.joints:
        Rp, Rc = b.links[j["parent"]]["R"], b.links[j["child"]]["R"]
        pp = origin_of[j["parent"]]
        joint = ET.Element("joint", name=j["name"], type=j["kind"])
        ET.SubElement(joint, "parent", link=names[j["parent"]])
        ET.SubElement(joint, "child", link=names[j["child"]])
        ET.SubElement(joint, "origin", xyz=_fmt(Rp.T @ (j["at"] - pp)), rpy=_fmt(pin.rpy.matrixToRpy(Rp.T @ Rc)))
        if j["axis"] is None and spec.fixed_axis_zero:
            ET.SubElement(joint, "axis", xyz="0 0 0")
        if j["axis"] is not None:
            ET.SubElement(joint, "axis", xyz=_fmt(Rc.T @ j["axis"]))
            bounds = _limits(spec, j["role"], j["side"], j["own_axis"])
            if bounds is not None and j["kind"] == "revolute":
                ET.SubElement(joint, "limit", lower=f"{bounds[0]:g}", upper=f"{bounds[1]:g}", effort="10",
                              velocity="6")
        if j.get("mimic"):
            ET.SubElement(joint, "mimic", joint=j["mimic"], multiplier=f"{j['multiplier']:g}", offset="0")
        elements.append(joint)
    random.Random(spec.seed).shuffle(elements)
    robot.extend(elements)
    ET.ElementTree(robot).write(path)
    return path


def build_humanoid(path: Path, spec: HumanoidSpec) -> Path:
    """Write the humanoid of ``spec`` (see `HumanoidSpec`) to ``path``."""
    return _write(_build(spec), path)


# -- URDFs that are no humanoid, or no URDF ---------------------------------------------------------------

def _link(name: str, mass: float = 1.0) -> str:
    return (f'<link name="{name}"><inertial><mass value="{mass}"/>'
            '<inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>')


def _joint(name: str, parent: str, child: str, axis: str | None = "0 1 0", z: float = -0.1,
           kind: str = "revolute") -> str:
    ax = f'<axis xyz="{axis}"/>' if axis else ""
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="0 0 {z}"/>{ax}<limit lower="-2" upper="2" effort="5" velocity="5"/></joint>')


def malformed(out: Path) -> list[Path]:
    """Non-humanoid or broken URDFs, written to ``out``, each named after what is wrong with it: one leg; a
    loop; one link, no foot; a humanoid whose joints have no <axis> (x, by the URDF spec: no lateral axis in its
    legs); a floating joint; no masses; not XML; a joint to a link that is not there."""
    one_leg = "".join([_link("pelvis"), _link("thigh"), _link("shank"), _link("foot"),
                       _joint("hip", "pelvis", "thigh"), _joint("knee", "thigh", "shank"),
                       _joint("ankle", "shank", "foot")])
    loop = one_leg + _joint("closing", "foot", "pelvis")
    no_leaf = _link("pelvis")
    no_axes = build_humanoid(out / "no_axes_src.urdf", HumanoidSpec()).read_text().replace('<axis xyz="0 1 0" />', "")
    texts = {
        "one_leg": f'<robot name="one_leg">{one_leg}</robot>',
        "loop": f'<robot name="loop">{loop}</robot>',
        "no_feet": f'<robot name="blob">{no_leaf}</robot>',
        "no_axes": no_axes,
        "floating": f'<robot name="fl">{_link("world")}{_link("pelvis")}'
                    f'{_joint("free", "world", "pelvis", None, kind="floating")}</robot>',
        "no_masses": '<robot name="m"><link name="a"/><link name="b"/>'
                     f'{_joint("j", "a", "b")}</robot>',
        "not_xml": "robot name='x'",
        "missing_child": f'<robot name="mc">{_link("a")}{_joint("j", "a", "ghost")}</robot>',
    }
    paths = []
    for name, text in texts.items():
        paths.append(out / f"{name}.urdf")
        paths[-1].write_text(text)
    return paths


def com_height(spec: HumanoidSpec) -> float:
    """Height (m, above the generator's ground) of the humanoid's centre of mass in its zero posture."""
    links = _build(spec).links.values()
    return sum(v["mass"] * v["com"][2] for v in links) / sum(v["mass"] for v in links)
