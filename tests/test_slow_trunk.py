"""A robot whose trunk answers slowly (its file's inertias far too large): the corrector must not make it fall
earlier than it would uncorrected (issue 16: THORMANG3's placeholder 1 kg m^2 inertias)."""

from dataclasses import replace

import numpy as np
import pytest
from humanoid_gen import HumanoidSpec, build_humanoid
from test_live_loop_closed import balance

from livezmp.correct.online import OnlineCorrector, braked, com_height, slow_trunk_factor
from livezmp.live.scenarios import make_scenario
from livezmp.model.base_placement import BasePlacer
from livezmp.model.robot import load_robot


@pytest.fixture(scope="module")
def heavy_torso(tmp_path_factory):
    """The generated humanoid with its torso's inertia written 150 times too large (Darwin-OP's file: 1e6, refused
    at load; 150 passes the load's check): its trunk's response time sqrt(K/S) is 2.1 times its sqrt(h/g)."""
    spec = replace(HumanoidSpec(), inertia_scale=150.0, seed=3)
    return load_robot(str(build_humanoid(tmp_path_factory.mktemp("slow") / "slow.urdf", spec)), None).body


def test_a_slow_trunk_widens_the_margin_and_an_ordinary_one_does_not(heavy_torso):
    assert slow_trunk_factor(0.0159, 0.1625, 0.7) == 1.0  # AgiBot X1 (ratio 1.18)
    assert slow_trunk_factor(0.0819, 0.1447, 0.76) == pytest.approx(1.76, abs=0.05)  # THORMANG3 (ratio 2.6)
    assert slow_trunk_factor(0.0, 0.1, 0.5) == 1.0 and slow_trunk_factor(0.1, 0.0, 0.5) == 1.0
    joints = make_scenario("lean", heavy_torso, hold_s=1.0).goals(0.0)
    q = np.concatenate([BasePlacer(heavy_torso).update(joints), joints])
    corrector = OnlineCorrector(heavy_torso, 0.008, margin_m=0.015)
    corrector.prepare(q)
    assert corrector.limits.margin_m > 0.015 * 1.3, "a trunk 2x slower than a humanoid's keeps a humanoid's margin"
    assert com_height(heavy_torso, q) > 0


def test_the_corrector_keeps_a_slow_trunked_robot_up_in_lean(heavy_torso):
    """On main, corrected it fell at 1.94 s, earlier than uncorrected (2.25 s): turning its trunk back at the
    acceleration limit pushed its ZMP past its toes before the turn moved its CoM."""
    scenario = make_scenario("lean", heavy_torso, hold_s=1.0)
    off, _ = balance(heavy_torso, scenario, correct=False)
    on, _ = balance(heavy_torso, scenario, correct=True)
    assert off.fallen is not None
    assert off.counters.longest_unsupported_s > 0.2 - 1e-9  # the simulator's fall: more than 0.2 s outside
    assert on.fallen is None, on.fallen


def test_the_turn_brakes_before_its_range_within_the_acceleration_limit():
    """Moving at 0.01 rad per frame 1.8 mrad short of its 15° range, the turn slows to what the acceleration
    limit (4e-5 rad per frame^2) can still stop; away from the range and moving back it is left alone."""
    bound, accel = np.full(2, np.radians(15.0)), np.full(2, 4e-5)
    near = braked(np.array([0.01, -0.01]), np.array([bound[0] - 0.0018, -bound[1] + 0.0018]), bound, accel)
    assert np.allclose(np.abs(near), np.sqrt(2 * 4e-5 * 0.0018)) and np.sign(near).tolist() == [1.0, -1.0]
    far = np.array([0.001, -0.005])
    assert np.array_equal(braked(far, np.array([0.0, bound[1]]), bound, accel), far)
