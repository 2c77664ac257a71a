"""A looped animation cycle (its last frame repeats its first) is analysed as the loop it is: every frame, the first
and last included, gets the ZMP it has in the middle of the loop played on, as a take of three cycles gives it."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from test_bvh_massless import skeleton

from livezmp.cli import main
from livezmp.model.bvh import BvhMotion, write_bvh
from livezmp.model.loop_cycle import MAX_LOOP_S, find_loop
from livezmp.model.motion_file import load_motion
from livezmp.offline.take import TakeOptions, analyse_loaded, stream_take

PERIOD, DT = 40, 1 / 30  # frames a cycle: 1.33 s, longer than the pads (1 s)
SPEED = 60.0  # cm/s forward, so each cycle starts where the last ended


def cycles(n: int) -> BvhMotion:
    """``n`` cycles of a take swaying over its feet (trunk ±8°, arms ±12°, the rest ±1°, each at the cycle's
    frequency, the root sideways ±3 cm) while it glides forward, ``n * PERIOD + 1`` frames: the last repeats the
    first pose, carried on by the travel."""
    joints = skeleton(False)
    t = np.arange(n * PERIOD + 1) * DT
    w = 2 * np.pi / (PERIOD * DT)
    cols = []
    for j in joints:
        for c in j.channels:
            if c == "Yposition":
                cols.append(np.full(len(t), 96.0))
            elif c == "Zposition":
                cols.append(SPEED * t)
            elif c == "Xposition":
                cols.append(3 * np.sin(w * t))
            else:
                amplitude = 8 if j.name + c == "SpineXrotation" else 12 if "Arm" in j.name else 1
                cols.append(amplitude * np.sin(w * t + sum(map(ord, j.name + c)) % 7))
    return BvhMotion(joints, DT, np.column_stack(cols))


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    d = tmp_path_factory.mktemp("loop")
    paths = {"loop": d / "loop.bvh", "three": d / "three.bvh", "cut": d / "cut.bvh"}
    write_bvh(cycles(1), paths["loop"])
    write_bvh(cycles(3), paths["three"])
    one = cycles(1)
    # the same loop cut where it leans out of its support (frames 14-24 of the cycle are outside): its seam is in
    # the stretch a correction changes most
    write_bvh(replace(one, frames=find_loop(one.channel_labels(), one.frames, DT).rows(one.frames, 17, 18 + PERIOD)),
              paths["cut"])
    return paths


def test_a_looped_cycle_is_analysed_as_the_middle_of_its_loop(takes):
    loop, three = load_motion(takes["loop"]), load_motion(takes["three"])
    assert loop.loop is not None and loop.loop.period == PERIOD
    middle = analyse_loaded(three).zmp[PERIOD: 2 * PERIOD + 1]
    looped = analyse_loaded(loop).zmp
    travel = loop.body.world_from_input @ [0.0, 0.0, SPEED * PERIOD * DT / 100]  # a cycle's, internal frame, m
    err = np.linalg.norm(looped - (middle - travel), axis=1)
    assert err.max() < 2e-3  # m, every frame, the first and last included (0.9 mm: the pads' 1 s against 1.33 s)
    alone = analyse_loaded(replace(loop, loop=None)).zmp  # without the rule: the cycle's ends are the filter's edges
    edge = np.linalg.norm(alone - (middle - travel), axis=1)
    assert edge[[0, 1, -2, -1]].min() > 0.02 and edge[PERIOD // 2] < 1e-3  # 53, 33, 31, 39 mm


def test_analyze_says_so_and_streams_what_the_whole_take_gives(takes, tmp_path):
    csv, js = tmp_path / "z.csv", tmp_path / "s.json"
    assert main(["analyze", str(takes["loop"]), "--out", str(csv), "--summary-json", str(js)]) == 0
    s = json.loads(js.read_text())
    assert s["loop"] == {"period_frames": PERIOD, "padded_frames": 30} and s["frames"] == PERIOD + 1
    rows = np.genfromtxt(csv, delimiter=",", names=True)
    whole = load_motion(takes["loop"]).body.to_input_frame(analyse_loaded(load_motion(takes["loop"])).zmp)
    for axis, name in enumerate(("zmp_x", "zmp_y", "zmp_z")):
        assert np.abs(rows[name] - whole[:, axis]).max() < 1e-6, name  # zmp.csv's 6 decimals


def test_only_a_take_whose_last_frame_repeats_its_first_is_a_loop():
    m = cycles(1)
    labels = m.channel_labels()
    assert find_loop(labels, m.frames, DT) is not None
    assert find_loop(labels, m.frames[:-3], DT) is None  # stops short of its first pose
    moved = m.frames.copy()
    moved[-1, labels.index("Spine.Xrotation")] += 2.0  # one joint 2° off at the seam: not a repeat of the first
    assert find_loop(labels, moved, DT) is None
    long = cycles(9)  # closes on itself too, but is longer than an animation cycle is
    assert len(long.frames) * DT > MAX_LOOP_S and find_loop(labels, long.frames, DT) is None


def test_a_loop_streamed_in_small_chunks_gives_the_whole_takes_rows(takes, tmp_path):
    """Chunks of 7 frames: the first ones are all padding (left out, not passed on empty); progress counts the
    take's own frames."""
    done = []
    stream_take(takes["loop"], TakeOptions(), csv=tmp_path / "z.csv", chunk=7, progress=done.append)
    rows = np.genfromtxt(tmp_path / "z.csv", delimiter=",", names=True)
    whole = load_motion(takes["loop"]).body.to_input_frame(analyse_loaded(load_motion(takes["loop"])).zmp)
    assert len(rows) == PERIOD + 1 and done[-1] == PERIOD + 1 and done == sorted(done)
    assert np.abs(rows["zmp_x"] - whole[:, 0]).max() < 1e-6  # zmp.csv's 6 decimals


