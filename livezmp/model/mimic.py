"""Mimic joints: a URDF ``<mimic joint="P" multiplier="m" offset="o"/>`` joint follows joint P, q = m q_P + o
(a gripper's second finger, a knee's linkage). Its angle is kept in the model as a joint of its own (it has a
servo that reads and is commanded like any other, and the model's coordinates stay one per joint: Pinocchio 4's
mimic-aware build, ``buildModel(..., mimic=True)``, drops the follower's coordinate, so its reading would have no
place and every joint-to-coordinate map would need the case); the live loop imposes the relation on what it
reads before the kinematics and on every goal it sends (the monitor's link source and joint CSVs on what they
read), and the scenarios and the corrector never move it on
their own: it plays no role in a scenario, and where it is on a leg (a double knee's second joint) the scenarios'
leg postures (``Poser.on_feet``) and the corrector's leg IK (``RootMover``) solve over the parents' coordinates
only, its Jacobian column folded into its parent's (J_parent += m J_follower) and its angle set by `follow` after
every step, so each foot goes where they place it once the relation is imposed."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from livezmp.errors import InputError


@dataclass(frozen=True)
class Mimic:
    """Joint ``joint`` follows joint ``parent`` (indices into a robot's actuated joints, ``BodyModel.joint_names``):
    q = ``multiplier`` q_parent + ``offset`` (rad, or m for a prismatic joint)."""

    joint: int
    parent: int
    multiplier: float
    offset: float


def follow(values: np.ndarray, mimics: tuple[Mimic, ...], offset: bool = True) -> np.ndarray:
    """``values`` (..., n) per actuated joint (angles or goals; a frame or frames) with each mimic joint's value
    set from its parent's; ``values`` itself when there are no mimics (parents are never mimics: chains are
    resolved when read). ``offset=False`` for rates (velocities, accelerations or changes of angle): the
    multiplier alone, the offset does not move."""
    if not mimics:
        return values
    out = np.array(values, dtype=float)
    for m in mimics:
        out[..., m.joint] = m.multiplier * out[..., m.parent] + (m.offset if offset else 0.0)
    return out


def read_mimics(root: ET.Element, path: Path) -> dict[str, tuple[str, float, float]]:
    """joint name → (parent joint name, multiplier, offset) of every ``<mimic>`` in the URDF ``root``; a mimic of a
    mimic is resolved to the first joint of the chain (m = m1 m2, o = m1 o2 + o1). InputError (file, joint, what)
    for a missing or unknown parent, a parent that is the joint itself, a fixed parent, a loop of mimics or
    numbers that are not finite. A fixed joint's ``<mimic>`` is ignored: the file has fixed it (Talos' reduced
    model keeps its fixed fingers' tags)."""
    kinds = {j.get("name"): j.get("type") for j in root.findall("joint")}
    raw = {}
    for j in root.findall("joint"):
        tag = j.find("mimic")
        if tag is None:
            continue
        if j.get("type") == "fixed":  # a joint the file has fixed (a reduced model's fingers) follows nothing
            continue
        where = f"{path}: joint {j.get('name')!r} <mimic>"
        parent = tag.get("joint")
        if parent not in kinds or parent == j.get("name"):
            raise InputError(f"{where}: joint={parent!r} is not another joint of this URDF")
        if kinds[parent] == "fixed":
            raise InputError(f"{where}: a fixed joint cannot be mimicked")
        try:
            numbers = float(tag.get("multiplier", "1")), float(tag.get("offset", "0"))
        except ValueError:
            raise InputError(f"{where}: multiplier and offset must be numbers") from None
        if not all(math.isfinite(v) for v in numbers):
            raise InputError(f"{where}: multiplier and offset must be finite")
        raw[j.get("name")] = (parent, *numbers)
    resolved = {}
    for name, (parent, m, o) in raw.items():
        seen = {name}
        while parent in raw:
            if parent in seen:
                raise InputError(f"{path}: joint {name!r} <mimic>: the mimics loop back to it ({parent!r})")
            seen.add(parent)
            up, m2, o2 = raw[parent]
            parent, m, o = up, m * m2, m * o2 + o
        resolved[name] = (parent, m, o)
    return resolved
