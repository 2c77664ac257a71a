"""Simulated CAN nodes: the frame type, the node interface, and two trivial nodes.

A node sits on the simulated bus behind a host adapter (e.g. `SlcanAdapter`).
The adapter calls ``on_frame`` for each frame the host transmits and ``tick``
periodically; whatever frames they return go to the host. Nodes do not hear
each other.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class CanFrame:
    """A classic CAN 2.0 frame. ``dlc`` defaults to ``len(data)``; remote frames carry no data."""

    arbitration_id: int
    data: bytes = b""
    is_extended: bool = False
    is_remote: bool = False
    dlc: int = -1

    def __post_init__(self) -> None:
        limit = 0x1FFFFFFF if self.is_extended else 0x7FF
        if not 0 <= self.arbitration_id <= limit:
            raise ValueError(f"CanFrame: arbitration_id {self.arbitration_id:#x} exceeds {limit:#x}")
        if self.dlc < 0:
            object.__setattr__(self, "dlc", len(self.data))
        if len(self.data) > 8 or not 0 <= self.dlc <= 8:
            raise ValueError(f"CanFrame: at most 8 data bytes, got dlc {self.dlc}, {len(self.data)} bytes")
        if self.is_remote and self.data:
            raise ValueError("CanFrame: a remote frame carries no data")
        if not self.is_remote and self.dlc != len(self.data):
            raise ValueError(f"CanFrame: dlc {self.dlc} does not match {len(self.data)} data bytes")


class CanNode(Protocol):
    """A simulated bus participant."""

    def on_frame(self, frame: CanFrame) -> list[CanFrame]:
        """React to a frame on the bus; return the frames sent in reply."""

    def tick(self, now: float) -> list[CanFrame]:
        """Periodic work at monotonic time ``now`` (s); return frames sent spontaneously."""


class EchoNode:
    """Answers every data frame with id ``listen_id`` by the same data on id ``reply_id``."""

    def __init__(self, listen_id: int, reply_id: int) -> None:
        self.listen_id = listen_id
        self.reply_id = reply_id

    def on_frame(self, frame: CanFrame) -> list[CanFrame]:
        if frame.arbitration_id != self.listen_id or frame.is_remote or frame.is_extended:
            return []
        return [CanFrame(self.reply_id, frame.data)]

    def tick(self, now: float) -> list[CanFrame]:
        return []


class CounterNode:
    """Sends a little-endian uint32 counter (0, 1, 2, ...) on ``frame_id`` every ``period`` seconds."""

    def __init__(self, frame_id: int, period: float) -> None:
        self.frame_id = frame_id
        self.period = period
        self.count = 0
        self._next: float | None = None

    def on_frame(self, frame: CanFrame) -> list[CanFrame]:
        return []

    def tick(self, now: float) -> list[CanFrame]:
        if self._next is None:
            self._next = now
        if now < self._next:
            return []
        self._next += self.period
        if self._next <= now:  # fell behind (stalled caller): resume the cadence, no burst
            self._next = now + self.period
        frame = CanFrame(self.frame_id, struct.pack("<I", self.count & 0xFFFFFFFF))
        self.count += 1
        return [frame]
