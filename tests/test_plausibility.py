"""Uncertainty and plausibility in every analysis: inside_fraction_tol with its tolerance, and the
verdict on the motion's CoM accelerations against real walks."""

from __future__ import annotations

import json

import numpy as np
import pytest

from livezmp.cli import main
from livezmp.offline.plausibility import WALK_COM_ACC_P99, plausibility
from tests.data_paths import BANDAI, DATA


def test_plausibility_ratios_are_the_closed_form_accelerations():
    """A CoM walking along +x at 1.2 m/s, swaying fore-aft with amplitude A at 2 Hz: its fore-aft
    acceleration peaks at A (2π f)²; the p99 of |sin| is 0.99988."""
    dt, f, amp = 0.005, 2.0, 0.05
    t = np.arange(0, 10, dt)
    com = np.column_stack([1.2 * t + amp * np.sin(2 * np.pi * f * t), np.zeros_like(t), np.full_like(t, 0.9)])
    out = plausibility(com, com.copy(), np.ones(len(t), dtype=bool), dt)
    peak = amp * (2 * np.pi * f) ** 2
    assert out["com_acc_p99_mps2"][0] == pytest.approx(peak * 0.99988, rel=2e-3)
    assert out["ratio"][0] == pytest.approx(peak / WALK_COM_ACC_P99[0], rel=5e-3)
    assert out["verdict"].startswith("not physically plausible") and "fore-aft" in out["verdict"]
    calm = plausibility(com * [1, 1, 1] - np.column_stack([amp * 0.8 * np.sin(2 * np.pi * f * t), 0 * t, 0 * t]),
                        com, np.ones(len(t), dtype=bool), dt)
    assert calm["verdict"].startswith("plausible")


def _summary(tmp_path, path, *extra) -> dict:
    out = tmp_path / "s.json"
    assert main(["analyze", str(path), "--summary-json", str(out), *extra]) == 0
    return json.loads(out.read_text())


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
