"""Mimic joints (URDF ``<mimic joint="P" multiplier="m" offset="o"/>``): the follower's angle is m q_P + o in the
kinematics and in every goal the live loop sends, and neither the scenarios nor the corrector move it on its own.
Truth: the relation the URDF states, and the simulated humanoid's exact whole-body dynamics (simulated time)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import replace

import numpy as np
import pytest
from humanoid_gen import HumanoidSpec, build_humanoid
from test_live_loop import SimTime
from test_live_loop_closed import BusTime, balance

from livezmp.cli import main
from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.scenarios import make_scenario
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
