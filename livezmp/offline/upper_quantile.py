"""An upper percentile (the 99th, say) of a stream of numbers, exactly, in bounded memory.

The q-th percentile by linear interpolation (numpy's default method) of n values reads two
neighbouring order statistics at rank (n - 1) q / 100; for q >= 50 both lie among the largest
n - floor((n - 1) q / 100) + 1 values. Keeping only those (a partition per added block) gives the
same number as :func:`numpy.percentile` over all the values, with a memory of (1 - q/100) of
the stream's length bound, instead of all of it.
"""

from __future__ import annotations

import math

import numpy as np


def kept_count(limit: int, q: float) -> int:
    """How many of the largest values hold the q-th percentile of any count up to ``limit`` values."""
    return min(limit, limit - math.floor((limit - 1) * (q / 100)) + 1)


class UpperQuantile:
    """The q-th percentile (q >= 50) of at most ``limit`` values added in blocks, as
    :func:`numpy.percentile` computes it over them all."""

    def __init__(self, limit: int, q: float = 99.0):
        if not 50 <= q <= 100:
            raise ValueError(f"an upper percentile: q = {q} is below 50")
        self.q, self.limit = q, limit
        self.keep = kept_count(max(limit, 1), q)
        self.count = 0
        self.top = np.empty(0)

    def add(self, values: np.ndarray) -> None:
        values = np.asarray(values, dtype=float).ravel()
        self.count += len(values)
        if self.count > self.limit:
            raise ValueError(f"more than the {self.limit} values announced")
        top = np.concatenate([self.top, values])
        self.top = np.partition(top, len(top) - self.keep)[-self.keep:] if len(top) > self.keep else top

    def value(self) -> float | None:
        """The percentile, or None before any value."""
        n = self.count
        if n == 0:
            return None
        top = np.sort(self.top)
        virtual = (n - 1) * np.true_divide(self.q, 100)  # numpy's linear method, step by step
        if virtual >= n - 1:
            return float(top[-1])
        below = math.floor(virtual)
        a, b = top[below - (n - len(top))], top[below + 1 - (n - len(top))]
        gamma = virtual - below
        diff = b - a
        return float(b - diff * (1 - gamma) if gamma >= 0.5 else a + diff * gamma)
