"""Closed loop: the live loop balancing the simulated humanoid, whose true ZMP comes from
its exact whole-body dynamics (sim_devices.humanoid), on simulated time.

The link is the package's mock link driving the humanoid directly; each read and write
is charged the time a 20-servo bus takes (0.6 ms and 0.2 ms), so the loop sees the
latency it would on a bus, and the result does not depend on this machine's load. The
same scenarios with corrections off make the robot fall: the test can fail."""

from __future__ import annotations

import pytest
from test_live_loop import SimTime

from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.scenarios import make_scenario
from sim_devices.humanoid import SimHumanoid
from sim_devices.launch import humanoid_sensors
from sim_devices.mock_link import MockLink

READ_S, WRITE_S = 6e-4, 2e-4


class BusTime:
    """Charges simulated time for each read and write of a link."""

    def __init__(self, link: MockLink, time: SimTime):
        self.link, self.time = link, time
        self.joint_names, self.stats = link.joint_names, link.stats

    def read(self):
        self.time.t += READ_S
        return self.link.read()

    def write_goals(self, goals):
        self.time.t += WRITE_S
        self.link.write_goals(goals)

    def safe_stop(self, drop_torque=False):
        self.link.safe_stop(drop_torque)

    def reconnect(self):
        return self.link.reconnect()


def balance(body, scenario, correct: bool, foot_sensors: bool = False,
            margin_m: float | None = None) -> tuple[SimHumanoid, dict]:
    time = SimTime()
    humanoid = SimHumanoid(body, scenario.goals(0.0))
    mock = MockLink(humanoid, body.joint_names, clock=time.now,
                    foot_sensors=humanoid_sensors(humanoid)[0] if foot_sensors else None)
    mock.open()
    for push in scenario.pushes:  # scenario time is loop time, and the humanoid's (both start at the link's opening)
        humanoid.push(push)
    loop = LiveLoop(BusTime(mock, time), body, LoopConfig(correct=correct, margin_m=margin_m), command=scenario.goals,
                    clock=LoopClock(500.0, now=time.now, sleep=time.advance), fell=lambda: humanoid.fallen is not None)
    return humanoid, loop.run(scenario.duration)


@pytest.mark.parametrize(("name", "options"), [("lean", {"hold_s": 1.0}), ("arm_swing", {"duration": 3.0})])
def test_corrections_keep_the_robot_up_and_without_them_it_falls(mini, name, options):
    scenario = make_scenario(name, mini, **options)
    off, s_off = balance(mini, scenario, correct=False)
    assert off.fallen is not None, f"{name} without corrections should fall"
    assert s_off["stopped_by"] == "fell" and s_off["fell"] is True and s_off["corrections_sent"] == 0
    on, s_on = balance(mini, scenario, correct=True)
    c = on.counters
    true_inside = 1 - c.unsupported_steps / c.steps
    print(f"{name}: uncorrected fell at {off.fallen.t:.2f} s; corrected: true ZMP inside {100 * true_inside:.2f} % "
          f"of {c.steps} steps, worst margin {1e3 * c.worst_margin:.1f} mm, {s_on['corrections_sent']} corrections")
    assert on.fallen is None and s_on["fell"] is False
    assert true_inside >= 0.99
    assert s_on["stopped_by"] == "duration" and s_on["cycles"] == round(scenario.duration * 500)
    assert s_on["corrections_sent"] > 0 and s_on["deadline_misses"] == 0
