"""Body model of a URDF robot on Pinocchio: a six-joint floating base, then the URDF.

Masses and inertias come from the URDF's ``<inertial>`` tags. Feet and soles come from
the robot config (:mod:`livezmp.model.robot_config`); without one, the feet are the two
lowest leaf links in the zero pose (left = +y), level and side by side at the ends of two
legs; a foot whose leaf links include three or more on one plane near level (cleats, contact
points, force sensors: :mod:`livezmp.model.foot_contacts`) has their hull for its sole and
their plane for its level, else a foot whose links have ``<collision>`` boxes stands on the
lowest face of them that faces down (`box_sole`), else one whose links have collision cylinders or spheres on
where they touch the floor (:mod:`livezmp.model.foot_primitives`; refused where that is one point), else one whose
links have meshes (``<collision>``, else
``<visual>``; found beside the URDF or above it: :mod:`livezmp.model.foot_meshes`) on the footprint of their
vertices on the ground (`mesh_sole`; a mesh not found or unreadable is warned of in one line), else its sole is a
level box under the link's centre of mass: ``sole_length`` × ``sole_width``, ``sole_drop`` below the link origin
(given, they are the sole: no collision box or mesh is looked at), by default 0.5 × / 0.28 × / 0.12 × the
hip-to-foot height, its inner edge no further in than the mid-line between the feet. A leg
is the joints from the trunk to a foot that the other foot's chain does not share (a waist
above the legs is the trunk's). Continuous joints, and revolute ones without a ``<limit>`` or
with lower = upper, are revolute joints without bounds; a mimic joint keeps its own angle in
the model and follows its parent's (``BodyModel.mimics``, :mod:`livezmp.model.mimic`); a link
named as a joint is renamed ``<name>_link``; a floating joint from a massless root link is the file's free base
(`_fix_free_base`), any other floating joint is refused. A foot link without ``<collision>`` takes its geometry from
the links between its ankle's joints (`_foot_joints`); a file that stands the robot on its head or lays it down has it
turned onto its feet (`_upright_feet`).
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from livezmp.checks import read_input_text
from livezmp.errors import InputError
from livezmp.model.body import BodyModel, CorrectionJoints, Foot, point_mass_copy
from livezmp.model.foot_contacts import ContactSole, box_sole, contact_sole, links_on
from livezmp.model.foot_meshes import Points, foot_only_urdf, mesh_sole
from livezmp.model.foot_primitives import collision_rounds, round_sole
from livezmp.model.mimic import Mimic, read_mimics
from livezmp.model.placeholder_inertia import placeholder_inertias, placeholder_note
from livezmp.model.robot_config import MAX_SOLE_M, RobotConfig, find_robot_config, load_robot_config
from livezmp.model.urdf_xml import INERTIA_KEYS, collision_shapes, inertia_matrix, numbers

MAX_LINKS = 256  # as MAX_CHANNELS for a BVH skeleton: the model data grows as the cube of the joints
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


MAX_LINK_MASS = 1e4  # kg: heavier than any humanoid's link
MAX_LENGTH = 1e3  # m: joint origins and centres of mass
ROUNDOFF = 1e-9  # a principal moment this far below zero (relative: `_check_inertial`) is a zero written in decimals
# kg m^2 per kg m^2 of the whole robot (mass x size^2): a link's principal moment this far below zero or less is
# taken as zero, its inertia as the nearest positive semi-definite one. Its ZMP answer at 100 rad/s^2 is under
# 1e-6 s^2 100 / g (0.03 mm on a 1.6 m robot): HRP-4C's 13 g wrists are written -7e-08 kg m^2 (a CAD export's
# rounding of a tiny link), and refusing the robot for them would serve no one
NEGLIGIBLE_INERTIA = 1e-6


def _check_inertial(link: ET.Element, path: Path) -> tuple[float, np.ndarray]:
    """Mass finite and >= 0, centre of mass finite, inertia finite and positive semi-definite: what the
    ZMP's dynamics need. An inertia below positive semi-definite by more than roundoff is written back as the
    nearest one (its negative principal moments zeroed) and returned for `_check_deficits`, which refuses it
    unless it is negligible for the whole robot. Principal moments that break the triangle inequality (one
    larger than the sum of the other two: no rigid body has them) are used as written: CAD exports give them to
    published robots (Darwin-OP's neck, Romeo's shoulder, iCub's 1 mg base link) and a monitor that refused the
    robot for one link's inertia would serve no one.
    A mass of 0 makes the link massless (a frame, a sensor's placeholder, as real URDFs write
    them): its ``<inertial>`` is removed, whatever inertia it gives (no massless body has one).
    Zero principal moments are a point mass or a thin rod (a sensor link of 0.01 kg written
    with a zero inertia): the limits of rigid bodies, accepted. Returns the largest principal moment (kg m^2; 0
    for a massless link), for `_check_sizes`, and the principal moments as written where they were not positive
    semi-definite (else empty)."""
    where = f"{path}: link {link.get('name')!r} <inertial>"
    inertial = link.find("inertial")
    none = np.zeros(0)
    if inertial is None:
        return 0.0, none
    mass_el, inertia_el, origin = inertial.find("mass"), inertial.find("inertia"), inertial.find("origin")
    if mass_el is None or inertia_el is None:
        raise InputError(f"{where}: needs <mass> and <inertia>")
    mass = numbers(mass_el, "value", 1, "", f"{where} <mass>")[0]
    if mass == 0:
        link.remove(inertial)
        return 0.0, none
    if not 0 < mass <= MAX_LINK_MASS:
        raise InputError(f"{where} <mass> value: {mass:g} kg is outside [0, {MAX_LINK_MASS:g}]")
    if origin is not None:
        for attr in ("xyz", "rpy"):
            v = numbers(origin, attr, 3, "0 0 0", f"{where} <origin>")
            if np.abs(v).max() > MAX_LENGTH:
                raise InputError(f"{where} <origin> {attr}: beyond ±{MAX_LENGTH:g}")
    inertia = inertia_matrix(inertia_el, f"{where} <inertia>")
    moments, axes = np.linalg.eigh(inertia)
    if moments[0] >= -ROUNDOFF * max(float(np.abs(moments).max()), mass * 1.0):  # kg m^2: the mass 1 m out
        return float(moments[2]), none
    nearest = axes @ np.diag(np.maximum(moments, 0.0)) @ axes.T
    for k, v in zip(INERTIA_KEYS, nearest[np.triu_indices(3)], strict=True):
        inertia_el.set(k, repr(float(v)))
    return float(moments[2]), moments


def _check_deficits(written: dict[str, np.ndarray], mass: float, size: float, path: Path) -> None:
    """Refuse a link whose inertia as written (``written``: principal moments, kg m^2, by link name; those not
    positive semi-definite) falls below zero by more than ``NEGLIGIBLE_INERTIA`` x the robot's ``mass`` (kg) x
    ``size``^2 (m); warn once of the others, taken as their nearest positive semi-definite inertia."""
    if not written:
        return
    scale = NEGLIGIBLE_INERTIA * mass * size**2
    for name, moments in written.items():
        if -moments[0] > scale:
            raise InputError(f"{path}: link {name!r} <inertial> <inertia>: not positive semi-definite (principal "
                             f"moments {', '.join(f'{m:.3g}' for m in moments)} kg m^2)")
    worst = min(m[0] for m in written.values())
    warnings.warn(f"{path}: link{'s' * (len(written) > 1)} {', '.join(map(repr, written))} <inertia>: principal "
                  f"moments down to {worst:.2g} kg m^2, negligible for a {mass:.3g} kg robot {size:.2f} m across: "
                  f"taken as the nearest positive semi-definite inertia", UserWarning, stacklevel=3)


def _robot_size(model: pin.Model) -> float:
    """m: the largest distance between two of the robot's joints in its zero pose."""
    data = model.createData()
    pin.forwardKinematics(model, data, np.zeros(model.nq))
    points = np.array([data.oMi[j].translation for j in range(model.njoints)])
    return float(np.linalg.norm(points[:, None] - points[None], axis=2).max())


def _check_sizes(mass: float, size: float, moments: dict[str, float], path: Path) -> None:
    """No link's largest principal moment (``moments``, kg m^2 by link name) above what the whole robot's mass
    (``mass``, kg) could have at its size (all of it at the largest distance between two of its joints, zero
    pose): no link of the robot can have it (Darwin-OP's file gives its 1 kg body 6.5 kg m^2, 9 times the whole
    robot's most, and its ZMP then moved by metres; a unit error). InputError naming the link."""
    name, moment = max(moments.items(), key=lambda item: item[1])
    if size > 0 and moment > mass * size**2:  # 0: a single link, no size to judge by
        raise InputError(f"{path}: link {name!r} <inertia>: a principal moment of {moment:.3g} kg m^2, more than "
                         f"the whole robot ({mass:.3g} kg, {size:.2f} m across its joints) could have "
                         f"({mass * size**2:.2g}): not a link of it (units?)")


def _check_tree(root: ET.Element, path: Path) -> None:
    """Names unique, every joint between two existing links, every link but one (the root) the child of
    exactly one joint, and no loop: a tree, as a URDF must be."""
    links = [link.get("name") for link in root.findall("link")]
    joints = [j.get("name") for j in root.findall("joint")]
    for what, names in (("link", links), ("joint", joints)):
        seen = set()
        for name in names:
            if not name:
                raise InputError(f"{path}: a <{what}> without a name")
            if name in seen:
                raise InputError(f"{path}: {what} name {name!r} is used twice")
            seen.add(name)
    parent_of: dict[str, str] = {}
    link_set = set(links)
    for j in root.findall("joint"):
        ends = []
        for end in ("parent", "child"):
            el = j.find(end)
            link = el.get("link") if el is not None else None
            if link not in link_set:
                raise InputError(f"{path}: joint {j.get('name')!r} <{end}>: no link {link!r} in the file")
            ends.append(link)
        if ends[1] in parent_of:
            raise InputError(f"{path}: link {ends[1]!r} is the child of two joints (a kinematic loop; a URDF is a "
                             "tree)")
        parent_of[ends[1]] = ends[0]
    for link in links:
        seen, up = set(), link
        while up in parent_of:
            if up in seen:
                raise InputError(f"{path}: link {up!r} is its own ancestor (a kinematic loop; a URDF is a tree)")
            seen.add(up)
            up = parent_of[up]
    roots = [name for name in links if name not in parent_of]
    if len(roots) != 1:
        raise InputError(f"{path}: {len(roots)} root links ({', '.join(map(repr, roots[:4]))}); a URDF is one "
                         "tree (give every link but one a parent joint)")


JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed")
UNBOUNDED = '<limit lower="-1" upper="1" effort="0" velocity="0"/>'  # placeholder, made ±inf once built


def _has_range(joint: ET.Element, where: str) -> bool:
    """Whether a joint's ``<limit>`` gives it a range: lower and upper differ. Lower equal to upper (both 0, or left
    out: the URDF's default) is how CAD exports write a joint whose limits nobody set (Z-Bot2's file, every one of
    its 18 joints; raisim ignores such a limit): taken as absent, not as a joint locked at one angle (a locked
    joint is a fixed one)."""
    limit = joint.find("limit")
    if limit is None:
        return False
    lower = numbers(limit, "lower", 1, "0", f"{where} <limit>")[0]
    upper = numbers(limit, "upper", 1, "0", f"{where} <limit>")[0]
    if lower > upper:  # no angle satisfies it: every reading would be refused, every goal clipped to one end
        raise InputError(f"{where} <limit>: lower {lower:g} is above upper {upper:g}")
    return bool(lower != upper)


def _fix_free_base(root: ET.Element) -> None:
    """Make fixed a floating joint from the root link where that link is massless (no ``<inertial>``: a mass of 0
    is none by then, `_check_inertial`) and the floating joint its only child: the file's way of saying the robot's
    base is free (HighTorque's Hi: ``<link name="world"/>``, as MuJoCo conversions write it), which every robot here
    is on its six base joints (`BASE_JOINTS`); its ``<origin>`` still places the robot on them, as a fixed base
    joint's does. Any other floating joint is refused (`JOINT_TYPES`)."""
    children = {j.find("child").get("link") for j in root.findall("joint")}
    masses = {link.get("name"): link.find("inertial") is not None for link in root.findall("link")}
    base = [name for name in masses if name not in children]
    from_base = [j for j in root.findall("joint") if base and j.find("parent").get("link") == base[0]]
    if len(from_base) == 1 and from_base[0].get("type") == "floating" and not masses[base[0]]:
        from_base[0].set("type", "fixed")


def _check_joints(root: ET.Element, path: Path) -> list[str]:
    """Check every joint; turn continuous joints, and revolute ones without a <limit> or whose limit gives no range
    (`_has_range`), into revolute joints
    without bounds (one angle each, as a servo reports it; the URDF parser needs a limit on a revolute joint);
    rename links named as a joint (Pinocchio needs frame names unique). Returns the unbounded joints' names."""
    _check_tree(root, path)
    _fix_free_base(root)
    unbounded = []
    joint_names = {j.get("name") for j in root.findall("joint")}
    for j in root.findall("joint"):
        where = f"{path}: joint {j.get('name')!r}"
        if j.get("type") not in JOINT_TYPES:
            raise InputError(f"{where}: type {j.get('type')!r} not supported ({', '.join(JOINT_TYPES)})")
        origin = j.find("origin")
        if origin is not None:
            for attr in ("xyz", "rpy"):
                if np.abs(numbers(origin, attr, 3, "0 0 0", f"{where} <origin>")).max() > MAX_LENGTH:
                    raise InputError(f"{where} <origin> {attr}: beyond ±{MAX_LENGTH:g}")
        axis = j.find("axis") if j.get("type") != "fixed" else None  # a fixed one means nothing: files give 0 0 0
        if axis is not None and not np.any(numbers(axis, "xyz", 3, "1 0 0", f"{where} <axis>")):
            raise InputError(f"{where} <axis>: zero vector")
        if j.get("type") == "continuous" or (j.get("type") == "revolute" and not _has_range(j, where)):
            j.set("type", "revolute")
            for limit in j.findall("limit"):
                j.remove(limit)
            j.append(ET.fromstring(UNBOUNDED))
            unbounded.append(j.get("name"))
    links = {link.get("name") for link in root.findall("link")}
    for link in root.findall("link"):
        name = link.get("name")
        if name in joint_names:
            new = next(f"{name}_link{k or ''}" for k in range(len(links) + 1)
                       if f"{name}_link{k or ''}" not in links | joint_names)
            links.add(new)
            link.set("name", new)
            for ref in root.iter():
                if ref.tag in ("parent", "child") and ref.get("link") == name:
                    ref.set("link", new)
    return unbounded


@contextlib.contextmanager
def _quiet_stderr():
    """Silence the C++ URDF parser's console output (urdfdom writes warnings to fd 2):
    a refused URDF gets our one-line message only."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


Boxes = dict[str, list[tuple[np.ndarray, pin.SE3]]]  # link name -> (size (3,) m, centre in the link's frame)


def _collision_boxes(root: ET.Element, path: Path) -> Boxes:
    """Each link's ``<collision>`` boxes (`Boxes`); a box of a size not three positive numbers is left out."""
    boxes: Boxes = {}
    for link, box, origin, where in collision_shapes(root, path, ("box",)):
        size = numbers(box, "size", 3, "0 0 0", where)
        if np.all(size > 0):
            boxes.setdefault(link, []).append((size, origin))
    return boxes


def _load_fixed(path: Path) -> tuple[pin.Model, dict[str, tuple[str, float, float]], Boxes, ET.Element, list[str]]:
    """The URDF's model without a base, its mimics (`read_mimics`), its links' collision boxes, its XML as the
    model was built from it (links renamed, a free base fixed) and the links whose inertias are placeholders
    (`placeholder_inertias`, told in one warning)."""
    text = read_input_text(path, "URDF")
    try:
        root = ET.fromstring(text)
    except ET.ParseError as e:
        raise InputError(f"{path}: cannot read URDF: {e}") from None
    if root.tag != "robot":
        raise InputError(f"{path}: not a URDF (root element <{root.tag}>)")
    links = root.findall("link")
    if len(links) > MAX_LINKS:
        raise InputError(f"{path}: {len(links)} links, more than the {MAX_LINKS} this tool analyses")
    checked = {link.get("name"): _check_inertial(link, path) for link in links}
    moments = {name: largest for name, (largest, _) in checked.items()}
    if root.find("./link/inertial") is None:
        raise InputError(f"{path}: URDF has no <inertial> with a mass on any link; masses are needed for the ZMP")
    unbounded = _check_joints(root, path)
    mimics = read_mimics(root, path)
    try:
        with _quiet_stderr():
            model = pin.buildModelFromXML(ET.tostring(root, encoding="unicode"))
    except (RuntimeError, ValueError) as e:
        first = str(e).splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(f"{path}: Pinocchio cannot load it: {first}") from None
    mass = sum(float(m.get("value")) for m in root.findall("./link/inertial/mass"))
    size = _robot_size(model)
    _check_deficits({name: w for name, (_, w) in checked.items() if len(w)}, mass, size, path)
    _check_sizes(mass, size, moments, path)
    placeholders = placeholder_inertias(root, path, mass, size)
    if placeholders:
        warnings.warn(placeholder_note(path, placeholders), UserWarning, stacklevel=3)
    for name in unbounded:
        k = model.joints[model.getJointId(name)].idx_q
        model.lowerPositionLimit[k], model.upperPositionLimit[k] = -np.inf, np.inf
    return model, mimics, _collision_boxes(root, path), root, placeholders


def _mesh_points(root: ET.Element, fixed: pin.Model, links: set[str], path: Path) -> tuple[Points, str]:
    """The mesh vertices of ``links`` (`Points`) read by Pinocchio's geometry model (coal's loader; a mesh's
    ``scale`` applied): their ``<collision>`` meshes, else, where those are absent, not found or unreadable, their
    ``<visual>`` ones; and where neither loads, why not (one line naming the file; "" where the links have no mesh).
    ``root``, ``fixed``: `_load_fixed`'s."""
    why = ""
    for tag, kind in (("collision", pin.GeometryType.COLLISION), ("visual", pin.GeometryType.VISUAL)):
        xml, unusable = foot_only_urdf(root, links, tag, path)
        why = why or unusable
        if xml is None:
            continue
        try:
            with _quiet_stderr():
                geometry = pin.buildGeomFromUrdfString(fixed, xml, kind)
        except (RuntimeError, ValueError) as e:
            why = why or f"cannot read a mesh of {sorted(links)[0]!r}: {str(e).strip().splitlines()[-1]}"
            continue
        points: Points = {}
        for g in geometry.geometryObjects:
            frame = fixed.frames[g.parentFrame]
            local = frame.placement.actInv(g.placement)  # the mesh in its link's frame
            points.setdefault(frame.name, []).append(np.asarray(g.geometry.vertices()) @ local.rotation.T
                                                      + local.translation)
        return points, ""
    return {}, why


def _link_names_on(model: pin.Model, joints: tuple[int, ...]) -> set[str]:
    """Names of the links on ``joints`` (`links_on`)."""
    return {model.frames[f].name for f in links_on(model, joints)}


def _foot_joints(model: pin.Model, data: pin.Data, joint: int, collided: set[str]) -> tuple[int, ...]:
    """The joints whose links give the foot on ``joint`` its sole: its own; where none of its links has a
    ``<collision>`` (``collided``: the names of the links that have one), also the joints above it that meet it at
    the ankle, their origins within `ANKLE_M` of its own in the zero posture (``data``): Fourier GR3's file gives its
    right foot's two collision cylinders to the 59 g link between its ankle's pitch and roll joints (one point),
    its left foot's to the foot link, and its right foot stood on the default box, 34 mm lower than the left's
    cylinders: its left sole stayed 3 mm off the floor, and every scenario fell at 0.2 s, uncorrected or not."""
    if _link_names_on(model, (joint,)) & collided:
        return (joint,)
    out, j = [joint], model.parents[joint]
    while j > len(BASE_JOINTS) and np.linalg.norm(data.oMi[j].translation - data.oMi[joint].translation) <= ANKLE_M:
        out.append(j)
        j = model.parents[j]
    return tuple(out)


def _sole_of_meshes(model: pin.Model, data: pin.Data, joints: tuple[int, ...], root: ET.Element, fixed: pin.Model,
                    path: Path) -> tuple[ContactSole | None, str]:
    """(`mesh_sole` of the meshes of the links on ``joints`` (`_foot_joints`), `_mesh_points`; where there is none
    though the links have meshes, why not, else "")."""
    points, why = _mesh_points(root, fixed, _link_names_on(model, joints), path)
    sole = mesh_sole(model, data, joints, points)
    across = float(np.ptp(sole.corners[:, :2], axis=0).max()) if sole is not None else 0.0
    if across > MAX_SOLE_M:  # as a config's box: a mesh in mm read as m stood the robot on 1000-times feet
        return None, f"its meshes' footprint is {across:.3g} m across, more than a sole's {MAX_SOLE_M:g} m"
    return sole, ("" if sole is not None or not (why or points) else why or "its meshes have no face that faces down")


def _with_base(fixed: pin.Model, yaw: float = 0.0, tilt: tuple[float, float] = (0.0, 0.0)) -> pin.Model:
    """The URDF's model on the six base joints, turned by ``yaw`` (rad, about z) on the base (`_heading`), after
    the turn ``tilt`` (roll about x, then pitch about y, rad) that stands it on its feet (`_upright_feet`)."""
    base = pin.Model()
    j = 0
    for name, jm in BASE_JOINTS:
        j = base.addJoint(j, jm(), pin.SE3.Identity(), name)
    f = base.addFrame(pin.Frame("base_attach", j, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    turn = pin.rpy.rpyToMatrix(tilt[0], tilt[1], 0.0)
    model = pin.appendModel(base, fixed, f, pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw) @ turn, np.zeros(3)))
    model.name = fixed.name
    return model


def _posed(fixed: pin.Model, yaw: float = 0.0, tilt: tuple[float, float] = (0.0, 0.0)) -> tuple[pin.Model, pin.Data]:
    """`_with_base`'s model and its data with the zero posture's frame placements."""
    model = _with_base(fixed, yaw, tilt)
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(model.nq))
    return model, data


