"""The live loop with the robot's foot sensors: contacts from them, the board's centre of
pressure paired with the analysed sample and compared with the computed ZMP, and the
run recorded (``--record``).

The simulated humanoid's force cells report its true centre of pressure (its exact
ZMP clipped to the feet), so on a standing robot the loop's ZMP and the measured CoP
agree, and a push (which moves the true ZMP but not the motion the loop sees) makes
them differ: the comparison measures something. Runs on simulated time use the mock
link; the fw link runs pyserial against the simulated firmware board on a pty."""

from __future__ import annotations

import json
import math
import signal
import threading
import time

import numpy as np
import pinocchio as pin
import pytest
from sim_support import short_gil_switch  # noqa: F401 - fixture
from test_live_loop import SimTime
from test_live_loop_closed import BusTime
from test_run_cli import line_from, livezmp, stop

from livezmp.balance.contacts import support_label
from livezmp.balance.foot_sensors import GRAVITY
from livezmp.cli import build_parser
from livezmp.commands.run import run_loop
from livezmp.links import open_link
from livezmp.links.base import FootSensors
from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.recorder import LoopRecorder
from livezmp.live.scenarios import Push, make_scenario
from livezmp.model.body_spec import robot_body
from livezmp.model.demo_robot import demo_robot_path
from livezmp.model.robot import load_robot
from livezmp.recording.reader import iter_messages, open_recording
from sim_devices.humanoid import SimHumanoid
from sim_devices.launch import humanoid_sensors, start_devices
from sim_devices.mock_link import MockLink


def recorder_for(body, path, **kw) -> LoopRecorder:
    _, spec = robot_body(demo_robot_path())
    return LoopRecorder(path, spec, {"fps": 500.0}, body.channel_names, body.joint_names, **kw)


def on_sim_time(body, scenario, foot_sensors=None, config=None, recorder=None, duration=1.0):
    """The loop over the mock link on simulated time; (loop, summary, results of real samples by index)."""
    clock = SimTime()
    humanoid = SimHumanoid(body, scenario.goals(0.0))
    mock = MockLink(humanoid, body.joint_names, clock=clock.now,
                    foot_sensors=foot_sensors(humanoid) if foot_sensors else None)
    mock.open()
    loop = LiveLoop(BusTime(mock, clock), body, config or LoopConfig(), command=scenario.goals,
                    clock=LoopClock(500.0, now=clock.now, sleep=clock.advance), recorder=recorder)
    results = {}
    feed = loop._feed

    def keep(t, channels, valid):
        feed(t, channels, valid)
        if loop._fresh:
            results[loop.result.index] = loop.result

    loop._feed = keep
    return loop, loop.run(duration), results


def on_fw_board(body, robot_config, config: LoopConfig, push: Push | None = None, recorder=None, duration=2.0):
    """Stand on the simulated firmware board through pyserial at 100 Hz (``push`` starts
    ``push.start`` s after the loop); the summary."""
    scenario = make_scenario("stand", body)
    humanoid = SimHumanoid(body, scenario.goals(0.0))
    feet, imu = humanoid_sensors(humanoid)
    devices = start_devices("fw", humanoid, robot_config, joint_names=body.joint_names, foot_sensors=feet, imu=imu)
    try:
        url = devices.url + ("&" if "?" in devices.url else "?") + "rate=100"
        link = open_link(url, body.joint_names, robot_config)
        try:
            if push is not None:
                humanoid.push(Push(push.force, push.height, humanoid.t + push.start, push.duration))
            loop = LiveLoop(link, body, config, command=scenario.goals, recorder=recorder,
                            fell=lambda: humanoid.fallen is not None)
            return loop.run(duration)
        finally:
            link.close()
    finally:
        devices.close()


# -- contacts ---------------------------------------------------------------------------------


