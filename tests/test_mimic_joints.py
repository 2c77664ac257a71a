"""Mimic joints (URDF ``<mimic joint="P" multiplier="m" offset="o"/>``): the follower's angle is m q_P + o in the
kinematics and in every goal the live loop sends, and neither the scenarios nor the corrector move it on its own;
on a leg (a double knee) their leg postures and IK put the feet where they asked with the relation imposed.
Truth: the relation the URDF states, the feet a knee of one joint puts where the standing posture says (soles
parallel to the trunk), and the simulated humanoid's exact whole-body dynamics (simulated time)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from humanoid_gen import HumanoidSpec, build_humanoid
from test_live_loop import SimTime
from test_live_loop_closed import BusTime, balance

from livezmp.balance.zmp import compute_zmp
from livezmp.cli import main
from livezmp.correct.root_motion import RootMover
from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.scenarios import Poser, Y, joint_roles, make_scenario, standing_support
from livezmp.model.base_placement import BasePlacer
from livezmp.model.mimic import follow
from livezmp.model.robot import load_robot
from sim_devices.humanoid import SimHumanoid
from sim_devices.mock_link import MockLink

M, O = 0.5, 0.1  # the follower finger: q = 0.5 q_parent + 0.1 rad


def gripper_urdf(path, multiplier=M, offset=O, edit=None):
    """The generated humanoid with a two-finger gripper on each hand, the second finger a mimic of the first."""
    urdf = build_humanoid(path, replace(HumanoidSpec(), grippers=True, seed=3))
    tree = ET.parse(urdf)
    for tag in tree.getroot().iter("mimic"):
        tag.set("multiplier", str(multiplier))
        tag.set("offset", str(offset))
    if edit is not None:
        edit(tree.getroot())
    tree.write(urdf)
    return urdf


@pytest.fixture(scope="module")
def gripper(tmp_path_factory):
    return load_robot(str(gripper_urdf(tmp_path_factory.mktemp("mimic") / "g.urdf")), None).body


def fingers(body):
    names = body.joint_names
    return [(m.joint, m.parent) for m in body.mimics], {names[m.joint]: names[m.parent] for m in body.mimics}


def test_the_urdf_mimics_are_read_with_their_multiplier_and_offset(gripper):
    pairs, named = fingers(gripper)
    assert named == {"l_finger1": "l_finger0", "r_finger1": "r_finger0"}
    assert all((m.multiplier, m.offset) == (M, O) for m in gripper.mimics)


class Recording(BusTime):
    """Keeps the goals written; reads the joint ``misread`` 0.3 rad off (a follower's servo need not agree)."""

    def __init__(self, link, time, misread):
        super().__init__(link, time)
        self.goals, self.misread = [], misread

    def read(self):
        frame = super().read()
        if frame is not None:
            frame.positions[self.misread] += 0.3
        return frame

    def write_goals(self, goals):
        self.goals.append(np.array(goals))
        super().write_goals(goals)


def test_every_goal_sent_for_a_mimic_joint_follows_its_parents_goal(gripper):
    # before: the follower was a servo of its own, sent whatever the command held for it (here 0, then -0.4)
    body = gripper
    scenario = make_scenario("arm_swing", body, duration=1.0)
    (lf, lp), (rf, rp) = fingers(body)[0]

    def command(t):  # the parent fingers close and open; the command asks the followers for something else
        q = scenario.goals(t)
        q[[lp, rp]] = 0.4 * np.sin(2 * np.pi * t)
        q[[lf, rf]] = -0.4
        return q

    time = SimTime()
    humanoid = SimHumanoid(body, scenario.goals(0.0))
    mock = MockLink(humanoid, body.joint_names, clock=time.now)
    mock.open()
    link = Recording(mock, time, misread=lf)
    loop = LiveLoop(link, body, LoopConfig(correct=True), command=command,
                    clock=LoopClock(500.0, now=time.now, sleep=time.advance), fell=lambda: humanoid.fallen is not None)
    summary = loop.run(1.0)
    goals = np.array(link.goals)
    assert summary["cycles"] == 500 and len(goals) > 400
    assert np.ptp(goals[:, lp]) > 0.5  # the parents did move
    for f, p in ((lf, lp), (rf, rp)):
        np.testing.assert_allclose(goals[:, f], M * goals[:, p] + O, atol=1e-12)
    # the kinematics put the follower where its parent's reading puts it, not where its own servo says
    q = loop.result.q[len(body.base_channels):]
    assert q[lf] == pytest.approx(M * q[lp] + O, abs=1e-9) and abs(q[lp]) > 0.05
    # the servos followed, so the simulated fingers keep the relation up to the servos' lag
    q = humanoid.servo.position
    assert q[lf] == pytest.approx(M * q[lp] + O, abs=0.02)


def test_the_scenarios_and_the_loop_hold_the_relation_and_the_robot_still_balances(gripper):
    scenario = make_scenario("arm_swing", gripper, duration=3.0)
    (lf, lp), _ = fingers(gripper)[0]
    for t in (0.0, 0.7, 2.1):
        g = scenario.goals(t)
        assert g[lf] == pytest.approx(M * g[lp] + O)
    off, _ = balance(gripper, scenario, correct=False)
    on, _ = balance(gripper, scenario, correct=True)
    assert off.fallen is not None and on.fallen is None


def test_a_mimic_of_a_mimic_follows_the_first_joint_of_the_chain(tmp_path):
    def chain(root):  # l_finger1 mimics l_finger0 (0.5, 0.1); make l_finger0 mimic l_el (2, -0.2)
        joint = next(j for j in root.iter("joint") if j.get("name") == "l_finger0")
        ET.SubElement(joint, "mimic", joint="l_el", multiplier="2", offset="-0.2")

    body = load_robot(str(gripper_urdf(tmp_path / "c.urdf", edit=chain)), None).body
    names = body.joint_names
    got = {names[m.joint]: (names[m.parent], m.multiplier, m.offset) for m in body.mimics}
    # q1 = 0.5 (2 q_el - 0.2) + 0.1 = q_el + 0
    assert got["l_finger0"] == ("l_el", 2.0, -0.2)
    assert got["l_finger1"][0] == "l_el" and got["l_finger1"][1:] == pytest.approx((1.0, 0.0))


@pytest.mark.parametrize(("edit", "says"), [
    (lambda m: m.set("joint", "no_such_joint"), "joint='no_such_joint' is not another joint"),
    (lambda m: m.set("multiplier", "nan"), "must be finite"),
    (lambda m: m.set("offset", "half"), "must be numbers"),
])
def test_a_bad_mimic_is_refused_in_one_line(tmp_path, capsys, edit, says):
    urdf = gripper_urdf(tmp_path / "b.urdf", edit=lambda root: edit(next(root.iter("mimic"))))
    rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "lean", "--duration", "0.1"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and "<mimic>" in err[0] and says in err[0], err


def test_a_joint_csv_and_the_monitors_link_source_put_the_follower_where_its_parent_says(gripper, tmp_path):
    from livezmp.links.base import LinkFrame, LinkStats
    from livezmp.model.motion_file import trajectory_frames
    from livezmp.model.trajectory_csv import JointTrajectory
    from livezmp.sources.link_source import LinkSource

    (lf, lp), (rf, rp) = fingers(gripper)[0]
    nb = len(gripper.base_channels)
    q = np.zeros((3, len(gripper.joint_names)))
    q[:, lp] = (0.1, 0.2, 0.3)
    q[:, lf] = 0.7  # what the file (or a servo) says of the follower: not where its parent puts it
    frames = trajectory_frames(gripper, JointTrajectory(t=np.arange(3) * 0.01, q=q, joint_names=gripper.joint_names))
    np.testing.assert_allclose(frames[:, nb + lf], M * q[:, lp] + O)

    class OneFrame:  # a link whose follower servo reads 0.7
        joint_names, stats = gripper.joint_names, LinkStats()

        def read(self):
            return LinkFrame(t=1.0, positions=q[0].copy())

    source = LinkSource("fake", gripper, None, None, link=OneFrame())
    frame = source.read(timeout=0.1)
    assert frame.channels[nb + lf] == pytest.approx(M * 0.1 + O)


# -- a mimic joint on a leg: a double knee, its lower joint following the upper (multiplier 1) ----------------

@pytest.fixture(scope="module")
def double_knee(tmp_path_factory):
    spec = HumanoidSpec(double_knee=True, names="poppy", seed=5)
    return load_robot(str(build_humanoid(tmp_path_factory.mktemp("knee") / "k.urdf", spec)), None).body


def soles(body, q):
    """Both soles' corners (8, 3), m, in the base's frame (``q``: the joints, base at the origin) or the world's
    (``q``: the whole configuration)."""
    data = body.model.createData()
    q = np.concatenate([np.zeros(len(body.base_channels)), q]) if len(q) < body.model.nq else q
    pin.framesForwardKinematics(body.model, data, q)
    return np.concatenate([f.sole_local @ data.oMf[f.frame_id].rotation.T + data.oMf[f.frame_id].translation
                           for f in body.feet.values()])


def test_a_double_knees_postures_put_the_feet_where_the_scenario_asks(double_knee):
    # before: the scenario bent the upper knee by 2 theta, then its follower was made to bend as much: 4 theta of
    # knee, each sole turned 2 theta (0.6 rad) from the trunk's level and 72-82 mm from where it was asked
    body = double_knee
    names = body.joint_names
    assert sorted((names[m.joint], names[m.parent], m.multiplier) for m in body.mimics) == [
        ("l_knee2", "l_knee_y", 1.0), ("r_knee2", "r_knee_y", 1.0)]
    assert joint_roles(body)["l_knee"] == "l_knee_y"  # the follower plays no role
    poser = Poser(body)

    def one_knee(theta):  # the standing posture as the scenario states it, the upper knee taking all the bend
        return poser.arms_down(0.1) + sum(theta * (-poser.unit(f"{s}_hip_pitch", Y) + 2 * poser.unit(f"{s}_knee", Y)
                                                   - poser.unit(f"{s}_ank_pitch", Y)) for s in "lr")

    stood = soles(body, poser.standing())
    assert np.ptp(stood[:, 2]) < 1e-9  # level, parallel to the trunk, as the standing posture says
    scenario = make_scenario("lean", body, hold_s=1.0)
    for t in (0.0, 1.5, 3.0):  # standing, mid-lean, leaning past the toes
        goals = scenario.goals(t)
        for m in body.mimics:
            assert goals[m.joint] == pytest.approx(goals[m.parent], abs=1e-12)
        asked = one_knee(0.3) + (goals - poser.standing())  # the lean: the ankles on top of it
        held = np.abs(soles(body, goals) - soles(body, asked)).max()
        unheld = np.abs(soles(body, follow(asked, body.mimics)) - soles(body, asked)).max()
        print(f"t={t} s: sole error {1e3 * held:.2g} mm; without the relation in the posture {1e3 * unheld:.0f} mm")
        assert held < 1e-3 < unheld
    squat = make_scenario("squat", body)  # the legs bent anew each cycle (the IK warm-started from the last)
    for t in np.arange(0.0, 2.0, 0.01):
        flexion = 0.3 + 0.3 * 0.5 * (1.0 - np.cos(np.pi * t))  # its depth 0.3 over its period 2 s
        assert np.abs(soles(body, squat.goals(t)) - soles(body, one_knee(flexion))).max() < 1e-3


def test_the_correctors_leg_ik_keeps_a_double_knees_feet(double_knee):
    # before: the IK moved the follower on its own; the loop then sent it its parent's goal, and the soles went
    # 1.3 mm (0.1 rad of trunk pitch) to 6.2 mm (0.26 rad, the corrector's limit) from where they stood
    body = double_knee
    q = np.concatenate([np.zeros(len(body.base_channels)), make_scenario("lean", body, hold_s=1.0).goals(3.0)])
    ignoring = RootMover(replace(body, mimics=()))
    base = len(body.base_channels)
    for pitch in (0.1, 0.26):
        errors = []
        for mover in (RootMover(body), ignoring):
            moved = mover.apply(q, np.array([0.0, pitch, 0.0]), 0.5)
            sent = np.concatenate([moved[:base], follow(moved[base:], body.mimics)])  # what the loop makes of it
            errors.append(np.abs(soles(body, sent) - soles(body, q)).max())
        print(f"trunk pitch {pitch} rad: sole error {1e3 * errors[0]:.2g} mm, the IK ignoring the relation "
              f"{1e3 * errors[1]:.1f} mm")
        assert errors[0] < 1e-3 < errors[1]


def test_a_double_knee_robot_falls_leaning_uncorrected_and_stands_corrected(double_knee):
    lean = make_scenario("lean", double_knee, hold_s=1.0)
    lean = replace(lean, duration=lean.duration - 2.0)  # through the hold (falls uncorrected), not the lean back
    off, _ = balance(double_knee, lean, correct=False)
    on, _ = balance(double_knee, lean, correct=True)
    print(f"uncorrected fell at {off.fallen and off.fallen.t:.2f} s; corrected: fell {on.fallen}, worst true "
          f"margin {1e3 * on.counters.worst_margin:.1f} mm")
    assert off.fallen is not None and on.fallen is None


def double_shoulder(tmp_path, arm):
    """The generated humanoid whose arms' first joint (``arm[0]``) is followed by a second about the same axis."""
    spec = HumanoidSpec(arm=arm, double_shoulder=True, seed=31)
    return load_robot(str(build_humanoid(tmp_path / f"s_{arm}.urdf", spec)), None).body


def test_arms_with_a_double_shoulder_roll_hang_where_the_posture_says(tmp_path):
    # before: the roll was found for the arm as if it turned alone; with its follower turning as much, each upper
    # arm hung 0.171 rad (9.8 deg) from vertical, not the 0.1 rad asked
    body = double_shoulder(tmp_path, "rpe")
    names = body.joint_names
    assert sorted(names[m.parent] for m in body.mimics) == ["l_sho_roll", "r_sho_roll"]
    poser = Poser(body)
    sent = make_scenario("stand", body).goals(0.0)
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, np.concatenate([np.zeros(len(body.base_channels)), sent]))
    for s, lateral in (("l", 1.0), ("r", -1.0)):
        arm = poser.arms[s]
        d = (data.oMi[body.model.getJointId(arm.elbow)].translation
             - data.oMi[body.model.getJointId(arm.roll)].translation)
        assert np.arctan2(lateral * d[1], -d[2]) == pytest.approx(0.1, abs=1e-9)  # out from vertical, as asked
        assert abs(d[0]) < 1e-12


