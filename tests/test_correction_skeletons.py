"""`livezmp correct` on skeletons it was not tuned for (issue 12, item 10): a Bandai walk
re-expressed exactly on other skeletons (tests/skeleton_variants.py: CMU-style hip joints,
rotation-only channels below the root, other channel orders, z up, metres, 120 Hz). The
weight-bearing feet (ankle and toe joints, per the support labels) move at most 1 mm and
the ZMP still comes inside the support polygon. Short clips: the solver costs ~0.1 s/frame."""

from __future__ import annotations

import numpy as np
import pytest
import skeleton_variants as sv
from data_paths import BANDAI

from livezmp.balance.pipeline import default_config
from livezmp.correct.edit import foot_displacement, hold_feet
from livezmp.correct.limits import CORRECTION_CUTOFF_HZ
from livezmp.correct.root_motion import RootMover
from livezmp.correct.solver import correct_motion
from livezmp.model.bvh import read_bvh
from livezmp.model.bvh_body import body_from_bvh

THIGHS = {"L": "UpperLeg_L", "R": "UpperLeg_R"}


def walk(start: int, stop: int):
    s = sv.decompose(read_bvh(BANDAI / "walk_normal_001.bvh"))
    s.trans, s.rot = s.trans[start:stop], s.rot[start:stop]
    return s


VARIANTS = {
    "cmu": lambda: sv.channel_orders(sv.cmu_hip_joints(sv.positions_below_root_dropped(walk(0, 75)), THIGHS), "ZYX"),
    "zup_metres": lambda: sv.channel_orders(sv.scaled(sv.z_up(walk(0, 75)), 0.01), "XYZ", "ZXY"),
    "120hz": lambda: sv.resampled(walk(40, 62), 4),
}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_feet_held_within_1_mm_on_other_skeletons(name):
    motion = sv.compose(VARIANTS[name]())
    body = body_from_bvh(motion)
    times = np.arange(len(motion.frames)) * motion.frame_time
    cfg = default_config(body, motion.fps, cutoff_hz=CORRECTION_CUTOFF_HZ)  # as `livezmp correct` judges it
    result = correct_motion(body, times, motion.frames, cfg, nominal_dt=motion.frame_time)
    rep = result.report()
    # measured independently of the solver's own report: every foot frame, both takes' kinematics
    feet = foot_displacement(body, motion.frames, result.frames, [r.support for r in result.before])
    assert feet["stance"] <= 0.001 and rep["max_foot_displacement_mm"] <= 1.0, (name, feet)
    assert rep["out_of_support_before"] >= 8 and rep["out_of_support_after"] <= rep["out_of_support_before"] // 4, rep


def test_hold_feet_scales_a_rotation_that_would_move_a_loaded_foot():
    motion = read_bvh(BANDAI / "walk_normal_001.bvh")
    body = body_from_bvh(motion)
    frames = motion.frames[40:41]
    mover = RootMover(body)
    delta = np.radians([[6.0, 0.0, 6.0]])  # roll and yaw about the mid-hip: each hip moves ~1 cm
    moved = foot_displacement(body, frames, _applied(mover, body, frames, delta), ["double"])["stance"]
    held, scaled_frames = hold_feet(mover, body, frames, delta, np.array([0.5]), ["double"], 0.0006)
    after = foot_displacement(body, frames, _applied(mover, body, frames, held), ["double"])["stance"]
    assert moved > 0.002 and after <= 0.0006 and scaled_frames == [0]
    assert 0.0 < held[0, 0] / delta[0, 0] < 1.0 and held[0, 0] / delta[0, 0] == pytest.approx(held[0, 2] / delta[0, 2])


def _applied(mover, body, frames, delta):
    from livezmp.correct.edit import apply_delta

    return apply_delta(mover, body, frames, delta, np.array([0.5]))
