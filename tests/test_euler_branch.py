"""A BVH joint whose Euler triples jump between the two branches of the same rotations, away from gimbal lock
(Perception Neuron's Axis exports at the neck, every few frames): analysed as the take written on one branch."""

from __future__ import annotations

import json

import numpy as np
from test_bvh_massless import motion

from livezmp.cli import main
from livezmp.model.bvh import BvhMotion, write_bvh
from livezmp.model.euler import other_branch
from livezmp.model.euler_orders import scan_orders


def _jumping(m: BvhMotion, joint: str, every: int = 3) -> BvhMotion:
    """``m`` with ``joint``'s rotation triple written on its other branch every ``every``-th frame (the same poses)."""
    frames = m.frames.copy()
    j = next(j for j in m.joints if j.name == joint)
    cols = [j.first_channel + i for i, c in enumerate(j.channels) if c.endswith("rotation")]
    rows = np.arange(1, len(frames), every)
    frames[np.ix_(rows, cols)] = other_branch(frames[np.ix_(rows, cols)], 180.0)
    return BvhMotion(m.joints, m.frame_time, frames)


def test_a_joint_jumping_branch_is_analysed_as_the_take_on_one_branch(tmp_path):
    """Without the rule the estimator filters each of the head's channels across the jumps into poses between the
    branches: the CoM up to 9 mm off, 4 frames taken for flight, inside 75.6 -> 15.1 %, the ZMP 20.9 m away."""
    plain = motion(False)
    out = {}
    for k, m in {"plain": plain, "jumping": _jumping(plain, "Head")}.items():
        path, csv, js = tmp_path / f"{k}.bvh", tmp_path / f"{k}.csv", tmp_path / f"{k}.json"
        write_bvh(m, path)
        assert main(["analyze", str(path), "--out", str(csv), "--summary-json", str(js)]) == 0
        out[k] = np.genfromtxt(csv, delimiter=",", names=True), json.loads(js.read_text())
    (a, sa), (b, sb) = out["plain"], out["jumping"]
    for name in ("zmp_x", "zmp_y", "com_x", "com_y", "com_z", "margin"):
        assert np.array_equal(np.isnan(a[name]), np.isnan(b[name])), name
        assert np.nanmax(np.abs(a[name] - b[name])) < 1e-6, name
    assert sa["inside_fraction"] == sb["inside_fraction"] and sb["flight_frames"] == 0


def test_a_jump_between_two_pieces_is_found():
    """A take read in pieces: the only jump falls between two blocks."""
    m = motion(False)
    frames = m.frames.copy()
    head = next(k for k, j in enumerate(m.joints) if j.name == "Head")
    cols = [m.joints[head].first_channel + i for i in range(3)]
    frames[45:, cols] = other_branch(frames[45:, cols], 180.0)
    assert scan_orders(m.joints, lambda: (frames[:45], frames[45:])) == {head: "ZXY"}
    assert scan_orders(m.joints, lambda: (m.frames[:45], m.frames[45:])) == {}
