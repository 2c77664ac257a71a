"""Board side of the protocol in Python: the engine a (simulated) firmware board runs.

``BoardEngine.step()`` reads the transport, answers HELLO, applies commands
through a ``BoardBackend``, enforces the watchdog and emits the streams that
are due. The state machine is the one in SPEC.md ("Board states").
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

from .can_framing import BROADCAST
from .errors import LinkError
from .messages import (
    Ack,
    Estop,
    Fault,
    FootSensors,
    Heartbeat,
    Hello,
    HelloAck,
    Imu,
    JointState,
    Message,
    Nack,
    SetGoals,
    Status,
    StreamRates,
    Torque,
    Watchdog,
)
from .schema import SCHEMA_HASH, BoardState, Capability, FaultCode, NackCode, WatchdogAction
from .serial_framing import Received

NO_JOINT = 0xFF  # FAULT.joint_id of a board-level fault
DEFAULT_RATES = StreamRates(joint_state_hz=100, foot_sensors_hz=0, imu_hz=0, heartbeat_hz=10)


class BoardBackend(Protocol):
    """What the engine needs from the hardware (or a simulation). Joint order is the engine's joint_ids."""

    def joint_state(self, board_time_us: int) -> JointState:
        """Sample every joint: position rad, velocity rad/s, current A, JointError bits."""

    def foot_sensors(self, board_time_us: int) -> FootSensors | None:
        """Sample the foot load cells (N) and centres of pressure (m, sole frame); None if absent."""

    def imu(self, board_time_us: int) -> Imu | None:
        """Sample the IMU (see messages.Imu for frames and units); None if absent."""

    def supply_voltage(self) -> float:
        """Supply voltage, V (0 if not measured)."""

    def set_goals(self, ids: Sequence[int], positions: Sequence[float]) -> None:
        """Command goal positions, rad."""

    def set_torque(self, ids: Sequence[int], enable: Sequence[bool]) -> None:
        """Switch torque per joint."""

    def hold(self) -> None:
        """Hold every joint at its measured position (watchdog HOLD)."""

    def drop_torque(self) -> None:
        """Switch every joint limp (ESTOP, watchdog DROP_TORQUE)."""


