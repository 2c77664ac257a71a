"""firmware_protocol: the host <-> robot-board wire protocol (SPEC.md), both ends.

Codec: ``encode`` / ``StreamDecoder`` (serial), ``encode_can`` / ``CanDecoder``
(CAN). Transports: ``SerialTransport`` (pyserial), ``CanTransport``
(python-can). Sessions: ``HostSession`` (host) and ``BoardEngine`` (board).
"""

from .board import BoardBackend, BoardEngine
from .can_framing import CanDecoder, CanFrame, encode_can
from .errors import CommandRefused, DecodeError, HandshakeError, LinkError, ProtocolError
from .host import HostSession, LinkHealth
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
    from_dict,
    to_dict,
)
from .payload import decode_payload, encode_payload
from .schema import (
    MAX_FEET,
    MAX_JOINTS,
    MAX_PAYLOAD,
    PROTOCOL_VERSION,
    SCHEMA_HASH,
    BoardState,
    Capability,
    FaultCode,
    JointError,
    NackCode,
    WatchdogAction,
)
from .serial_framing import Received, StreamDecoder, encode
from .transport import CanTransport, SerialTransport

__all__ = [
    "Ack", "BoardBackend", "BoardEngine", "BoardState", "CanDecoder", "CanFrame", "CanTransport", "Capability",
    "CommandRefused", "DecodeError", "Estop", "Fault", "FaultCode", "FootSensors", "HandshakeError", "Heartbeat",
    "Hello", "HelloAck", "HostSession", "Imu", "JointError", "JointState", "LinkError", "LinkHealth", "MAX_FEET",
    "MAX_JOINTS", "MAX_PAYLOAD", "Message", "Nack", "NackCode", "PROTOCOL_VERSION", "ProtocolError", "Received",
    "SCHEMA_HASH", "SerialTransport", "SetGoals", "Status", "StreamDecoder", "StreamRates", "Torque", "Watchdog",
    "WatchdogAction", "decode_payload", "encode", "encode_can", "encode_payload", "from_dict", "to_dict",
]
