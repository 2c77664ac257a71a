"""A take that closes on itself: a looped animation cycle, analysed as the loop it is.

Animation exports (Mixamo's walks and idles, game-engine cycles) are one cycle whose last frame repeats its first,
made to be played over and over. Analysed alone, the cycle's first and last frames are the estimator's edges: on
Mixamo's 36-frame walks 7 of the 14 frames outside support were in the first 9, while the filter's window formed.
Such a take is padded before and after with its own cycle (the root carried on by the cycle's travel, so each
repetition starts where the last one ended), analysed, and the pads' results dropped: every frame of the file is
then judged as a frame in the middle of the loop. Nothing else is changed, and the summary says it was done.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# the seam (last frame against first, each rotation channel, wrapped) as a share of the take's median frame-to-frame
# change (the largest channel's). Measured over 61 public BVH takes: the looped ones (Mixamo, K-Scale's) 0.00-0.08;
# every other take at least 0.3 (most 2-100)
SEAM_SHARE = 0.1
MOVING_DEG = 1.0  # a rotation channel moving less than this over the take says nothing about the seam
MIN_MOVING = 3  # channels: a take with fewer moving ones is not judged (a single-joint test take)
MIN_PERIOD = 4  # frames: a shorter "cycle" is a pose held, not a loop
MAX_LOOP_S = 10.0  # s: longer takes are not judged (read whole to be; animation cycles are 1-5 s)
PAD_S = 1.0  # s of the cycle analysed before and after the take: the estimator's window and the contacts settle


@dataclass(frozen=True)
class Loop:
    """A take's loop: ``period`` frames a cycle (the take's frames but its last, which repeats its first);
    ``positions`` (C,) bool: the position channels, carried on by each cycle's travel (the other channels repeat)."""

    period: int
    positions: np.ndarray

    def pad_frames(self, frame_time: float) -> int:
        """Frames of the cycle analysed before the take and after it (:data:`PAD_S` s, ``frame_time`` s a frame)."""
        return max(1, round(PAD_S / frame_time))

    def padded(self, frames: np.ndarray, t0: float, fps: float) -> tuple[int, np.ndarray, np.ndarray]:
        """The take's ``frames`` (F, C) at ``fps`` Hz with :meth:`pad_frames` of the loop before and after them:
        that count ``lead``, their times (s, the take's first at ``t0``) and rows (F + 2 ``lead``, C)."""
        lead, n = self.pad_frames(1.0 / fps), len(frames)
        return lead, t0 + np.arange(-lead, n + lead) / fps, self.rows(frames, -lead, n + lead)

    def rows(self, frames: np.ndarray, start: int, stop: int) -> np.ndarray:
        """Frames ``start``..``stop``-1 of the loop played on (negative: before the take's first frame), from the
        take's ``frames`` (F, C), whose columns ``positions`` names: a frame k is the cycle's frame k mod
        ``period``, its positions moved on by k // ``period`` cycles' travel."""
        k = np.arange(start, stop)
        laps, at = np.divmod(k, self.period)
        travel = np.where(self.positions, frames[self.period] - frames[0], 0.0)
        return frames[at] + laps[:, None] * travel


def find_loop(labels: list[str], frames: np.ndarray, frame_time: float) -> Loop | None:
    """The loop of a take whose last frame repeats its first, or None. ``labels`` name the columns of ``frames``
    (F, C; degrees for rotation channels, as :meth:`livezmp.model.bvh.BvhMotion.channel_labels`: "hip.Xrotation",
    "hip.Xposition"); ``frame_time`` s. Only takes of at most :data:`MAX_LOOP_S` are judged."""
    if not MIN_PERIOD < len(frames) <= MAX_LOOP_S / frame_time + 1:
        return None
    rot = np.array([label.endswith("rotation") for label in labels])
    angles = frames[:, rot]
    moving = np.ptp(angles, axis=0) > MOVING_DEG
    if moving.sum() < MIN_MOVING:
        return None
    steps = np.abs(_wrapped(np.diff(angles[:, moving], axis=0))).max(axis=1)
    seam = np.abs(_wrapped(angles[-1, moving] - angles[0, moving])).max()
    if seam > SEAM_SHARE * np.median(steps):
        return None
    return Loop(len(frames) - 1, np.array([label.endswith("position") for label in labels]))


def _wrapped(deg: np.ndarray) -> np.ndarray:
    return (deg + 180.0) % 360.0 - 180.0