# (roll, pitch) rad: the robot as its file stands it, on its head, lying along +x or -x (its legs pointing there), along
# +y or -y; the first of them on whose feet it stands is taken (`_upright_feet`)
TILTS = ((0.0, 0.0), (np.pi, 0.0), (0.0, np.pi / 2), (0.0, -np.pi / 2), (-np.pi / 2, 0.0), (np.pi / 2, 0.0))
HANGING = np.cos(np.radians(45.0))  # legs hang when the hips-to-feet line is within 45 deg of straight down


def _legs_hang(model: pin.Model, data: pin.Data, feet: dict[str, int]) -> bool:
    """Whether the line from the hips (each leg's first joint, `leg_joints`) to the feet points down, within `HANGING`,
    in the zero posture (``data``)."""
    hips = [data.oMi[chain[0]].translation for chain in leg_joints(model, feet).values() if chain]
    if not hips:
        return False
    down = np.mean([data.oMf[f].translation for f in feet.values()], axis=0) - np.mean(hips, axis=0)
    return -down[2] >= HANGING * float(np.linalg.norm(down)) > 0.0


def _upright_feet(fixed: pin.Model, cfg: RobotConfig, path: Path
                  ) -> tuple[pin.Model, pin.Data, dict[str, int], tuple[float, float]]:
    """The model on its base (`_posed`), its feet (`_feet`) and the turn (`TILTS`) that stood it on them. A file
    may stand the robot on its head (K-Scale's GPR: its feet 0.6 m above its hips in the zero pose, "no two feet")
    or lay it down (WATonomous' humanoid V1: its legs along +x, its hips and feet all at one height, its default soles
    1 mm long, every scenario refused): the first turn in which two feet are found and the legs hang from the hips
    to them is taken; where the legs hang in none, the first in which two feet are found; where none are found,
    the upright robot's refusal stands."""
    found, refusal = None, None
    for tilt in TILTS:
        model, data = _posed(fixed, tilt=tilt)
        try:
            feet = _feet(model, data, cfg, path)
        except InputError as e:
            refusal = refusal or e
            continue
        if _legs_hang(model, data, feet):
            return model, data, feet, tilt
        found = found or (model, data, feet, tilt)
    if found is None:
        raise refusal
    return found


