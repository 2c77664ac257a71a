"""Instrumented treadmills (livezmp.offline.treadmill): a synthetic walker whose stance feet ride the belts
backwards, its contacts, belts, plausibility and gait speed; an overground walk and a standing take not taken for one.

The walker's feet each walk in their own belt's frame: stance still there, swing carried forward a stride on a
smooth (1 - cos) profile, lifted 8 cm; in the lab the belt moves its foot back at its speed. Its Plug-in Gait
lower-body markers (z up, metres, walking along +x) ride a pelvis that travels at ``travel`` m/s (0 on a treadmill),
its knees placed by the legs' two-link geometry.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.balance.support import SUPPORT_LABELS
from livezmp.cli import main
from livezmp.gait.features import walk_features
from livezmp.gait.take import load_take
from livezmp.model.c3d import C3dTrial
from livezmp.model.markers import MarkerBodyOptions, body_from_markers
from livezmp.offline.batch import run_batch
from livezmp.offline.gaitlab import LabOptions, analyse_lab_take
from livezmp.offline.treadmill import SIDES, find_treadmill
from tests.test_c3d_gaitlab import _points_c3d

RATE, SECONDS, MASS = 100.0, 8.0, 70.0
CYCLE_S, STANCE = 1.1, 0.6  # gait cycle (s) and the stance's part of it
LIFT_M = 0.08  # the swing foot's lift
THIGH_M = SHANK_M = 0.45
PELVIS_Z = 0.93
EDGE_S = 0.5  # the take's ends: the estimator's one-sided window (0.4 s), left out of the frame-by-frame checks
# frames on either side of a true touch-down or lift-off where detection may differ: the hysteresis (a foot lifts
# off above 5 cm or 1 m/s relative to the belt) and the debounce (2 frames at 100 Hz)
TRANSITION_FRAMES = 6
BELT_TOL_MPS = 0.03  # the belt speed recovered within this


def _stance(t: np.ndarray, phase0: float) -> np.ndarray:
    """(F,) bool: the foot in stance (gait phase within the stance part of its cycle)."""
    return np.mod(t / CYCLE_S + phase0, 1.0) < STANCE


def _foot(t: np.ndarray, phase0: float, speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Ankle x and lift z (F,) m of a foot walking at ``speed`` m/s, in its belt's frame less its mean travel (so
    periodic about 0): still in stance, a stride forward in swing."""
    phase = t / CYCLE_S + phase0
    cycle, frac = np.floor(phase), np.mod(phase, 1.0)
    swing = np.clip((frac - STANCE) / (1 - STANCE), 0.0, 1.0)
    stride = speed * CYCLE_S
    x = stride * (cycle + 0.5 * (1 - np.cos(np.pi * swing))) - speed * CYCLE_S * phase
    return x - x.mean(), LIFT_M * np.sin(np.pi * swing)


def _knee(hip: np.ndarray, ankle: np.ndarray) -> np.ndarray:
    """(F, 3) knee centre of the two-link leg from ``hip`` to ``ankle`` (F, 3) m, bent forward (+x)."""
    d = ankle - hip
    r = np.minimum(np.linalg.norm(d[:, [0, 2]], axis=1), 0.999 * (THIGH_M + SHANK_M))
    a = np.arctan2(d[:, 2], d[:, 0])
    bend = np.arccos((THIGH_M**2 + r**2 - SHANK_M**2) / (2 * THIGH_M * r))
    return hip + THIGH_M * np.column_stack([np.cos(a + bend), 0 * a, np.sin(a + bend)])  # in the hip's sagittal plane


def walker(t: np.ndarray, speeds: tuple[float, float], travel: float) -> dict[str, np.ndarray]:
    """(F, 3) m per label: the walker with its (left, right) feet walking at ``speeds`` m/s in their belts' frames
    and its pelvis travelling at ``travel`` m/s in the lab (the belts then run at speed - travel, backwards)."""
    out = {}
    sway = np.column_stack([0.01 * np.sin(4 * np.pi * t / CYCLE_S), 0.02 * np.sin(2 * np.pi * t / CYCLE_S),
                            0.01 * np.cos(4 * np.pi * t / CYCLE_S)])
    pelvis = np.column_stack([travel * t, 0 * t, PELVIS_Z + 0 * t]) + sway
    for (side, sign), phase0, speed in zip((("L", 1.0), ("R", -1.0)), (0.0, 0.5), speeds, strict=True):
        x, lift = _foot(t, phase0, speed)
        ankle = np.column_stack([x + travel * t, sign * 0.10 + 0 * t, 0.08 + lift])
        hip = pelvis + [0.0, sign * 0.085, -0.05]
        knee = _knee(hip, ankle)
        lateral = np.array([0.0, sign, 0.0])
        out |= {side + "ASI": pelvis + [0.05, sign * 0.12, 0.02], side + "PSI": pelvis + [-0.10, sign * 0.05, 0.05],
                side + "THI": (hip + knee) / 2 + 0.07 * lateral, side + "KNE": knee + 0.05 * lateral,
                side + "TIB": (knee + ankle) / 2 + 0.05 * lateral, side + "ANK": ankle + 0.035 * lateral,
                side + "HEE": ankle + [-0.06, 0.0, -0.04], side + "TOE": ankle + [0.15, 0.0, -0.05]}
    return out


