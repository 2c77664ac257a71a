"""The simulated humanoid against independent truth: statics in closed form, the CoM's
motion by finite differences of its positions, rotations by hand, the push's lever arm,
fall timing from the recorded steps, a real dynamixel-sdk client, and the live loop's
corrector closing the loop."""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from data_paths import OP3_URDF
from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from sim_support import sdk_latency_timer, short_gil_switch, wait_until  # noqa: F401 - fixtures

import livezmp
from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.balance.support import clamp_to_polygon
from livezmp.correct.online import OnlineCorrector
from livezmp.errors import InputError
from livezmp.estimate.estimator import EstimatorConfig
from livezmp.live import scenarios as sc
from livezmp.live.config import LoopConfig
from livezmp.live.scenarios import Push
from livezmp.model.base_placement import BasePlacer
from livezmp.model.body import sole_velocities
from livezmp.model.trajectory_csv import JointTrajectory, write_joint_csv
from livezmp.model.urdf_body import body_from_urdf
from sim_devices.dynamixel_chain import DynamixelChain
from sim_devices.humanoid import RealtimeThread, SimHumanoid, cop_weights
from sim_devices.scenario_player import ScenarioPlayer

MINI_URDF = Path(livezmp.__file__).parent / "data" / "robots" / "livezmp_mini.urdf"
G = 9.81
H = 1e-3  # the humanoid's internal step
_BODIES: dict[str, object] = {}


def load(name: str):
    if name not in _BODIES:
        _BODIES[name] = body_from_urdf(OP3_URDF if name == "op3" else MINI_URDF)
    return _BODIES[name]


@pytest.fixture(params=["op3", "mini"])
def body(request):
    return load(request.param)


def record(humanoid: SimHumanoid, scenario: sc.Scenario, seconds: float, stop_on_fall: bool = True) -> list:
    """Play with a goal update every internal step and keep every dynamic state."""
    player = ScenarioPlayer(humanoid, scenario, rate_hz=1.0 / H)
    states = []
    while player.t < seconds - 1e-9 and not (stop_on_fall and humanoid.fallen):
        player.tick()
        if humanoid.fallen is None:
            states.append(humanoid.state())
    return states


def second_difference(values: np.ndarray) -> np.ndarray:
    """(x[k+1] - 2 x[k] + x[k-1]) / H² for the inner samples."""
    return (values[2:] - 2 * values[1:-1] + values[:-2]) / (H * H)


# -- postures and scenarios ---------------------------------------------------------------------


def test_standing_posture_bends_the_knees_forward_keeps_the_soles_flat_and_hangs_the_arms(body):
    q_j = sc.Poser(body).standing(0.3)
    q = np.concatenate([BasePlacer(body).update(q_j), q_j])
    model, data = body.model, body.model.createData()
    pin.framesForwardKinematics(model, data, q)
    pos = {n: data.oMi[model.getJointId(n)].translation for n in body.joint_names}
    for s in ("l", "r"):
        hip, knee, ankle = pos[f"{s}_hip_pitch"], pos[f"{s}_knee"], pos[f"{s}_ank_pitch"]
        # the knee is ahead of the hip-ankle line: thigh and shank are ~0.11 m, flexed 0.3 rad
        assert knee[0] - (hip[0] + ankle[0]) / 2 == pytest.approx(0.11 * np.sin(0.3), abs=0.005)
        foot = data.oMf[body.feet["left" if s == "l" else "right"].frame_id]
        assert np.allclose(foot.rotation, np.eye(3), atol=1e-9)  # sole flat, facing forward
        shoulder, elbow = pos[f"{s}_sho_roll"], pos[f"{s}_el"]
        down = (elbow - shoulder) / np.linalg.norm(elbow - shoulder)
        assert down[2] < -0.99 and np.sign(down[1]) == (1 if s == "l" else -1)  # hanging, turned out


def test_scenarios_reject_a_body_without_humanoid_joint_names():
    with pytest.raises(InputError, match="l_knee"):
        sc.Poser(load("op3")).unit("l_knee_typo", 1)
    with pytest.raises(InputError, match="not the world"):
        sc.Poser(load("op3")).unit("l_knee", 0)  # a pitch joint asked to roll


