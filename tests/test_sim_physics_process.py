"""The simulated humanoid stepping in a process of its own (sim_devices.physics_process): goals and torque
written in this process drive its joints there, its state and sensors come back, and it stops cleanly."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

from livezmp.errors import InputError
from livezmp.live.scenarios import Push, make_scenario
from sim_devices.humanoid import SimHumanoid
from sim_devices.physics_process import PhysicsProcess
from tests.sim_support import wait_until


def test_goals_in_this_process_move_the_joints_stepped_in_another(mini):
    posture = make_scenario("stand", mini).goals(0.0)
    humanoid = SimHumanoid(mini, posture, clock=time.monotonic, device_steps=False)
    physics = PhysicsProcess(humanoid, sensors=True)
    try:
        remote = physics.humanoid
        assert physics.pid != os.getpid()
        t0 = remote.t
        assert wait_until(lambda: remote.t >= t0 + 0.05)  # it steps on its own, to the clock
        knee = mini.joint_names.index("l_knee")
        goal = posture[knee] + 0.2
        remote.set_torque(knee, True)
        remote.set_goal(knee, goal)
        # the servo plant tracks the goal (first order, limited speed): there within the deadline
        assert wait_until(lambda: abs(remote.position[knee] - goal) < 1e-3, timeout=5.0)
        others = np.delete(np.arange(len(posture)), knee)
        np.testing.assert_allclose(remote.position[others], posture[others], atol=1e-12)  # torque off: held
        # its sensors: the foot cells carry the robot's weight, the IMU reads gravity along the base's z
        weight = mini.total_mass * 9.81
        assert wait_until(lambda: abs(remote.foot_forces().total - weight) < 0.02 * weight)
        assert np.linalg.norm(remote.imu().specific_force) == pytest.approx(9.81, rel=0.02)
        assert remote.fallen is None and remote.counters.steps > 0
    finally:
        physics.close()
    with pytest.raises(ChildProcessError):  # reaped by close()
        os.waitpid(physics.pid, os.WNOHANG)


def test_only_a_clocked_humanoid_left_to_its_thread_can_be_stepped_elsewhere(mini):
    with pytest.raises(InputError, match="device_steps=False"):
        PhysicsProcess(SimHumanoid(mini, clock=time.monotonic))


def test_an_error_in_the_physics_process_is_raised_by_close(mini):
    humanoid = SimHumanoid(mini, make_scenario("stand", mini).goals(0.0), clock=time.monotonic, device_steps=False)
    physics = PhysicsProcess(humanoid)
    remote = physics.humanoid
    remote.goal[0] = float("nan")  # past set_goal's check: the physics process's own check refuses it
    # a step under way when the goal was written may still publish, once (a catch-up step can cover
    # several ms); the next one takes the goal and stops
    t0 = remote.t
    wait_until(lambda: remote.t != t0, timeout=0.1)
    t = remote.t
    assert not wait_until(lambda: remote.t > t, timeout=0.2)  # it stopped stepping
    with pytest.raises(InputError, match="not finite"):
        physics.close()


def test_a_request_is_answered_between_steps_and_stepping_goes_on(mini):
    # the wait between steps wakes for a request (its poll object watches the pipe), not only at the next step
    humanoid = SimHumanoid(mini, make_scenario("stand", mini).goals(0.0), clock=time.monotonic, device_steps=False)
    physics = PhysicsProcess(humanoid)
    remote, took, answered = physics.humanoid, [], True

    def push() -> None:
        t0 = time.monotonic()
        remote.push(Push(force=(1.0, 0.0), height=0.3, start=remote.t + 0.01, duration=0.02))
        took.append(time.monotonic() - t0)

    try:
        for _ in range(20):
            asking = threading.Thread(target=push, daemon=True)
            asking.start()
            asking.join(2.0)
            answered = not asking.is_alive()
            assert answered, "the physics process did not answer"
        assert max(took) < 0.1  # a step's wait is at most a few ms
        t = remote.t
        assert wait_until(lambda: remote.t >= t + 0.02)  # and it steps on
    finally:
        if not answered:  # deaf to the stop as well: its end unblocks the waiting request, then close reaps it
            os.kill(physics.pid, signal.SIGKILL)
        physics.close()


def test_a_fall_nobody_asked_about_is_still_told_after_the_close(mini):
    """`livezmp sim` gives its verdict after closing its physics: a fall the devices never asked about (a
    Dynamixel chain has no IMU to read it through) must come back with the stop, not be asked of a closed
    pipe (before: OSError 'handle is closed', a traceback where the closing line should be)."""
    humanoid = SimHumanoid(mini, make_scenario("stand", mini).goals(0.0), clock=time.monotonic, device_steps=False)
    physics = PhysicsProcess(humanoid)
    remote = physics.humanoid
    try:
        # a shove from behind far beyond what its feet hold (the robot weighs a few kg)
        remote.push(Push(force=(60.0, 0.0), height=0.3, start=remote.t, duration=1.0))
        assert wait_until(lambda: remote._a["status"][4], timeout=10.0)  # fell there; not asked here
    finally:
        physics.close()
    assert remote.fallen is not None and remote.fallen.t > 0
