"""Inertias a URDF gives as placeholders: told, not changed.

A URDF may give links an inertia no body of their mass and size can have: THORMANG3's file gives 38 links
diag(1, 1, 1) kg m^2, its 13 g grippers as its 6.9 kg pelvis, and its trunk then answered its acceleration with 82 mm
of ZMP per rad/s^2 (AgiBot X1's: 16). The dynamics use the file as written; the user is told which links.

A link's RMS mass radius, sqrt(tr I / 2m) (the root mean square distance of its mass from its centre of mass), is at
most its reach, the farthest any of its mass lies from that centre. The reach is known only in part from the file:
the link's joints and its collision and visual boxes, cylinders and spheres (meshes are not read); where those say
less, a link is allowed `UNSEEN_REACH` of the robot's size (the largest distance between two of its joints). An
inertia whose RMS radius is more than `PLACEHOLDER_FACTOR` times that reach, and large enough to matter
(`NEGLIGIBLE_SHARE`), is implausible; every link whose file gives the very inertia tensor of an implausible one
carries the same placeholder (THORMANG3's pelvis and chest: 1 kg m^2 is within what their reach allows, but it is
their grippers' value).

Chosen on the robots on hand (the 64 URDFs of /work/extra_robots, rounds 1-9 and meshed originals, the OP3,
livezmp_mini): THORMANG3 (38 links) and simple_humanoid (30: 1 kg m^2 on links of 0.4 to 27 kg) are told; the
largest ratio among the others' links that matter is 3.3 (DRACO 3's gripper fingers, 0.01 kg m^2 on 25 g), then 3.2
(Bolt's base, iCub 3's wrists), 2.9 (Unitree G1's 12-DOF ankles): values a CAD export or a simulation's stabiliser
may give, not told.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from livezmp.model.urdf_xml import collision_shapes, inertia_matrix, numbers

# an RMS mass radius this many times the link's reach is a placeholder, not a body: THORMANG3's lightest links lie
# 8-4500 times beyond theirs, real robots' links at most 3.3 times (module docstring)
PLACEHOLDER_FACTOR = 4.0
# share of the robot's size (m, largest joint distance) a link's mass may lie from its centre where its file's joints
# and shapes say less: a humanoid's trunk reaches 0.2-0.35 of its size from its centre of mass
UNSEEN_REACH = 0.2
# a largest principal moment below this share of the whole robot's mass x size^2 does not matter to its ZMP (under
# 0.2 mm at 10 rad/s^2 on a 1.2 m robot): iCub's 1 mg base link with 1e-6 kg m^2 is not told
NEGLIGIBLE_SHARE = 1e-4


def _half_extent(shape: ET.Element, where: str) -> np.ndarray:
    """(3,) m: the half sizes of a ``box``, ``cylinder`` (axis z) or ``sphere`` element along its own axes."""
    if shape.tag == "box":
        return np.abs(numbers(shape, "size", 3, "0 0 0", where)) / 2
    radius = abs(numbers(shape, "radius", 1, "0", where)[0])
    half = abs(numbers(shape, "length", 1, "0", where)[0]) / 2 if shape.tag == "cylinder" else radius
    return np.array([radius, radius, half])


def _known_points(root: ET.Element, path: Path) -> dict[str, list[np.ndarray]]:
    """Each link's points the file places (m, the link's frame): its child joints' origins and the corners of its
    collision and visual shapes' bounding boxes."""
    points: dict[str, list[np.ndarray]] = {}
    for joint in root.findall("joint"):
        parent, origin = joint.find("parent"), joint.find("origin")
        if parent is not None and origin is not None:
            where = f"{path}: joint {joint.get('name')!r} <origin>"
            points.setdefault(parent.get("link"), []).append(numbers(origin, "xyz", 3, "0 0 0", where))
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    for element in ("collision", "visual"):
        for link, shape, origin, where in collision_shapes(root, path, ("box", "cylinder", "sphere"), element):
            corners = signs * _half_extent(shape, where)
            points.setdefault(link, []).extend(corners @ origin.rotation.T + origin.translation)
    return points


def placeholder_inertias(root: ET.Element, path: Path, mass: float, size: float) -> list[str]:
    """The names of the links of the URDF ``root`` (its inertials checked: `urdf_body._check_inertial`) whose
    inertia is a placeholder (module docstring), in the file's order; ``mass`` (kg) and ``size`` (m, the largest
    distance between two joints) the whole robot's."""
    points = _known_points(root, path)
    tensors: dict[str, tuple[float, ...]] = {}
    implausible: set[str] = set()
    for link in root.findall("link"):
        inertial, name = link.find("inertial"), link.get("name")
        if inertial is None:  # massless
            continue
        where = f"{path}: link {name!r} <inertial>"
        m = numbers(inertial.find("mass"), "value", 1, "", f"{where} <mass>")[0]
        inertia = inertia_matrix(inertial.find("inertia"), f"{where} <inertia>")
        tensors[name] = tuple(inertia[np.triu_indices(3)].tolist())  # links that share it share the placeholder
        origin = inertial.find("origin")
        com = np.zeros(3) if origin is None else numbers(origin, "xyz", 3, "0 0 0", f"{where} <origin>")
        rms = np.sqrt(max(float(np.trace(inertia)), 0.0) / (2 * m))
        known = [np.zeros(3), *points.get(name, [])]  # its own joint at its frame's origin
        reach = max([UNSEEN_REACH * size] + [float(np.linalg.norm(p - com)) for p in known])
        if rms > PLACEHOLDER_FACTOR * reach and np.linalg.eigvalsh(inertia)[-1] > NEGLIGIBLE_SHARE * mass * size**2:
            implausible.add(name)
    shared = {tensors[name] for name in implausible}
    return [name for name, tensor in tensors.items() if tensor in shared]


def placeholder_note(path: Path, names: list[str]) -> str:
    """The one line that tells the user of ``names``, the links of the URDF at ``path`` whose inertias are
    placeholders."""
    return (f"{path}: {len(names)} link{'s' * (len(names) > 1)} with a placeholder inertia, far beyond what a "
            f"link's mass and size allow (used as written: the ZMP's and the corrector's dynamics may be off): "
            f"{', '.join(names)}")