def test_humanoid_rejects_bad_arguments_with_one_line_errors():
    body = load("mini")
    with pytest.raises(InputError, match="posture must be 20"):
        SimHumanoid(body, np.zeros(3))
    with pytest.raises(InputError, match="dt > 0"):
        SimHumanoid(body, dt=0.0)
    with pytest.raises(InputError, match="duration > 0"):
        Push((1.0, 0.0), 0.2, 0.0, 0.0)
    with pytest.raises(InputError, match="no clock"):
        SimHumanoid(body).sync()
    h = SimHumanoid(body)
    with pytest.raises(InputError, match="r_knee not finite"):
        h.set_goals(np.where(np.array(body.joint_names) == "r_knee", np.nan, 0.0))
    with pytest.raises(InputError, match=r"joint 3 \(l_hip_roll\)"):
        h.set_goal(3, float("inf"))
    with pytest.raises(InputError, match="not both"):
        SimHumanoid(body, np.zeros(20), servo=h.servo)


# -- statics ----------------------------------------------------------------------------------


def test_standing_still_the_zmp_is_the_com_projection_and_nothing_falls(body):
    h = SimHumanoid(body, sc.Poser(body).standing())
    states = record(h, sc.stand(body), 1.0)
    last = states[-1]
    assert h.fallen is None and h.counters.unsupported_steps == 0
    assert np.abs(last.v).max() == 0.0 and np.abs(last.a).max() == 0.0
    np.testing.assert_allclose(last.zmp[:2], last.com[:2], atol=1e-12)
    np.testing.assert_allclose(last.force, [0.0, 0.0, body.total_mass * G], rtol=1e-12, atol=1e-9)
    assert last.support == "double" and last.supported


def test_static_foot_forces_sum_to_the_weight_with_their_cop_at_the_zmp(body):
    h = SimHumanoid(body, sc.Poser(body).standing())
    record(h, sc.stand(body), 0.05)
    f, s = h.foot_forces(), h.state()
    assert f.total == pytest.approx(body.total_mass * G, rel=1e-12)
    assert np.all(f.left > 0) and np.all(f.right > 0)  # double support, CoM well inside
    cells = np.concatenate([f.left, f.right])
    corners = np.vstack([s.soles["left"][:, :2], s.soles["right"][:, :2]])
    np.testing.assert_allclose(cells @ corners / cells.sum(), s.com[:2], atol=1e-12)
    np.testing.assert_allclose(f.cop, s.zmp[:2], atol=1e-12)


@settings(max_examples=200, deadline=None)
@given(st.floats(-0.2, 0.2), st.floats(0.01, 0.2), st.floats(0.05, 0.3), st.floats(0.03, 0.1),
       st.floats(0, 1), st.floats(0, 1), st.floats(0, 1))
def test_cop_weights_are_non_negative_and_reproduce_any_point_of_the_hull(dx, gap, length, width, a, b, c):
    """Two soles (one shifted by dx, gap apart); the point is a convex combination of three
    corners, so it is in the hull; the weights must reproduce it exactly."""
    sole = np.array([[0, 0], [length, 0], [length, width], [0, width]])
    corners = np.vstack([sole, sole + [dx, width + gap]])
    pick = corners[[0, 5, 6]]
    w3 = np.array([a, b, c]) + 1e-3
    point = w3 @ pick / w3.sum()
    w = cop_weights(corners, point)
    assert np.all(w >= 0) and w.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(w @ corners, point, atol=1e-12)


def test_two_soles_touching_at_the_mid_line_share_the_load_of_a_point_where_they_meet():
    # before: where rounding put one foot's front edge 1e-8 m behind the other's, the corner both soles share at the
    # mid-line became a hull vertex and all its weight went to the left foot's copy: the right foot read as lifted
    # (Cassie's default soles, trimmed to the mid-line: the corrector rolled its trunk over the left foot and its
    # corrected push fell, its true ZMP 3.6 m off its feet for moments)
    left = np.array([[-0.2, 0.0], [0.2, 0.0], [0.2, 0.15], [-0.2, 0.15]])
    right = left * [1.0, -1.0] - [1e-8, 0.0]
    w = cop_weights(np.vstack([left, right]), np.array([0.19, 0.0]))
    assert w[:4].sum() == pytest.approx(w[4:].sum(), abs=1e-6)