def _seam(frames: np.ndarray, labels: list[str]) -> float:
    """The largest rotation channel's difference (deg, wrapped) between a take's last frame and its first."""
    rot = np.array([label.endswith("rotation") for label in labels])
    return float(np.abs((frames[-1, rot] - frames[0, rot] + 180.0) % 360.0 - 180.0).max())


def test_a_looped_cycle_is_corrected_as_a_loop_that_still_closes(takes, tmp_path):
    """`correct` gives a loop one rotation per frame of its cycle, smooth and rate-limited across the seam: the cycle
    it writes closes as the original did and, played as a loop, has no frame outside. Corrected frame by frame (the
    cycle's ends as a take's edges) the seam opens and the loop it makes has frames outside."""
    original = load_motion(takes["cut"])
    labels = original.bvh.channel_labels()
    out, report = tmp_path / "fixed.bvh", tmp_path / "r.json"
    assert main(["correct", str(takes["cut"]), "-o", str(out), "--report", str(report)]) == 0
    r = json.loads(report.read_text())
    assert r["loop"]["period_frames"] == PERIOD and r["out_of_support_before"] == 12 and r["out_of_support_after"] == 0
    fixed = load_motion(out)
    assert fixed.loop is not None and fixed.loop.period == PERIOD
    assert abs(_seam(fixed.bvh.frames, labels) - _seam(original.bvh.frames, labels)) < 1e-5  # BVH's decimals
    played = analyse_loaded(fixed)
    assert not np.any(played.judged & ~played.inside)

    from livezmp.correct.limits import CORRECTION_CUTOFF_HZ
    from livezmp.correct.solver import correct_motion
    from livezmp.offline.take import take_config

    edges = correct_motion(original.body, original.times, original.frames,
                           take_config(original, "full", None, CORRECTION_CUTOFF_HZ), nominal_dt=DT)
    opened = original.body.into_input(original.bvh.frames, edges.frames)
    assert _seam(opened, labels) > 0.2  # deg (0.29)
    played = analyse_loaded(replace(original, frames=edges.frames))  # as the loop the original is
    assert np.sum(played.judged & ~played.inside) >= 3  # 5


def test_monitor_loop_plays_a_looped_cycle_on_as_one_timeline(takes, tmp_path):
    """`monitor --loop` of a looped cycle streams what the three-cycle take holds, frame for frame, with no restart;
    a take that is not a loop still starts over, marked, each lap."""
    from livezmp.sources.factory import SourceOptions, open_source

    three = load_motion(takes["three"])
    source = open_source(str(takes["loop"]), SourceOptions(loop=True, speed=0.0))
    frames = [source.read(1.0) for _ in range(3 * PERIOD + 1)]
    assert not any(f.restart for f in frames)
    assert np.abs(np.array([f.channels for f in frames]) - three.frames).max() < 1e-4  # the BVH's decimals
    assert np.allclose(np.diff([f.t for f in frames]), DT)
    short = tmp_path / "short.bvh"  # stops 3 frames short of its first pose: not a loop
    write_bvh(replace(cycles(1), frames=cycles(1).frames[:-3]), short)
    replay = open_source(str(short), SourceOptions(loop=True, speed=0.0))
    laps = [replay.read(1.0) for _ in range(2 * (PERIOD - 2))]
    assert [k for k, f in enumerate(laps) if f.restart] == [PERIOD - 2]

