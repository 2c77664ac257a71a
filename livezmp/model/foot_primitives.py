"""A foot's sole from its collision cylinders and spheres, where its links have no collision box.

Some humanoids give their feet as primitives: a cylinder lying along the foot (a skate, a rolling edge), balls at
the sole's corners, a disc (a cylinder standing on its end). A rigid primitive touches a level floor where it is
lowest: a sphere at one point, a lying cylinder along a line, a standing one over its end's disc. The sole is
the hull of those contacts at the foot's lowest level (`round_sole`): an area where the contacts span one (four
balls, two cylinders side by side, a disc; cut to four corners as a mesh's footprint is, `quadrilateral`); a strip
where they lie on one line, as wide as the surface within `CONTACT_DEPTH` of the floor (what a mesh of the cylinder
gives, `foot_meshes`); refused where they meet at one point: on two point feet no robot stands still, nothing
holds it fore-aft.

World frame z up, the robot's zero posture, metres.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from livezmp.balance.support import convex_hull
from livezmp.errors import InputError
from livezmp.model.foot_contacts import ON_PLANE, ContactSole, links_on, plane_frame
from livezmp.model.foot_meshes import CONTACT_DEPTH, quadrilateral
from livezmp.model.urdf_xml import collision_shapes, numbers

RIM_POINTS = 32  # points on a cylinder's end circle (a disc sole's polygon before it is cut to four corners)
STANDING = np.cos(np.radians(5.0))  # a cylinder whose axis is this close to vertical stands on its end's disc


@dataclass(frozen=True)
class Round:
    """A ``<collision>`` cylinder (``length`` > 0, its axis its frame's z) or sphere (``length`` 0) of ``radius``
    (m), its centre's placement ``origin`` in its link's frame."""

    radius: float
    length: float
    origin: pin.SE3


Rounds = dict[str, list[Round]]  # link name -> its collision cylinders and spheres


def collision_rounds(root: ET.Element, path: Path) -> Rounds:
    """Each link's ``<collision>`` cylinders and spheres (`Rounds`), as the URDF places them; a cylinder of no size is
    left out, a sphere of radius 0 is a contact point (Drake's Atlas gives its feet eight so)."""
    rounds: Rounds = {}
    for link, shape, origin, where in collision_shapes(root, path, ("cylinder", "sphere")):
        radius = numbers(shape, "radius", 1, "", where)[0]
        length = numbers(shape, "length", 1, "", where)[0] if shape.tag == "cylinder" else 0.0
        if radius < 0 or (shape.tag == "cylinder" and min(radius, length) <= 0):
            continue  # no shape, as a box of no size is left out; a sphere of radius 0 is a contact point
        rounds.setdefault(link, []).append(Round(radius, length, origin))
    return rounds


def _lowest(shape: Round, world: pin.SE3) -> np.ndarray:
    """(k, 3) world points where ``shape`` (its centre's world placement ``world``) would touch a level floor
    beneath it: a sphere's bottom; a cylinder's lower end circle where its axis is within `STANDING` of vertical
    (a disc), else the lowest point of each end circle (a lying cylinder's bottom line ends there; a tilted one
    touches at the lower of them)."""
    centre = world.translation
    if shape.length == 0:
        return (centre - [0.0, 0.0, shape.radius])[None]
    axis = world.rotation[:, 2] * np.sign(world.rotation[2, 2] or 1.0)  # pointing up
    if axis[2] >= STANDING:
        angles = np.linspace(0.0, 2 * np.pi, RIM_POINTS, endpoint=False)
        rim = np.cos(angles)[:, None] * world.rotation[:, 0] + np.sin(angles)[:, None] * world.rotation[:, 1]
        return centre - shape.length / 2 * axis + shape.radius * rim
    down = np.array([0.0, 0.0, -1.0]) + axis[2] * axis  # straight down, laid across the axis
    down *= shape.radius / np.linalg.norm(down)
    return np.array([centre + k * shape.length / 2 * axis + down for k in (-1.0, 1.0)])


def round_sole(model: pin.Model, data: pin.Data, joints: tuple[int, ...], rounds: Rounds, where: str
               ) -> ContactSole | None:
    """The sole of the foot on ``joints`` (`box_sole`'s) from the cylinders and spheres of their links (``rounds``;
    module docstring), level; None where they have none. InputError naming ``where`` (the file and foot) where they
    touch the floor at one point only. ``data``: frame placements of the zero posture."""
    shapes = [(shape, data.oMf[f] * shape.origin) for f in links_on(model, joints)
              for shape in rounds.get(model.frames[f].name, ())]
    if not shapes:
        return None
    lowest = [(shape.radius, _lowest(shape, world)) for shape, world in shapes]
    points = np.vstack([p for _, p in lowest])
    level = points[:, 2].min() + ON_PLANE * float(np.ptp(points, axis=0).max())
    radius = max(r for r, p in lowest if np.any(p[:, 2] <= level))  # of the shapes that touch the floor
    low = points[:, 2] <= level
    contact = points[low]
    hull = convex_hull(contact[:, :2])
    base = float(contact[:, 2].min())
    if len(hull) < 3:
        hull = _strip(hull, radius, where)
    hull = quadrilateral(hull)
    centre = hull.mean(axis=0)
    placement = pin.SE3(plane_frame(np.array([0.0, 0.0, 1.0])), np.array([*centre, base]))
    return ContactSole(placement, np.column_stack([hull - centre, np.zeros(len(hull))]), ())


def _strip(ends: np.ndarray, radius: float, where: str) -> np.ndarray:
    """(4, 2) m: the contacts' hull ``ends`` (k <= 2, 2), a segment, widened across it by the half-width of a
    curved surface of ``radius`` within `CONTACT_DEPTH` of the floor, √(2 r d − d²); InputError where it is one
    point (shorter than twice that depth)."""
    a, b = ends[0], ends[-1]
    length = float(np.linalg.norm(b - a))
    if length < 2 * CONTACT_DEPTH:
        raise InputError(f"{where}: its collision spheres or cylinders touch the floor at one point (a ball foot): on "
                         "two such feet a robot cannot stand still (nothing holds it fore-aft); give a robot config "
                         "with [feet] soles")
    if radius <= 0:
        raise InputError(f"{where}: its collision contact points (spheres of radius 0) lie on one line: on two such "
                         "feet a robot cannot stand still; give a robot config with [feet] soles")
    along = (b - a) / length
    d = min(CONTACT_DEPTH, radius)
    half = math.sqrt(2 * radius * d - d * d) * np.array([-along[1], along[0]])
    return np.array([a - half, b - half, b + half, a + half])
