"""An IMU on a Dynamixel bus: the sub-controller a humanoid carries beside its servos.

The ROBOTIS OP3's sub-controller is an OpenCR board at id 200 on the servos' bus
(ROBOTIS-OP3 ``op3_manager/config/OP3.robot``: ``sensor | /dev/ttyUSB0 | 200 | OPEN-CR``).
Its control table (ROBOTIS-Framework ``robotis_device/devices/sensor/OPEN-CR.device``),
the part read here: gyro x, y, z at addresses 32, 34, 36 and accelerometer x, y, z at 38,
40, 42, each a signed 16-bit little-endian value. Units (ROBOTIS-OP3
``open_cr_module.cpp``): gyro ±2000 deg/s over ±32800 (16.4 per deg/s), accelerometer
±2 g over ±32768 (16384 per g). The board is mounted turned about z: the vendor's module
negates x and y of both to get the robot's axes, which is what ``axes`` (the robot
config's ``[imu] axes``, board → base-link sign per axis) says. Its orientation
registers (roll, pitch, yaw at 44-48) are not read: the loop fuses gyro and
accelerometer with the legs itself (:mod:`livezmp.estimate.ground_tilt`), and every byte
costs rate on the bus.

Reading it is one more transaction per cycle (a Read instruction, 14 bytes, and its
status packet, 11 + 12 bytes): it costs its wire time and one more adapter round trip,
which the bus ceiling counts (:class:`livezmp.links.bus_timing.BusCeiling`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from livezmp.links.bus_timing import INSTRUCTION_OVERHEAD, STATUS_OVERHEAD

IMU_ADDRESS = 32  # gyro x (then y, z, then accelerometer x, y, z), int16 each
IMU_LENGTH = 12
GYRO_PER_DEG_S = 32800 / 2000  # raw units per deg/s: the vendor's 16.4
ACC_PER_G = 32768 / 2  # raw units per g
G = 9.81  # m/s^2 per g
_RAW = np.dtype("<i2")


def decode_imu(data: bytes, axes: Sequence[int]) -> dict[str, np.ndarray]:
    """The 12 register bytes from ``IMU_ADDRESS`` → the links' IMU dict: ``angular_velocity``
    (rad/s) and ``acceleration`` (specific force, m/s²), in base-link axes (``axes``: sign of
    each board axis)."""
    raw = np.frombuffer(data, dtype=_RAW).astype(float)
    signs = np.asarray(axes, dtype=float)
    return {"angular_velocity": signs * np.radians(raw[:3] / GYRO_PER_DEG_S),
            "acceleration": signs * raw[3:] * (G / ACC_PER_G)}


def encode_imu(angular_velocity: np.ndarray, specific_force: np.ndarray, axes: Sequence[int]) -> bytes:
    """The register bytes a board reads for base-link ``angular_velocity`` (rad/s) and
    ``specific_force`` (m/s²), saturating at its ranges (±2000 deg/s, ±2 g), as its sensor does."""
    signs = np.asarray(axes, dtype=float)
    gyro = signs * np.degrees(np.asarray(angular_velocity, dtype=float)) * GYRO_PER_DEG_S
    acc = signs * np.asarray(specific_force, dtype=float) * (ACC_PER_G / G)
    raw = np.clip(np.rint(np.concatenate([gyro, acc])), -32768, 32767)
    return raw.astype(_RAW).tobytes()


def read_bytes() -> tuple[int, int]:
    """(instruction bytes, status bytes) of the Read of the IMU's registers (Protocol 2.0)."""
    return INSTRUCTION_OVERHEAD + 4, STATUS_OVERHEAD + IMU_LENGTH

