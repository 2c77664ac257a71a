"""The "MIT mode" CAN protocol of the Mini Cheetah actuators: one command frame in, one state frame out.

The layout is that of B. Katz's motor controller firmware for the MIT Mini Cheetah
(``motorcontrol``, ``CAN_com.cpp``; B. Katz, "A low cost modular actuator for dynamic
robots", MIT 2018), which CubeMars AK-series motors ship as their "MIT mode" and many
legged robots use. Standard 11-bit ids at 1 Mbit/s:

* command, id = the motor's CAN id, 8 bytes, big-endian bit fields:
  position 16 bits, velocity 12, Kp 12, Kd 12, feed-forward torque 12;
* state reply, id = the master's id (0), 6 bytes: the motor's id, position 16 bits,
  velocity 12, torque 12. The motor answers every frame addressed to it, so a cycle is
  one command and one reply per motor;
* special commands, 7 x 0xFF then 0xFC (enter motor mode), 0xFD (exit: no torque),
  0xFE (set the present position as zero).

Each field is a float mapped linearly onto an unsigned integer over a fixed range
(`Ranges`, the firmware's P/V/KP/KD/T limits; the defaults are the Mini Cheetah actuator's):
``uint = (x - lo) * (2**bits - 1) / (hi - lo)``, truncated, and back.
"""

from __future__ import annotations

from dataclasses import dataclass

MASTER_ID = 0  # the id state replies are sent on (the firmware's CAN_MASTER)
ENTER_MOTOR_MODE = bytes([0xFF] * 7 + [0xFC])
EXIT_MOTOR_MODE = bytes([0xFF] * 7 + [0xFD])
SET_ZERO = bytes([0xFF] * 7 + [0xFE])
COMMAND_BYTES, REPLY_BYTES = 8, 6


@dataclass(frozen=True)
class Ranges:
    """The fields' ranges: position rad, velocity rad/s, Kp N·m/rad, Kd N·m·s/rad, torque N·m."""

    p: float = 12.5
    v: float = 65.0
    kp: float = 500.0
    kd: float = 5.0
    t: float = 18.0


MINI_CHEETAH = Ranges()


def float_to_uint(x: float, lo: float, hi: float, bits: int) -> int:
    """``x`` clipped to [lo, hi] as an unsigned ``bits``-bit integer (the firmware's conversion)."""
    x = min(max(x, lo), hi)
    return int((x - lo) * ((1 << bits) - 1) / (hi - lo))


def uint_to_float(u: int, lo: float, hi: float, bits: int) -> float:
    return u * (hi - lo) / ((1 << bits) - 1) + lo


def pack_command(p: float, v: float, kp: float, kd: float, t: float, r: Ranges = MINI_CHEETAH) -> bytes:
    """The 8 data bytes of a command: position goal p (rad), velocity v (rad/s), gains kp, kd, torque t (N·m)."""
    pi = float_to_uint(p, -r.p, r.p, 16)
    vi = float_to_uint(v, -r.v, r.v, 12)
    kpi = float_to_uint(kp, 0.0, r.kp, 12)
    kdi = float_to_uint(kd, 0.0, r.kd, 12)
    ti = float_to_uint(t, -r.t, r.t, 12)
    return bytes([pi >> 8, pi & 0xFF, vi >> 4, ((vi & 0xF) << 4) | (kpi >> 8), kpi & 0xFF, kdi >> 4,
                  ((kdi & 0xF) << 4) | (ti >> 8), ti & 0xFF])


def unpack_command(data: bytes, r: Ranges = MINI_CHEETAH) -> tuple[float, float, float, float, float]:
    """(p, v, kp, kd, t) of a command's 8 data bytes."""
    pi = (data[0] << 8) | data[1]
    vi = (data[2] << 4) | (data[3] >> 4)
    kpi = ((data[3] & 0xF) << 8) | data[4]
    kdi = (data[5] << 4) | (data[6] >> 4)
    ti = ((data[6] & 0xF) << 8) | data[7]
    return (uint_to_float(pi, -r.p, r.p, 16), uint_to_float(vi, -r.v, r.v, 12), uint_to_float(kpi, 0.0, r.kp, 12),
            uint_to_float(kdi, 0.0, r.kd, 12), uint_to_float(ti, -r.t, r.t, 12))


def pack_reply(motor_id: int, p: float, v: float, t: float, r: Ranges = MINI_CHEETAH) -> bytes:
    """The 6 data bytes of a state reply: the motor's id, position p (rad), velocity v (rad/s), torque t (N·m)."""
    pi = float_to_uint(p, -r.p, r.p, 16)
    vi = float_to_uint(v, -r.v, r.v, 12)
    ti = float_to_uint(t, -r.t, r.t, 12)
    return bytes([motor_id, pi >> 8, pi & 0xFF, vi >> 4, ((vi & 0xF) << 4) | (ti >> 8), ti & 0xFF])


def unpack_reply(data: bytes, r: Ranges = MINI_CHEETAH) -> tuple[int, float, float, float]:
    """(motor id, p rad, v rad/s, t N·m) of a state reply's 6 data bytes."""
    pi = (data[1] << 8) | data[2]
    vi = (data[3] << 4) | (data[4] >> 4)
    ti = ((data[4] & 0xF) << 8) | data[5]
    return (data[0], uint_to_float(pi, -r.p, r.p, 16), uint_to_float(vi, -r.v, r.v, 12),
            uint_to_float(ti, -r.t, r.t, 12))
