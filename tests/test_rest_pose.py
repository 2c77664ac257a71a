"""A BVH take that opens with its skeleton's rest pose (the CMU conversions' T-pose frame, rotations zero) is
analysed as the take that starts at its first moving pose, and written back with the rest pose as it was."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_bvh_massless import motion

from livezmp.cli import main
from livezmp.model.bvh import BvhMotion, read_bvh, write_bvh
from livezmp.model.rest_pose import leading_rest_frames, without_rest_pose
from livezmp.offline.take import TakeOptions, analyse_path
from livezmp.sources.factory import SourceOptions, open_source


def _with_rest_pose(m: BvhMotion) -> BvhMotion:
    """``m`` with its first frame the rest pose: every rotation zero, the root 12 cm higher and 20 cm aside."""
    frames = m.frames.copy()
    rot = np.array([c.endswith("rotation") for c in m.channel_labels()])
    frames[0, rot] = 0.0
    frames[0, :3] += [20.0, 12.0, 0.0]
    return BvhMotion(m.joints, m.frame_time, frames)


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    d = tmp_path_factory.mktemp("rest")
    m = motion(False)
    rest = _with_rest_pose(m)
    held = m.frames.copy()
    held[0] = held[1]
    paths = {"rest": d / "rest.bvh", "held": d / "held.bvh"}
    write_bvh(rest, paths["rest"])
    write_bvh(BvhMotion(m.joints, m.frame_time, held), paths["held"])
    return paths


def test_a_leading_rest_pose_is_analysed_at_the_first_moving_pose(takes, tmp_path):
    """Without the rule the rest frame is motion: a 23 cm jump of the root in 1/30 s, feet and ground 12 cm low."""
    out = {}
    for k, path in takes.items():
        csv, js = tmp_path / f"{k}.csv", tmp_path / f"{k}.json"
        assert main(["analyze", str(path), "--out", str(csv), "--summary-json", str(js)]) == 0
        out[k] = np.genfromtxt(csv, delimiter=",", names=True), json.loads(js.read_text())
    (rest, s_rest), (held, s_held) = out["rest"], out["held"]
    assert s_rest["rest_pose_frames"] == 1 and "rest_pose_frames" not in s_held
    assert s_rest["frames"] == s_held["frames"] == len(read_bvh(takes["rest"]).frames)
    for name in ("zmp_x", "zmp_y", "com_x", "com_y", "com_z", "margin"):
        assert np.array_equal(np.isnan(rest[name]), np.isnan(held[name])), name
        assert np.nanmax(np.abs(rest[name] - held[name])) < 1e-9, name
    assert s_rest["ground_height_m"] == s_held["ground_height_m"]
    whole = {k: analyse_path(p, TakeOptions()).result for k, p in takes.items()}  # the whole-take path (monitor's)
    assert np.abs(whole["rest"].com - whole["held"].com).max() < 1e-9


def test_correct_writes_the_rest_pose_back_as_the_file_has_it(takes, tmp_path):
    outs = {k: tmp_path / f"{k}_corrected.bvh" for k in takes}
    for k, path in takes.items():
        assert main(["correct", str(path), "-o", str(outs[k])]) == 0
    rest, corrected, held = read_bvh(takes["rest"]), read_bvh(outs["rest"]), read_bvh(outs["held"])
    assert np.array_equal(corrected.frames[0], rest.frames[0])
    assert np.abs(corrected.frames[1:] - held.frames[1:]).max() < 1e-6


def test_a_take_that_starts_moving_has_no_rest_pose():
    m = motion(False)
    assert leading_rest_frames(m.channel_labels(), m.frames) == 0
    some = m.frames.copy()
    rot = np.flatnonzero([c.endswith("rotation") for c in m.channel_labels()])
    some[0, rot[::4]] = 0.0  # a quarter of its rotations at zero in the first frame: a pose, not the rest pose
    assert leading_rest_frames(m.channel_labels(), some) == 0
    rested = _with_rest_pose(m)
    held, n = without_rest_pose(rested)
    assert n == 1 and np.array_equal(held.frames[0], m.frames[1]) and np.array_equal(held.frames[1:], m.frames[1:])


def test_a_replay_starts_at_the_first_moving_pose(takes):
    """`monitor`'s file replay and a `--skeleton` file hold the rest frame as `analyze` does."""
    src = {k: open_source(str(p), SourceOptions(speed=0)) for k, p in takes.items()}
    try:
        rows = {k: [s.read(1.0).channels for _ in range(3)] for k, s in src.items()}
    finally:
        for s in src.values():
            s.close()
    assert all(np.array_equal(a, b) for a, b in zip(rows["rest"], rows["held"], strict=True))
