"""Durations or distances in constant memory: the live loop's timings, the monitor's
latencies, the foot sensors' CoP-to-ZMP distances."""

from __future__ import annotations

import math

import numpy as np


class TimingHistogram:
    """Durations (s) in fixed bins of ``bin_s`` up to ``span_s`` (longer ones share the
    last bin), plus exact count, sum, min and max: the mean exactly and quantiles to
    within one bin, in constant memory and constant time per sample."""

    def __init__(self, bin_s: float = 1e-5, span_s: float = 0.1):
        self.bin_s = bin_s
        # a list: the live loop adds seven durations a cycle, and a list's item costs a fifth of an array's
        self.counts = [0] * (int(math.ceil(span_s / bin_s)) + 1)
        self._last = len(self.counts) - 1
        self.count = 0
        self.total = 0.0
        self.min = math.inf
        self.max = -math.inf

    def add(self, x: float) -> None:
        """Record one duration (s); negative values count as 0 in the bins."""
        i = int(x / self.bin_s)
        self.counts[i if 0 <= i <= self._last else (0 if i < 0 else self._last)] += 1
        self.count += 1
        self.total += x
        if x < self.min:
            self.min = x
        if x > self.max:
            self.max = x

    @property
    def mean(self) -> float:
        return self.total / self.count if self.count else math.nan

    def quantile(self, q: float) -> float:
        """The q-quantile (0 ≤ q ≤ 1, s): upper edge of the bin holding it, capped at the max."""
        if not self.count:
            return math.nan
        k = int(np.searchsorted(np.cumsum(self.counts), max(1, math.ceil(q * self.count))))
        return min((k + 1) * self.bin_s, self.max)

    def summary_ms(self) -> dict[str, float | None]:
        """mean, p50, p99 and max in milliseconds (None when empty)."""
        if not self.count:
            return {"mean_ms": None, "p50_ms": None, "p99_ms": None, "max_ms": None}
        return {"mean_ms": 1e3 * self.mean, "p50_ms": 1e3 * self.quantile(0.5),
                "p99_ms": 1e3 * self.quantile(0.99), "max_ms": 1e3 * self.max}
