"""Fixed-rate loop timing on absolute deadlines, and what it measured.

Cycle k is due at ``start + k·T`` (T = 1 / rate). :meth:`LoopClock.wait` ends the
current cycle: it records the slack (time left before the next deadline; negative = the
deadline was missed) and sleeps until the next deadline. Deadlines are absolute, so
sleep overshoot and work-time jitter never accumulate into drift. A cycle that ends
more than a whole period late skips the deadlines it overran (they are counted) rather
than running cycles back to back: samples stay on the k·T grid and the loop never
bursts.

Statistics live in bounded memory (:class:`TimingHistogram`): the clock's cost and
memory do not grow with the length of the run. Times in seconds, from the clock's
``now`` (default ``time.monotonic``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from livezmp.errors import InputError


class TimingHistogram:
    """Durations (s) in fixed bins of ``bin_s`` up to ``span_s`` (longer ones share the
    last bin), plus exact count, sum, min and max: the mean exactly and quantiles to
    within one bin, in constant memory and constant time per sample."""

    def __init__(self, bin_s: float = 1e-5, span_s: float = 0.1):
        self.bin_s = bin_s
        self.counts = np.zeros(int(math.ceil(span_s / bin_s)) + 1, dtype=np.int64)
        self.count = 0
        self.total = 0.0
        self.min = math.inf
        self.max = -math.inf

    def add(self, x: float) -> None:
        """Record one duration (s); negative values count as 0 in the bins."""
        self.counts[min(max(int(x / self.bin_s), 0), len(self.counts) - 1)] += 1
        self.count += 1
        self.total += x
        self.min = min(self.min, x)
        self.max = max(self.max, x)

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


@dataclass(frozen=True)
class Tick:
    """One cycle: ``index`` k on the grid (skipped cycles included), its ``deadline``
    (due time, s) and when the loop ``woke`` for it (s)."""

    index: int
    deadline: float
    woke: float


@dataclass
class ClockStats:
    """What the clock measured. ``deadline_misses``: cycles whose work ended after the
    next cycle's deadline; ``skipped``: deadlines passed over to catch up; ``period_*``
    (s): time between consecutive wake-ups; ``wake_late``/``slack``: histograms (s) of
    how late the loop woke after each deadline and how much time was left at the end of
    each cycle (0 for a miss)."""

    cycles: int
    deadline_misses: int
    skipped: int
    period_mean: float
    period_std: float
    period_max: float
    wake_late: TimingHistogram
    slack: TimingHistogram

    @property
    def achieved_hz(self) -> float:
        return 1.0 / self.period_mean if self.period_mean > 0 else math.nan

    def as_dict(self) -> dict:
        return {"cycles": self.cycles, "achieved_hz": self.achieved_hz, "deadline_misses": self.deadline_misses,
                "skipped_cycles": self.skipped, "period_mean_ms": 1e3 * self.period_mean,
                "period_std_ms": 1e3 * self.period_std, "period_max_ms": 1e3 * self.period_max,
                "wake_late": self.wake_late.summary_ms(),
                "slack": {"p01_ms": 1e3 * self.slack.quantile(0.01), "p50_ms": 1e3 * self.slack.quantile(0.5),
                          "min_ms": 1e3 * max(self.slack.min, 0.0)} if self.slack.count else None}


class LoopClock:
    """Absolute-deadline clock for a loop at ``rate_hz``; ``now`` and ``sleep`` are
    injectable (a simulated clock in tests)."""

    def __init__(self, rate_hz: float, now: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep):
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise InputError(f"loop rate {rate_hz!r} Hz: must be a positive number")
        self.period = 1.0 / rate_hz
        self.now = now
        self._sleep = sleep
        self._start = math.nan
        self._tick: Tick | None = None
        self.cycles = 0
        self.misses = 0
        self.skipped = 0
        self._periods = (0, 0.0, 0.0, 0.0)  # count, mean, M2 (Welford), max
        self.wake_late = TimingHistogram(span_s=max(0.1, 10 * self.period))
        self.slack = TimingHistogram(span_s=self.period)

    def start(self) -> Tick:
        """Begin at the present time: cycle 0, due now."""
        t = self.now()
        self._start = t
        self._tick = Tick(0, t, t)
        self.cycles = 1
        return self._tick

    def deadline(self, index: int) -> float:
        """Due time (s) of cycle ``index``."""
        return self._start + index * self.period

    def wait(self) -> Tick:
        """End the current cycle: record its slack, sleep until the next due deadline
        (skipping those already past) and return the new cycle."""
        if self._tick is None:
            raise RuntimeError("LoopClock.wait() before start()")
        end = self.now()
        nxt = self._tick.index + 1
        slack = self.deadline(nxt) - end
        self.slack.add(max(slack, 0.0))
        if slack < 0:
            self.misses += 1
            # run the cycle whose slot we are in now, if its deadline is not yet a whole period old
            behind = math.floor((end - self.deadline(nxt)) / self.period)
            self.skipped += behind
            nxt += behind
        else:
            self._sleep(slack)
        woke = self.now()
        deadline = self.deadline(nxt)
        self.wake_late.add(woke - deadline)
        self._record_period(woke - self._tick.woke)
        self._tick = Tick(nxt, deadline, woke)
        self.cycles += 1
        return self._tick

    def _record_period(self, p: float) -> None:
        n, mean, m2, mx = self._periods
        n += 1
        d = p - mean
        mean += d / n
        self._periods = (n, mean, m2 + d * (p - mean), max(mx, p))

    def stats(self) -> ClockStats:
        n, mean, m2, mx = self._periods
        std = math.sqrt(m2 / n) if n else 0.0
        return ClockStats(self.cycles, self.misses, self.skipped, mean if n else self.period, std, mx,
                          self.wake_late, self.slack)
