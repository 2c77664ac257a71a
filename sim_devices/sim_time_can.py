"""A simulated CAN bus in simulated time, as a python-can bus: deterministic tests of what the wire allows.

`SimTimeCanBus` is a `can.BusABC` whose frames take their wire time
(`livezmp.links.can_timing.frame_bits` at ``bitrate``) on a `SimClock` rather than on the
wall clock: a frame the host sends goes on the wire when the bus is free, the nodes'
answers follow it, and ``recv`` advances the clock to the next frame's arrival (or by its
timeout). Several buses share one clock and carry their frames at the same time. The
host's own computing takes no simulated time, so a loop run on the clock shows what the
buses alone allow.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Sequence

import can

from sim_devices.can_node import CanFrame, CanNode
from sim_devices.socketcand_server import wire_time


class SimClock:
    """Simulated monotonic time (s): ``now``; ``sleep`` and ``advance_to`` move it forward."""

    def __init__(self, start: float = 0.0) -> None:
        self.t = start

    def now(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += max(dt, 0.0)

    def advance_to(self, t: float) -> None:
        self.t = max(self.t, t)


class SimTimeCanBus(can.BusABC):
    """``nodes`` on one CAN bus at ``bitrate`` bit/s in ``clock``'s time (see module docstring)."""

    def __init__(self, nodes: Sequence[CanNode], clock: SimClock, bitrate: int = 1_000_000,
                 channel: str = "sim") -> None:
        self.nodes = list(nodes)
        self.clock = clock
        self.bitrate = bitrate
        self.channel_info = f"simulated-time CAN bus {channel}"
        self.frames = 0
        self._bus_free = clock.now()
        self._arrivals: list[tuple[float, int, CanFrame]] = []
        self._seq = itertools.count()
        super().__init__(channel=channel)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        frame = CanFrame(msg.arbitration_id, bytes(msg.data), is_extended=msg.is_extended_id)
        t = max(self.clock.now(), self._bus_free) + wire_time(frame, self.bitrate)
        self.frames += 1
        for node in self.nodes:
            for answer in node.on_frame(frame):
                t += wire_time(answer, self.bitrate)  # right behind the command: its id 0 wins arbitration
                heapq.heappush(self._arrivals, (t, next(self._seq), answer))
                self.frames += 1
        self._bus_free = t

    def recv(self, timeout: float | None = None) -> can.Message | None:
        """The next frame to arrive within ``timeout`` s of simulated time (the clock moves to its
        arrival), else None after the clock moved by ``timeout``. (BusABC's own recv would wait on
        the wall clock.)"""
        return self._recv_internal(timeout)[0]

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        now = self.clock.now()
        if self._arrivals and (self._arrivals[0][0] <= now or timeout is None
                               or self._arrivals[0][0] <= now + timeout):
            due, _, frame = heapq.heappop(self._arrivals)
            self.clock.advance_to(due)
            return can.Message(timestamp=due, arbitration_id=frame.arbitration_id, data=frame.data,
                               is_extended_id=frame.is_extended, is_rx=True), False
        self.clock.sleep(timeout or 0.0)
        return None, False