def test_imu_reads_gravity_at_rest_and_the_tilt_of_a_lean(body):
    poser = sc.Poser(body)
    h = SimHumanoid(body, poser.standing())
    record(h, sc.stand(body), 0.05)
    imu = h.imu()
    np.testing.assert_allclose(imu.quaternion, [0, 0, 0, 1], atol=1e-9)
    np.testing.assert_allclose(imu.angular_velocity, 0.0, atol=1e-12)
    np.testing.assert_allclose(imu.specific_force, [0, 0, G], atol=1e-9)
    # Leaning at the ankles by beta with the soles flat turns the whole body by beta about y
    # (the pitch joints' rotations sum to the lean), whatever the URDF's axis signs.
    beta = 0.2
    leaned = poser.standing() + poser.ankles_lean(beta)
    h = SimHumanoid(body, leaned)
    record(h, sc.Scenario("still", lambda t: leaned, 0.05), 0.05)
    imu = h.imu()
    np.testing.assert_allclose(imu.quaternion, [0, np.sin(beta / 2), 0, np.cos(beta / 2)], atol=1e-9)
    np.testing.assert_allclose(imu.specific_force, [-G * np.sin(beta), 0, G * np.cos(beta)], atol=1e-9)


# -- dynamics ---------------------------------------------------------------------------------


def test_imu_follows_the_base_motion_during_a_lean(body):
    """Specific force = Rᵀ(p̈ − g) with p̈ from the base origin's recorded positions, and
    ω from consecutive base rotations (built here from yaw, pitch, roll)."""
    h = SimHumanoid(body, sc.Poser(body).standing())
    player = ScenarioPlayer(h, sc.lean(body), rate_hz=1.0 / H)
    player.run(1.0)  # mid-ramp: leaning faster and faster
    states, imus = [], []
    for _ in range(3):
        player.tick()
        states.append(h.state())
        imus.append(h.imu())
    p = np.array([s.q[:3] for s in states])
    rots = [Rotation.from_euler("ZYX", s.q[3:6]) for s in states]
    r1 = rots[1].as_matrix()
    acc = (p[2] - 2 * p[1] + p[0]) / (H * H)
    omega = (rots[1].inv() * rots[2]).as_rotvec() / (2 * H) + (rots[0].inv() * rots[1]).as_rotvec() / (2 * H)
    assert np.linalg.norm(omega) > 0.1  # really moving
    np.testing.assert_allclose(imus[1].specific_force, r1.T @ (acc + [0, 0, G]), atol=2e-3)
    np.testing.assert_allclose(imus[1].angular_velocity, omega, atol=1e-5)
    np.testing.assert_allclose(Rotation.from_quat(imus[1].quaternion).as_matrix(), r1, atol=1e-12)


@pytest.mark.parametrize("make", [sc.squat, sc.arm_swing], ids=["squat", "arm_swing"])
def test_contact_force_matches_the_com_acceleration_from_its_positions(body, make):
    """F = m (c̈ − g) with c̈ the second difference of the recorded CoM positions: the
    base's velocity and acceleration are consistent with its motion."""
    scenario = make(body)
    h = SimHumanoid(body, scenario.goals(0.0), fall_after_s=10.0)
    states = record(h, scenario, 2.0)
    com = np.array([s.com for s in states])
    force = np.array([s.force for s in states])[1:-1]
    acc = second_difference(com)
    m = body.total_mass
    assert np.abs(acc).max() > 0.1  # the motion is dynamic
    np.testing.assert_allclose(force / m - [0, 0, G], acc, atol=2e-3 * np.abs(acc).max())


def test_squat_foot_forces_carry_the_weight_plus_the_vertical_inertia_and_soles_stay_put(body):
    scenario = sc.squat(body, period=1.0)
    h = SimHumanoid(body, scenario.goals(0.0))
    player = ScenarioPlayer(h, scenario, rate_hz=1.0 / H)
    model, data = body.model, body.model.createData()
    com, totals, sole_speed = [], [], 0.0
    while player.t < 1.0:
        player.tick()
        s = h.state()
        com.append(s.com[2])
        totals.append(h.foot_forces().total)
        pin.forwardKinematics(model, data, s.q, s.v)
        pin.updateFramePlacements(model, data)
        vel = sole_velocities(body, model, data, s.soles)
        sole_speed = max(sole_speed, np.abs(vel["left"]).max(), np.abs(vel["right"]).max())
    z_acc = second_difference(np.array(com))
    m = body.total_mass
    assert np.abs(z_acc).max() > 0.3
    np.testing.assert_allclose(np.array(totals)[1:-1], m * (G + z_acc), atol=2e-3 * m * np.abs(z_acc).max())
    assert sole_speed < 1e-4  # m/s, while the hips move at ~0.1 m/s
    assert h.fallen is None and h.counters.unsupported_steps == 0


