"""Goals move no faster than their joints' URDF velocity limits (`GoalLimiter`): a motion that steps is sent
to the servos as a ramp at the joint's top speed, counted in the summary and recorded (audit 10's leftover:
a 0 -> 3 rad step between two rows went to the servos in one cycle)."""

from __future__ import annotations

import math

import numpy as np
from test_live_loop import RATE, T, _limits, scripted_loop

from livezmp.live.config import LoopConfig, SafetyConfig
from livezmp.live.recorder import LoopRecorder
from livezmp.live.safety import GoalLimiter, JointLimits
from livezmp.live.scenarios import make_scenario
from livezmp.model.body_spec import robot_body
from livezmp.model.demo_robot import demo_robot_path
from livezmp.recording.reader import iter_messages


def test_a_goal_moves_from_the_last_one_at_most_its_joint_speed_a_period():
    """Joint 0 steps 0 -> 0.8 rad (5 rad/s: 0.01 rad a 2 ms period): 80 periods of 0.01 rad; the other joints,
    asked nothing faster, are sent as asked; the first goals after `start_from` move from that posture."""
    limiter = GoalLimiter(_limits(), SafetyConfig(), T)
    limiter.start_from(np.zeros(3))
    step = np.array([0.8, 0.005, -0.004])
    sent, cuts = [], 0
    for _ in range(100):
        goals, limited, slowed = limiter.apply(step, np.zeros(3))
        sent.append(goals)
        cuts += slowed is not None
        assert limited == (slowed is not None)
        if slowed is not None:
            assert slowed.joint == 0 and list(slowed.mask) == [True, False, False]
            assert math.isclose(slowed.allowed, 5.0 * T)
    sent = np.array(sent)
    assert cuts == 79  # 0.8 rad is reached in the 80th period, uncut
    assert np.abs(np.diff(np.vstack([np.zeros(3), sent]), axis=0)).max() <= 5.0 * T + 1e-12
    assert np.array_equal(sent[-1], step) and np.array_equal(sent[:, 1:], np.tile(step[1:], (100, 1)))


def test_a_command_held_beyond_a_joint_limit_is_not_counted_as_slowed():
    """Joint 0 asked for 2 rad (its limit 1, less the 0.01 margin): paced to 0.99 in 99 periods, each counted;
    then held there, nothing more counted (bez2's head_pitch was counted every cycle this way)."""
    limiter = GoalLimiter(_limits(), SafetyConfig(), T)
    limiter.start_from(np.zeros(3))
    slowed = [limiter.apply(np.array([2.0, 0.0, 0.0]), np.zeros(3))[2] for _ in range(150)]
    assert sum(s is not None for s in slowed) == 98 and limiter.goals[0] == 0.99


def test_a_joint_without_a_urdf_velocity_moves_at_the_default_speed():
    lim = JointLimits(["a", "b"], np.full(2, -3.0), np.full(2, 3.0), np.array([math.inf, 2.0]))
    limiter = GoalLimiter(lim, SafetyConfig(default_joint_speed_rad_s=1.0), T)
    limiter.start_from(np.zeros(2))
    goals, _, slowed = limiter.apply(np.array([3.0, 3.0]), np.zeros(2))
    assert np.allclose(goals, [1.0 * T, 2.0 * T]) and slowed.mask.all()


def test_a_non_finite_goal_does_not_poison_the_next_ones():
    """A NaN command is the link's to refuse; the joint's next goals move from the last finite one."""
    limiter = GoalLimiter(_limits(), SafetyConfig(), T)
    limiter.start_from(np.zeros(3))
    goals, _, slowed = limiter.apply(np.array([np.nan, 0.0, 0.0]), np.zeros(3))
    assert np.isnan(goals[0]) and slowed is None
    goals, _, _ = limiter.apply(np.array([0.5, 0.0, 0.0]), np.zeros(3))
    assert goals[0] == 5.0 * T


def _step_motion(body, joint: str, at: float, to: float):
    j = body.joint_names.index(joint)

    def command(t: float) -> np.ndarray:
        q = np.zeros(len(body.joint_names))
        q[j] = to if t >= at else 0.0
        return q

    return command, j


