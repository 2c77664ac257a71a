"""Host side of a session with one board: handshake, commands, heartbeats, link health.

The caller drives it: ``poll()`` must run regularly (every control cycle); it
reads the transport, sends the host heartbeat when due and returns what the
board sent. Commands the board acknowledges (TORQUE, WATCHDOG, STREAM_RATES,
ESTOP) wait for ACK with a deadline and are re-sent a bounded number of times.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from .errors import CommandRefused, HandshakeError, LinkError, ProtocolError
from .messages import (
    Ack,
    Estop,
    Heartbeat,
    Hello,
    HelloAck,
    Message,
    Nack,
    SetGoals,
    Status,
    StreamRates,
    Torque,
    Watchdog,
)
from .schema import SCHEMA_HASH, BoardState, NackCode, WatchdogAction


@dataclass
class LinkHealth:
    """What the host knows of the link; times are the host clock, seconds."""

    last_rx: float | None = None  # last valid frame from the board
    last_heartbeat: float | None = None  # last HEARTBEAT from the board
    board_state: BoardState | None = None
    status: Status | None = None
    nacks: dict[NackCode, int] = field(default_factory=dict)
    faults: int = 0
    inbox_dropped: int = 0  # messages dropped because poll() was not called for too long

    def alive(self, now: float, timeout: float) -> bool:
        """True if a board heartbeat arrived within ``timeout`` seconds before ``now``."""
        return self.last_heartbeat is not None and now - self.last_heartbeat <= timeout


class HostSession:
    """One host <-> board session over a SerialTransport or CanTransport (role "host").

    heartbeat_period (s): how often poll() sends HEARTBEAT. watchdog_timeout (s)
    and watchdog_action: configured on the board at connect. An acknowledged command
    is sent again every ack_timeout (s) without an ACK, ``retries`` times, and further
    until ack_deadline (s; None: (retries + 1) x ack_timeout) has passed since its first
    try; an ACK to any of its tries counts (on a loaded host the first try's ACK often
    arrives while the second waits).
    """

    def __init__(self, transport, *, heartbeat_period: float = 0.05, watchdog_timeout: float = 0.2,
                 watchdog_action: WatchdogAction = WatchdogAction.HOLD, ack_timeout: float = 0.1,
                 retries: int = 2, ack_deadline: float | None = None, inbox_limit: int = 1024,
                 clock: Callable[[], float] = time.monotonic):
        if transport.is_board:
            raise ProtocolError("HostSession needs a transport with role='host'")
        self.transport = transport
        self.heartbeat_period = heartbeat_period
        self.watchdog_timeout = watchdog_timeout
        self.watchdog_action = watchdog_action
        self.ack_timeout = ack_timeout
        self.retries = retries
        self.ack_deadline = (retries + 1) * ack_timeout if ack_deadline is None else ack_deadline
        self.clock = clock
        self.health = LinkHealth()
        self.board: HelloAck | None = None
        self._inbox: deque[Message] = deque()
        self._inbox_limit = inbox_limit
        self._replies: dict[tuple[int, int], Ack | Nack] = {}
        self._cmd_seq = 0
        self._start = clock()
        self._next_heartbeat = self._start

    @property
    def errors(self) -> dict[str, int]:
        """Transport receive errors by kind, plus tx_failed."""
        return self.transport.errors

    def connect(self, timeout: float = 1.0) -> HelloAck:
        """HELLO until HELLO_ACK or ``timeout`` s; then configure the watchdog. Returns the board's HELLO_ACK.

        HandshakeError if no board answers or its schema hash differs from ours.
        """
        deadline = self.clock() + timeout
        while self.clock() < deadline:
            self.transport.send(Hello(SCHEMA_HASH))
            ack = self._wait(lambda m: isinstance(m, HelloAck), min(self.ack_timeout, deadline - self.clock()))
            if ack is None:
                continue
            if ack.schema_hash != SCHEMA_HASH:
                raise HandshakeError(
                    f"{self.transport.name}: board {ack.device_id:#x} speaks protocol schema "
                    f"{ack.schema_hash:#018x}, this host {SCHEMA_HASH:#018x}: update the firmware or firmware_protocol"
                )
            self.board = ack
            self._next_heartbeat = self.clock()
            self.configure_watchdog(self.watchdog_timeout, self.watchdog_action)
            return ack
        raise HandshakeError(f"{self.transport.name}: no HELLO_ACK within {timeout} s")

    def send_goals(self, ids: Sequence[int], positions: Sequence[float]) -> int:
        """Send goal positions (rad) for joint ``ids``; returns the command sequence number. Not acknowledged:
        the board NACKs a refused one, and STATUS.last_cmd_seq reports the last applied."""
        self._require_connected()
        seq = self._cmd_seq
        self.transport.send(SetGoals(seq, tuple(ids), tuple(float(p) for p in positions)))
        self._cmd_seq = (seq + 1) & 0xFFFF
        return seq

    def set_torque(self, ids: Sequence[int], enable: bool | Sequence[bool]) -> None:
        """Enable or disable torque on joint ``ids`` (one bool for all, or one per id); waits for ACK."""
        flags = (bool(enable),) * len(ids) if isinstance(enable, bool) else tuple(bool(e) for e in enable)
        self._request(Torque(tuple(ids), flags))

    def configure_watchdog(self, timeout: float, action: WatchdogAction) -> None:
        """Board watchdog: ``timeout`` s (0 disables, resolution 1 ms, at most 65.535 s) and action."""
        if not 0 <= timeout <= 65.535:
            raise ProtocolError(f"watchdog timeout {timeout} s is not in 0..65.535")
        self._request(Watchdog(round(timeout * 1000), WatchdogAction(action)))
        self.watchdog_timeout, self.watchdog_action = timeout, WatchdogAction(action)

    def set_rates(self, joint_state_hz: int, foot_sensors_hz: int, imu_hz: int, heartbeat_hz: int) -> None:
        """Rates (Hz, 0 = off) of the board's streams; waits for ACK."""
        self._request(StreamRates(joint_state_hz, foot_sensors_hz, imu_hz, heartbeat_hz))

    def estop(self) -> None:
        """Emergency stop: the board drops torque on every joint and latches ESTOP; waits for ACK."""
        self._request(Estop(True), require_connected=False)

    def release_estop(self) -> None:
        """Release the ESTOP latch; torque stays off until set_torque enables it."""
        self._request(Estop(False), require_connected=False)

    def poll(self, timeout: float = 0.0) -> list[Message]:
        """Everything the board sent since the last poll (waiting up to ``timeout`` s for the first frame);
        sends the host heartbeat when due."""
        self._pump(timeout)
        out = list(self._inbox)
        self._inbox.clear()
        return out

    def _require_connected(self) -> None:
        if self.board is None:
            raise ProtocolError(f"{self.transport.name}: not connected: call connect() first")

    def _request(self, msg: Message, require_connected: bool = True) -> None:
        if require_connected:
            self._require_connected()
        start = self.clock()
        keys: list[tuple[int, int]] = []  # (message id, sequence number) of every try
        while True:
            keys.append((msg.spec.msg_id, self.transport.send(msg)))
            left = start + self.ack_deadline - self.clock()
            wait = self.ack_timeout if len(keys) <= self.retries else min(self.ack_timeout, max(left, 0.0))
            self._wait(lambda _m: any(k in self._replies for k in keys), wait)
            replies = [r for r in (self._replies.pop(k, None) for k in keys) if r is not None]
            if any(isinstance(r, Nack) for r in replies):
                code = next(r.code for r in replies if isinstance(r, Nack))
                raise CommandRefused(f"{self.transport.name}: board refused {msg.spec.name}: {code.name}", code)
            if replies:
                return
            if len(keys) > self.retries and self.clock() - start >= self.ack_deadline:
                break
        raise LinkError(f"{self.transport.name}: no ACK for {msg.spec.name} after {len(keys)} tries in "
                        f"{self.clock() - start:.2g} s")

    def _wait(self, done: Callable[[Message], bool], timeout: float) -> Message | None:
        """Pump until a received message satisfies ``done`` (returned) or the deadline passes (None)."""
        deadline = self.clock() + timeout
        while True:
            # A fixed read timeout: changing a serial port's timeout reconfigures the port.
            for msg in self._pump(0.005 if deadline - self.clock() > 0.005 else 0.0):
                if done(msg):
                    return msg
            if self.clock() >= deadline:
                return None

    def _pump(self, timeout: float) -> list[Message]:
        now = self.clock()
        if self.board is not None and now >= self._next_heartbeat:
            self._next_heartbeat = max(self._next_heartbeat + self.heartbeat_period, now)
            try:
                self.transport.send(Heartbeat(int((now - self._start) * 1000) & 0xFFFFFFFF, BoardState.ACTIVE))
            except LinkError:
                pass  # counted by the transport (tx_failed); the board's watchdog covers a dead link
        received = [r.message for r in self.transport.receive(timeout)]
        now = self.clock()
        for msg in received:
            self._note(msg, now)
        return received

    def _note(self, msg: Message, now: float) -> None:
        health = self.health
        health.last_rx = now
        if isinstance(msg, Ack | Nack):
            self._replies[(msg.ref_msg_id, msg.ref_seq)] = msg
            if len(self._replies) > 64:  # unclaimed replies (e.g. to retries): keep the newest only
                self._replies.pop(next(iter(self._replies)))
            if isinstance(msg, Nack):
                health.nacks[msg.code] = health.nacks.get(msg.code, 0) + 1
        elif isinstance(msg, Heartbeat):
            health.last_heartbeat = now
            health.board_state = msg.state
        elif isinstance(msg, Status):
            health.status = msg
            health.board_state = msg.state
        elif msg.spec.name == "FAULT":
            health.faults += 1
        if len(self._inbox) >= self._inbox_limit:
            self._inbox.popleft()
            health.inbox_dropped += 1
        self._inbox.append(msg)
