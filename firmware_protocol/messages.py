"""The protocol's messages as frozen dataclasses, one per line of the schema.

Field order and names follow ``schema.MESSAGE_LINES`` exactly (the payload
codec relies on it). Repeated groups are stored column-wise: one tuple per
record field, e.g. ``JointState.ids`` and ``JointState.position`` have one
entry per joint. Units are SI; frames are named in each docstring.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, ClassVar

from .errors import ProtocolError
from .schema import (
    BY_NAME,
    SCHEMA_HASH,
    BoardState,
    FaultCode,
    MessageSpec,
    NackCode,
    WatchdogAction,
)

_CLASSES: dict[int, type] = {}


def _message(name: str):
    def register(cls):
        cls.spec = BY_NAME[name]
        _CLASSES[cls.spec.msg_id] = cls
        return cls

    return register


@_message("ESTOP")
@dataclass(frozen=True, slots=True)
class Estop:
    """Host -> board. engage=True: drop torque on every joint and latch ESTOP; False releases the latch."""

    spec: ClassVar[MessageSpec]
    engage: bool = True


@_message("FAULT")
@dataclass(frozen=True, slots=True)
class Fault:
    """Board -> host. A fault event; joint_id 0xFF means the board itself; value's unit depends on code."""

    spec: ClassVar[MessageSpec]
    board_time_us: int
    code: FaultCode
    joint_id: int
    value: float


@_message("SET_GOALS")
@dataclass(frozen=True, slots=True)
class SetGoals:
    """Host -> board. Goal joint positions (rad) for the listed joint ids; cmd_seq counts commands mod 2**16."""

    spec: ClassVar[MessageSpec]
    cmd_seq: int
    ids: tuple[int, ...]
    position: tuple[float, ...]


@_message("JOINT_STATE")
@dataclass(frozen=True, slots=True)
class JointState:
    """Board -> host. Measured position (rad), velocity (rad/s), motor current (A) and JointError bits
    per joint, sampled at board_time_us (board clock, microseconds, wraps at 2**32)."""

    spec: ClassVar[MessageSpec]
    board_time_us: int
    ids: tuple[int, ...]
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    current: tuple[float, ...]
    error: tuple[int, ...]


@_message("IMU")
@dataclass(frozen=True, slots=True)
class Imu:
    """Board -> host. orientation: unit quaternion (w, x, y, z) rotating IMU-frame vectors into the world
    frame (z up); angular_velocity (rad/s) and acceleration (specific force, m/s^2) in the IMU frame."""

    spec: ClassVar[MessageSpec]
    board_time_us: int
    orientation: tuple[float, float, float, float]
    angular_velocity: tuple[float, float, float]
    acceleration: tuple[float, float, float]


@_message("FOOT_SENSORS")
@dataclass(frozen=True, slots=True)
class FootSensors:
    """Board -> host. Per foot: the four corner load-cell forces (N; front-left, front-right, rear-left,
    rear-right) and the board's centre of pressure (m) in the sole frame (x forward, y left)."""

    spec: ClassVar[MessageSpec]
    board_time_us: int
    foot_ids: tuple[int, ...]
    force: tuple[tuple[float, float, float, float], ...]
    cop_x: tuple[float, ...]
    cop_y: tuple[float, ...]


@_message("TORQUE")
@dataclass(frozen=True, slots=True)
class Torque:
    """Host -> board. Enable (True) or disable torque for each listed joint id."""

    spec: ClassVar[MessageSpec]
    ids: tuple[int, ...]
    enable: tuple[bool, ...]


@_message("WATCHDOG")
@dataclass(frozen=True, slots=True)
class Watchdog:
    """Host -> board. No valid host frame for timeout_ms milliseconds -> action; 0 disables."""

    spec: ClassVar[MessageSpec]
    timeout_ms: int
    action: WatchdogAction


@_message("STREAM_RATES")
@dataclass(frozen=True, slots=True)
class StreamRates:
    """Host -> board. Rates (Hz, 0 = off) at which the board sends each stream."""

    spec: ClassVar[MessageSpec]
    joint_state_hz: int
    foot_sensors_hz: int
    imu_hz: int
    heartbeat_hz: int


