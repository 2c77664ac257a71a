"""A foot's sole from its contact frames: the leaf links a URDF fixes under a foot (cleats, contact points, toe and
heel frames) that lie on one plane; else from its collision boxes (`box_sole`).

Wolfgang-OP's feet (bit-bots/wolfgang_robot) end in four cleats, the real sole's corners, on a plane turned 15°
from the world's level in the zero posture (its front pair 48 mm higher); the lowest leaf alone, under a level box
sole, is not the foot that stands. Where a foot has three or more such points that span an area, its sole is their
convex hull on their plane, which is its level (`contact_sole`); else the caller keeps its default box.

World frame z up, the robot's zero posture, metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np
import pinocchio as pin

from livezmp.balance.support import clamp_to_polygon, convex_hull

MAX_TILT = np.radians(45.0)  # a sole plane's normal lies within this of the world's up in the zero posture
# a point within this share of the points' span of a plane lies on it: roundoff in CAD exports, not Romeo's sole
# frame, 3.8 mm (2 %) under its force sensors' plane
ON_PLANE = 0.002
MIN_AREA = 0.05  # the points on the plane enclose at least this share of their span squared (not a line)
MAX_POINTS = 16  # a foot's first leaves tried: planes through three of them, (16 choose 3) = 560, once at load


@dataclass(frozen=True)
class ContactSole:
    """A foot's sole from its contact frames, zero posture: ``placement`` the world placement of a frame at the
    sole's centre (its corners' mean) whose z is the sole plane's upward normal and whose x is the world's forward
    (x) laid into the plane; ``corners`` (k, 3) m, the contact points' convex hull in that frame (z = 0); ``names``
    the links on the plane."""

    placement: pin.SE3
    corners: np.ndarray
    names: tuple[str, ...]


def leaf_links(model: pin.Model, joint: int) -> list[int]:
    """Frame ids of the URDF's leaf links (links no other link or joint hangs from) fixed to ``joint``."""
    parents = {model.frames[f].parentFrame for f in range(model.nframes) if model.frames[f].parentFrame != f}
    return [f for f in range(model.nframes) if model.frames[f].type == pin.FrameType.BODY
            and model.frames[f].parentJoint == joint and f not in parents]


def links_on(model: pin.Model, joints: tuple[int, ...]) -> list[int]:
    """Frame ids of the links (body frames) on ``joints`` (Pinocchio joint ids), in frame order: each joint's child
    link and the links fixed to it."""
    return [f for f in range(model.nframes)
            if model.frames[f].type == pin.FrameType.BODY and model.frames[f].parentJoint in joints]


def plane_frame(normal: np.ndarray) -> np.ndarray:
    """Rotation (3, 3) whose z is ``normal`` (unit, world) and whose x is the world's x laid into its plane."""
    x = np.array([1.0, 0.0, 0.0]) - normal[0] * normal
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(normal, x), normal])


