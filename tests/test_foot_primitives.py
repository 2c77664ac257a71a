"""Soles from a foot's collision cylinders and spheres (livezmp/model/foot_primitives.py): generated humanoids
(tests/humanoid_gen.py) whose feet are two cylinders lying along them (Fourier GR1T2's), one (a skate: a strip),
four balls inside the sole's corners (Unitree G1's) or one ball (a point foot, refused), in turned link frames
and facing another way in their file. Before: every such foot stood on the default box sole, 0.5 x 0.28 hip heights
under its centre of mass (G1's 327 x 184 mm for the 170 x 60 mm its balls span; a ball foot stood on it too).
Truth: the geometry the generator wrote."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from humanoid_gen import HumanoidSpec, build_humanoid

from livezmp.cli import main
from livezmp.model.body import foot_soles
from livezmp.model.foot_meshes import CONTACT_DEPTH
from livezmp.model.robot import load_robot

SPEC = HumanoidSpec(frames="random", seed=54)
FOOT = np.array([0.16, 0.08, 0.03]) * SPEC.height  # m: the generator's foot box (length, width, height)


def _soles(tmp_path, spec: HumanoidSpec) -> dict[str, np.ndarray]:
    """The zero-pose soles (corners (k, 3) world, m) of the robot of ``spec``."""
    tmp_path.mkdir(parents=True, exist_ok=True)
    body = load_robot(str(build_humanoid(tmp_path / f"{spec.foot}_{spec.facing}.urdf", spec)), None).body
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, np.zeros(body.model.nq))
    return foot_soles(body, data)


@pytest.fixture(scope="module")
def boxed(tmp_path_factory) -> dict[str, np.ndarray]:
    """The zero-pose soles of the robot whose feet are the generator's collision boxes."""
    return _soles(tmp_path_factory.mktemp("boxed"), replace(SPEC, foot="box"))


@pytest.mark.parametrize(("foot", "facing", "width"), [
    ("cylinders", "-y", FOOT[1] / 2),  # the hull of two lines a quarter of the width either side of the middle
    ("balls", "x", FOOT[1] - FOOT[2]),  # the balls' bottoms, a radius inside the box's corners
    ("cylinder", "x", 2 * math.sqrt(2 * FOOT[2] / 2 * CONTACT_DEPTH - CONTACT_DEPTH**2)),  # a strip: within 3 mm
])
def test_a_foot_of_cylinders_or_balls_stands_where_they_touch_the_floor(tmp_path, boxed, facing, foot, width):
    soles = _soles(tmp_path, replace(SPEC, foot=foot, facing=facing))
    length = FOOT[0] - (FOOT[2] if foot == "balls" else 0.0)
    for side, sole in soles.items():
        assert len(sole) == 4
        np.testing.assert_allclose(np.ptp(sole, axis=0), [length, width, 0.0], atol=1e-6)
        np.testing.assert_allclose(sole.mean(axis=0), boxed[side].mean(axis=0), atol=1e-6)  # centred, as low


def test_a_ball_foot_is_refused_in_one_line(tmp_path, capsys):
    urdf = build_humanoid(tmp_path / "ball.urdf", replace(SPEC, foot="ball"))
    rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "lean", "--duration", "0.05"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and "foot 'l_foot'" in err[0] and "touch the floor at one point" in err[0]


@pytest.mark.parametrize("foot", ["cylinders", "box"])
def test_a_foot_whose_geometry_the_file_gives_its_ankle_link_stands_on_it(tmp_path, foot):
    """Fourier GR3's file gives its right foot's collision cylinders to the link between its ankle's pitch and roll
    joints, its left foot's to the foot link: the right foot stood on the default box, 34 mm lower than the left's
    cylinders, its left sole 3 mm off the floor, and every scenario fell at 0.2 s. Both feet now stand on the
    geometry the file gives them, as the twin whose right foot carries its own does."""
    plain = _soles(tmp_path / "plain", replace(SPEC, foot=foot, ankle="pr"))
    moved = _soles(tmp_path / "ankle", replace(SPEC, foot=foot, ankle="pr", sole_on_ankle="r"))
    for side in ("left", "right"):
        np.testing.assert_allclose(moved[side], plain[side], atol=1e-9)