@_message("ACK")
@dataclass(frozen=True, slots=True)
class Ack:
    """Either way. The command (message id, frame sequence number) was applied."""

    spec: ClassVar[MessageSpec]
    ref_msg_id: int
    ref_seq: int


@_message("NACK")
@dataclass(frozen=True, slots=True)
class Nack:
    """Either way. The command (message id, frame sequence number) was refused for ``code``."""

    spec: ClassVar[MessageSpec]
    ref_msg_id: int
    ref_seq: int
    code: NackCode


@_message("STATUS")
@dataclass(frozen=True, slots=True)
class Status:
    """Board -> host. torque_mask bit i is joint i of HELLO_ACK's list; supply_voltage in V (0: unknown);
    rx_errors counts rejected host frames (saturates at 65535)."""

    spec: ClassVar[MessageSpec]
    state: BoardState
    watchdog_action: WatchdogAction
    watchdog_timeout_ms: int
    torque_mask: int
    last_cmd_seq: int
    supply_voltage: float
    rx_errors: int


@_message("HEARTBEAT")
@dataclass(frozen=True, slots=True)
class Heartbeat:
    """Either way. Liveness: the sender's uptime (ms, wraps) and state (the host sends ACTIVE)."""

    spec: ClassVar[MessageSpec]
    uptime_ms: int
    state: BoardState


@_message("HELLO")
@dataclass(frozen=True, slots=True)
class Hello:
    """Host -> board. Opens a session; the board answers HELLO_ACK. Layout frozen across schema versions."""

    spec: ClassVar[MessageSpec]
    schema_hash: int = SCHEMA_HASH


@_message("HELLO_ACK")
@dataclass(frozen=True, slots=True)
class HelloAck:
    """Board -> host. The board's schema hash, identity, Capability bits and joint list (ids, ASCII names).
    Layout frozen across schema versions."""

    spec: ClassVar[MessageSpec]
    schema_hash: int
    device_id: int
    firmware_version: int
    capabilities: int
    joint_ids: tuple[int, ...]
    joint_names: tuple[str, ...]


Message = (
    Estop | Fault | SetGoals | JointState | Imu | FootSensors | Torque | Watchdog | StreamRates | Ack | Nack
    | Status | Heartbeat | Hello | HelloAck
)
MESSAGE_CLASSES: dict[int, type] = dict(_CLASSES)


def to_dict(msg: Message) -> dict[str, Any]:
    """A JSON-ready dict: {"type": NAME, field: value...}; tuples become lists, enums plain ints."""
    out: dict[str, Any] = {"type": msg.spec.name}
    for f in fields(msg):
        out[f.name] = _plain(getattr(msg, f.name))
    return out


def from_dict(data: dict[str, Any]) -> Message:
    """Inverse of ``to_dict``; ProtocolError naming the field on a missing or unknown key."""
    try:
        spec = BY_NAME[data["type"]]
    except KeyError:
        raise ProtocolError(f"message dict: unknown or missing 'type' ({data.get('type')!r})") from None
    cls = MESSAGE_CLASSES[spec.msg_id]
    kinds = {f.name: f for f in (*spec.head, *spec.group)}
    extra = set(data) - set(kinds) - {"type"}
    if extra:
        raise ProtocolError(f"{spec.name}: unknown field(s) {sorted(extra)}")
    values = {}
    for name, f in kinds.items():
        if name not in data:
            raise ProtocolError(f"{spec.name}: missing field {name!r}")
        try:
            values[name] = _typed(data[name], f.kind, f.enum, name in (g.name for g in spec.group))
        except (TypeError, ValueError) as err:
            raise ProtocolError(f"{spec.name}.{name}: {err}") from None
    return cls(**values)


def _plain(value: Any) -> Any:
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return int(value)
    return value


def _typed(value: Any, kind: str, enum_cls, in_group: bool) -> Any:
    def one(v):
        if isinstance(v, list):
            return tuple(one(x) for x in v)
        if kind == "enum":
            return enum_cls(v)
        if kind == "bool":
            return bool(v)
        if kind == "float":
            return float(v)
        return v

    return tuple(one(v) for v in value) if in_group else one(value)
