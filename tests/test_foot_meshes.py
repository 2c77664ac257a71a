"""Soles from a foot's meshes (livezmp/model/foot_meshes.py): generated humanoids (tests/humanoid_gen.py) whose
feet are meshes the test writes, an STL box (scaled, offset, in a turned link frame) and a tapered five-sided
foot (cut to four corners, as the simulated foot sensors take), then one missing and one unreadable. Before:
every mesh-only foot stood on the default box sole, 0.5 x 0.28 hip heights under the foot's centre of mass
(Fourier GR-Mini's 295 mm for its feet of 170 mm). Truth: the geometry the test wrote."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import replace
from itertools import combinations
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from humanoid_gen import HumanoidSpec, build_humanoid
from scipy.spatial import ConvexHull

from livezmp.balance.support import convex_hull
from livezmp.model import foot_meshes
from livezmp.model.body import foot_soles
from livezmp.model.foot_meshes import quadrilateral
from livezmp.model.robot import load_robot

SPEC = HumanoidSpec(foot="mesh", frames="random", seed=53)  # foot link frames turned, the mesh placed level in them
FEET = ("l_foot", "r_foot")


def _write_stl(path: Path, vertices: np.ndarray) -> None:
    """An ASCII STL of the convex solid of ``vertices`` (its hull's triangles)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = ["solid foot"]
    for tri in vertices[ConvexHull(vertices).simplices]:
        lines += ["facet normal 0 0 0", "outer loop", *(f"vertex {x:.9g} {y:.9g} {z:.9g}" for x, y, z in tri),
                  "endloop", "endfacet"]
    path.write_text("\n".join([*lines, "endsolid foot", ""]))


def _cube(size=(1.0, 1.0, 1.0), centre=(0.0, 0.0, 0.0)) -> np.ndarray:
    corners = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    return corners * size + centre


def _zero_pose_soles(body) -> dict[str, np.ndarray]:
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, np.zeros(body.model.nq))
    return foot_soles(body, data)


def _edit_meshes(urdf: Path, visual: bool = False, **attrs: str) -> None:
    """Set ``attrs`` on every foot ``<mesh>`` of ``urdf`` (``{name}`` in a value: the foot link's name); ``visual``:
    its ``<collision>`` made a ``<visual>``."""
    tree = ET.parse(urdf)
    for link in tree.getroot().findall("link"):
        for collision in link.findall("collision"):
            collision.tag = "visual" if visual else "collision"
            mesh = collision.find("geometry/mesh")
            mesh.attrib.update({k: v.format(name=link.get("name")) for k, v in attrs.items()})
    tree.write(urdf)


def _assert_same_corners(got: np.ndarray, want: np.ndarray) -> None:
    """The same polygon's corners (k, 3) m, in any order, to 1 µm."""
    assert got.shape == want.shape
    np.testing.assert_allclose(np.linalg.norm(got[:, None] - want[None], axis=2).min(axis=1), 0.0, atol=1e-6)


@pytest.fixture(scope="module")
def boxed(tmp_path_factory) -> dict[str, np.ndarray]:
    """The zero-pose soles of the robot whose feet are the generator's collision boxes."""
    urdf = build_humanoid(tmp_path_factory.mktemp("boxed") / "b.urdf", replace(SPEC, foot="box"))
    return _zero_pose_soles(load_robot(str(urdf), None).body)


def test_a_foot_mesh_of_a_scaled_offset_box_stands_on_its_bottom_face(tmp_path, boxed):
    # before: the default box (240 x 134 mm here) under the foot's centre of mass, whatever the mesh
    size = np.array([0.16, 0.08, 0.03]) * SPEC.height  # the generator's foot box
    urdf = build_humanoid(tmp_path / "m.urdf", SPEC)
    scale = np.array([2.0, 0.5, 1.0])
    _edit_meshes(urdf, scale=" ".join(f"{s:g}" for s in scale))
    for name in FEET:  # a unit cube, 10 mm off in its own frame; scaled, the generator's box 10 mm off centre
        _write_stl(tmp_path / "humanoid" / "meshes" / f"{name}.stl",
                   _cube(size / scale, np.array([0.01, 0.0, 0.0]) / scale))
    soles = _zero_pose_soles(load_robot(str(urdf), None).body)
    for side in ("left", "right"):
        _assert_same_corners(soles[side], boxed[side] + np.array([0.01, 0.0, 0.0]))


def test_a_tapered_five_sided_visual_mesh_gives_the_four_corners_of_most_of_its_footprint(tmp_path, boxed):
    # before: the default box. The foot's only mesh a <visual> one, by a relative path (Fourier GR-Mini's
    # "../meshes/*.STL"); its top narrower all round than its 5-sided bottom, which is the footprint; the simulated
    # foot sensors take four corners: the toe's point, the corner whose cut loses least area, is left out
    (tmp_path / "urdf").mkdir()
    urdf = build_humanoid(tmp_path / "urdf" / "t.urdf", SPEC)
    _edit_meshes(urdf, visual=True, filename="../meshes/tapered.stl")
    bottom = np.array([[-0.03, -0.02], [0.03, -0.02], [0.05, 0.0], [0.03, 0.02], [-0.03, 0.02]])  # a toe's point
    top = bottom * 0.6
    _write_stl(tmp_path / "meshes" / "tapered.stl",
               np.vstack([np.column_stack([bottom, np.full(5, -0.02)]), np.column_stack([top, np.zeros(5)])]))
    soles = _zero_pose_soles(load_robot(str(urdf), None).body)
    for side in ("left", "right"):
        # the mesh's origin is the generator's box centre, 0.015 heights above its bottom; the mesh's bottom 20 mm below
        offset = boxed[side].mean(axis=0) + np.array([0.0, 0.0, 0.015 * SPEC.height - 0.02])
        _assert_same_corners(soles[side], np.column_stack([np.delete(bottom, 2, axis=0), np.zeros(4)]) + offset)