def _chain(model: pin.Model, frame_id: int) -> list[int]:
    """Actuated joint ids from the base to the frame's joint (excluding the base joints)."""
    out = []
    j = model.frames[frame_id].parentJoint
    while j > len(BASE_JOINTS):
        out.append(j)
        j = model.parents[j]
    return out[::-1]


def leg_joints(model: pin.Model, feet: dict[str, int]) -> dict[str, list[int]]:
    """Each foot's leg (``feet``: side -> frame id): the actuated joint ids from the trunk to it that the other
    foot's chain does not share (a waist above both legs is the trunk's, not a leg's), top first."""
    chains = {side: _chain(model, f) for side, f in feet.items()}
    shared = set.intersection(*(set(c) for c in chains.values())) if len(chains) > 1 else set()
    return {side: [j for j in chain if j not in shared] for side, chain in chains.items()}


ANKLE_M = 0.01  # m: joints whose origins lie this near a foot's own joint's meet it at its ankle (`_foot_joints`)
FEET_LEVEL = 0.05  # a pair of feet differ in height by at most this share of the legs' length in the zero pose


def _default_feet(model: pin.Model, data: pin.Data, path: Path) -> dict[str, int]:
    """The lowest leaf link on a body with mass in the zero pose, and the lowest on another limb (a leaf whose
    chain parts from the first's: a foot's sole, sensor and end-effector frames, JVRC-1's and XBot-L's, are one
    foot; a foot bears weight: NimbRo-OP2X's massless copy of each leg, its parallel linkage, is none); left has
    the larger y. They must be level (`FEET_LEVEL`), side by side and each at the end of its own leg: else this is
    not a two-legged robot standing in its zero pose (a one-legged robot's lowest leaves are its foot and a
    hand)."""
    children = {j: 0 for j in range(model.njoints)}
    for j in range(1, model.njoints):
        children[model.parents[j]] += 1
    leaves = [f for f in range(model.nframes)
              if model.frames[f].type == pin.FrameType.BODY and children[model.frames[f].parentJoint] == 0
              and model.frames[f].parentJoint > len(BASE_JOINTS)
              and model.inertias[model.frames[f].parentJoint].mass > 0]
    if len(leaves) < 2:
        raise InputError(f"{path}: cannot find two feet (leaf links); give a robot config with [feet]")
    leaves.sort(key=lambda f: data.oMf[f].translation[2])
    a = leaves[0]
    b = next((f for f in leaves[1:] if all(leg_joints(model, {"a": a, "b": f}).values())), leaves[1])
    if data.oMf[a].translation[1] < data.oMf[b].translation[1]:
        a, b = b, a
    pa, pb = data.oMf[a].translation, data.oMf[b].translation
    legs = leg_joints(model, {"left": a, "right": b})
    top = min((data.oMi[c[0]].translation[2] for c in legs.values() if c), default=max(pa[2], pb[2]))
    length = top - min(pa[2], pb[2])
    names = f"{model.frames[a].name!r} and {model.frames[b].name!r}"
    if not all(legs.values()) or length <= 0 or abs(pa[2] - pb[2]) > FEET_LEVEL * length:
        raise InputError(f"{path}: no two feet: its lowest leaf links {names} are not level at the ends of two legs "
                         "in the zero pose; give a robot config with [feet]")
    return {"left": a, "right": b}


