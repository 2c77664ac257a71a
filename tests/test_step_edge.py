"""One foot rolled over a step's edge: the flat-foot base estimate, with and without the IMU.

The simulated humanoid stands with its left foot rolled 8 degrees outward over a step's edge
and its right foot flat (the scenario ``edge``); its true ZMP comes from its exact whole-body
dynamics on the level floor (simulated time). The loop's base placer takes the rolled foot as
the flat one (placed flat, it leaves the other foot above the floor), so without the IMU it
sees the whole body rolled by 8 degrees. The frames of the two differ (each places its own
stance sole at the origin), so each ZMP is compared in the frame of the flat right sole,
which both compute from the same joint angles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_ground_tilt import zmp_errors

from livezmp.errors import InputError
from livezmp.live.config import LoopConfig
from livezmp.live.scenarios import make_scenario
from livezmp.model.base_placement import BasePlacer
from sim_devices.humanoid import SimHumanoid, edge_strip
from sim_devices.launch import humanoid_imu


def in_sole(point: np.ndarray, sole: np.ndarray) -> np.ndarray:
    """(u, v) of ``point`` along two orthonormal directions of the plane of the rectangle ``sole``
    (corners (4, 3)) from its corner 0: the same numbers in any frame the sole is given in."""
    e1 = sole[1] - sole[0]
    e1 /= np.linalg.norm(e1)
    e2 = sole[2] - sole[0]
    e2 -= (e2 @ e1) * e1
    e2 /= np.linalg.norm(e2)
    d = point - sole[0]
    return np.array([d @ e1, d @ e2])


def test_the_edge_scenario_rolls_one_foot_and_the_flat_foot_carries_the_base(mini):
    scenario = make_scenario("edge", mini)
    h = SimHumanoid(mini, scenario.goals(0.0), edge=scenario.edge)
    s = h.state()
    left, right = s.soles["left"], s.soles["right"]
    assert s.stance == "right" and s.support == "double"
    assert np.allclose(right[:, 2], 0.0, atol=1e-9)
    # the rolled sole: its width w at 8 degrees rises by w sin 8 deg from its low edge to its high edge
    z = np.sort(left[:, 2])
    assert z[2:].mean() - z[:2].mean() == pytest.approx(0.066 * math.sin(math.radians(8.0)), rel=0.02)
    # the strip that bears weight: its low edge and 60 % of the way across
    strip = edge_strip(left, 0.6)
    assert np.allclose(strip[:2], left[np.argsort(left[:, 2])[:2]])
    assert np.linalg.norm(strip[2] - strip[0]) == pytest.approx(0.6 * 0.066, rel=1e-6)
    # the flat-foot placer of the loop takes the rolled foot as its flat stance, and so rolls the body 8 degrees
    placer = BasePlacer(mini)
    base = placer.update(scenario.goals(0.0))
    assert placer.stance == "left" and math.degrees(abs(base[5])) == pytest.approx(8.0, abs=1e-6)
    with pytest.raises(InputError, match="edge must be"):
        SimHumanoid(mini, edge=("middle", 0.5))


def zmp_error_on_edge(body, imu: bool) -> tuple[np.ndarray, dict]:
    """`zmp_errors` on the edge scenario (estimate only), each ZMP in the flat right sole's frame."""
    scenario = make_scenario("edge", body, duration=2.0)
    h = SimHumanoid(body, scenario.goals(0.0), edge=scenario.edge)
    return zmp_errors(body, scenario, h, humanoid_imu(h) if imu else None,
                      where=lambda zmp, soles: in_sole(zmp, soles["right"]), config=LoopConfig(correct=False))


@pytest.mark.parametrize("robot", ["livezmp_mini", "robotis_op3"])
def test_on_a_step_edge_the_imu_makes_the_zmp_right_and_without_it_it_is_centimetres_off(robot, mini, op3_body):
    body = mini if robot == "livezmp_mini" else op3_body
    flat, s_flat = zmp_error_on_edge(body, imu=False)
    fused, s_fused = zmp_error_on_edge(body, imu=True)
    for name, e in (("no IMU (flat foot)", flat), ("IMU", fused)):
        print(f"{robot}, left foot rolled 8 deg on a step edge, {name}: ZMP error mean {1e3 * e.mean():.2f} mm, "
              f"p95 {1e3 * np.percentile(e, 95):.2f}, max {1e3 * e.max():.2f} ({len(e)} samples)")
    assert s_flat["ground_slope_deg"] is None
    # the IMU sees the rolled foot's sole plane tilted by the roll
    assert s_fused["ground_slope_deg"] == pytest.approx(8.0, abs=0.1)
    # without the IMU: sideways by about the CoM height times tan(8 degrees)
    assert flat.mean() > 0.02
    assert len(fused) > 950 and np.percentile(fused, 95) < 0.003 and fused.max() < 0.005