def test_arm_swing_pushes_the_zmp_out_while_the_static_com_stays_in(body):
    scenario = sc.arm_swing(body)
    h = SimHumanoid(body, scenario.goals(0.0))
    states = record(h, scenario, 3.0)
    swing = [s for s in states if s.t > 1.0]
    com_margin = [clamp_to_polygon(s.com[:2], s.polygon).margin for s in swing]
    offset = np.array([s.zmp[0] - s.com[0] for s in swing])
    assert min(com_margin) > 0.003  # the CoM never leaves the feet
    assert min(s.margin for s in swing) < -0.008  # the ZMP does, by more than 8 mm
    assert offset.max() > 0.012 and offset.min() < -0.012
    assert h.fallen is None  # each excursion is shorter than fall_after_s


# -- falls ------------------------------------------------------------------------------------


@pytest.mark.parametrize("fall_after_s", [0.2, 0.05])
def test_a_lean_past_the_toes_falls_after_fall_after_s_and_then_holds(body, fall_after_s):
    scenario = sc.lean(body, beyond=0.004)
    h = SimHumanoid(body, scenario.goals(0.0), fall_after_s=fall_after_s)
    states = record(h, scenario, scenario.duration)
    fall = h.fallen
    assert fall is not None and "outside the support polygon" in fall.reason
    assert fall.t - fall.since == pytest.approx(fall_after_s, abs=0.5 * H)
    since = next(k for k, s in enumerate(states) if s.t >= fall.since - 1e-9)
    assert not any(s.supported for s in states[since:])  # unsupported from `since` on
    assert states[since - 1].supported
    # it holds: the joints stay frozen while the goals keep changing
    frozen = h.position.copy()
    player = ScenarioPlayer(h, scenario, rate_hz=125.0)
    player.run(0.5)
    assert np.array_equal(h.position, frozen) and not np.any(h.velocity)
    assert np.abs(h.state().v).max() == 0.0 and h.fallen is fall


def imu_tilt(h: SimHumanoid) -> float:
    """Angle (rad) between the IMU's z axis and the world's vertical."""
    x, y, _, _ = h.imu().quaternion
    return float(np.arccos(np.clip(1.0 - 2.0 * (x * x + y * y), -1.0, 1.0)))


def test_after_a_fall_the_imu_reads_the_body_toppling_forwards_until_it_lies(body):
    scenario = sc.lean(body, beyond=0.004)  # past the toes: it topples forwards, about the y axis
    h = SimHumanoid(body, scenario.goals(0.0))
    record(h, scenario, scenario.duration)
    assert h.fallen is not None
    upright = imu_tilt(h)
    rate = np.sqrt(9.81 / h.state().com[2])
    player = ScenarioPlayer(h, scenario, rate_hz=125.0)
    # linearised pendulum from 0.05 rad: the added tilt is 0.05 (cosh(t rate) - 1)
    t0 = h.t - h.fallen.t
    player.run(0.3)
    expected = 0.05 * (np.cosh((h.t - h.fallen.t) * rate) - 1.0)
    assert imu_tilt(h) - upright == pytest.approx(expected, rel=0.05, abs=1e-3)
    assert h.imu().angular_velocity[1] > 0.0 and t0 >= 0.0  # pitching forwards (y up to the left)
    player.run(1.5)
    assert imu_tilt(h) == pytest.approx(np.pi / 2 - 0.05 + upright, abs=0.02)  # lying on its front
    assert np.abs(h.imu().angular_velocity).max() < 1e-6


def test_a_lean_that_stays_inside_does_not_fall(body):
    scenario = sc.lean(body, beyond=-0.008)  # static CoM 8 mm inside the toes at the hold
    h = SimHumanoid(body, scenario.goals(0.0))
    ScenarioPlayer(h, scenario).run()
    assert h.fallen is None and h.counters.unsupported_steps == 0
    assert 0.0 < h.counters.worst_margin < 0.008


