"""The live loop's settings, with their defaults: what ``livezmp run`` and ``demo`` offer on the
command line (kept free of heavy imports, so parsing the command line stays fast)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from livezmp.balance.foot_sensors import CONTACT_FRACTION
from livezmp.correct.limits import CorrectionLimits
from livezmp.errors import InputError


@dataclass(frozen=True)
class SafetyConfig:
    """Safety settings (see the module docstring); every number must be positive."""

    watchdog_s: float = 0.1
    drop_torque: bool = False
    reconnect_every_s: float = 0.25
    max_frame_age_s: float = 0.02
    position_tolerance_rad: float = 0.05
    speed_factor: float = 1.5
    max_correction_rad: float = 0.5
    max_correction_rate_rad_s: float = 3.0
    limit_margin_rad: float = 0.01
    # a joint whose URDF gives no <limit velocity> (or 0) may move its goal at most this fast (rad/s): one turn
    # a second, above the no-load speed of common hobby and humanoid servos (XM430-W350 4.8 rad/s at 12 V)
    default_joint_speed_rad_s: float = 2 * math.pi
    stop_on_hardware_error: bool = True

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool):
                continue
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise InputError(f"safety setting {f.name} = {value!r}: must be a positive number")



CONTACT_MODES = ("auto", "sensors", "kinematics")


@dataclass(frozen=True)
class LoopConfig:
    """``rate_hz``: loop rate; ``correct``: add balance corrections; ``correct_hz``: the
    corrector's rate (every round(rate_hz / correct_hz) cycles' worth of loop time, at
    least every cycle; measured: the balance is the same at 125 Hz as at 500 Hz);
    ``ramp_s``: blend time from the present posture to the command (s);
    ``estimator_*``: window, lag (s) and cutoff (Hz) of the estimator;
    ``trunk_accel_deg_s2`` and ``correction_limits``: the corrector's limits on the root
    rotation (its angular acceleration pushes the ZMP the other way first, so it is kept
    gentle; the acceleration limit is for a robot whose CoM stands at most 0.3 m high, scaled
    down for taller ones: :func:`livezmp.correct.online.size_scaled_accel`);
    ``margin_m``: how far inside the support polygon the corrector aims the ZMP (m); None: 15 mm
    scaled up with the robot's size (:func:`livezmp.correct.online.size_scaled_margin`);
    ``status_every_s``: period of the status callback.
    ``contacts``: where the feet's contacts come from: ``"sensors"`` (the link's foot
    sensors: a foot is down when its cells carry more than ``contact_fraction`` of the
    body's weight; a frame without a reading falls back to kinematic detection, counted
    and told), ``"kinematics"`` (detected from the sole heights and speeds, sensors
    ignored), ``"auto"`` (sensors whenever the frame has them, silently kinematics
    otherwise). Sensor readings are compared with the ZMP in every mode.
    ``imu_tilt``: where the link reads an IMU, gravity's direction under the feet comes from
    it fused with the legs' kinematics, so a sloped ground gives the right ZMP
    (:mod:`livezmp.estimate.ground_tilt`); False: the ground is taken as level."""

    rate_hz: float = 500.0
    correct: bool = True
    correct_hz: float = 125.0
    ramp_s: float = 0.5
    estimator_window_s: float = 0.2
    estimator_lag_s: float = 0.03
    estimator_cutoff_hz: float = 8.0
    trunk_accel_deg_s2: float = 100.0
    correction_limits: CorrectionLimits = field(default_factory=CorrectionLimits)
    margin_m: float | None = None
    status_every_s: float = 1.0
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    contacts: str = "auto"
    contact_fraction: float = CONTACT_FRACTION
    imu_tilt: bool = True

    def estimator_config(self, rate_hz: float):
        """The loop's :class:`~livezmp.estimate.estimator.EstimatorConfig` at ``rate_hz`` (Hz); EstimatorError
        where the rate is too slow for its window (3 samples) or cutoff (below Nyquist)."""
        from livezmp.estimate.estimator import EstimatorConfig  # numerics: not for the command line's parsing

        return EstimatorConfig(rate_hz=rate_hz, window_s=self.estimator_window_s, lag_s=self.estimator_lag_s,
                               cutoff_hz=self.estimator_cutoff_hz)