class BoardEngine:
    """Protocol engine of one board over a SerialTransport or CanTransport (role "board").

    joint_ids / joint_names: the board's joints in HELLO_ACK order. rates:
    initial stream rates (Hz). watchdog_timeout (s) / watchdog_action: armed
    once a host connects. status_period (s): STATUS is sent at least this
    often, and at once on every change. schema_hash: what HELLO_ACK reports
    (a different value plays firmware built from another schema).
    """

    def __init__(self, transport, backend: BoardBackend, *, joint_ids: Sequence[int], joint_names: Sequence[str],
                 device_id: int = 1, firmware_version: int = 1,
                 capabilities: int = Capability.JOINT_CURRENT | Capability.FOOT_SENSORS | Capability.IMU,
                 rates: StreamRates = DEFAULT_RATES, watchdog_timeout: float = 0.5,
                 watchdog_action: WatchdogAction = WatchdogAction.HOLD, max_rate_hz: int = 1000,
                 status_period: float = 1.0, schema_hash: int = SCHEMA_HASH,
                 clock: Callable[[], float] = time.monotonic):
        if not transport.is_board:
            raise LinkError("BoardEngine needs a transport with role='board'")
        self.transport = transport
        self.backend = backend
        self.hello_ack = HelloAck(schema_hash, device_id, firmware_version, int(capabilities),
                                  tuple(joint_ids), tuple(joint_names))
        self.capabilities = Capability(capabilities)
        self.max_rate_hz = max_rate_hz
        self.status_period = status_period
        self.clock = clock
        self.rates = rates
        self.watchdog_timeout = watchdog_timeout
        self.watchdog_action = watchdog_action
        self.state = BoardState.DISCONNECTED
        self.connected = False  # a host with our schema said HELLO
        self.torque = dict.fromkeys(joint_ids, False)
        self.last_cmd_seq: int | None = None
        self._start = clock()
        self._last_feed = self._start
        self._next_due: dict[str, float] = {}
        self._next_status = self._start
        self._link_down_since: float | None = None

    def step(self, timeout: float = 0.0) -> None:
        """One firmware cycle: handle what arrived (waiting up to ``timeout`` s), watchdog, due streams."""
        for received in self.transport.receive(timeout):
            self._handle(received, self.clock())
        now = self.clock()
        self._check_watchdog(now)
        self._emit_streams(now)

    def board_time_us(self, now: float) -> int:
        """The board clock: microseconds since start, wrapping at 2**32."""
        return int((now - self._start) * 1e6) & 0xFFFFFFFF

    # --- commands -------------------------------------------------------

    def _handle(self, received: Received, now: float) -> None:
        msg = received.message
        if isinstance(msg, Hello):
            self._hello(msg, now)
            return
        if isinstance(msg, Estop):
            self._estop(msg.engage)
        elif isinstance(msg, Heartbeat | Ack | Nack):
            if not self.connected:
                return  # a host we have no session with: does not feed the watchdog
        elif not self.connected:
            self._reply(received, NackCode.NOT_CONNECTED)
            return
        else:
            if received.node == BROADCAST and isinstance(msg, SetGoals | Torque):
                msg = self._own_part(msg)  # a broadcast addresses every node: take our joints, ignore the rest
                if msg is None:
                    return
            code = self._command(msg)
            if code is not None:
                self._reply(received, code)
                return
        if not isinstance(msg, SetGoals | Heartbeat | Ack | Nack):
            self._reply(received, None)
        self._last_feed = now

    def _own_part(self, msg: SetGoals | Torque) -> SetGoals | Torque | None:
        """The records of a broadcast command for our joints; None if it has none."""
        mine = [i for i, joint in enumerate(msg.ids) if joint in self.torque]
        if not mine:
            return None
        ids = tuple(msg.ids[i] for i in mine)
        if isinstance(msg, SetGoals):
            return SetGoals(msg.cmd_seq, ids, tuple(msg.position[i] for i in mine))
        return Torque(ids, tuple(msg.enable[i] for i in mine))

    def _hello(self, msg: Hello, now: float) -> None:
        self._send(self.hello_ack)
        self.connected = msg.schema_hash == self.hello_ack.schema_hash
        if self.connected:
            if self.state != BoardState.ESTOP:
                self._set_state(BoardState.ACTIVE)
            self.last_cmd_seq = None
            self._last_feed = now
        elif self.state != BoardState.ESTOP:
            if self.state == BoardState.ACTIVE:
                self.backend.hold()  # a host we cannot understand: stop following the old one's goals
            self._set_state(BoardState.DISCONNECTED)
        self._next_status = now  # STATUS follows every HELLO_ACK

    def _estop(self, engage: bool) -> None:
        if engage:
            self.backend.drop_torque()
            self.torque = dict.fromkeys(self.torque, False)
            self._set_state(BoardState.ESTOP)
        elif self.state == BoardState.ESTOP:
            self._set_state(BoardState.ACTIVE if self.connected else BoardState.DISCONNECTED)

    def _command(self, msg: Message) -> NackCode | None:
        """Apply a command of a connected host; the NACK code if refused."""
        if isinstance(msg, SetGoals | Torque) and not set(msg.ids) <= self.torque.keys():
            return NackCode.UNKNOWN_JOINT
        if isinstance(msg, SetGoals):
            return self._set_goals(msg)
        if isinstance(msg, Torque):
            if self.state == BoardState.ESTOP and any(msg.enable):
                return NackCode.ESTOPPED
            self.backend.set_torque(msg.ids, msg.enable)
            self.torque.update(zip(msg.ids, msg.enable, strict=True))
            if self.state == BoardState.LIMP and any(msg.enable):
                self._set_state(BoardState.ACTIVE)
            self._next_status = self.clock()
            return None
        if isinstance(msg, Watchdog):
            self.watchdog_timeout, self.watchdog_action = msg.timeout_ms / 1000, msg.action
            self._next_status = self.clock()
            return None
        if isinstance(msg, StreamRates):
            return self._set_rates(msg)
        return NackCode.UNSUPPORTED

    def _set_goals(self, msg: SetGoals) -> NackCode | None:
        if self.state == BoardState.ESTOP:
            return NackCode.ESTOPPED
        if self.last_cmd_seq is not None and not 0 < (msg.cmd_seq - self.last_cmd_seq) % 65536 < 32768:
            return NackCode.STALE_COMMAND
        self.backend.set_goals(msg.ids, msg.position)
        self.last_cmd_seq = msg.cmd_seq
        if self.state == BoardState.HOLDING:
            self._set_state(BoardState.ACTIVE)
        return None

    def _set_rates(self, msg: StreamRates) -> NackCode | None:
        if max(msg.joint_state_hz, msg.foot_sensors_hz, msg.imu_hz, msg.heartbeat_hz) > self.max_rate_hz:
            return NackCode.BAD_VALUE
        if (msg.foot_sensors_hz and Capability.FOOT_SENSORS not in self.capabilities) or (
            msg.imu_hz and Capability.IMU not in self.capabilities
        ):
            return NackCode.UNSUPPORTED
        self.rates = msg
        self._next_due.clear()
        return None

    def _reply(self, received: Received, code: NackCode | None) -> None:
        if received.node == BROADCAST:
            return  # broadcasts are never answered: twenty nodes would answer at once
        msg_id = received.message.spec.msg_id
        self._send(Ack(msg_id, received.seq) if code is None else Nack(msg_id, received.seq, code))

    # --- watchdog and streams ------------------------------------------

    def _check_watchdog(self, now: float) -> None:
        idle = now - self._last_feed
        if self.state != BoardState.ACTIVE or not self.watchdog_timeout or idle <= self.watchdog_timeout:
            return
        if self.watchdog_action == WatchdogAction.HOLD:
            self.backend.hold()
            self._set_state(BoardState.HOLDING)
        else:
            self.backend.drop_torque()
            self.torque = dict.fromkeys(self.torque, False)
            self._set_state(BoardState.LIMP)
        self._send(Fault(self.board_time_us(now), FaultCode.WATCHDOG_EXPIRED, NO_JOINT, idle))

    def _emit_streams(self, now: float) -> None:
        t_us = self.board_time_us(now)
        rates = self.rates
        if self._due("joint_state", rates.joint_state_hz, now):
            self._send(self.backend.joint_state(t_us))
        if self._due("foot_sensors", rates.foot_sensors_hz, now):
            feet = self.backend.foot_sensors(t_us)
            if feet is not None:
                self._send(feet)
        if self._due("imu", rates.imu_hz, now):
            imu = self.backend.imu(t_us)
            if imu is not None:
                self._send(imu)
        if self._due("heartbeat", rates.heartbeat_hz, now):
            self._send(Heartbeat(int((now - self._start) * 1000) & 0xFFFFFFFF, self.state))
        if now >= self._next_status:
            self._next_status = now + self.status_period
            self._send(self._status())

    def _due(self, stream: str, rate_hz: int, now: float) -> bool:
        """Fixed-rate schedule; after a stall it skips the missed slots instead of bursting."""
        if not rate_hz:
            return False
        due = self._next_due.get(stream, now)
        if now < due:
            return False
        period = 1.0 / rate_hz
        self._next_due[stream] = due + period if due + period > now else now + period
        return True

    def _status(self) -> Status:
        mask = sum(1 << i for i, on in enumerate(self.torque.values()) if on)
        errors = sum(n for kind, n in self.transport.decoder.errors.items() if not kind.startswith("seq_"))
        return Status(
            self.state, self.watchdog_action, round(self.watchdog_timeout * 1000), mask,
            self.last_cmd_seq or 0, float(self.backend.supply_voltage()), min(errors, 0xFFFF),
        )

    def _set_state(self, state: BoardState) -> None:
        if state != self.state:
            self.state = state
            self._next_status = self.clock()

    def _send(self, msg: Message) -> None:
        """Send, riding out a dead link (CAN bus-off, unplugged cable): report when it comes back."""
        now = self.clock()
        try:
            self.transport.send(msg)
        except LinkError:
            if self._link_down_since is None:
                self._link_down_since = now
            return
        if self._link_down_since is not None:
            down = now - self._link_down_since
            self._link_down_since = None
            self._send(Fault(self.board_time_us(now), FaultCode.LINK_RECOVERED, NO_JOINT, down))
            self._next_status = now