@pytest.mark.usefixtures("short_gil_switch")
@pytest.mark.parametrize("mode", ["auto", "kinematics"])
def test_on_the_fw_board_contacts_come_from_the_foot_sensors(mini, mini_config, tmp_path, mode):
    """A sideways push (5 N at the hips for 0.4 s) shifts the weight onto the left foot;
    both feet stay on the ground. With a foot counted down above 30 % of the weight, the
    sensors make those samples single support while kinematic detection, which sees two
    feet flat on the ground, keeps them double. Every analysed sample's support is the
    one its recorded sensor contacts give."""
    path = tmp_path / f"{mode}.mcap"
    rec = recorder_for(mini, path)
    config = LoopConfig(rate_hz=100.0, correct=False, contacts=mode, contact_fraction=0.3)
    s = on_fw_board(mini, mini_config, config, Push((0.0, 5.0), 0.25, 0.8, 0.4), recorder=rec)
    rec.close()
    assert s["fell"] is False and s["stopped_by"] == "duration"
    contacts = {m["index"]: m["contacts"] for m in iter_messages(path, "/input")}
    support = {m["index"]: m["support"] for m in iter_messages(path, "/result")}
    print(f"{mode}: {s['contacts']}; supports {sorted(set(support.values()))}; cop_vs_zmp {s['cop_vs_zmp']}")
    assert len(support) == s["analysed_frames"] > 100
    if mode == "auto":
        # the first frames may come before the board's first FOOT_SENSORS message
        assert s["good_frames"] - 5 <= s["contacts"]["from_sensors"] <= s["good_frames"]
        assert all(support[i] == support_label(*contacts[i]) for i in support if contacts[i] is not None)
        single = sum(v == "left" for v in support.values())
        assert 20 <= single <= 60  # the push's 0.4 s at 100 Hz, give or take the debounce
    else:
        assert s["contacts"]["from_sensors"] == 0 and all(c is None for c in contacts.values())
        assert set(support.values()) == {"double"}
    # the loop's ZMP cannot see the push; the sensors do
    assert s["cop_vs_zmp"]["max_mm"] > 20.0


def test_without_foot_sensors_contacts_are_detected_from_the_kinematics(mini):
    """A link with no foot sensors: ``auto`` detects contacts from the kinematics without
    a word; ``sensors`` does too, but counts every such frame and says so (once a second)."""
    stand = make_scenario("stand", mini)
    loop, s, results = on_sim_time(mini, stand, config=LoopConfig(contacts="auto"))
    assert s["contacts"] == {"mode": "auto", "from_sensors": 0, "frames_without_sensors": 0}
    assert s["cop_vs_zmp"] is None and not loop.events
    assert len(results) == s["analysed_frames"] > 400 and {r.support for r in results.values()} == {"double"}
    _, s, _ = on_sim_time(mini, stand, config=LoopConfig(contacts="sensors"), duration=2.5)
    assert s["contacts"]["frames_without_sensors"] == s["good_frames"] == 1250
    told = [e for e in s["events"] if "no foot-sensor reading" in e]
    # at 0 s, then how many in each second since, at 1 and 2 s and at the end
    assert [e.split(":")[0] for e in told] == ["t=0.000s", "t=1.000s", "t=2.000s", "t=2.500s"]
    assert told[1].endswith("(499 in the 1.0 s before)") and told[3].endswith("(250 in the 0.5 s before)")


# -- the board's centre of pressure beside the ZMP ----------------------------------------------


class KnownSensors:
    """Foot sensors that report a known, different reading at every read: the left foot
    carries 60 % of the weight, the right 40 %, each with its own centre of pressure (m,
    sole frame) that steps with the read number."""

    def __init__(self, body):
        self.weight = body.total_mass * GRAVITY
        self.readings: list[FootSensors] = []

    def __call__(self) -> FootSensors:
        n = len(self.readings)
        cop = {"left": np.array([0.002 * (n % 5) - 0.004, 0.003]), "right": np.array([-0.005, 0.001 * (n % 3)])}
        forces = {"left": np.full(4, 0.6 * self.weight / 4), "right": np.full(4, 0.4 * self.weight / 4)}
        self.readings.append(FootSensors(forces, cop))
        return self.readings[-1]


def expected_cop(body, result, reading: FootSensors) -> np.ndarray:
    """The reading's CoP in the result's world frame, by forward kinematics of its q."""
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, result.q)
    total, point = 0.0, np.zeros(3)
    for side, forces in reading.forces.items():
        foot = body.feet[side]
        local = foot.sole_local.mean(axis=0) + np.array([*reading.cop[side], 0.0])
        load = float(forces.sum())
        point += load * data.oMf[foot.frame_id].act(local)
        total += load
    return point / total


