"""Uncertainty and plausibility in every analysis: inside_fraction_tol with its tolerance, and the
verdict on the motion's CoM accelerations against real walks."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from livezmp.cli import main
from livezmp.gait.sinewalk import sine_bvh, walk_spec
from livezmp.model.bvh import write_bvh
from livezmp.offline.plausibility import WALK_COM_ACC_P99, plausibility
from tests.data_paths import BANDAI, DATA


def test_plausibility_ratios_are_the_closed_form_accelerations():
    """A CoM walking along +x at 1.2 m/s, swaying fore-aft with amplitude A at 2 Hz: its fore-aft
    acceleration peaks at A (2π f)²; the p99 of |sin| is 0.99988 (1 % more: the slow part's means, cut short at the
    take's ends, keep some of the swing there)."""
    dt, f, amp = 0.005, 2.0, 0.05
    t = np.arange(0, 10, dt)
    com = np.column_stack([1.2 * t + amp * np.sin(2 * np.pi * f * t), np.zeros_like(t), np.full_like(t, 0.9)])
    out = plausibility(com, com.copy(), np.ones(len(t), dtype=bool), dt)
    peak = amp * (2 * np.pi * f) ** 2
    assert out["com_acc_p99_mps2"][0] == pytest.approx(peak * 0.99988, rel=1.5e-2)
    assert out["ratio"][0] == pytest.approx(peak / WALK_COM_ACC_P99[0], rel=1.5e-2)
    assert out["verdict"].startswith("not physically plausible") and "fore-aft" in out["verdict"]
    calm = plausibility(com * [1, 1, 1] - np.column_stack([amp * 0.8 * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]),
                        com, np.ones(len(t), dtype=bool), dt)
    assert calm["verdict"].startswith("plausible")


def _circle_walk(sway: float, dt: float = 0.01) -> np.ndarray:
    """(N, 3) m: a CoM walking 10 s at 1.3 m/s round a circle of radius 1.2 m (centripetal 1.41 m/s², within the
    turns of the real takes here: their slow part's p99 reaches 1.4-1.8 m/s² in Xsens' and LAFAN1's walks), swaying
    ``sway`` m to the side at a stride frequency of 0.9 Hz (no fore-aft swing: turning, it would add a lateral
    part at the step frequency, 2 v/r times its speed)."""
    t = np.arange(0, 10, dt)
    radius, speed, stride = 1.2, 1.3, 0.9
    heading = speed / radius * t
    reach = radius + sway * np.sin(2 * np.pi * stride * t)
    return np.column_stack([reach * np.cos(heading), reach * np.sin(heading),
                            0.9 + 0.02 * np.sin(2 * np.pi * 2 * stride * t)])


def test_a_turning_walk_is_judged_on_its_steps_not_its_turn():
    """The turn's centripetal acceleration (v²/r) is the slow part; the sway (A (2π f)², 0.80 m/s²) is judged
    against the straight walks' lateral reference. Along the lab's axes the two add up (2.2 m/s², 1.7x)."""
    dt = 0.01
    com = _circle_walk(0.025, dt)
    out = plausibility(com, com, np.ones(len(com), dtype=bool), dt)
    sway = 0.025 * (2 * np.pi * 0.9) ** 2
    assert out["com_acc_p99_mps2"][1] == pytest.approx(sway, rel=0.1)
    assert out["path_acc_p99_mps2"] == pytest.approx(1.3**2 / 1.2, rel=0.05)
    assert out["verdict"].startswith("plausible")
    wide = plausibility(com := _circle_walk(3 * 0.025, dt), com, np.ones(len(com), dtype=bool), dt)
    assert wide["ratio"][1] == pytest.approx(3 * sway / WALK_COM_ACC_P99[1], rel=0.1)
    assert wide["verdict"].startswith("not physically plausible") and "lateral" in wide["verdict"]


def _summary(tmp_path, path, *extra) -> dict:
    out = tmp_path / "s.json"
    assert main(["analyze", str(path), "--summary-json", str(out), *extra]) == 0
    return json.loads(out.read_text())


def _circle_bvh(sway_cm: float, radius: float = 1.2, speed: float = 1.3, stride: float = 0.9):
    """:func:`sine_bvh`'s walk bent round a circle (10 s, y up, cm; its heading turned with it), its root swaying
    ``sway_cm`` to the side at the stride frequency."""
    motion = sine_bvh(walk_spec(), stride, speed, 10.0)
    f = motion.frames
    t = np.arange(len(f)) * motion.frame_time
    heading = speed * t / radius
    side = sway_cm * np.sin(2 * np.pi * stride * t)
    f[:, 0] = 100 * radius * (1 - np.cos(heading)) + side * np.cos(heading)
    f[:, 2] = 100 * radius * np.sin(heading) - side * np.sin(heading)
    turned = Rotation.from_euler("y", heading[:, None]) * Rotation.from_euler("ZXY", f[:, 3:6], degrees=True)
    f[:, 3:6] = turned.as_euler("ZXY", degrees=True)
    return motion


def test_analyze_judges_a_walk_round_a_circle_on_its_steps(tmp_path):
    """The same through ``analyze``: the sine walk round the circle has a within-step lateral acceleration of
    0.65x a real walk's (1.64x along the lab's axes: its turn's 1.41 m/s² with it) and the turn reported; with
    the sway three times as wide, 1.9x. (The sine walk's feet are not found on a ground: its verdict is the
    flight one, so the figures are checked.)"""
    figures = []
    for sway in (2.5, 7.5):
        write_bvh(_circle_bvh(sway), tmp_path / "circle.bvh")
        figures.append(_summary(tmp_path, tmp_path / "circle.bvh")["plausibility"])
    assert figures[0]["ratio"][1] < 1.0 and figures[0]["path_acc_p99_mps2"] == pytest.approx(1.3**2 / 1.2, rel=0.05)
    assert figures[1]["ratio"][1] > 1.8


def test_tolerance_widens_inside_and_is_stated(tmp_path):
    walk = BANDAI / "walk_active_001.bvh"
    s = _summary(tmp_path, walk)
    assert s["tolerance_mm"] == 85.0 and "force plates" in s["tolerance_source"]
    assert s["inside_fraction"] < s["inside_fraction_tol"] < 1.0
    zero = _summary(tmp_path, walk, "--tolerance-mm", "0")
    assert zero["inside_fraction_tol"] == zero["inside_fraction"] and zero["tolerance_source"] == "--tolerance-mm"


def test_real_walks_are_plausible_and_an_exaggerated_take_is_not(tmp_path):
    for path in (DATA / "c3d" / "walk_plugingait_forceplates.c3d", DATA / "c3d" / "cgm24_walking01_forceplate.c3d",
                 BANDAI / "walk_normal_001.bvh"):
        assert _summary(tmp_path, path)["plausibility"]["verdict"].startswith("plausible"), path
    active = _summary(tmp_path, BANDAI / "walk_active_001.bvh")["plausibility"]
    # its vertical CoM acceleration p99 (10.3 m/s²) is twice the largest of 17 real plate walks' (5.2)
    assert active["verdict"].startswith("not physically plausible") and active["ratio"][2] > 1.9
