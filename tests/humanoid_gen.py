"""Humanoid URDFs generated from livezmp_mini with other joint and link names (Poppy-style: ``l_hip_y``,
``l_knee_y``, ``abs``-free), another joint order in the file and other proportions: robots the
scenarios have never seen, to show they find their limbs from the kinematic tree."""

from __future__ import annotations

import random
import xml.etree.ElementTree as ET
from pathlib import Path

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