def test_each_result_is_paired_with_the_sensor_reading_of_its_own_sample(mini, tmp_path):
    """The reading changes at every sample, so pairing a result with a neighbour's reading
    would be off by millimetres: the logged CoP is, to rounding, the reading of the same
    sample placed by forward kinematics of the result's q on its feet, and its logged
    distance is to that result's ZMP."""
    sensors = KnownSensors(mini)
    path = tmp_path / "pairing.mcap"
    rec = recorder_for(mini, path)
    _, s, results = on_sim_time(mini, make_scenario("lean", mini, hold_s=0.5), lambda h: sensors,
                                LoopConfig(contacts="kinematics"), recorder=rec, duration=1.5)
    rec.close()
    logged = list(iter_messages(path, "/foot_sensors"))
    assert len(logged) == len(results) == s["cop_vs_zmp"]["readings"] == s["analysed_frames"] > 700
    distances = []
    for m in logged:
        # sample i is read i + 1 (no failed reads; read 0: the start-up read the corrector measures the robot in)
        r, reading = results[m["index"]], sensors.readings[m["index"] + 1]
        assert m["t"] == r.t
        assert m["cop_sole"]["left"] == {"x": reading.cop["left"][0], "y": reading.cop["left"][1]}
        cop = np.array([m["cop"][k] for k in "xyz"])
        np.testing.assert_allclose(cop, expected_cop(mini, r, reading), atol=1e-12)
        assert m["zmp_distance"] == pytest.approx(math.hypot(*(cop[:2] - r.zmp[:2])), abs=1e-12)
        distances.append(m["zmp_distance"])
    c = s["cop_vs_zmp"]
    assert c["frames"] == len(logged) and c["max_mm"] == pytest.approx(1e3 * max(distances))
    assert c["mean_mm"] == pytest.approx(1e3 * np.mean(distances))
    # the upper edge of the 0.1 mm bin holding the nearest-rank 95th percentile
    assert 0.0 <= c["p95_mm"] - 1e3 * np.quantile(distances, 0.95, method="inverted_cdf") <= 0.1 + 1e-9


def test_a_standing_robot_cop_matches_the_zmp_and_lean_stays_close(mini):
    """The simulator's sensors in the fw board's conventions, on simulated time: standing,
    the measured CoP is the computed ZMP to rounding; leaning and swinging the arms (the
    demo), within a few millimetres."""
    def sensors(h):
        return humanoid_sensors(h)[0]

    _, stand, _ = on_sim_time(mini, make_scenario("stand", mini), sensors)
    c = stand["cop_vs_zmp"]
    print(f"standing: {c}")
    assert c["frames"] == c["readings"] == stand["analysed_frames"] > 400 and c["max_mm"] < 1e-6
    _, demo, _ = on_sim_time(mini, make_scenario("demo", mini), sensors, duration=6.0)
    c = demo["cop_vs_zmp"]
    print(f"lean, then arm swing: {c}")
    assert demo["fell"] is None and c["frames"] > 2900
    assert 0.05 < c["mean_mm"] < 3.0 and c["p95_mm"] < 8.0 and c["max_mm"] < 30.0


def test_a_three_corner_sole_has_a_cell_under_each_corner_and_its_cop_is_the_zmp(tmp_path):
    """A sole of three corners (Romeo's three force sensors: one at the heel, two at the front): its cells in the fw
    board's four, the quadrant without a corner an empty cell; standing, the measured CoP is the computed ZMP to
    rounding. (Before: refused, the simulated foot cells needed a sole of four corners.)"""
    config = tmp_path / "triangle.toml"
    config.write_text("".join(f'[feet.{side}]\nlink = "{side[0]}_foot"\nsole = [[-0.06, {y}, -0.035], '
                              f'[0.06, {y - 0.033}, -0.035], [0.06, {y + 0.033}, -0.035]]\n'
                              for side, y in (("left", 0.004), ("right", -0.004))))
    body = load_robot(None, str(config)).body
    assert [len(foot.sole_local) for foot in body.feet.values()] == [3, 3]
    _, stand, _ = on_sim_time(body, make_scenario("stand", body), lambda h: humanoid_sensors(h)[0], duration=0.5)
    c = stand["cop_vs_zmp"]
    assert c["frames"] == c["readings"] == stand["analysed_frames"] > 200 and c["max_mm"] < 1e-6


@pytest.mark.usefixtures("short_gil_switch")
def test_cop_vs_zmp_on_the_fw_board_is_finite_and_small_standing(mini, mini_config):
    s = on_fw_board(mini, mini_config, LoopConfig(rate_hz=100.0), duration=1.5)
    c = s["cop_vs_zmp"]
    print(f"fw, standing: {c}")
    assert s["fell"] is False and c["frames"] >= s["analysed_frames"] - 5 > 100
    assert all(math.isfinite(c[k]) for k in ("mean_mm", "p95_mm", "max_mm"))
    assert c["p95_mm"] < 2.0 and c["max_mm"] < 5.0


# -- the recording ------------------------------------------------------------------------------