def _trial(speeds: tuple[float, float], travel: float) -> C3dTrial:
    m = walker(np.arange(int(SECONDS * RATE)) / RATE, speeds, travel)
    return C3dTrial("synthetic walker", list(m), np.stack(list(m.values()), axis=1), RATE, RATE, 0.0, [], MASS,
                    "PROCESSING:Bodymass", 1.75)


def _contacts(lab) -> dict[str, np.ndarray]:
    """Each foot's detected contact (F,) bool."""
    labels = np.asarray(SUPPORT_LABELS)[lab.result.support]
    return {s: np.isin(labels, (s, "double")) for s in SIDES}


def _wrong_frames(lab) -> dict[str, int]:
    """Per foot, the frames (away from the take's ends and the true transitions) whose detected contact is not the
    walker's stance."""
    t = lab.times - lab.times[0]
    inner = (t >= EDGE_S) & (t <= t[-1] - EDGE_S)
    out = {}
    for side, phase0 in zip(SIDES, (0.0, 0.5), strict=True):
        truth = _stance(t, phase0)
        change = np.flatnonzero(np.diff(truth.astype(int)))
        near = np.zeros(len(t), dtype=bool)
        for c in change:
            near[max(c - TRANSITION_FRAMES, 0):c + TRANSITION_FRAMES + 2] = True
        out[side] = int(np.sum((_contacts(lab)[side] != truth) & inner & ~near))
    return out


def _assert_same_zmp_moved_by_the_belt(lab, overground, speed: float) -> None:
    """The ZMP in the lab needs no change on a belt at constant speed (an inertial frame): it is the overground
    walk's moved back by the belt's travel, to 0.1 mm fore-aft and 3 mm laterally (the lateral band's low-pass sees
    the two takes' different travel near its ends) away from the take's ends. Holds on main too: a check, not a fix."""
    t = lab.times
    inner = (t >= t[0] + EDGE_S) & (t <= t[-1] - EDGE_S)
    moved = overground.result.zmp - np.outer(t, [speed, 0.0, 0.0])
    error = np.abs(lab.result.zmp - moved)[inner]
    assert error[:, 0].max() < 1e-4 and error[:, 1].max() < 3e-3


@pytest.mark.parametrize("speeds", [(1.1, 1.1), (0.7, 1.2)], ids=["tied", "split"])
def test_a_treadmill_walks_contacts_are_judged_on_its_belts(speeds):
    """The walker on a treadmill (tied belts at 1.1 m/s; split belts at 0.7 and 1.2 m/s), its body in place: every
    stance found (no frame wrong away from the transitions, no flight) and each belt's speed recovered within 0.03
    m/s, running backwards (-x). Judged on a floor at rest, the feet riding the belts faster than 1 m/s are taken
    for swinging (main: the tied walk's every frame flight or single support)."""
    lab = analyse_lab_take(_trial(speeds, 0.0))
    assert lab.treadmill is not None and lab.treadmill.source == "estimated"
    for side, speed in zip(SIDES, speeds, strict=True):
        v = lab.treadmill.velocity[side]
        assert abs(v[0] + speed) < BELT_TOL_MPS and abs(v[1]) < BELT_TOL_MPS, (side, v)
    assert _wrong_frames(lab) == {"left": 0, "right": 0}
    assert not np.any(lab.result.support == SUPPORT_LABELS.index("none"))
    if speeds[0] == speeds[1]:  # the walk seen from its belt is the overground walk: the same support, frame by frame
        overground = analyse_lab_take(_trial(speeds, speeds[0]))
        assert np.array_equal(lab.result.support, overground.result.support)
        _assert_same_zmp_moved_by_the_belt(lab, overground, speeds[0])
    off = analyse_lab_take(_trial(speeds, 0.0), LabOptions(treadmill="off"))
    assert max(_wrong_frames(off).values()) > 100


def test_an_overground_walk_is_not_taken_for_a_treadmill():
    """The same walker travelling at 1.1 m/s over a floor at rest: no treadmill, every stance found as before."""
    lab = analyse_lab_take(_trial((1.1, 1.1), 1.1))
    assert lab.treadmill is None and lab.summary["treadmill"] is None
    assert _wrong_frames(lab) == {"left": 0, "right": 0}


def test_a_standing_take_is_not_taken_for_a_treadmill():
    """The walker standing (feet still, the pelvis swaying): no treadmill."""
    lab = analyse_lab_take(_trial((0.0, 0.0), 0.0))
    assert lab.treadmill is None