def test_a_push_moves_the_zmp_by_its_lever_arm_and_only_a_long_one_fells_the_robot(body):
    force, height = 4.0, 0.2
    h = SimHumanoid(body, sc.Poser(body).standing())
    states = record(h, sc.push(body, (force, 0.0), at=0.1, duration=0.2, height=height), 0.25)
    pushed = states[-1]
    weight = body.total_mass * G
    assert pushed.push[0] == force
    np.testing.assert_allclose(pushed.force, [-force, 0.0, weight], atol=1e-9)
    assert pushed.zmp[0] - pushed.com[0] == pytest.approx(height * force / weight, abs=1e-12)
    np.testing.assert_allclose(h.foot_forces().cop, pushed.zmp[:2], atol=1e-12)
    big = 4 * 0.07 * weight / height  # enough to move the ZMP ~0.28 m: far past the toes
    short = SimHumanoid(body, sc.Poser(body).standing())
    states = record(short, sc.push(body, (big, 0.0), at=0.1, duration=0.15, height=height), 0.5)
    assert short.fallen is None and short.counters.unsupported_steps == pytest.approx(150, abs=1)
    clipped = next(s for s in states if not s.supported)
    np.testing.assert_allclose(clipped.clamped, clamp_to_polygon(clipped.zmp[:2], clipped.polygon).point)
    long = SimHumanoid(body, sc.Poser(body).standing())
    record(long, sc.push(body, (big, 0.0), at=0.1, duration=0.3, height=height), 0.5)
    assert long.fallen is not None and long.fallen.since == pytest.approx(0.1, abs=1.5 * H)


def test_the_cop_of_an_unsupported_zmp_is_its_nearest_point_of_the_polygon(body):
    h = SimHumanoid(body, sc.Poser(body).standing())
    record(h, sc.push(body, (60.0, 0.0), at=0.0, duration=0.1, height=0.2), 0.02)
    s, f = h.state(), h.foot_forces()
    assert not s.supported
    np.testing.assert_allclose(f.cop, clamp_to_polygon(s.zmp[:2], s.polygon).point, atol=1e-12)
    assert f.total == pytest.approx(s.force[2]) and np.all(np.concatenate([f.left, f.right]) >= 0)


# -- walking and stance changes --------------------------------------------------------------


def _march(body, path: Path) -> np.ndarray:
    """A march in place as a 100 Hz joint CSV: shift over the left foot, lift and lower the
    right, shift over the right, lift and lower the left, back to the middle."""
    poser = sc.Poser(body)
    stand = poser.standing()
    sway = 0.2 * (poser.unit("l_ank_roll", sc.X) + poser.unit("r_ank_roll", sc.X)
                  - poser.unit("l_hip_roll", sc.X) - poser.unit("r_hip_roll", sc.X))  # pelvis to the left
    keys = [(0.0, stand), (0.3, stand), (1.3, stand + sway), (1.8, stand + sway + poser.legs_flexed(0.25, ("r",))),
            (2.3, stand + sway), (3.3, stand - sway), (3.8, stand - sway + poser.legs_flexed(0.25, ("l",))),
            (4.3, stand - sway), (5.3, stand), (5.5, stand)]
    t = np.arange(0, 551) / 100.0
    q = np.empty((len(t), len(stand)))
    for (t0, a), (t1, b) in zip(keys, keys[1:], strict=False):
        sel = (t >= t0 - 1e-9) & (t <= t1 + 1e-9)
        q[sel] = a + np.outer(sc.smooth_step((t[sel] - t0) / (t1 - t0)), b - a)
    write_joint_csv(JointTrajectory(t, q, list(body.joint_names)), path)
    return q


