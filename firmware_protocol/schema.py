"""The message schema: one canonical text that fixes every payload layout.

The text (``SCHEMA_TEXT``) is the single source of truth. Each message line is
``<id> <NAME> <direction> <field>...`` where a field is ``name:type`` and ``*N``
starts a repeated group: a u8 record count (at most N) followed by that many
records of the fields after it. Types: u8 u16 u32 u64 (little-endian
integers), f32 (IEEE-754 binary32), f32xK (K of them), bool (u8 0 or 1), str16
(u8 length 1..16 then that many printable ASCII bytes) and the enum / flag
names declared in the same text.

From the text come the per-message CRC seed (CRC-32 of the message's line, so
a frame whose layout changed fails its CRC) and the 64-bit schema hash
exchanged in HELLO (first 8 bytes of SHA-256 of the whole text, little-endian).
"""

from __future__ import annotations

import enum
import hashlib
import zlib
from dataclasses import dataclass

PROTOCOL_VERSION = 1
MAX_PAYLOAD = 1020  # bytes; 128 CAN frames of 8 bytes less the 4-byte transfer CRC
MAX_JOINTS = 32  # per message; also the width of STATUS.torque_mask
MAX_FEET = 4
MAX_NAME = 16  # bytes of a joint name


class WatchdogAction(enum.IntEnum):
    """What the board does when no valid command arrived for the watchdog timeout."""

    HOLD = 0  # keep torque on, hold the measured position
    DROP_TORQUE = 1  # switch every joint limp


class BoardState(enum.IntEnum):
    """The board's protocol state (see SPEC.md, "Board states")."""

    DISCONNECTED = 0
    ACTIVE = 1
    HOLDING = 2
    LIMP = 3
    ESTOP = 4


class NackCode(enum.IntEnum):
    """Why a command was refused."""

    NOT_CONNECTED = 1
    UNSUPPORTED = 2
    UNKNOWN_JOINT = 3
    ESTOPPED = 4
    STALE_COMMAND = 5
    BAD_VALUE = 6


class FaultCode(enum.IntEnum):
    """What a FAULT message reports; FAULT.value carries the SI quantity named here."""

    WATCHDOG_EXPIRED = 1  # value: seconds since the last valid command
    SERVO_COMMS = 2  # value: unused (0)
    OVERHEAT = 3  # value: temperature, kelvin
    UNDERVOLTAGE = 4  # value: supply voltage, volts
    OVERCURRENT = 5  # value: current, amperes
    SENSOR = 6  # value: unused (0)
    LINK_RECOVERED = 7  # value: seconds the link was down
    INTERNAL = 8  # value: unused (0)


class JointError(enum.IntFlag):
    """Per-joint error bits of JOINT_STATE.error."""

    OVERHEAT = 1
    OVERLOAD = 2
    VOLTAGE = 4
    ENCODER = 8
    COMMS = 16
    TORQUE_OFF = 32
    LIMIT = 64
    STALE = 128


class Capability(enum.IntFlag):
    """Bits of HELLO_ACK.capabilities."""

    JOINT_CURRENT = 1
    FOOT_SENSORS = 2
    IMU = 4


ENUMS: dict[str, tuple[type[enum.IntEnum], str]] = {
    "WatchdogAction": (WatchdogAction, "u8"),
    "BoardState": (BoardState, "u8"),
    "NackCode": (NackCode, "u8"),
    "FaultCode": (FaultCode, "u16"),
}
FLAGS: dict[str, tuple[type[enum.IntFlag], str]] = {
    "JointError": (JointError, "u16"),
    "Capability": (Capability, "u32"),
}