ALIGNED = 0.99  # |cos| between a joint's axis and a direction for the joint to turn about it
TILTED = 0.69  # |cos|: a leg's hip pitch may turn up to 46° off the lateral axis (H2's, GR2's 30°; AgiBot X1's 45°)
STANCE_FLEXION = 0.3  # rad: the scenarios' standing posture bends hip, knee, ankle by -1, +2, -1 times this


def _stance_fits(model: pin.Model, data: pin.Data, feet: dict[str, int], forward: np.ndarray) -> int:
    """How many legs can take the scenarios' knees-bent stance within their joints' limits, the robot facing
    ``forward``: hip, knee and ankle pitch (of a leg's joints turning about the lateral axis, the first, the
    one nearest mid-height between the first and the last, and the last) turned by −1, +2 and −1 times
    `STANCE_FLEXION` about the robot's left (a knee flexes so its foot goes back)."""
    left = np.cross([0.0, 0.0, 1.0], forward)
    pin.computeJointJacobians(model, data, np.zeros(model.nq))
    fits = 0
    for chain in leg_joints(model, feet).values():
        along = {j: float(data.J[3:, model.joints[j].idx_v] @ left) for j in chain}
        pitch = [j for j in chain if abs(along[j]) >= ALIGNED]
        if len(pitch) < 3:
            continue
        middle = 0.5 * (data.oMi[pitch[0]].translation[2] + data.oMi[pitch[-1]].translation[2])
        knee = min(pitch[1:-1], key=lambda j: abs(data.oMi[j].translation[2] - middle))
        turns = ((pitch[0], -1.0), (knee, 2.0), (pitch[-1], -1.0))
        angles = [(model.joints[j].idx_q, k * STANCE_FLEXION / along[j]) for j, k in turns]
        fits += all(model.lowerPositionLimit[i] <= q <= model.upperPositionLimit[i] for i, q in angles)
    return fits