def test_an_arm_swing_with_a_double_shoulder_pitch_takes_the_zmp_as_far_as_it_was_designed_to(tmp_path):
    # before: the swing was designed with the follower standing still while the goals sent swung it with its
    # parent: twice the swing, and the ZMP went 9.6 mm past the toes where 4 mm was asked
    body = double_shoulder(tmp_path, "pre")
    scenario = make_scenario("arm_swing", body)  # ARM_SWING: the ZMP 4 mm past the toes at each swing's peak
    q0 = scenario.goals(0.0)
    base = BasePlacer(body).update(q0)
    toe = float(standing_support(body, q0)[1][:, 0].max())
    data, h, still = body.model.createData(), 1e-4, np.zeros(len(base))
    past = []
    for t in np.arange(1.5, 3.0, 0.002):  # the swing at its full amplitude: the goals sent, differentiated
        g = [scenario.goals(t + k * h) for k in (-1, 0, 1)]
        assert g[1][[m.joint for m in body.mimics]] == pytest.approx(g[1][[m.parent for m in body.mimics]])
        zmp = compute_zmp(body.model, data, np.concatenate([base, g[1]]),
                          np.concatenate([still, (g[2] - g[0]) / (2 * h)]),
                          np.concatenate([still, (g[2] - 2 * g[1] + g[0]) / h ** 2])).zmp
        past.append(float(zmp[0]) - toe)
    assert max(past) == pytest.approx(0.004, abs=1e-4)
    off, _ = balance(body, scenario, correct=False)
    on, _ = balance(body, scenario, correct=True)
    print(f"peak ZMP {1e3 * max(past):.2f} mm past the toes; uncorrected fell at {off.fallen and off.fallen.t:.2f} s, "
          f"corrected: fell {on.fallen}")
    assert off.fallen is not None and on.fallen is None