def test_demo_record_holds_every_sample_result_and_sensor_reading(tmp_path):
    """`livezmp demo --link fw --record`: the file opens as a finished recording; every good
    sample has its /input, every analysed one its /result and /foot_sensors with the same
    index and time, every command its /correction; nothing dropped."""
    path, summary = tmp_path / "run.mcap", tmp_path / "s.json"
    proc = livezmp("demo", "--link", "fw", "--duration", "2", "--quiet", "--record", str(path),
                   "--summary-json", str(summary))
    out, err = proc.communicate(timeout=90)
    assert proc.returncode == 0, err
    s = json.loads(summary.read_text())
    rec = s["recording"]
    assert rec["dropped_total"] == 0 and rec["failed"] == 0 and rec["path"] == str(path)
    counts = open_recording(path).counts
    assert counts == rec["written"]
    assert counts["/input"] == s["good_frames"] > 500
    assert counts["/result"] == counts["/foot_sensors"] == s["analysed_frames"] == s["cop_vs_zmp"]["readings"]
    assert counts["/correction"] == s["commands_sent"]
    inputs = [m["index"] for m in iter_messages(path, "/input")]
    assert inputs == sorted(set(inputs))
    results = {m["index"]: m for m in iter_messages(path, "/result")}
    for m in iter_messages(path, "/foot_sensors"):
        r = results[m["index"]]
        assert m["t"] == r["t"] and m["cop"] is not None
        assert m["zmp_distance"] == pytest.approx(math.hypot(m["cop"]["x"] - r["zmp"]["x"],
                                                             m["cop"]["y"] - r["zmp"]["y"]), abs=1e-12)


def test_a_full_queue_drops_messages_and_counts_them(mini, tmp_path):
    """A writer that cannot keep up (here: its disk stalls until the run ends) leaves the
    loop running on time; what found the queue full is counted per topic, the rest is in
    the file."""
    path = tmp_path / "full.mcap"
    rec = recorder_for(mini, path, capacity=100)
    disk, holding = threading.Event(), threading.Event()
    write = rec.writer.recorder.write

    def stalled(*args):
        holding.set()
        disk.wait()
        write(*args)

    rec.writer.recorder.write = stalled
    _, s, _ = on_sim_time(mini, make_scenario("stand", mini), lambda h: humanoid_sensors(h)[0], recorder=rec)
    held = holding.is_set()  # whether the writer thread got to take a message out before the run ended
    disk.set()
    totals = rec.close()
    offered = {"/input": s["good_frames"], "/result": s["analysed_frames"], "/foot_sensors": s["analysed_frames"],
               "/correction": s["commands_sent"]}
    # the queue's 100, and the one message the stalled writer held if it took one
    kept = 100 + held
    assert sum(totals["written"].values()) == kept and totals["dropped_total"] == sum(offered.values()) - kept
    assert {k: totals["written"][k] + totals["dropped"][k] for k in offered} == offered
    assert open_recording(path).counts == totals["written"]
    assert s["cycles"] == 500 and s["deadline_misses"] == 0


def test_the_file_is_finished_when_the_loop_raises(mini, tmp_path):
    """An exception inside the loop: the safe stop goes out, the exception comes through,
    and the recording is a finished file holding the samples up to it."""
    path = tmp_path / "crash.mcap"
    args = build_parser().parse_args(["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--rate", "100",
                                      "--quiet", "--realtime-priority", "0", "--record", str(path)])
    robot = load_robot(None, None)
    link = open_link("mock:", robot.body.joint_names, robot.config)
    calls = []
    write = link.write_goals

    def failing_write(goals):
        calls.append(goals)
        if len(calls) == 51:  # once: the safe stop's hold after it goes through
            raise RuntimeError("a bug in the middle of the run")
        write(goals)

    link.write_goals = failing_write
    with pytest.raises(RuntimeError, match="a bug"):
        run_loop(link, robot, args, None, 5.0)
    rec = open_recording(path)  # finished: no `livezmp recover` needed
    assert len(calls) == 52  # the safe stop's hold went out after the exception
    assert rec.counts["/input"] == 51 and rec.counts["/correction"] == 50
    inputs = list(iter_messages(path, "/input"))
    assert [m["index"] for m in inputs] == list(range(51))


def test_ctrl_c_finishes_the_recording(tmp_path):
    path, summary = tmp_path / "stopped.mcap", tmp_path / "s.json"
    proc = livezmp("demo", "--link", "mock", "--duration", "0", "--record", str(path), "--summary-json", str(summary))
    try:
        line_from(proc.stderr, time.monotonic() + 40, lambda line: line.startswith("t "))
    finally:
        rc, _, err = stop(proc, signal.SIGINT)
    assert rc == 0, err
    s = json.loads(summary.read_text())
    assert s["stopped_by"] == "SIGINT" and s["recording"]["dropped_total"] == 0
    assert open_recording(path).counts["/input"] == s["good_frames"] > 100


def test_replay_of_a_loop_recording_is_the_same_analysis(tmp_path, capsys):
    """`livezmp replay` re-runs a `demo --record` file with the loop's own estimator settings and
    the recorded sensor contacts: the same results."""
    from livezmp.cli import main

    path = tmp_path / "loop.mcap"
    assert main(["demo", "--link", "mock", "--duration", "1", "--quiet", "--record", str(path)]) == 0
    capsys.readouterr()
    assert main(["replay", str(path)]) == 0
    out = capsys.readouterr().out
    assert "same analysis" in out and "0 support differences" in out
