"""Has the robot fallen? From its IMU, as a robot without a simulator must tell.

Two signs, each held for ``hold_s`` so one bad sample is not a fall:

* the trunk tilted more than ``tilt_rad`` from where it was at the first reading (the
  robot stood then; comparing with it makes a tilted IMU mount or a sloped floor
  harmless): the robot is toppling or lying;
* the specific force below ``free_fall_g`` of g: the robot is in free fall (lifted off
  and dropped, or falling from a step).

Readings follow the links' IMU dict: ``orientation`` (w, x, y, z) rotating IMU-frame
vectors into the world (z up), ``acceleration`` the specific force (m/s², IMU axes),
``angular_velocity`` (rad/s, IMU axes). An IMU without an orientation (a gyro and an
accelerometer, as a Dynamixel sub-controller's) gives the tilt as the angle through which
gravity's direction in its axes has turned since the first reading, tracked by a
complementary filter: the gyro turns it, the accelerometer (within 20 % of 1 g) pulls it
back with a 0.2 s time constant.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from livezmp.estimate.ground_tilt import gravity_in_imu

G = 9.81  # m/s^2
ACCEL_TAU_S = 0.2  # s, the accelerometer's pull on the tracked gravity direction


@dataclass(frozen=True)
class FallConfig:
    """Thresholds: ``tilt_rad`` (rad from the first reading), ``free_fall_g`` (fraction of g),
    ``hold_s`` (s a sign must last)."""

    tilt_rad: float = math.radians(45.0)
    free_fall_g: float = 0.3
    hold_s: float = 0.05


def tilt_between(q0: np.ndarray, q1: np.ndarray) -> float:
    """Angle (rad) between the z axes of two orientations given as (w, x, y, z) quaternions."""
    return float(np.arccos(np.clip(_z_axis(q0) @ _z_axis(q1), -1.0, 1.0)))


def _z_axis(q: np.ndarray) -> np.ndarray:
    w, x, y, z = (float(v) for v in q)
    return np.array([2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)])


class FallDetector:
    """Feed IMU readings with `update`; ``fell`` (a reason) once a sign held for ``hold_s``."""

    def __init__(self, config: FallConfig | None = None) -> None:
        self.config = config or FallConfig()
        self.fell: str | None = None
        self.max_tilt = 0.0  # rad, the largest tilt seen
        self._upright: np.ndarray | None = None
        self._since: dict[str, float] = {}
        self._down: np.ndarray | None = None  # gravity's direction in the IMU's axes (no orientation given)
        self._down0: np.ndarray | None = None
        self._t: float | None = None

    def update(self, t: float, imu: dict[str, np.ndarray]) -> str | None:
        """One reading at ``t`` (s); the fall's reason once fallen (it stays), else None."""
        if self.fell is not None:
            return self.fell
        c = self.config
        signs = {}
        orientation = imu.get("orientation")
        tilt = None
        if orientation is not None and np.all(np.isfinite(orientation)):
            if self._upright is None:
                self._upright = np.asarray(orientation, dtype=float)
            tilt = tilt_between(self._upright, orientation)
        else:
            tilt = self._tracked_tilt(t, imu)
        if tilt is not None:
            self.max_tilt = max(self.max_tilt, tilt)
            signs["tilt"] = (tilt > c.tilt_rad, f"the trunk tilted {math.degrees(tilt):.0f} degrees")
        acceleration = imu.get("acceleration")
        if acceleration is not None and np.all(np.isfinite(acceleration)):
            g = float(np.linalg.norm(acceleration)) / G
            signs["free_fall"] = (g < c.free_fall_g, f"free fall ({g:.2f} g)")
        self._t = t
        for name, (on, reason) in signs.items():
            if not on:
                self._since.pop(name, None)
                continue
            since = self._since.setdefault(name, t)
            if t - since >= c.hold_s:
                self.fell = f"{reason} for {1e3 * (t - since):.0f} ms (IMU)"
        return self.fell

    def _tracked_tilt(self, t: float, imu: dict[str, np.ndarray]) -> float | None:
        """Tilt (rad) from gyro and accelerometer (module docstring); None before a usable reading."""
        dt = 0.0 if self._t is None else max(t - self._t, 0.0)
        gyro = imu.get("angular_velocity")
        if self._down is not None and gyro is not None and np.all(np.isfinite(gyro)):
            # a direction fixed in the world turns the other way in the IMU's axes
            self._down = pin.exp3(-np.asarray(gyro, dtype=float) * dt) @ self._down
        measured, _ = gravity_in_imu({"acceleration": imu["acceleration"]} if "acceleration" in imu else {}, 0.2)
        if measured is not None:
            measured = measured / np.linalg.norm(measured)
            if self._down is None:
                self._down = self._down0 = measured
            else:
                blended = self._down + min(1.0, dt / ACCEL_TAU_S) * (measured - self._down)
                self._down = blended / np.linalg.norm(blended)
        if self._down is None:
            return None
        return float(np.arccos(np.clip(self._down @ self._down0, -1.0, 1.0)))