def test_walk_replays_a_csv_and_the_stance_passes_between_the_feet(body, tmp_path):
    rows = _march(body, tmp_path / "march.csv")
    scenario = sc.walk(body, tmp_path / "march.csv")
    assert scenario.duration == pytest.approx(5.5)
    np.testing.assert_allclose(scenario.goals(1.3), rows[130], atol=1e-8)  # CSV keeps 9 digits
    np.testing.assert_allclose(scenario.goals(1.305), (rows[130] + rows[131]) / 2, atol=1e-8)
    np.testing.assert_allclose(scenario.goals(99.0), rows[-1], atol=1e-8)
    h = SimHumanoid(body, scenario.goals(0.0))
    states = record(h, scenario, scenario.duration)
    labels = [s.support for s in states]
    phases = [lab for k, lab in enumerate(labels) if k == 0 or lab != labels[k - 1]]
    assert phases == ["double", "left", "double", "right", "double"]
    assert states[0].stance == "left" and states[-1].stance == "right"
    assert h.fallen is None and h.counters.unsupported_steps == 0
    # The dynamics see no jump when the stance passes: the contact force stays smooth and
    # matches the CoM's second difference, except across the switch itself, where the base
    # is re-anchored on the new stance foot (flat on the ground; it had sunk < 1 mm).
    acc = np.array([s.force for s in states]) / body.total_mass - [0, 0, G]
    assert np.abs(acc).max() < 0.5  # m/s²; a 1 mm jump within one step would read 1000
    same = np.array([states[k - 1].stance == states[k + 1].stance for k in range(1, len(states) - 1)])
    assert same.sum() == len(same) - 2
    com_acc = second_difference(np.array([s.com for s in states]))
    np.testing.assert_allclose(com_acc[same], acc[1:-1][same], atol=2e-3)
    model, data = body.model, body.model.createData()
    for s in states:
        pin.forwardKinematics(model, data, s.q, s.v)
        pin.updateFramePlacements(model, data)
        vel = sole_velocities(body, model, data, s.soles)
        for side in ("left", "right"):
            # the stance foot, and a foot resting exactly on the ground, do not slide
            if side == s.stance or abs(s.soles[side][:, 2].min()) < 1e-9:
                assert np.abs(vel[side]).max() < 2e-4, (s.t, side)


# -- determinism, threads, a real client ------------------------------------------------------


def test_runs_are_deterministic():
    body = load("op3")
    runs = []
    for _ in range(2):
        scenario = sc.arm_swing(body)
        h = SimHumanoid(body, scenario.goals(0.0))
        ScenarioPlayer(h, scenario).run(0.5)
        runs.append((h.state(), h.foot_forces(), h.imu()))
    (a, fa, ia), (b, fb, ib) = runs
    for x, y in [(a.q, b.q), (a.v, b.v), (a.a, b.a), (a.zmp, b.zmp), (fa.left, fb.left), (ia.specific_force,
                                                                                          ib.specific_force)]:
        assert np.array_equal(x, y)


def test_goals_set_from_other_threads_while_a_realtime_thread_steps():
    body = load("mini")
    stand = sc.Poser(body).standing()
    target = stand + 0.05
    h = SimHumanoid(body, stand, clock=time.monotonic, torque_on=True)
    started = time.monotonic()
    errors: list[BaseException] = []

    def hammer(work):
        try:
            work()
        except BaseException as e:  # reported below
            errors.append(e)

    goals_done = threading.Event()

    def set_goals():
        for k in range(3000):
            h.set_goal(k % 20, stand[k % 20] + 0.001 * (k % 7))
        h.set_goals(target)
        goals_done.set()

    def bus_steps():  # a servo bus stepping the plant lazily, as DynamixelChain does, while goals change
        for _ in range(300):
            h.step(0.004)
            if goals_done.wait(0.0005):
                break

    with RealtimeThread(h, period=0.002):
        workers = [threading.Thread(target=hammer, args=(w,)) for w in (set_goals, bus_steps)]
        for w in workers:
            w.start()
        for w in workers:
            w.join(timeout=10)
        assert not errors and not any(w.is_alive() for w in workers)
        assert wait_until(lambda: np.allclose(h.position, target, atol=1e-4), timeout=3.0)
    elapsed = time.monotonic() - started
    # the bus's step(dt) calls did not add time: the simulation never runs ahead of the clock
    assert 0.1 < h.t <= elapsed + H
    assert h.fallen is None


def test_realtime_thread_reraises_errors():
    body = load("mini")
    h = SimHumanoid(body, sc.Poser(body).standing(), clock=time.monotonic)
    thread = RealtimeThread(h, period=0.001).start()
    h.clock = None  # sync() now fails in the thread
    assert wait_until(lambda: thread.error is not None, timeout=2.0)
    with pytest.raises(InputError, match="no clock"):
        thread.stop()


