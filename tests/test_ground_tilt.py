"""The IMU in the estimate: gravity under the feet from the IMU fused with the legs, on a sloped ground.

Truth: closed forms (a still body on a slope has its centre of pressure where the line of gravity
through its CoM meets the ground; a foot turning at a known rate turns gravity in its frame by the
angle turned), and the simulated humanoid's exact whole-body ZMP on a 7 degree slope (simulated time).
Without the IMU the loop's flat-foot estimate is centimetres off: the failure the feature removes."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from test_live_loop import SimTime
from test_live_loop_closed import BusTime

from livezmp.errors import InputError
from livezmp.estimate.ground_tilt import G, GroundTilt
from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.scenarios import make_scenario
from sim_devices.humanoid import SimHumanoid
from sim_devices.launch import humanoid_imu
from sim_devices.mock_link import MockLink

SLOPE = math.radians(7.0)


def quaternion_wxyz(rotation: np.ndarray) -> np.ndarray:
    x, y, z, w = pin.Quaternion(rotation).coeffs()
    return np.array([w, x, y, z])


def ry(angle: float) -> np.ndarray:
    return pin.AngleAxis(angle, np.array([0.0, 1.0, 0.0])).toRotationMatrix()


@pytest.mark.parametrize("reading", ["orientation", "accelerometer"])
def test_a_still_imu_gives_gravity_in_the_sloped_feet_frame(reading):
    # the base pitched 0.2 rad forward relative to feet on a ground rising 7 degrees: in the world the base is
    # pitched by 0.2 - 7 degrees; gravity in the ground's frame is (-g sin a, 0, -g cos a)
    base = np.array([0.0, 0.0, 0.3, 0.0, 0.2, 0.0])
    world = ry(-SLOPE) @ ry(0.2)
    imu = ({"orientation": quaternion_wxyz(world)} if reading == "orientation"
           else {"acceleration": world.T @ np.array([0.0, 0.0, G])})
    tilt = GroundTilt()
    for k in range(5):
        g = tilt.update(0.002 * k, base, imu)
    np.testing.assert_allclose(g, [-G * math.sin(SLOPE), 0.0, -G * math.cos(SLOPE)], atol=1e-9)
    assert tilt.slope_rad == pytest.approx(SLOPE, abs=1e-9)


def test_the_gyro_turns_gravity_with_a_rolling_foot_while_the_accelerometer_is_shaken():
    # a base fixed to its foot (kinematics unchanged) that rolls at 1 rad/s about x for 0.1 s; the accelerometer
    # reads 2 g (outside the 1 g +- 20 % gate) so only the gyro can tell: gravity turns by -0.1 rad about x
    tilt = GroundTilt()
    base = np.zeros(6)
    tilt.update(0.0, base, {"acceleration": np.array([0.0, 0.0, G])})
    for k in range(1, 51):
        g = tilt.update(0.002 * k, base, {"acceleration": np.array([0.0, 0.0, 2 * G]),
                                          "angular_velocity": np.array([1.0, 0.0, 0.0])})
    expected = pin.AngleAxis(0.1, np.array([1.0, 0.0, 0.0])).toRotationMatrix().T @ np.array([0.0, 0.0, -G])
    np.testing.assert_allclose(g, expected, atol=1e-9)


def test_the_simulators_zmp_on_a_slope_is_under_the_com_along_gravity(mini):
    scenario = make_scenario("slope", mini, amplitude=0.0)
    h = SimHumanoid(mini, scenario.goals(0.0), slope=scenario.slope)
    h.advance_to(0.1)
    s = h.state()
    g = h.gravity
    # still: the contact force is -m g, so the centre of pressure is where the line of gravity through the CoM
    # meets the ground plane z = 0
    np.testing.assert_allclose(s.zmp[:2], s.com[:2] - s.com[2] * g[:2] / g[2], atol=1e-6)
    imu = h.imu()
    world_z_in_base = pin.Quaternion(*imu.quaternion[[3, 0, 1, 2]]).toRotationMatrix()[2]
    np.testing.assert_allclose(imu.specific_force, G * world_z_in_base, atol=1e-6)  # at rest: 1 g up, in the world
    with pytest.raises(InputError, match="slope must be a finite angle under 45 degrees"):
        SimHumanoid(mini, slope=math.radians(50))


def zmp_errors(body, scenario, h: SimHumanoid, imu, where=lambda zmp, soles: zmp[:2],
               config: LoopConfig | None = None) -> tuple[np.ndarray, dict]:
    """The loop on ``scenario`` played by ``h`` (reading ``imu``, a provider or None), simulated time; the
    distance (m) of each analysed sample's ZMP to the simulator's true ZMP of the same sample, both taken
    by ``where(zmp, soles)`` (default: x, y in each one's ground frame), and the summary."""
    clock = SimTime()
    mock = MockLink(h, body.joint_names, clock=clock.now, imu=imu)
    mock.open()
    truth = []

    class Truthful(BusTime):
        def read(self):
            frame = super().read()
            s = h.state()
            truth.append(where(s.zmp, s.soles))
            return frame

    loop = LiveLoop(Truthful(mock, clock), body, config or LoopConfig(), command=scenario.goals,
                    clock=LoopClock(500.0, now=clock.now, sleep=clock.advance), fell=lambda: h.fallen is not None)
    errors = []
    feed = loop._feed

    def compare(t, channels, valid):
        feed(t, channels, valid)
        r = loop.result
        if loop._fresh and r.zmp is not None:
            errors.append(float(np.linalg.norm(where(r.zmp, r.soles) - truth[r.index])))

    loop._feed = compare
    summary = loop.run(scenario.duration)
    assert h.fallen is None and summary["stopped_by"] == "duration"
    return np.array(errors), summary


def zmp_error_on_slope(body, imu: str | None) -> tuple[np.ndarray, dict]:
    """`zmp_errors` on the slope scenario (with corrections). ``imu``: None (no IMU), "full" (orientation,
    gyro, accelerometer: a board's) or "raw" (gyro and accelerometer only)."""
    scenario = make_scenario("slope", body, duration=3.0)
    h = SimHumanoid(body, scenario.goals(0.0), slope=scenario.slope)
    reading = humanoid_imu(h)
    provider = None if imu is None else reading if imu == "full" else (
        lambda: {k: v for k, v in reading().items() if k != "orientation"})
    return zmp_errors(body, scenario, h, provider)


@pytest.mark.parametrize("robot", ["livezmp_mini", "robotis_op3"])
def test_on_a_slope_the_imu_makes_the_zmp_right_and_without_it_it_is_centimetres_off(robot, mini, op3_body):
    body = mini if robot == "livezmp_mini" else op3_body
    flat, s_flat = zmp_error_on_slope(body, None)
    full, s_full = zmp_error_on_slope(body, "full")
    raw, s_raw = zmp_error_on_slope(body, "raw")
    for name, e in (("no IMU (flat foot)", flat), ("IMU orientation", full), ("IMU gyro + accelerometer", raw)):
        print(f"{robot} on 7 deg, {name}: ZMP error mean {1e3 * e.mean():.2f} mm, p95 {1e3 * np.percentile(e, 95):.2f},"
              f" max {1e3 * e.max():.2f} ({len(e)} samples)")
    assert s_flat["ground_slope_deg"] is None
    assert s_full["ground_slope_deg"] == pytest.approx(7.0, abs=0.05)
    assert s_raw["ground_slope_deg"] == pytest.approx(7.0, abs=0.05)
    # without the IMU: about the CoM height times tan(7 degrees), a quarter of the foot's length
    assert flat.mean() > 0.025
    for e in (full, raw):
        assert len(e) > 1450 and np.percentile(e, 95) < 0.002 and e.max() < 0.003
