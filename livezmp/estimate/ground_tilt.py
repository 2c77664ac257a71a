"""Where gravity points under the robot's feet: the IMU fused with the leg kinematics.

Without a base sensor the live loop places the base with the stance foot flat on a level
ground (:class:`~livezmp.model.base_placement.BasePlacer`): on a slope, that frame's
"down" is wrong by the slope, and the ZMP by about the CoM height times its tangent
(≈ 25 mm for a 0.2 m-tall CoM on 7°). Keeping the placer's frame — the stance foot flat
on the plane z = 0, which is where the soles and the support polygon are — only gravity's
direction in it is needed; the ZMP computed under it is the centre of pressure on the
ground, whatever its tilt (:func:`livezmp.balance.zmp.compute_zmp`'s ``gravity``).

A complementary filter, per sample, constant cost:

* high frequencies from the leg kinematics: K, the base's orientation in the ground frame
  from the joint angles (exact, no drift, no lag), carries every fast change of the base,
  so gravity in the ground frame, g_c, is held still between updates (feet flat on a
  still ground do not turn);
* the gyro, where the IMU has one, turns g_c by the foot's own rotation, the gyro's rate
  less the base's rate relative to the foot (from K's change over the sample): a foot
  rolling on an edge or a rocking stance turns g_c at once;
* low frequencies from the IMU's gravity: its orientation's tilt where it gives one (a
  board's own attitude estimate), else its accelerometer's specific force (at rest, up),
  each turned into the ground frame by K, pull g_c towards themselves with time constant
  ``tau_s`` (longer for a bare accelerometer: the body's own accelerations average out
  over it; readings far from 1 g are skipped).

Why not an EKF: the state is one direction whose fast part the kinematics already give
exactly; an EKF would need noise models of the body's accelerations that we do not have,
and costs more per sample for the same steady state. The slope is a slow quantity, which
is what a complementary filter is for.

Frames: the IMU's axes are the base link's (as the simulated devices and the ``fw:``
boards give them); readings follow the links' IMU dict (``orientation`` (w, x, y, z)
IMU → world, ``angular_velocity`` rad/s and ``acceleration`` m/s² in IMU axes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

G = 9.81  # m/s^2


@dataclass(frozen=True)
class TiltConfig:
    """Time constants (s) of the pull towards the IMU's gravity: from its orientation,
    from its accelerometer; ``accel_gate`` (fraction of g): accelerometer readings whose
    magnitude is further than this from 1 g are not used (the body is accelerating)."""

    orientation_tau_s: float = 0.05
    accel_tau_s: float = 0.5
    accel_gate: float = 0.2


def _rotation(base: np.ndarray) -> np.ndarray:
    """Rotation of base coordinates (x, y, z, yaw, pitch, roll): R = Rz(yaw)·Ry(pitch)·Rx(roll)."""
    return pin.rpy.rpyToMatrix(float(base[5]), float(base[4]), float(base[3]))


def gravity_in_imu(imu: dict[str, np.ndarray], gate: float) -> tuple[np.ndarray | None, bool]:
    """(gravity in the IMU's axes (3,) m/s² or None, whether it came from an orientation)."""
    q = imu.get("orientation")
    if q is not None and np.all(np.isfinite(q)) and np.linalg.norm(q) > 0.5:
        w, x, y, z = (float(v) for v in np.asarray(q) / np.linalg.norm(q))
        world_z_in_imu = np.array([2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)])
        return -G * world_z_in_imu, True
    f = imu.get("acceleration")
    if f is not None and np.all(np.isfinite(f)):
        norm = float(np.linalg.norm(f))
        if abs(norm - G) <= gate * G:
            return -G * np.asarray(f, dtype=float) / norm, False
    return None, False


class GroundTilt:
    """Gravity in the base placer's ground frame, from an IMU and the legs (module docstring).

    Call :meth:`update` once per sample with the placer's base coordinates and the IMU
    reading (None when the sample has none); it returns gravity (3,) m/s² in the ground
    frame, or None before the first IMU reading."""

    def __init__(self, config: TiltConfig | None = None):
        self.config = config or TiltConfig()
        self.gravity: np.ndarray | None = None
        self._k: np.ndarray | None = None  # the base's orientation in the ground frame at the last sample
        self._t: float | None = None

    def update(self, t: float, base: np.ndarray, imu: dict[str, np.ndarray] | None) -> np.ndarray | None:
        """One sample at ``t`` (s): ``base`` (6,) from the placer (m, rad), ``imu`` its reading."""
        k = _rotation(base)
        dt = 0.0 if self._t is None else max(t - self._t, 0.0)
        if self.gravity is not None and imu is not None and self._k is not None and dt > 0:
            gyro = imu.get("angular_velocity")
            if gyro is not None and np.all(np.isfinite(gyro)):
                # the base's rotation relative to the foot over the sample, in base axes
                relative = pin.log3(self._k.T @ k)
                foot_turn = k @ (np.asarray(gyro, dtype=float) * dt - relative)  # in ground axes
                self.gravity = pin.exp3(foot_turn).T @ self.gravity
        self._k, self._t = k, t
        if imu is None:
            return self.gravity
        measured, from_orientation = gravity_in_imu(imu, self.config.accel_gate)
        if measured is None:
            return self.gravity
        measured = k @ measured
        if self.gravity is None:
            self.gravity = measured
            return self.gravity
        tau = self.config.orientation_tau_s if from_orientation else self.config.accel_tau_s
        alpha = min(1.0, dt / tau) if tau > 0 else 1.0
        blended = self.gravity + alpha * (measured - self.gravity)
        self.gravity = G * blended / np.linalg.norm(blended)
        return self.gravity

    @property
    def slope_rad(self) -> float | None:
        """The ground's tilt (rad) from level, or None before the first reading."""
        if self.gravity is None:
            return None
        return float(np.arccos(np.clip(-self.gravity[2] / np.linalg.norm(self.gravity), -1.0, 1.0)))
