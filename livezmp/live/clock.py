"""Fixed-rate loop timing on absolute deadlines, and what it measured.

Cycle k is due at ``start + k·T`` (T = 1 / rate). :meth:`LoopClock.wait` ends the
current cycle: it records the slack (time left before the next deadline; negative = the
deadline was missed) and sleeps until the next deadline. Deadlines are absolute, so
sleep overshoot and work-time jitter never accumulate into drift. A cycle that ends
more than a whole period late skips the deadlines it overran (they are counted) rather
than running cycles back to back: samples stay on the k·T grid and the loop never
bursts.

Waiting is hybrid, as real-time control loops do it: sleep until ``spin_s`` before the
deadline, then spin on the clock, so the cycle starts on time rather than when a late
wake-up from the sleep allows (tens of microseconds late on an idle machine, more under
load); the spin costs ``spin_s`` of CPU a cycle.

Statistics live in bounded memory (:class:`~livezmp.histogram.TimingHistogram`): the clock's cost and
memory do not grow with the length of the run. Times in seconds, from the clock's
``now`` (default ``time.monotonic``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from livezmp.errors import InputError
from livezmp.histogram import TimingHistogram


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


# `livezmp run --cpu`: on a core of its own the loop spins this long before each deadline. Not pinned,
# it sleeps: measured on 2 CPUs shared with the simulator, spinning took CPU time the servos' side needed
# (OP3, 2 Mbps: 6-15 % missed deadlines spinning, 1-5 % sleeping).
SPIN_BEFORE_DEADLINE_S = 2e-4


class LoopClock:
    """Absolute-deadline clock for a loop at ``rate_hz``; ``now`` and ``sleep`` are
    injectable (a simulated clock in tests); ``spin_s``: how long before each deadline the
    wait stops sleeping and spins on ``now`` (s; 0: sleep only)."""

    def __init__(self, rate_hz: float, now: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep, spin_s: float = 0.0):
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise InputError(f"loop rate {rate_hz!r} Hz: must be a positive number")
        self.period = 1.0 / rate_hz
        self.now = now
        self._sleep = sleep
        self.spin_s = spin_s
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

    def pause(self, seconds: float) -> None:
        """Sleep ``seconds`` within a cycle, with the clock's ``sleep`` (simulated time in tests)."""
        self._sleep(seconds)

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
            self._wait_until(self.deadline(nxt), slack)
        woke = self.now()
        deadline = self.deadline(nxt)
        self.wake_late.add(woke - deadline)
        self._record_period(woke - self._tick.woke)
        self._tick = Tick(nxt, deadline, woke)
        self.cycles += 1
        return self._tick

    def _wait_until(self, deadline: float, slack: float) -> None:
        """Sleep through all but the last ``spin_s`` of ``slack`` (s), then spin until ``deadline``."""
        if not self.spin_s:
            self._sleep(slack)
            return
        if slack > self.spin_s:
            self._sleep(slack - self.spin_s)
        now = self.now
        while now() < deadline:
            pass

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