def test_a_missing_or_unreadable_foot_mesh_keeps_the_default_box_and_says_so_once(tmp_path):
    # before: no word; the default box was used without saying the meshes were looked for
    urdf = build_humanoid(tmp_path / "m.urdf", SPEC)
    (tmp_path / "humanoid" / "meshes").mkdir(parents=True)
    (tmp_path / "humanoid" / "meshes" / "r_foot.stl").write_text("not a mesh\n")
    default = _zero_pose_soles(load_robot(str(build_humanoid(tmp_path / "n.urdf", replace(SPEC, foot="none"))),
                                          None).body)
    with pytest.warns(UserWarning) as record:
        soles = _zero_pose_soles(load_robot(str(urdf), None).body)
    assert len(record) == 1
    message = str(record[0].message)
    assert message.startswith(f"{urdf}: left foot: mesh 'package://humanoid/meshes/l_foot.stl' not found; "
                              "right foot: cannot read a mesh of 'r_foot': ")
    assert message.endswith(": default box soles used") and "\n" not in message
    for side in ("left", "right"):
        np.testing.assert_allclose(soles[side], default[side], atol=1e-12)


def test_a_rounded_footprint_gives_the_four_of_its_corners_that_enclose_the_most_area():
    # before (cutting one corner at a time, the smallest triangle first): 91 % of the best four's area on this
    # 200 x 100 mm sole with 28 mm round corners (TienKung Lite's footprint kept 82 % of its area, now 84 %)
    arcs = [(cx + 0.028 * np.cos(a), cy + 0.028 * np.sin(a))
            for cx, cy, start in ((0.072, -0.022, -90), (0.072, 0.022, 0), (-0.072, 0.022, 90), (-0.072, -0.022, 180))
            for a in np.radians(start + np.linspace(0.0, 90.0, 5))]
    footprint = convex_hull(np.array(arcs))
    assert len(footprint) == 20

    def area(corners: np.ndarray) -> float:
        x, y = corners[:, 0], corners[:, 1]
        return 0.5 * abs(float(x @ np.roll(y, 1) - y @ np.roll(x, 1)))

    best = max(area(footprint[list(four)]) for four in combinations(range(len(footprint)), 4))
    sole = quadrilateral(footprint)
    assert len(sole) == 4 and area(sole) == pytest.approx(best, rel=1e-12)


@pytest.mark.parametrize("scale", ["nan 1 1", "big", "1 1"])
def test_a_foot_mesh_whose_scale_is_not_three_numbers_is_said_to_be_unusable(tmp_path, scale):
    # before: urdfdom dropped the foot's <collision> without a word: the default box soles, nothing said
    urdf = build_humanoid(tmp_path / "m.urdf", SPEC)
    _edit_meshes(urdf, scale=scale)
    for name in FEET:
        _write_stl(tmp_path / "humanoid" / "meshes" / f"{name}.stl", _cube(np.array([0.16, 0.08, 0.03])))
    with pytest.warns(UserWarning) as record:
        load_robot(str(urdf), None)
    assert len(record) == 1
    assert (f"left foot: mesh 'package://humanoid/meshes/l_foot.stl': scale {scale!r} is not three finite numbers"
            in str(record[0].message))


def test_a_foot_mesh_file_too_large_to_read_in_time_is_said_and_not_read(tmp_path, monkeypatch):
    # before: every foot mesh was read whole: a 2M-face STL (100 MB) was still loading after 4 min at load 12.
    # The limit lowered here to this test's small cubes, so that nothing large need be written
    monkeypatch.setattr(foot_meshes, "MAX_MESH_BYTES", 100)
    urdf = build_humanoid(tmp_path / "m.urdf", SPEC)
    for name in FEET:
        _write_stl(tmp_path / "humanoid" / "meshes" / f"{name}.stl", _cube(np.array([0.16, 0.08, 0.03])))
    with pytest.warns(UserWarning) as record:
        load_robot(str(urdf), None)
    assert len(record) == 1
    assert re.search(r"left foot: mesh 'package://humanoid/meshes/l_foot.stl': 0 MB, more than the 0 MB a foot mesh "
                     r"is read up to; right foot: .*: default box soles used$", str(record[0].message))


def test_a_foot_mesh_in_millimetres_read_as_metres_is_said_not_stood_on(tmp_path):
    # before: the robot stood on soles 240 m long (the generator's foot box written in mm, no scale) without a word
    urdf = build_humanoid(tmp_path / "m.urdf", SPEC)
    for name in FEET:
        _write_stl(tmp_path / "humanoid" / "meshes" / f"{name}.stl",
                   _cube(1000 * np.array([0.16, 0.08, 0.03]) * SPEC.height))
    with pytest.warns(UserWarning) as record:
        load_robot(str(urdf), None)
    assert len(record) == 1
    assert re.search(r"left foot: its meshes' footprint is \d+ m across, more than a sole's 1 m; right foot: .*: "
                     r"default box soles used$", str(record[0].message))
