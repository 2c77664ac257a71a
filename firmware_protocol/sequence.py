"""Sequence-number bookkeeping for one stream of frames (serial arithmetic, RFC 1982 style)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class SequenceTracker:
    """Classifies each received sequence number of one stream.

    With d = (seq - last) mod 2**bits: d == 0 is a duplicate; 0 < d < 2**(bits-1)
    is new (d - 1 frames were lost); d within ``behind`` of 2**bits is a stale,
    reordered frame; anything else is taken as the peer restarting its count.
    Duplicates and stale frames are to be dropped.
    """

    bits: int
    behind: int
    last: int | None = None

    def classify(self, seq: int) -> tuple[str, int]:
        """('new', lost) | ('duplicate', 0) | ('stale', 0) | ('restart', 0); updates ``last`` unless dropped."""
        if self.last is None:
            self.last = seq
            return "new", 0
        modulus = 1 << self.bits
        d = (seq - self.last) % modulus
        if d == 0:
            return "duplicate", 0
        if d >= modulus - self.behind:
            return "stale", 0
        self.last = seq
        if d < modulus >> 1:
            return "new", d - 1
        return "restart", 0

    def reset(self) -> None:
        """Forget the stream: the next number is accepted as new (after a HELLO / HELLO_ACK)."""
        self.last = None
