"""Shared test vectors: example messages with their exact serial and CAN bytes.

``vectors/frames.json`` is what other implementations (the C reference, a
firmware port) check themselves against. Regenerate it after a schema change:

    python -m firmware_protocol.vectors firmware_protocol/vectors/frames.json
"""

from __future__ import annotations

import json
import struct
import sys
from pathlib import Path

from .can_framing import encode_can
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
    Nack,
    SetGoals,
    Status,
    StreamRates,
    Torque,
    Watchdog,
    to_dict,
)
from .schema import MAX_JOINTS, SCHEMA_HASH, BoardState, FaultCode, NackCode, WatchdogAction
from .serial_framing import encode

VECTORS_PATH = Path(__file__).with_name("vectors") / "frames.json"


def f32(x: float) -> float:
    """x rounded to float32, so a value is exactly what the wire carries."""
    return struct.unpack("<f", struct.pack("<f", x))[0]


def example_joint_state(n: int) -> JointState:
    """A JOINT_STATE of joints 0..n-1 with float32-exact, distinct values."""
    return JointState(
        board_time_us=0xFFFFFFFF - n,
        ids=tuple(range(n)),
        position=tuple(f32(0.1 * i - 1.5) for i in range(n)),
        velocity=tuple(f32(-0.25 * i) for i in range(n)),
        current=tuple(f32(0.01 * i) for i in range(n)),
        error=tuple((1 << (i % 8)) if i % 3 == 0 else 0 for i in range(n)),
    )


def examples() -> list[tuple[str, object, int, int, int]]:
    """(name, message, serial seq, CAN node, CAN transfer id) for every vector."""
    tiny = struct.unpack("<f", struct.pack("<I", 1))[0]  # smallest float32 subnormal
    return [
        ("estop_engage", Estop(True), 0, 0, 0),
        ("estop_release", Estop(False), 65535, 3, 31),
        ("fault_overheat", Fault(123456789, FaultCode.OVERHEAT, 7, f32(358.15)), 42, 5, 1),
        ("set_goals_two", SetGoals(65535, (1, 2), (f32(0.5), f32(-1.25))), 1, 1, 0),
        ("set_goals_one_fits_one_can_frame", SetGoals(9, (4,), (-0.0,)), 2, 4, 2),
        ("set_goals_empty", SetGoals(0, (), ()), 3, 1, 3),
        ("joint_state_20", example_joint_state(20), 500, 1, 7),
        ("joint_state_max", example_joint_state(MAX_JOINTS), 501, 2, 8),
        ("joint_state_one", example_joint_state(1), 502, 9, 9),
        ("imu_upright", Imu(1000, (1.0, 0.0, 0.0, 0.0), (0.0, tiny, -0.0), (0.0, 0.0, f32(9.80665))), 7, 1, 4),
        ("foot_sensors_two", FootSensors(2000, (0, 1), ((10.0, 20.0, 30.0, 40.0), (0.0, 0.0, 0.0, f32(3.0e38))),
                                         (f32(0.02), 0.0), (f32(-0.01), 0.0)), 8, 1, 5),
        ("torque_mixed", Torque((1, 2, 255), (True, False, True)), 9, 1, 6),
        ("watchdog_drop", Watchdog(200, WatchdogAction.DROP_TORQUE), 10, 1, 10),
        ("stream_rates", StreamRates(1000, 100, 500, 10), 11, 1, 11),
        ("ack", Ack(0x10, 9), 12, 1, 12),
        ("nack_estopped", Nack(0x08, 65535, NackCode.ESTOPPED), 13, 1, 13),
        ("status_holding", Status(BoardState.HOLDING, WatchdogAction.HOLD, 500, 0xFFFFFFFF, 77, f32(11.9), 3),
         14, 1, 14),
        ("heartbeat_host", Heartbeat(0xFFFFFFFF, BoardState.ACTIVE), 15, 127, 15),
        ("hello", Hello(SCHEMA_HASH), 0, 1, 0),
        ("hello_ack", HelloAck(SCHEMA_HASH, 0xB0A4D001, 0x00010203, 7, (1, 2, 3),
                               ("l_hip_pitch", "x" * 16, 'q"\\ ~')), 0, 1, 0),
    ]


def build() -> list[dict]:
    """The vectors as JSON-ready dicts (serial frame hex; CAN frames as [id, data hex])."""
    out = []
    for name, msg, seq, node, tid in examples():
        from_board = msg.spec.direction == "board" or (msg.spec.direction == "both" and seq % 2 == 0)
        out.append({
            "name": name,
            "message": to_dict(msg),
            "seq": seq,
            "from_board": from_board,
            "serial": encode(msg, seq, from_board).hex(),
            "can_node": node,
            "can_tid": tid,
            "can": [[f.can_id, f.data.hex()] for f in encode_can(msg, node, tid, from_board)],
        })
    return out


def dumps(vectors: list[dict]) -> str:
    """Canonical text of the vectors file."""
    return json.dumps(vectors, indent=1) + "\n"


if __name__ == "__main__":
    Path(sys.argv[1] if len(sys.argv) > 1 else VECTORS_PATH).write_text(dumps(build()))
