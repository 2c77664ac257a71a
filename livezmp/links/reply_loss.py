"""The share of a bus's replies lost or rejected, over a sliding window: is the bus usable?"""

from __future__ import annotations

from collections import deque


class ReplyLoss:
    """Replies expected and lost, in the last ``window`` expected replies (bounded memory).

    `exceeded` once a whole window was seen and more than ``limit`` (a fraction) of
    it was lost: a share a bad cable or a wrong termination gives, not the odd glitch. A bus
    that falls silent (`SILENT_RUN` transactions in a row without a single reply: unplugged,
    powered off) is not a noisy one: the window is emptied, and the caller's watchdog and
    reconnect deal with it.
    """

    SILENT_RUN = 5

    def __init__(self, window: int, limit: float) -> None:
        self.window = window
        self.limit = limit
        self._batches: deque[tuple[int, int]] = deque()
        self._expected = 0
        self._lost = 0
        self._silent = 0

    def add(self, expected: int, lost: int) -> None:
        """One transaction: ``expected`` replies of which ``lost`` were lost or rejected."""
        self._silent = self._silent + 1 if lost >= expected else 0
        if self._silent >= self.SILENT_RUN:
            self.clear()
            return
        self._batches.append((expected, lost))
        self._expected += expected
        self._lost += lost
        while self._batches and self._expected - self._batches[0][0] >= self.window:
            e, lost_ = self._batches.popleft()
            self._expected -= e
            self._lost -= lost_

    def clear(self) -> None:
        """Forget what was seen (a new connection starts a new measure)."""
        self._batches.clear()
        self._expected = self._lost = 0

    @property
    def fraction(self) -> float:
        """Share of the window's replies lost (0 with none expected yet)."""
        return self._lost / self._expected if self._expected else 0.0

    def exceeded(self) -> bool:
        return self._expected >= self.window and self.fraction > self.limit

    def describe(self) -> str:
        return (f"the bus lost or corrupted {100 * self.fraction:.0f} % of the last {self._expected} replies "
                f"(more than {100 * self.limit:.0f} %)")
