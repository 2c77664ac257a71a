"""ServoPlant against closed-form motion: first-order tracking, velocity and acceleration
limits, coasting with torque off, hard stops, and the current estimate."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_devices.servo_plant import ServoPlant

INF = math.inf


def run(plant: ServoPlant, seconds: float, dt: float) -> None:
    for _ in range(round(seconds / dt)):
        plant.step(dt)


@pytest.mark.parametrize("dt", [1e-4, 1e-3, 7e-3, 0.05])
def test_unlimited_tracking_is_exactly_first_order_for_any_step(dt):
    plant = ServoPlant(3, position=[0.0, 1.0, -2.0], tau=[0.02, 0.05, 0.1], max_velocity=INF,
                       max_acceleration=INF)
    goals = np.array([1.0, -1.0, 0.5])
    for i, goal in enumerate(goals):
        plant.set_goal(i, goal)
        plant.set_torque(i, True)
    t = 0.35
    run(plant, t, dt)
    expected = goals + (np.array([0.0, 1.0, -2.0]) - goals) * np.exp(-t / plant.tau)
    np.testing.assert_allclose(plant.position, expected, rtol=0, atol=1e-12)


def test_velocity_limit_gives_a_constant_speed_ramp():
    plant = ServoPlant(1, tau=0.01, max_velocity=2.0, max_acceleration=INF)
    plant.set_goal(0, 10.0)
    plant.set_torque(0, True)
    run(plant, 0.5, 1e-3)
    assert plant.position[0] == pytest.approx(2.0 * 0.5, abs=1e-9)
    assert plant.velocity[0] == pytest.approx(2.0)


def test_acceleration_limit_gives_a_parabola_from_rest():
    amax, h, t = 50.0, 1e-3, 0.2
    plant = ServoPlant(1, tau=0.01, max_velocity=INF, max_acceleration=amax, max_substep=h)
    plant.set_goal(0, 100.0)
    plant.set_torque(0, True)
    run(plant, t, h)
    # Each step moves at the velocity it ends with, so the discrete sum exceeds a t^2 / 2 by a t h / 2.
    assert plant.velocity[0] == pytest.approx(amax * t, rel=1e-9)
    assert plant.position[0] == pytest.approx(amax * t * t / 2, abs=amax * t * h / 2 + 1e-9)


def test_torque_off_coasts_with_exponentially_decaying_velocity():
    v0, tau_c, t = 3.0, 0.05, 0.08
    plant = ServoPlant(1, tau=0.01, max_velocity=INF, max_acceleration=INF, coast_time_constant=tau_c)
    plant.velocity[:] = v0
    run(plant, t, 1e-3)
    assert plant.velocity[0] == pytest.approx(v0 * math.exp(-t / tau_c), rel=1e-9)
    assert plant.position[0] == pytest.approx(v0 * tau_c * (1 - math.exp(-t / tau_c)), rel=1e-9)
    assert plant.current[0] == 0.0
    run(plant, 2.0, 1e-3)
    assert abs(plant.velocity[0]) < 1e-12  # comes to rest


def test_goal_is_ignored_while_torque_is_off():
    plant = ServoPlant(1)
    plant.set_goal(0, 1.0)
    run(plant, 0.5, 1e-3)
    assert plant.position[0] == 0.0


def test_hard_stop_holds_the_joint_at_its_limit():
    plant = ServoPlant(1, upper=0.3, max_velocity=INF, max_acceleration=INF)
    plant.set_goal(0, 1.0)
    plant.set_torque(0, True)
    run(plant, 0.5, 1e-3)
    assert plant.position[0] == 0.3
    assert plant.velocity[0] == 0.0


def test_current_is_damping_plus_load_over_torque_constant():
    plant = ServoPlant(2, damping=0.2, torque_constant=1.5, max_velocity=1.0, max_acceleration=INF)
    plant.external_torque[:] = [0.0, 0.9]
    plant.set_goal(0, 50.0)  # cruising at the velocity limit: no acceleration
    plant.set_torque(0, True)
    plant.set_torque(1, True)  # holding still against a load
    run(plant, 0.1, 1e-3)
    assert plant.current[0] == pytest.approx(0.2 * 1.0 / 1.5)
    assert plant.current[1] == pytest.approx(0.9 / 1.5)


def test_long_step_is_bounded_and_stable():
    plant = ServoPlant(1, max_substeps=10)
    plant.set_goal(0, 1.0)
    plant.set_torque(0, True)
    plant.step(30.0)  # 10 substeps of 3 s each: no overshoot, ends at the goal
    assert plant.position[0] == pytest.approx(1.0)


def test_state_arrays_are_updated_in_place():
    plant = ServoPlant(1, max_acceleration=INF)
    position = plant.position
    plant.set_goal(0, 0.2)
    plant.set_torque(0, True)
    plant.step(0.5)
    assert position[0] == pytest.approx(0.2, abs=1e-6)


def test_bad_parameter_names_itself():
    with pytest.raises(ValueError, match="'tau' must be a scalar or have 3 entries"):
        ServoPlant(3, tau=[0.1, 0.2])
    with pytest.raises(ValueError, match="'max_velocity' must be > 0"):
        ServoPlant(2, max_velocity=0.0)


def test_steps_of_changing_length_each_use_their_own_factors():
    # the substep factors are made once per step length: a step of another length makes them again
    plant = ServoPlant(2, position=[0.0, 1.0], tau=[0.02, 0.05], max_velocity=INF, max_acceleration=INF)
    goals = np.array([1.0, -1.0])
    for i, goal in enumerate(goals):
        plant.set_goal(i, goal)
        plant.set_torque(i, True)
    t = 0.0
    for dt in (1e-3, 5e-4, 1e-3, 2e-4, 5e-4):
        plant.step(dt)
        t += dt
        expected = goals + (np.array([0.0, 1.0]) - goals) * np.exp(-t / plant.tau)
        np.testing.assert_allclose(plant.position, expected, rtol=0, atol=1e-12)


def test_all_joints_driven_move_as_when_another_joint_coasts():
    # every joint on skips the coasting terms: the driven joints' state is the general path's, bit for bit
    rng = np.random.default_rng(3)
    start, goal = rng.uniform(-1, 1, 4), rng.uniform(-2, 2, 4)
    driven = ServoPlant(4, position=start, lower=-1.2, upper=1.2, max_acceleration=80.0)
    mixed = ServoPlant(5, position=np.append(start, 0.3), lower=-1.2, upper=1.2, max_acceleration=80.0)
    mixed.velocity[4] = 2.0
    for i in range(4):
        for plant in (driven, mixed):
            plant.set_goal(i, goal[i])
            plant.set_torque(i, True)
    for k in range(300):
        load = rng.normal(0.0, 0.3, 4)
        driven.external_torque[:], mixed.external_torque[:4] = load, load
        dt = 1e-3 if k % 3 else 4e-4
        driven.step(dt)
        mixed.step(dt)
        for name in ("position", "velocity", "current"):
            assert np.array_equal(getattr(driven, name), getattr(mixed, name)[:4]), (k, name)
    assert mixed.current[4] == 0.0 and mixed.velocity[4] != 0.0  # the fifth joint coasted throughout