TOES_AHEAD = 0.02  # share of the legs' height a foot's centre of mass lies ahead of its ankle to tell which way


def _toes_ahead(model: pin.Model, data: pin.Data, feet: dict[str, int], forward: np.ndarray) -> float:
    """How far the feet's centres of mass lie ahead (along ``forward``) of their legs' last joints, on average,
    as a share of the legs' height (hip to foot) in the zero pose."""
    ahead, height = [], []
    for side, chain in leg_joints(model, feet).items():
        if not chain:
            return 0.0
        j = model.frames[feet[side]].parentJoint
        ahead.append(float((data.oMi[j].act(model.inertias[j].lever) - data.oMi[chain[-1]].translation) @ forward))
        height.append(float(data.oMi[chain[0]].translation[2] - data.oMf[feet[side]].translation[2]))
    return float(np.mean(ahead) / np.mean(height)) if np.mean(height) > 0 else 0.0


def _heading(model: pin.Model, data: pin.Data, feet: dict[str, int], sided: bool) -> float:
    """The yaw (rad, a multiple of 90°) that turns the robot to face +x, where its URDF faces another way (Poppy
    faces −y, iCub −x): its forward axis is the lateral one (right foot to left) turned 90° clockwise seen from
    above; where the feet's sides are not ``sided`` (a config names them; else they are the lowest leaves, left
    the one at larger y) and more legs take the knees-bent stance within their limits facing the other way
    (`_stance_fits`: iCub's knees flex only one way, the Gepetto simple humanoid's ankles too), it faces that
    way; where as many legs take it either way, it faces the way its feet's centres of mass lie ahead of their
    ankles by `TOES_AHEAD` of the legs' height or more (toes are longer than heels: Sigmaban's file faces −x,
    its knees' limits ±π; a tie kept its right foot as the left, and bent its knees backward)."""
    lateral = data.oMf[feet["left"]].translation - data.oMf[feet["right"]].translation
    lateral[2] = 0.0
    if np.linalg.norm(lateral) < 1e-9:
        return 0.0
    lateral /= np.linalg.norm(lateral)
    forward = np.cross(lateral, [0.0, 0.0, 1.0])
    if not sided:
        ahead, behind = _stance_fits(model, data, feet, forward), _stance_fits(model, data, feet, -forward)
        if behind > ahead or (behind == ahead and _toes_ahead(model, data, feet, forward) < -TOES_AHEAD):
            forward = -forward
    return float(np.pi / 2 * round(-np.arctan2(forward[1], forward[0]) / (np.pi / 2)))