def test_analyze_says_the_belts_and_judges_the_walk_plausible(tmp_path, capsys):
    """`livezmp analyze` of the treadmill walk: no flight, a plausible walk, the summary's treadmill its belts; with
    --treadmill off the flight and the implausible verdict a floor at rest gives; a given speed is used as given."""
    path = _points_c3d(tmp_path / "walk.c3d", walker(np.arange(int(SECONDS * RATE)) / RATE, (1.1, 1.1), 0.0))
    out = tmp_path / "s.json"
    assert main(["analyze", str(path), "--summary-json", str(out)]) == 0
    s = json.loads(out.read_text())
    assert s["flight_frames"] == 0 and s["plausibility"]["verdict"].startswith("plausible")
    assert s["treadmill"]["source"] == "estimated"
    assert s["treadmill"]["belt_mps"] == pytest.approx([1.1, 1.1], abs=BELT_TOL_MPS)
    assert "treadmill: belts at 1.1" in capsys.readouterr().out
    assert main(["analyze", str(path), "--summary-json", str(out), "--treadmill", "off"]) == 0
    s = json.loads(out.read_text())
    assert s["flight_frames"] > 0 and s["treadmill"] is None
    assert main(["analyze", str(path), "--summary-json", str(out), "--treadmill", "1.1"]) == 0
    s = json.loads(out.read_text())
    assert s["treadmill"]["source"] == "given" and s["flight_frames"] == 0
    assert s["treadmill"]["belt_velocity_mps"]["left"] == pytest.approx([-1.1, 0.0, 0.0])


@pytest.mark.parametrize("value", ["fast", "1,2,3", "-1", "nan"])
def test_a_bad_treadmill_option_is_refused_in_one_line(value, tmp_path, capsys):
    path = _points_c3d(tmp_path / "walk.c3d", walker(np.arange(300) / RATE, (1.1, 1.1), 0.0))
    assert main(["analyze", str(path), f"--treadmill={value}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--treadmill" in err


def test_find_treadmill_needs_both_feet_riding_one_way_and_skips_gaps():
    """Feet whose stance velocities point opposite ways (no belt does that) are no treadmill; frames missing from a
    sole are no samples (the belt found as without them), a body path ending in a gap no evidence."""
    t = np.arange(800) / RATE
    m = walker(t, (1.1, 1.1), 0.0)
    soles = {s: np.stack([m[k + "HEE"], m[k + "TOE"]], axis=1) for s, k in zip(SIDES, "LR", strict=True)}
    pelvis = (m["LASI"] + m["RASI"]) / 2
    soles["left"][100:120] = np.nan
    found = find_treadmill(soles, pelvis, 1 / RATE)
    assert found is not None and found.velocity["left"] == pytest.approx([-1.1, 0.0], abs=BELT_TOL_MPS)
    assert find_treadmill(soles, np.where(t[:, None] < 7.9, pelvis, np.nan), 1 / RATE) is None
    soles["right"] = soles["right"] * [-1.0, 1.0, 1.0]
    assert find_treadmill(soles, pelvis, 1 / RATE) is None


def test_gait_speed_and_stride_of_a_treadmill_walk_are_the_belts(tmp_path, capsys):
    """`livezmp gait`: the treadmill walk's speed is the belt's (its body drifting nowhere) and its stride the
    overground walk's, within 0.03 m/s and 3 cm; read on a floor at rest (main) its speed was the body's drift."""
    t = np.arange(int(SECONDS * RATE)) / RATE
    belt = _points_c3d(tmp_path / "belt.c3d", walker(t, (1.1, 1.1), 0.0))
    floor = _points_c3d(tmp_path / "floor.c3d", walker(t, (1.1, 1.1), 1.1))
    on_belt, overground = walk_features(load_take(belt)), walk_features(load_take(floor))
    assert on_belt.speed == pytest.approx(1.1, abs=BELT_TOL_MPS)
    assert on_belt.stride_length == pytest.approx(overground.stride_length, abs=0.03)
    assert on_belt.stride_length == pytest.approx(1.1 * CYCLE_S, abs=0.03)
    assert walk_features(load_take(belt, treadmill="off")).speed < 0.05
    assert main(["gait", "compare", str(belt), str(floor)]) == 0
    assert "on a treadmill's belt at 1.1" in capsys.readouterr().out


def test_the_per_frame_pipeline_judges_contacts_on_the_belts_as_the_batch_path_does():
    """A belt in the pipeline's settings: stepping frame by frame gives the batch path's support labels."""
    take = body_from_markers(_trial((0.7, 1.2), 0.0), MarkerBodyOptions(total_mass=MASS))
    times = np.arange(len(take.frames)) / RATE
    cfg = replace(default_config(take.body, RATE), belt=((-0.7, 0.0), (-1.2, 0.0)))
    batch = run_batch(Pipeline(take.body, cfg, nominal_dt=1 / RATE), times, take.frames)
    stepped = Pipeline(take.body, cfg, nominal_dt=1 / RATE).run(times, take.frames)
    assert [r.support for r in stepped] == list(batch.labels)
    assert "none" not in batch.labels[50:-50]