def test_a_motion_that_steps_reaches_the_servos_at_the_joints_speed_counted_and_told(mini):
    """A motion whose l_sho_pitch steps 0 -> 1.5 rad at 0.6 s (livezmp_mini's URDF: 4.8 rad/s). On main the whole
    step went out in one cycle; now every written goal is within 4.8 rad/s x 2 ms of the one before, for ~156 cycles,
    each counted (`goals_slowed`) and told at most once a second. Uncorrected and corrected."""
    command, j = _step_motion(mini, "l_sho_pitch", 0.6, 1.5)
    allowed = 4.8 * T
    for correct in (False, True):
        loop, link, _, events = scripted_loop(mini, command=command, config=LoopConfig(rate_hz=RATE, correct=correct))
        s = loop.run(duration=1.2)
        goals = np.array([g for _, g, _ in link.writes])
        steps = np.abs(np.diff(goals, axis=0))
        assert steps[:, j].max() <= allowed + 1e-12, correct
        assert goals[-1, j] == 1.5
        slowed = s["goals_slowed"]
        assert slowed["commands"] == math.ceil(1.5 / allowed) - 1 == s["goals_slowed"]["joints"]["l_sho_pitch"]
        told = [e for e in events if "slowed to its speed limit" in e]
        assert told and told[0].startswith("t=0.600s: goal of l_sho_pitch slowed") and "4.80 rad/s" in told[0]
        assert len(told) <= 2 and s["corrections_limited"] >= slowed["commands"]


def test_goals_slowed_are_on_the_recording_with_counts_that_add_up(mini, tmp_path):
    """r_sho_pitch steps 0 -> -2 rad at 0.3 s: 208 slowed commands over 0.42 s, folded into /device_error records
    (at most one a second) whose counts add up to the summary's."""
    command, _ = _step_motion(mini, "r_sho_pitch", 0.3, -2.0)
    loop, _, _, _ = scripted_loop(mini, command=command, config=LoopConfig(rate_hz=RATE, correct=False))
    path = tmp_path / "r.mcap"
    loop.recorder = LoopRecorder(path, robot_body(demo_robot_path())[1], {"fps": RATE}, mini.channel_names,
                                 mini.joint_names)
    s = loop.run(duration=1.5)
    loop.recorder.close(s)
    records = [m for m in iter_messages(path, "/device_error") if m["kind"] == "goal_speed"]
    assert len(records) == 2 and records[0]["t"] == 0.3 and "r_sho_pitch" in records[0]["message"]
    assert sum(m["count"] for m in records) == s["goals_slowed"]["commands"] == math.ceil(2.0 / (4.8 * T)) - 1


def test_the_demo_scenarios_on_livezmp_mini_stay_within_its_joint_speeds(mini):
    """The built-in scenarios already move slower than the URDF allows: none is cut (their outputs unchanged)."""
    for name in ("lean", "arm_swing", "push", "squat"):
        sc = make_scenario(name, mini)
        ts = np.arange(0.0, sc.duration, T)
        speed = np.abs(np.diff(np.array([sc.goals(t) for t in ts]), axis=0)).max() / T
        assert speed < 4.8, (name, speed)


def test_a_late_loop_keeps_the_pace_of_a_motion_within_the_joint_speeds(mini):
    """A motion at 4 rad/s (under livezmp_mini's 4.8) on a loop whose cycles take 2.5 ms of a 2 ms period: it skips
    deadlines, so its goals move 2 periods' worth at a time now and then. They are not slowed: the limit counts the
    loop time since the goals before (up to MAX_PACE_PERIODS), as the command does. (With the nominal period
    alone, a humanoid's arm swing within its joints' speeds was slowed on a loaded machine and no longer fell.)"""
    j = mini.joint_names.index("l_sho_pitch")
    clock = []

    def command(t: float) -> np.ndarray:
        clock[0].t += 2.5e-3  # the cycle's work
        q = np.zeros(len(mini.joint_names))
        q[j] = 4.0 * min(t, 0.5)
        return q

    loop, link, time, _ = scripted_loop(mini, command=command,
                                        config=LoopConfig(rate_hz=RATE, correct=False, ramp_s=1e-9))
    clock.append(time)
    s = loop.run(duration=0.8)
    assert s["clock"]["skipped_cycles"] > 100 and s["goals_slowed"]["commands"] == 0
    goals = np.array([g[j] for _, g, _ in link.writes])
    steps = np.diff(goals)
    # each goal the command's at its cycle's loop time (4 rad/s x 2 ms = 0.008 rad a period): one or two periods on
    assert set(np.round(steps[goals[1:] < 2.0] / 0.008, 9)) == {1.0, 2.0}