def _feet(model: pin.Model, data: pin.Data, cfg: RobotConfig, path: Path) -> dict[str, int]:
    """Side -> frame id of each foot: the config's, else `_default_feet`."""
    feet_frames: dict[str, int] = {}
    for side, f in cfg.feet.items():
        if not model.existFrame(f["link"]):
            raise InputError(f"{cfg.source}: [feet.{side}] link {f['link']!r} is not in {path}")
        feet_frames[side] = model.getFrameId(f["link"])
    if len(feet_frames) < 2:
        feet_frames = {**_default_feet(model, data, path), **feet_frames}
    return feet_frames


def _hip_pitch(model: pin.Model, data: pin.Data, chain: list[int]) -> int:
    """The joint of a leg (``chain``, top first) about which the trunk pitches on it: its first joint turning about
    the lateral axis (world y, zero posture) within `ALIGNED` where three do (hip, knee, ankle; NAO's hip yaw-pitch
    above its hip pitch, 45° off the axis, is not it), else the first within `TILTED` above those (Unitree H2's hip
    pitch, 30° off it, AgiBot X1's, 45°, not the knee), else its first. The corrector turns the root about the
    hips' line: about the pitch joints' it moves no joint below them, while about a hip yaw's origin, 4 cm above and
    2 cm behind Wolfgang-OP's hip pitch, its trunk turned back 0.2 rad straightened the knees 0.24 rad, to where the
    legs' IK lost the feet by 17 mm (its corrected lean fell, its true ZMP 1 m off its feet)."""
    pin.computeJointJacobians(model, data, np.zeros(model.nq))
    along = {j: abs(float(data.J[4, model.joints[j].idx_v])) for j in chain}
    aligned = [j for j in chain if along[j] >= ALIGNED]
    if len(aligned) >= 3:
        return aligned[0]
    return next((j for j in chain if along[j] >= TILTED), chain[0])


