"""A BVH take's leading rest pose: frames an exporter put before the motion, not part of it.

The CMU database's BVH conversions (cgspeed's MotionBuilder- and Daz-friendly sets, and the files made from them)
open with the skeleton's rest pose, a T-pose whose rotations are all zero, one frame before the first captured
one. Read as motion it is a jump of 20-150° in one frame: a ZMP a metre off at the start and, worse, a ground
height set by the T-pose's feet, 13 cm below where the subject stands (rgbd_49_04: 76 % of frames with no foot
found on the ground, judged "the floor is not level"). Such frames are held at the first moving frame's pose
(the frame count, and so every row number, stays the file's); a corrected take writes them back as the file has
them.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from livezmp.model.bvh import BvhMotion
from livezmp.model.bvh_body import CALIBRATION_S

# of the rotation channels that move through the frames after it (non-zero in MOVING_SHARE of them), the share
# exactly zero in a frame that makes it a rest pose. Measured over 61 public takes: the CMU conversions' first
# frame 0.53-0.95; every other frame of every take at most 0.17
REST_SHARE = 0.4
MOVING_SHARE = 0.9
MIN_MOVING = 3  # channels: fewer moving ones say nothing about a pose (a single-joint test take)
# s: the window the frames after a candidate are judged by: the first seconds a take's body is made from, all a take
# read in pieces has read when its body is made (livezmp.offline.take_stream)
REST_SCAN_S = CALIBRATION_S
MAX_REST_FRAMES = 5  # leading frames at most held; exporters write one


def leading_rest_frames(labels: list[str], frames: np.ndarray) -> int:
    """How many of the first rows of ``frames`` (F, C; file units and degrees, channels named ``labels`` as
    :meth:`BvhMotion.channel_labels`, e.g. "hip.Xrotation") are a rest pose rather than motion (0: none). Give
    the take's first :data:`REST_SCAN_S` s or all of it: a row is judged by the rows after it."""
    rot = np.array([label.endswith("rotation") for label in labels])
    n = 0
    while n < min(MAX_REST_FRAMES, len(frames) - 2):
        moving = rot & ((frames[n + 1 :] != 0).mean(axis=0) >= MOVING_SHARE)
        if moving.sum() < MIN_MOVING or (frames[n, moving] == 0).mean() < REST_SHARE:
            break
        n += 1
    return n


def hold_rest(frames: np.ndarray, rest: int, first_moving: np.ndarray | None = None, start: int = 0) -> np.ndarray:
    """``frames`` (rows ``start``.. of a take) with the take's first ``rest`` rows set to its first moving row
    (``first_moving``, (C,); default: row ``rest`` of these frames); a copy only where a row changes."""
    end = rest - start
    if end <= 0:
        return frames
    out = frames.copy()
    out[:end] = frames[end] if first_moving is None else first_moving
    return out


def without_rest_pose(motion: BvhMotion) -> tuple[BvhMotion, int]:
    """``motion`` with its leading rest frames (:func:`leading_rest_frames` over its first :data:`REST_SCAN_S` s)
    held at its first moving pose, and how many there were."""
    rest = leading_rest_frames(motion.channel_labels(), motion.frames[: max(2, round(REST_SCAN_S / motion.frame_time))])
    return (replace(motion, frames=hold_rest(motion.frames, rest)), rest) if rest else (motion, 0)
