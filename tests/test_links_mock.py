"""The in-process mock link: a plant stepped on the caller's clock, against the plant's closed-form response."""

from __future__ import annotations

import numpy as np
import pytest
from test_links_support import NAMES

from livezmp.links import FootSensors, LinkError, make_link
from livezmp.model.robot_config import RobotConfig
from sim_devices.mock_link import MockLink
from sim_devices.servo_plant import ServoPlant


class Clock:
    """A clock that moves only when told to (s)."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_goal_step_follows_the_first_order_response_on_the_callers_clock():
    clock = Clock()
    tau = 0.03
    start = np.array([0.1, -0.2, 0.3])
    plant = ServoPlant(3, position=start, tau=tau, max_velocity=1e9, max_acceleration=1e12)  # no limit active
    link = MockLink(plant, NAMES[:3], clock=clock)
    link.open()
    goal = np.array([0.5, 0.0, -0.1])
    link.write_goals(goal)
    for k in range(1, 51):
        clock.t += 0.002
        frame = link.read()
        assert frame.t == clock.t
        np.testing.assert_allclose(frame.positions, goal + (start - goal) * np.exp(-0.002 * k / tau), atol=1e-12)
    assert link.stats.reads == 50 and link.stats.writes == 1


def test_open_holds_torque_on_and_safe_stop_drops_it():
    link = make_link("mock:", ["a", "b"], RobotConfig())
    with pytest.raises(LinkError, match="not open"):
        link.read()
    link.open()
    plant = link.plant  # the mock: URL makes a plant at rest at 0 rad
    assert plant.torque_on.all()
    np.testing.assert_array_equal(plant.goal, [0.0, 0.0])
    link.write_goals(np.array([0.3, -0.3]))
    np.testing.assert_array_equal(plant.goal, [0.3, -0.3])
    link.safe_stop(drop_torque=True)
    assert not plant.torque_on.any()
    assert link.reconnect() is True


def test_sensor_providers_are_passed_through():
    feet = FootSensors({"left": np.ones(4), "right": np.zeros(4)}, {"left": np.zeros(2), "right": None})
    imu = {"orientation": np.array([1.0, 0, 0, 0]), "angular_velocity": np.zeros(3),
           "acceleration": np.array([0, 0, 9.81])}
    link = MockLink(ServoPlant(1), ["a"], foot_sensors=lambda: feet, imu=lambda: imu)
    link.open()
    frame = link.read()
    assert frame.feet is feet and frame.imu is imu