def _foot_frame(model: pin.Model, data: pin.Data, fid: int, world: pin.SE3, name: str) -> int:
    """A frame on the foot's joint with the zero-posture world placement ``world`` (``data``: the zero posture's
    placements): the foot link's own frame ``fid`` when it already has it, else a new frame ``name``. Soles and
    the base placement take a foot frame's z as the sole's normal and its x as forward: a URDF may turn a leg's
    link frames (e.g. so a pitch axis is local z), and a foot's contact frames may lie on a plane turned from
    the world's level (`contact_sole`)."""
    if data.oMf[fid].isApprox(world, 1e-9):
        return fid
    joint = model.frames[fid].parentJoint
    return model.addFrame(pin.Frame(name, joint, data.oMi[joint].actInv(world), pin.FrameType.OP_FRAME))


def _box(length: float, width: float, center: np.ndarray) -> np.ndarray:
    dx, dy = length / 2, width / 2
    return center + np.array([[-dx, -dy, 0.0], [dx, -dy, 0.0], [dx, dy, 0.0], [-dx, dy, 0.0]])


def _own_side(sole: np.ndarray, lateral: float) -> np.ndarray:
    """A default sole (corners (k, 3), level foot frame, m) kept on its own side of the mid-line between the feet,
    ``lateral`` (m, its frame's y) away: its inner edge moved to the mid-line where it crosses it, its outer edge
    kept. A default box is as wide as 0.28 hip heights, centred under the foot's centre of mass: Z-Bot2's feet,
    10 cm apart with their centres of mass 18 mm inside their ankles, had soles overlapping by 18 mm, where the
    simulated feet's load split between them jumped as the centre of pressure crossed from one sole's corner to
    the other's (its corrected push rolled the trunk 3.7° over the one foot the load went to, and its true ZMP
    left the feet by 0.44 m for moments). Unchanged where the outer edge too is past the mid-line."""
    y = sole[:, 1]
    clipped = np.maximum(y, lateral) if lateral < 0 else np.minimum(y, lateral)
    if np.ptp(clipped) <= 0:
        return sole
    out = sole.copy()
    out[:, 1] = clipped
    return out


