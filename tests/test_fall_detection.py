"""Fall detection from the IMU: thresholds on synthetic readings, and a run against a simulator in
another process, whose only way to tell the host it fell is its IMU (as on hardware)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from livezmp.links import open_link
from livezmp.live.config import LoopConfig
from livezmp.live.fall_detection import FallConfig, FallDetector, tilt_between
from livezmp.live.loop import LiveLoop
from livezmp.live.scenarios import make_scenario
from sim_devices.process import SimProcess


def about_y(angle: float) -> np.ndarray:
    """(w, x, y, z) of a rotation by ``angle`` rad about the y axis."""
    return np.array([math.cos(angle / 2), 0.0, math.sin(angle / 2), 0.0])


UPRIGHT = {"acceleration": np.array([0.0, 0.0, 9.81])}


def test_tilt_is_the_angle_between_the_z_axes():
    assert tilt_between(about_y(0.0), about_y(0.3)) == pytest.approx(0.3)
    assert tilt_between(about_y(0.2), about_y(-0.5)) == pytest.approx(0.7)


def test_a_tilt_past_the_threshold_for_the_hold_time_is_a_fall():
    detector = FallDetector(FallConfig(tilt_rad=math.radians(45), hold_s=0.05))
    t = 0.0
    for angle in np.radians([0, 10, 30, 44]):
        assert detector.update(t, {**UPRIGHT, "orientation": about_y(angle)}) is None
        t += 0.01
    for _ in range(5):  # 46 degrees for 40 ms: not yet
        assert detector.update(t, {**UPRIGHT, "orientation": about_y(math.radians(46))}) is None
        t += 0.01
    t += 0.001  # 51 ms
    assert "tilted 46 degrees for 51 ms" in detector.update(t, {**UPRIGHT, "orientation": about_y(math.radians(46))})


def test_the_tilt_counts_from_the_first_reading_so_a_tilted_mount_is_no_fall():
    detector = FallDetector()
    for k in range(20):  # mounted 30 degrees off, then the robot leans 30 more: 60 absolute, 30 relative
        angle = math.radians(30 if k < 10 else 60)
        assert detector.update(0.01 * k, {**UPRIGHT, "orientation": about_y(angle)}) is None
    assert detector.max_tilt == pytest.approx(math.radians(30))


def test_free_fall_is_a_fall():
    detector = FallDetector()
    falling = {"orientation": about_y(0.0), "acceleration": np.array([0.0, 0.0, 0.5])}
    assert detector.update(0.0, falling) is None
    assert "free fall (0.05 g)" in detector.update(0.06, falling)


def against_a_simulator(kind: str, body, robot_config, correct: bool, scenario: tuple[str, dict],
                        url_options: str = "", config_path: str | None = None) -> tuple[dict, dict]:
    """The loop at 100 Hz against the simulator in another process, with no fall flag: only what the link
    reads (its IMU) can tell it the robot fell. (summary, the simulator's verdict)."""
    command = make_scenario(scenario[0], body, **scenario[1])
    with SimProcess(kind, scenario, config=config_path) as sim:
        link = open_link(sim.url + url_options, body.joint_names, robot_config)
        try:
            sim.start_scenario()
            s = LiveLoop(link, body, LoopConfig(rate_hz=100.0, correct=correct), command=command.goals).run(
                command.duration)
        finally:
            link.close()
        return s, sim.verdict()


@pytest.mark.parametrize("correct", [False, True], ids=["uncorrected", "corrected"])
def test_the_host_tells_the_simulators_fall_from_its_imu(mini, mini_config, correct):
    """The fw board in another process; the loop gets no fall flag, only the board's IMU. Leaning past the
    toes, the uncorrected robot falls and the loop stops on the IMU's word; the corrected one stands."""
    s, truth = against_a_simulator("fw", mini, mini_config, correct, ("lean", {}), "&rate=100")
    print(truth["fall"], s["imu_fall"], s["stopped_by"], s["imu_max_tilt_deg"])
    assert s["fell"] is truth["fell"] is (not correct)
    if correct:
        # it leans forwards at the ankles (and the corrector tilts the trunk back a little), far from 45 degrees
        assert s["stopped_by"] == "duration" and s["imu_max_tilt_deg"] < 25
    else:
        assert s["stopped_by"] == "fell" and "tilted" in s["imu_fall"]