@pytest.mark.usefixtures("short_gil_switch", "sdk_latency_timer")
def test_dynamixel_sdk_leans_the_simulated_robot_over_a_pty():
    body = load("op3")
    poser = sc.Poser(body)
    stand = poser.standing()
    h = SimHumanoid(body, stand, clock=time.monotonic)
    ids = list(range(1, 21))  # servo ids[i] drives body.joint_names[i]
    chain = DynamixelChain(ids, h, settings={"return_delay_time": 0})
    port = PortHandler(chain.path)
    try:
        assert port.openPort()
        ph = PacketHandler(2.0)
        with RealtimeThread(h):
            torque = GroupSyncWrite(port, ph, 64, 1)
            for i in ids:
                torque.addParam(i, [1])
            assert torque.txPacket() == COMM_SUCCESS
            leaned = stand + poser.ankles_lean(0.15)
            goal = GroupSyncWrite(port, ph, 116, 4)
            for i, rad in zip(ids, leaned, strict=True):
                goal.addParam(i, list(int(round(2048 + rad * 4096 / (2 * np.pi))).to_bytes(4, "little")))
            assert goal.txPacket() == COMM_SUCCESS
            assert wait_until(lambda: np.abs(h.position - leaned).max() < 2e-3, timeout=3.0)
            read = GroupSyncRead(port, ph, 132, 4)
            for i in ids:
                read.addParam(i)
            assert read.txRxPacket() == COMM_SUCCESS
            present = np.array([read.getData(i, 132, 4) for i in ids], dtype=np.int64)
            present = np.where(present >= 2**31, present - 2**32, present)
            np.testing.assert_allclose((present - 2048) * 2 * np.pi / 4096, h.position, atol=4 * 2 * np.pi / 4096)
        s = h.state()
        assert s.com[0] > 0.02 and h.fallen is None  # leaned forward on its feet
    finally:
        port.closePort()
        chain.close()


# -- the live loop's corrector closes the loop ------------------------------------------------


def _closed_loop_lean(body, correct: bool, rate: float = 125.0):
    """The lean scenario, goals sent at ``rate``; with ``correct`` the measured channels
    (base from a BasePlacer on the measured joints, then the joints) go through the
    pipeline and the online corrector, whose leg offsets are added to the goals."""
    scenario = sc.lean(body, beyond=0.004)
    h = SimHumanoid(body, scenario.goals(0.0))
    live = LoopConfig()  # the live loop's estimator (clean encoders), not a stream's default
    est = EstimatorConfig(rate_hz=rate, window_s=live.estimator_window_s, lag_s=live.estimator_lag_s,
                          cutoff_hz=live.estimator_cutoff_hz)
    pipe = Pipeline(body, replace(default_config(body, rate), estimator=est), nominal_dt=1.0 / rate)
    corrector = OnlineCorrector(body, 1.0 / rate)
    measured, commanded = BasePlacer(body), BasePlacer(body)
    deltas = []

    def corrected(t, goals):
        joints = h.position.copy()
        result = pipe.step(t, np.concatenate([measured.update(joints), joints]))
        if result is None:
            return goals
        c = corrector.step(result, np.concatenate([commanded.update(goals), goals]))
        deltas.append(c.delta)
        return goals + c.offsets[6:]

    ScenarioPlayer(h, scenario, rate_hz=rate, correct=corrected if correct else None).run()
    return h, np.array(deltas)


@pytest.mark.parametrize("name", ["op3", "mini"])
def test_online_corrector_keeps_the_leaning_robot_up_and_it_falls_without(name):
    body = load(name)
    off, _ = _closed_loop_lean(body, correct=False)
    assert off.fallen is not None
    on, deltas = _closed_loop_lean(body, correct=True)
    inside = 1 - on.counters.unsupported_steps / on.counters.steps
    print(f"{name}: uncorrected fell at {off.fallen.t:.3f} s; corrected: inside {inside:.4f} of "
          f"{on.counters.steps} steps, worst margin {on.counters.worst_margin * 1e3:.2f} mm, "
          f"max |delta| {np.degrees(np.abs(deltas).max(axis=0)).round(2)} deg")
    assert on.fallen is None
    assert inside >= 0.99
    assert np.degrees(np.abs(deltas).max()) <= 15.0 + 1e-9  # within the corrector's default limit