def body_from_urdf(path: str | Path, opts: UrdfBodyOptions | None = None) -> BodyModel:
    """Build the body model of a URDF robot (see module docstring)."""
    opts = opts or UrdfBodyOptions()
    path = Path(path)
    fixed, mimics, boxes, root, placeholders = _load_fixed(path)
    rounds = collision_rounds(root, path)
    collided = {link.get("name") for link in root.findall("link") if link.find("collision") is not None}
    cfg: RobotConfig = load_robot_config(opts.config) if opts.config else find_robot_config(path, fixed.name)
    model, data, feet_frames, tilt = _upright_feet(fixed, cfg, path)
    yaw = _heading(model, data, feet_frames, sided=len(cfg.feet) >= 2)
    if yaw:  # the same model turned: frame ids are kept, the default feet's sides found again
        model, data = _posed(fixed, yaw, tilt)
        feet_frames = _feet(model, data, cfg, path)
    leg_ids = leg_joints(model, feet_frames)
    for side, chain in leg_ids.items():
        if not chain:
            raise InputError(f"{path}: foot {model.frames[feet_frames[side]].name!r} has no joint of its own "
                             "between it and the trunk (not a leg)")
    hip_h = float(np.mean([data.oMi[leg_ids[s][0]].translation[2] - data.oMf[f].translation[2]
                           for s, f in feet_frames.items()]))
    turns = {side: data.oMf[fid].rotation.copy() for side, fid in feet_frames.items()}
    ankles_y = {side: float(data.oMf[fid].translation[1]) for side, fid in feet_frames.items()}
    chosen = opts.sole_length is None and opts.sole_width is None and opts.sole_drop is None  # else: the box asked
    feet, unread = {}, []
    for side, link in feet_frames.items():
        spec = cfg.feet.get(side, {})
        joint = model.frames[link].parentJoint
        joints = _foot_joints(model, data, joint, collided)
        given = bool({"sole", "box"} & set(spec))
        contact = None if given else (contact_sole(model, data, joint)
                                      or box_sole(model, data, joints, boxes if chosen else {})
                                      or round_sole(model, data, joints, rounds if chosen else {},
                                                    f"{path}: {side} foot {model.frames[link].name!r}"))
        if contact is None and chosen and not given:
            contact, why = _sole_of_meshes(model, data, joints, root, fixed, path)
            unread += [f"{side} foot: {why}"] if why else []
        if contact is not None:
            fid = _foot_frame(model, data, link, contact.placement, f"{side}_contact_sole")
            feet_frames[side] = fid
            feet[side] = Foot(side, fid, sole_local=contact.corners)
            continue
        name = f"{model.frames[link].name}_level"
        fid = feet_frames[side] = _foot_frame(model, data, link, pin.SE3(np.eye(3), data.oMf[link].translation), name)
        turn = turns[side]  # a config's sole and box centre are in the link's frame: into the level one
        if "sole" in spec:
            sole = np.asarray(spec["sole"], dtype=float) @ turn.T
        else:
            box = spec.get("box", {})
            com = model.inertias[model.frames[fid].parentJoint].lever
            placement = model.frames[fid].placement
            com_in_link = placement.actInv(com) if np.any(com) else np.zeros(3)
            drop = opts.sole_drop if opts.sole_drop is not None else 0.12 * hip_h
            center = (turn @ np.asarray(box["center"], dtype=float) if "center" in box
                      else np.array([com_in_link[0], com_in_link[1], -drop]))
            sole = _box(box.get("length", opts.sole_length or 0.5 * hip_h),
                        box.get("width", opts.sole_width or 0.28 * hip_h), center)
            if not box:
                other = next(y for s, y in ankles_y.items() if s != side)
                sole = _own_side(sole, 0.5 * (other - ankles_y[side]))
        feet[side] = Foot(side, fid, sole_local=sole)
    if unread:
        warnings.warn(f"{path}: {'; '.join(unread)}: default box sole{'s' * (len(unread) > 1)} used", UserWarning,
                      stacklevel=2)
    names = [model.names[j] for j in range(1, model.njoints)]
    jid = {n: model.getJointId(n) for n in names}
    legs = {}
    for side in feet_frames:
        chain = [model.names[j] for j in leg_ids[side]]
        wanted = cfg.legs.get(side, chain)
        for n in wanted:
            if n not in jid:
                raise InputError(f"{cfg.source}: correction leg joint {n!r} is not in {path}")
        legs[side] = [model.joints[jid[n]].idx_q for n in wanted]
    hips = {s: model.getFrameId(model.names[_hip_pitch(model, data, leg_ids[s])], pin.FrameType.JOINT)
            for s in feet_frames}
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
        mimics=tuple(Mimic(names.index(n) - 6, names.index(p) - 6, m, o) for n, (p, m, o) in mimics.items()),
        placeholder_inertias=tuple(placeholders),
    )
