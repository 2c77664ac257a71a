"""Online Kalman filter, constant-acceleration model, one independent filter per channel.

State per channel: [position, velocity, acceleration] in the channel's unit,
unit/s and unit/s^2.  The acceleration is driven by white jerk of power
spectral density ``jerk_psd`` (unit^2/s^5), the position is measured with
variance ``meas_var`` (unit^2).  All channels share the time step, so the
transition F and noise Q are two 3x3 matrices per step (cached while dt is
unchanged) and the per-channel covariances (n, 3, 3) are updated with
batched array operations.

Missing samples (NaN or inf, for some or all channels) only predict; a
dropped frame is simply a larger dt.  Angle channels compare the measurement
with the prediction modulo 2 pi (innovation wrapped to (-pi, pi]) so the
state stays continuous through +-pi.
"""

from __future__ import annotations

import numpy as np


def ca_transition(dt: float) -> np.ndarray:
    """(3, 3) constant-acceleration transition over ``dt`` seconds."""
    return np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])


def white_jerk_covariance(dt: float) -> np.ndarray:
    """(3, 3) process covariance gathered over ``dt`` seconds by white jerk of unit spectral density.

    Multiply by the jerk PSD (unit^2/s^5).  Exact integral of e^{A s} B B^T e^{A^T s} over [0, dt].
    """
    d2, d3 = dt * dt, dt * dt * dt
    return np.array(
        [
            [d3 * d2 / 20.0, d2 * d2 / 8.0, d3 / 6.0],
            [d2 * d2 / 8.0, d3 / 3.0, d2 / 2.0],
            [d3 / 6.0, d2 / 2.0, dt],
        ]
    )


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles (rad) wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


class ConstantAccelerationKalman:
    """Per-channel constant-acceleration Kalman filter over ``n`` channels.

    ``angle_mask`` (n,) bool marks angle channels (rad).  ``jerk_psd`` (>= 0)
    and ``meas_var`` (> 0) are scalars or (n,) arrays.  ``init_var`` (3,) is the prior
    variance of [position, velocity, acceleration] about [first sample, 0, 0]
    when a channel is first seen; make the last two large for a diffuse start.
    ``started`` (n,) marks the channels seen so far, ``all_started`` all of them.
    """

    def __init__(self, angle_mask: np.ndarray, jerk_psd, meas_var, init_var):
        self.angle_mask = np.asarray(angle_mask, dtype=bool)
        n = self.angle_mask.shape[0]
        self.jerk_psd = np.broadcast_to(np.asarray(jerk_psd, dtype=float), (n,))[:, None, None]
        self.meas_var = np.broadcast_to(np.asarray(meas_var, dtype=float), (n,)).copy()
        self.init_cov = np.diag(np.asarray(init_var, dtype=float))
        self.x = np.zeros((n, 3))
        self.P = np.zeros((n, 3, 3))
        self.started = np.zeros(n, dtype=bool)
        self.all_started = False
        self._any_angle = bool(self.angle_mask.any())
        self._dt = None
        self._F = self._FF = self._Q = None

    def reset(self) -> None:
        """Forget all channels' state."""
        self.x[:] = 0.0
        self.P[:] = 0.0
        self.started[:] = False
        self.all_started = False

    def _predict(self, dt: float) -> None:
        # Timestamps like i / rate differ in the last bits from step to step; F and Q for a dt within
        # 1e-9 of the cached one differ by far less than the filter's rounding, so reuse them.
        if self._dt is None or abs(dt - self._dt) > 1e-9 * self._dt:
            self._dt = dt
            self._F = ca_transition(dt)
            # Row-major vec(F P F^T) = (F kron F) vec(P): one (n, 9) @ (9, 9) product, far cheaper than
            # a stacked 3x3 matmul.  (np.kron itself is slow for 3x3.)
            self._FF = (self._F[:, None, :, None] * self._F[None, :, None, :]).reshape(9, 9).T
            self._Q = (self.jerk_psd * white_jerk_covariance(dt)).reshape(-1, 9)
        n = self.x.shape[0]
        self.x = self.x @ self._F.T
        self.P = (self.P.reshape(n, 9) @ self._FF + self._Q).reshape(n, 3, 3)

    def step(self, dt: float | None, y: np.ndarray) -> np.ndarray:
        """Advance ``dt`` seconds (None for the first sample) and take the measurements ``y`` (n,).

        Non-finite entries of ``y`` are missing: those channels only predict.
        A channel's first finite sample sets its state to [y, 0, 0] with
        covariance ``init_var``.  Returns the filtered positions (n,), a view
        of the state: angle channels are continuous, not wrapped.
        """
        valid = np.isfinite(y)
        if dt is not None:
            self._predict(dt)
        predicted = self.x[:, 0]
        col = self.P[:, :, 0].copy()  # P is symmetric: column 0 is also row 0 (H P)
        scale = 1.0 / (col[:, 0] + self.meas_var)
        if valid.all() and self.all_started:
            innovation = y - predicted  # the common case: every channel measured
        else:
            fresh = valid & ~self.started
            if fresh.any():
                self.x[fresh] = 0.0
                self.x[fresh, 0] = y[fresh]
                self.P[fresh] = self.init_cov
                self.started |= fresh
                self.all_started = bool(self.started.all())
            update = valid & ~fresh
            innovation = np.where(update, y, predicted) - predicted
            scale *= update
        if self._any_angle:
            innovation = np.where(self.angle_mask, wrap_angle(innovation), innovation)
        gain = col * scale[:, None]
        self.x += gain * innovation[:, None]
        self.P -= gain[:, :, None] * col[:, None, :]
        return self.x[:, 0]