def _best_plane(points: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """(upward unit normal, mask of the points on it) of the plane through three of ``points`` that holds the most
    of them (`ON_PLANE`), its normal within `MAX_TILT` of up, its points spanning an area (`MIN_AREA`); the lowest
    of equals. None where no plane holds three."""
    span = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    best = None
    for i, j, k in combinations(range(len(points)), 3):
        n = np.cross(points[j] - points[i], points[k] - points[i])
        if span <= 0 or np.linalg.norm(n) < MIN_AREA * span**2:
            continue
        n = n / np.linalg.norm(n) * np.sign(n[2] or 1.0)
        if n[2] < np.cos(MAX_TILT):
            continue
        on = np.abs((points - points[i]) @ n) <= ON_PLANE * span
        key = (int(on.sum()), -float(points[on, 2].mean()))
        if best is None or key > best[0]:
            best = key, n, on
    return None if best is None else (best[1], best[2])


def contact_sole(model: pin.Model, data: pin.Data, joint: int) -> ContactSole | None:
    """The sole of the foot on ``joint`` from its leaf links (module docstring), or None where fewer than three
    of them lie on a plane near level (one leaf; a toe and a heel frame). The sole lies as low as the lowest of
    the leaves over its area: a sole frame a few millimetres below the cleats' or force sensors' own frames
    (Wolfgang-OP's ``l_sole``, 4.9 mm; Romeo's, 3.8 mm below its FSRs) is where the designer put the ground.
    ``data``: frame placements of the zero posture."""
    leaves = leaf_links(model, joint)[:MAX_POINTS]
    if len(leaves) < 3:
        return None
    points = np.array([data.oMf[f].translation for f in leaves])
    plane = _best_plane(points)
    if plane is None:
        return None
    normal, on = plane
    rotation = plane_frame(normal)
    local = (points - points[on][0]) @ rotation
    hull = convex_hull(local[on, :2])
    if len(hull) < 3:
        return None
    tol = ON_PLANE * float(np.ptp(hull, axis=0).max())
    low = min(0.0, *(p[2] for p in local if clamp_to_polygon(p[:2], hull).margin >= -tol))
    centre = np.array([*hull.mean(axis=0), low])
    placement = pin.SE3(rotation, points[on][0] + rotation @ centre)
    corners = np.column_stack([hull - centre[:2], np.zeros(len(hull))])
    return ContactSole(placement, corners, tuple(model.frames[f].name for f, o in zip(leaves, on, strict=True) if o))


FACES = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0],
                  [0.0, 0.0, -1.0]])  # a box's faces by their outward normals, in its own frame


def _lowest_face(size: np.ndarray, world: pin.SE3) -> tuple[float, np.ndarray, np.ndarray] | None:
    """(height of its centre, upward unit normal, corners (4, 3) world) of the face of a box (``size`` (3,) m, its
    centre's world placement ``world``) that faces down within `MAX_TILT` of straight down; None without one."""
    for normal in FACES:
        out = world.rotation @ normal
        if -out[2] < np.cos(MAX_TILT):
            continue
        k = int(np.flatnonzero(normal)[0])
        u, v = (np.eye(3)[i] * size[i] / 2 for i in range(3) if i != k)
        centre = world.act(normal * size[k] / 2)
        corners = np.array([centre + world.rotation @ (a * u + b * v) for a, b in ((1, 1), (1, -1), (-1, -1), (-1, 1))])
        return float(centre[2]), -out, corners
    return None


def box_sole(model: pin.Model, data: pin.Data, joints: tuple[int, ...],
             boxes: dict[str, list[tuple[np.ndarray, pin.SE3]]]) -> ContactSole | None:
    """The sole of the foot on ``joints`` (its own joint, and its ankle's where they carry its geometry) from the
    collision boxes of their links (``boxes``: link name -> (size (3,)
    m, the box's centre in the link's frame) per ``<collision>`` box): the face of them that faces down, within
    `MAX_TILT`, lowest (Bez2's foot box, 17 x 9 cm; Valkyrie's, 27 x 16 cm; a heel's box above a sole's is not
    the sole), on its own plane, with every other such face on that plane (`ON_PLANE`): the sole is their convex
    hull (ergoCub's foot is a front and a rear link, a 117 x 100 mm box under each, on one plane: one alone is half
    its 237 mm sole). None where the foot's links have no box (a mesh's size is not in the URDF; the caller keeps
    its default box). ``data``: frame placements of the zero posture."""
    faces = [face for f in links_on(model, joints)
             for size, origin in boxes.get(model.frames[f].name, ())
             if (face := _lowest_face(size, data.oMf[f] * origin)) is not None]
    if not faces:
        return None
    _, normal, lowest = min(faces, key=lambda face: face[0])
    span = float(np.ptp(np.vstack([c for _, _, c in faces]), axis=0).max())
    corners = np.vstack([c for _, _, c in faces if np.all(np.abs((c - lowest[0]) @ normal) <= ON_PLANE * span)])
    rotation = plane_frame(normal)
    hull = convex_hull(((corners - lowest.mean(axis=0)) @ rotation)[:, :2])
    centre = hull.mean(axis=0)
    placement = pin.SE3(rotation, lowest.mean(axis=0) + rotation @ np.array([*centre, 0.0]))
    return ContactSole(placement, np.column_stack([hull - centre, np.zeros(len(hull))]), ())
