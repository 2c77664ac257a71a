"""A foot's sole from its meshes, where its links have no collision box: the footprint of the mesh vertices that
bear on the ground.

Most published humanoids give their feet as meshes only (Fourier GR-Mini's ``left_foot_pitch_link.STL``, K-Scale
Z-Bot2's ``FOOT.stl``): a mesh's size is not in the URDF, and such feet stood on a default box of half the hip
height (GR-Mini's 295 mm for its 170 mm feet). Here the URDF's ``<mesh>`` files are found (`resolve_mesh`), read
by Pinocchio's geometry model (coal's mesh loader: STL, DAE, OBJ ..., the ``scale`` attribute applied), and the
vertices in the foot's frame at the zero posture give the sole (`mesh_sole`): the downward face of their convex
hull with the most area (the sole's plane, within `MAX_TILT` of level), and the hull, on that plane, of the
vertices within `CONTACT_DEPTH` of it, cut to the four of its corners that enclose the most of its area
(`quadrilateral`).

World frame z up, the robot's zero posture, metres.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull, QhullError

from livezmp.balance.support import convex_hull
from livezmp.model.foot_contacts import MAX_TILT, ContactSole, links_on, plane_frame

CONTACT_DEPTH = 0.003  # m: vertices this close to the sole's plane bear on the ground (a tread, a chamfer's start)
SAME_PLANE = np.cos(np.radians(2.0))  # hull facets whose normals lie this close are one face (a curved sole's)

Points = dict[str, list[np.ndarray]]  # link name -> the vertices (k, 3) m of each of its meshes, in its frame


def _search_dirs(urdf: Path) -> list[Path]:
    """The URDF's directory, each directory above it, then ROS_PACKAGE_PATH's (ROS's own search path)."""
    here = urdf.resolve().parent
    ros = [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    return [here, *here.parents, *ros]


def resolve_mesh(filename: str, urdf: Path) -> Path | None:
    """The file a ``<mesh filename>`` of ``urdf`` names, None where none is found. ``package://PKG/REST``:
    PKG/REST, then REST, under the URDF's directory and each above it (a package's root holds its ``urdf/``
    folder; a package may be checked out under another name), then under ROS_PACKAGE_PATH's directories;
    ``file://`` and absolute paths as written; a relative path against the URDF's directory, then each above."""
    if filename.startswith("file://"):
        filename = filename[len("file://"):]
    if filename.startswith("package://"):
        rest = filename[len("package://"):]
        tails = [rest, rest.partition("/")[2]]
    elif Path(filename).is_absolute():
        return Path(filename) if Path(filename).is_file() else None
    else:
        tails = [filename]
    return next((d / t for d in _search_dirs(urdf) for t in tails if t and (d / t).is_file()), None)


# a foot mesh file larger is not read: loading and taking the hull of a 2M-face STL (100 MB) took over 4 min at
# load 12 (200k faces: 8 s); the published feet here are at most 2.4 MB (AgiBot X1's ankle)
MAX_MESH_BYTES = 20_000_000


def _mesh_fault(path: Path, scale: str | None) -> str:
    """Why the mesh file ``path`` with ``<mesh scale>`` ``scale`` is not one the sole can use ("" where it can): a
    file over :data:`MAX_MESH_BYTES`; a scale that is not three finite numbers (``"nan 1 1"``, ``"big"``), whose
    whole ``<collision>`` or ``<visual>`` urdfdom drops without a word to the caller (the foot then stood on the
    default box unsaid)."""
    size = path.stat().st_size
    if size > MAX_MESH_BYTES:
        return f"{size / 1e6:.0f} MB, more than the {MAX_MESH_BYTES / 1e6:.0f} MB a foot mesh is read up to"
    if scale is None:
        return ""
    try:
        values = [float(v) for v in scale.split()]
    except ValueError:
        values = []
    return "" if len(values) == 3 and np.isfinite(values).all() else f"scale {scale!r} is not three finite numbers"


def foot_only_urdf(root: ET.Element, links: set[str], tag: str, urdf: Path) -> tuple[str | None, str]:
    """(the URDF with no geometry but the ``<tag>`` meshes of ``links``, their files' paths resolved
    (`resolve_mesh`); why the first mesh that cannot be used cannot (not found, too large or its scale unusable:
    `_mesh_fault`), else ""). None for the URDF where ``links`` have no such mesh or one cannot be used. ``root``
    is not changed."""
    copy = ET.fromstring(ET.tostring(root))
    found = False
    for link in copy.findall("link"):
        for element in link.findall("collision") + link.findall("visual"):
            mesh = element.find("geometry/mesh")
            if element.tag != tag or link.get("name") not in links or mesh is None:
                link.remove(element)
                continue
            name = mesh.get("filename", "")
            path = resolve_mesh(name, urdf)
            if path is None:
                return None, f"mesh {name!r} not found"
            fault = _mesh_fault(path, mesh.get("scale"))
            if fault:
                return None, f"mesh {name!r}: {fault}"
            mesh.set("filename", str(path))
            found = True
    return (ET.tostring(copy, encoding="unicode") if found else None), ""


def _support_plane(points: np.ndarray) -> tuple[np.ndarray, float] | None:
    """(upward unit normal, offset: n·x = offset on it) of the face of ``points``' convex hull that faces down
    within `MAX_TILT` with the most area, its facets within `SAME_PLANE` and `CONTACT_DEPTH` of each other one
    face; None where the points span no volume or no facet faces down."""
    try:
        hull = ConvexHull(points)
    except (QhullError, ValueError):
        return None
    normals, offsets = hull.equations[:, :3], hull.equations[:, 3]  # outward: n·x + d <= 0 inside
    tri = points[hull.simplices]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    centres = tri.mean(axis=1)
    down = np.flatnonzero(-normals[:, 2] >= np.cos(MAX_TILT))
    if not len(down):
        return None
    face_area = [areas[down][(normals[down] @ normals[i] >= SAME_PLANE)
                             & (np.abs(centres[down] @ normals[i] + offsets[i]) <= CONTACT_DEPTH)].sum()
                 for i in down]
    best = down[int(np.argmax(face_area))]
    return -normals[best], float(offsets[best])


EXACT_CORNERS = 48  # a footprint of more corners is first cut to this many, the smallest triangle first


def quadrilateral(polygon: np.ndarray) -> np.ndarray:
    """The four corners of the convex polygon (k, 2) m, counter-clockwise, that enclose the most of its area (a
    triangle where k = 3): the sole then lies within the footprint. Every diagonal is tried, with the corner
    farthest from it on each side. The simulated foot sensors have one force cell a corner, one per quadrant
    (`sim_devices.launch.humanoid_sensors`). Cutting corners one at a time, the smallest triangle first, kept 82 %
    of TienKung Lite's footprint (a 200 x 100 mm sole with rounded corners), 77 % of GR-Mini's; these, 84 and 82 %."""
    poly = polygon
    while len(poly) > EXACT_CORNERS:
        prev, nxt = np.roll(poly, 1, axis=0), np.roll(poly, -1, axis=0)
        a, b = poly - prev, nxt - prev
        poly = np.delete(poly, int(np.argmin(np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]))), axis=0)
    if len(poly) <= 4:
        return poly
    d = poly[None, :, :] - poly[:, None, :]  # [i, k]: corner k from corner i
    cross = d[:, :, None, 0] * d[:, None, :, 1] - d[:, :, None, 1] * d[:, None, :, 0]  # [i, k, j]: j's side of i-k
    left, right = cross.max(axis=2), (-cross).max(axis=2)
    i, k = np.unravel_index(int(np.argmax(left + right)), left.shape)
    corners = {int(i), int(k), int(np.argmax(cross[i, k])), int(np.argmax(-cross[i, k]))}
    return poly[sorted(corners)]


def mesh_sole(model: pin.Model, data: pin.Data, joints: tuple[int, ...], points: Points) -> ContactSole | None:
    """The sole of the foot on ``joints`` (`box_sole`'s) from the mesh vertices of their links (``points``, `Points`;
    module docstring), or None where they give no face that faces down or no area on it. ``data``: frame placements of
    the zero posture."""
    world = [v @ data.oMf[f].rotation.T + data.oMf[f].translation for f in links_on(model, joints)
             for v in points.get(model.frames[f].name, ())]
    if not world:
        return None
    cloud = np.vstack(world)
    plane = _support_plane(cloud)
    if plane is None:
        return None
    normal, offset = plane
    rotation = plane_frame(normal)
    origin = normal * offset
    on = cloud[cloud @ normal - offset <= CONTACT_DEPTH]
    hull = convex_hull(((on - origin) @ rotation)[:, :2])
    if len(hull) < 3:
        return None
    hull = quadrilateral(hull)
    centre = hull.mean(axis=0)
    placement = pin.SE3(rotation, origin + rotation @ np.array([*centre, 0.0]))
    return ContactSole(placement, np.column_stack([hull - centre, np.zeros(len(hull))]), ())
