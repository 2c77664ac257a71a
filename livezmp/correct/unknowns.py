"""Which root rotation each analysed frame of a correction takes: one per frame, or one per frame of a looped cycle.

A take is corrected with one unknown rotation per frame. A looped cycle (:mod:`livezmp.model.loop_cycle`) is
analysed with copies of the cycle before and after it; corrected frame by frame, its two ends were corrected as
edges, and the cycle it wrote no longer closed (0.5-4.4 degrees at the seam on Mixamo's and K-Scale's walks). Here
every copy of a cycle frame takes that frame's one rotation, and the rotations' smoothness and rate wrap from the
cycle's last frame to its first: the correction is periodic, so the corrected cycle loops as the original did.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Unknowns:
    """``index`` (F,) int: the unknown rotation of each analysed frame, of ``count``; ``judged`` (F,) bool: the
    frames whose ZMP counts (a loop's pads are analysed, not judged); ``periodic``: the last unknown is followed by
    the first."""

    index: np.ndarray
    judged: np.ndarray
    count: int
    periodic: bool = False

    def expand(self, rotations: np.ndarray) -> np.ndarray:
        """Per analysed frame (F, 3) from per unknown (count, 3)."""
        return rotations[self.index]

    def first_frames(self) -> np.ndarray:
        """(count,) the first judged frame taking each unknown."""
        frames = np.nonzero(self.judged)[0]
        at = np.full(self.count, -1)
        at[self.index[frames[::-1]]] = frames[::-1]
        return at

    def selection(self) -> sp.csr_matrix:
        """(3F × 3 count): flattened rotations per analysed frame from flattened unknowns."""
        f = len(self.index)
        pick = sp.csr_matrix((np.ones(f), (np.arange(f), self.index)), shape=(f, self.count))
        return sp.kron(pick, sp.eye(3)).tocsr()

    def previous(self) -> np.ndarray:
        """(count,) the unknown before each (−1 for the first of a take that does not loop)."""
        prev = np.arange(self.count) - 1
        if self.periodic:
            prev[0] = self.count - 1
        return prev

    def second_difference(self, dt: float) -> sp.csr_matrix:
        """The rotations' second difference over ``dt`` (s), rad/s² per unknown triple; wrapped for a loop."""
        n = self.count
        if not self.periodic:
            d2 = sp.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(max(n - 2, 0), n))
        else:
            k = np.arange(n)
            d2 = sp.csr_matrix((np.tile([1.0, -2.0, 1.0], n), (np.repeat(k, 3), np.ravel([k, (k + 1) % n,
                                (k + 2) % n], order="F"))), shape=(n, n))
        return sp.kron(d2 / dt**2, sp.eye(3)).tocsr()

    def near(self, frame: int, half_width: int) -> tuple[np.ndarray, np.ndarray]:
        """The unknowns within ``half_width`` of analysed frame ``frame``'s and a Hann bump over them (peak 1)."""
        at = int(self.index[frame])
        if self.periodic:  # each unknown once, however short the cycle
            span = min(2 * half_width + 1, self.count)
            return (at + np.arange(span) - (span - 1) // 2) % self.count, np.hanning(span + 2)[1:-1]
        lo, hi = max(0, at - half_width), min(self.count, at + half_width + 1)
        return np.arange(lo, hi), np.hanning(hi - lo + 2)[1:-1]


def per_frame(frames: int) -> Unknowns:
    """One unknown per frame, every frame judged: a take corrected as it is."""
    return Unknowns(np.arange(frames), np.ones(frames, bool), frames)


def looped(lead: int, frames: int, period: int) -> Unknowns:
    """A looped cycle's ``frames`` (its last repeats its first) analysed after ``lead`` frames of the loop and
    before as many: one unknown per frame of its ``period``."""
    k = np.arange(-lead, frames + lead)
    return Unknowns(k % period, (k >= 0) & (k < frames), period, periodic=True)