MESSAGE_LINES = """\
0x01 ESTOP host engage:bool
0x02 FAULT board board_time_us:u32 code:FaultCode joint_id:u8 value:f32
0x08 SET_GOALS host cmd_seq:u16 *32 ids:u8 position:f32
0x09 JOINT_STATE board board_time_us:u32 *32 ids:u8 position:f32 velocity:f32 current:f32 error:u16
0x0a IMU board board_time_us:u32 orientation:f32x4 angular_velocity:f32x3 acceleration:f32x3
0x0b FOOT_SENSORS board board_time_us:u32 *4 foot_ids:u8 force:f32x4 cop_x:f32 cop_y:f32
0x10 TORQUE host *32 ids:u8 enable:bool
0x11 WATCHDOG host timeout_ms:u16 action:WatchdogAction
0x12 STREAM_RATES host joint_state_hz:u16 foot_sensors_hz:u16 imu_hz:u16 heartbeat_hz:u16
0x18 ACK both ref_msg_id:u8 ref_seq:u16
0x19 NACK both ref_msg_id:u8 ref_seq:u16 code:NackCode
0x1a STATUS board state:BoardState watchdog_action:WatchdogAction watchdog_timeout_ms:u16 \
torque_mask:u32 last_cmd_seq:u16 supply_voltage:f32 rx_errors:u16
0x1b HEARTBEAT both uptime_ms:u32 state:BoardState
0x20 HELLO host schema_hash:u64
0x21 HELLO_ACK board schema_hash:u64 device_id:u32 firmware_version:u32 capabilities:u32 \
*32 joint_ids:u8 joint_names:str16
"""

# Scalar wire types: struct code, byte size.
SCALARS = {"u8": ("B", 1), "u16": ("H", 2), "u32": ("I", 4), "u64": ("Q", 8), "f32": ("f", 4), "bool": ("B", 1)}


@dataclass(frozen=True)
class Field:
    """One payload field. ``kind`` is int, float, bool, enum, flags or str; ``count`` > 1 for f32xK."""

    name: str
    wire: str  # the type token as written in the schema
    kind: str
    code: str  # struct code of one element ('' for str16)
    size: int  # bytes on the wire (0 for the variable-size str16)
    count: int = 1
    enum: type[enum.IntEnum] | None = None


@dataclass(frozen=True)
class MessageSpec:
    """The layout of one message: fixed head fields, then an optional counted group."""

    msg_id: int
    name: str
    direction: str  # "host" (host -> board), "board" (board -> host) or "both"
    line: str
    head: tuple[Field, ...]
    group: tuple[Field, ...]
    group_max: int  # 0 when the message has no group
    seed: int  # CRC seed: CRC-32 of ``line``
    fixed_size: int  # payload bytes with an empty group: the head plus the count byte
    variable_records: bool  # a group record holds a str16, so records vary in size


def _parse_field(token: str) -> Field:
    name, wire = token.split(":")
    if wire in ENUMS:
        cls, base = ENUMS[wire]
        return Field(name, wire, "enum", *SCALARS[base], enum=cls)
    if wire in FLAGS:
        return Field(name, wire, "flags", *SCALARS[FLAGS[wire][1]])
    if wire == "str16":
        return Field(name, wire, "str", "", 0)
    if wire.startswith("f32x"):
        count = int(wire[4:])
        return Field(name, wire, "float", "f", 4 * count, count=count)
    kind = {"f32": "float", "bool": "bool"}.get(wire, "int")
    return Field(name, wire, kind, *SCALARS[wire])


def _parse_line(line: str) -> MessageSpec:
    tokens = line.split()
    msg_id, name, direction = int(tokens[0], 16), tokens[1], tokens[2]
    head: list[Field] = []
    group: list[Field] = []
    group_max = 0
    for token in tokens[3:]:
        if token.startswith("*"):
            group_max = int(token[1:])
        else:
            (group if group_max else head).append(_parse_field(token))
    seed = zlib.crc32(line.encode("ascii"))
    fixed_size = sum(f.size for f in head) + (1 if group_max else 0)
    variable = any(f.kind == "str" for f in group)
    return MessageSpec(msg_id, name, direction, line, tuple(head), tuple(group), group_max, seed, fixed_size, variable)


def _enum_lines() -> list[str]:
    lines = []
    for keyword, table in (("enum", ENUMS), ("flags", FLAGS)):
        for name, (cls, base) in table.items():
            members = " ".join(f"{m.name}={int(m.value)}" for m in cls)
            lines.append(f"{keyword} {name} {base} {members}")
    return lines


MESSAGES: tuple[MessageSpec, ...] = tuple(_parse_line(line) for line in MESSAGE_LINES.splitlines())
BY_ID: dict[int, MessageSpec] = {spec.msg_id: spec for spec in MESSAGES}
BY_NAME: dict[str, MessageSpec] = {spec.name: spec for spec in MESSAGES}

SCHEMA_TEXT = "\n".join([f"version {PROTOCOL_VERSION}", *_enum_lines(), *MESSAGE_LINES.splitlines()]) + "\n"
SCHEMA_HASH = int.from_bytes(hashlib.sha256(SCHEMA_TEXT.encode("ascii")).digest()[:8], "little")
