"""Online Kalman filter, constant-acceleration model, one independent filter per channel.

State per channel: [position, velocity, acceleration] in the channel's unit,
unit/s and unit/s^2.  The acceleration is driven by white jerk of power
spectral density ``jerk_psd`` (unit^2/s^5), the position is measured with
variance ``meas_var`` (unit^2).  All channels share the time step, so the
transition F and noise Q are two 3x3 matrices per step (cached while dt is
unchanged) and the per-channel covariances (n, 3, 3) are updated with
batched array operations.

While every channel has the same noise parameters and is measured at every
step, all channels have the same covariance: it is then kept once, as six
floats (the 3x3 symmetric matrix), and only the states are updated per
channel.  A step with some (not all) samples missing or some channels
starting gives the channels their own covariances again (:attr:`P`); these
converge to each other within some tens of steps, and once every entry agrees
with the first channel's to ``SHARE_RTOL`` that one is shared again.

Missing samples (NaN or inf, for some or all channels) only predict; a
dropped frame is simply a larger dt.  Angle channels are unwrapped so the state
stays continuous through +-pi: each sample is taken on the branch nearest the
channel's previous sample when that one was measured (as the batch estimator,
:mod:`livezmp.offline.estimator`, unwraps them), else nearest the prediction.
Against the prediction alone a filter whose angle rate had been driven past
half a turn per step (a marker glitch flipping a segment for a frame) predicted
whole turns off, saw an innovation near 0 and never took its rate back: the
foot of MOtoNMS' UNIPD Walking5 ran away by 3319 turns at 30037 rad/s
(docs/validation.md, held-out round 5).
"""

from __future__ import annotations

import math

import numpy as np

# Per-channel covariances this close (relative, entry by entry) are taken as one shared covariance.
SHARE_RTOL = 1e-12


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
        self._P = np.zeros((n, 3, 3))
        # Covariance shared by every channel, (P00, P01, P02, P11, P12, P22), or None when each channel has its own
        # (self._P).  Possible only when all channels have the same noise parameters.
        self._uniform = bool(np.all(self.jerk_psd == self.jerk_psd[0]) and np.all(self.meas_var == self.meas_var[0]))
        self._shared: tuple[float, ...] | None = None
        self.started = np.zeros(n, dtype=bool)
        self.all_started = False
        self._any_angle = bool(self.angle_mask.any())
        self._last = np.full(n, np.nan)  # each channel's previous sample, unwrapped; NaN: not measured then
        self._dt = None
        self._F = self._FF = self._Q = self._Q1 = self._h = None

    @property
    def P(self) -> np.ndarray:
        """(n, 3, 3) covariance of each channel's state (unit^2, unit^2/s, ... as the state)."""
        self._unshare()  # hand out the per-channel array: what the caller does with it, the next step sees
        return self._P

    @P.setter
    def P(self, value: np.ndarray) -> None:
        self._P = np.asarray(value, dtype=float)
        self._shared = None

    def reset(self) -> None:
        """Forget all channels' state."""
        self.x[:] = 0.0
        self._P[:] = 0.0
        self._shared = None
        self.started[:] = False
        self.all_started = False
        self._last[:] = np.nan

    def _unshare(self) -> None:
        if self._shared is not None:
            self._P[:] = _symmetric(self._shared)
            self._shared = None

    def _cache(self, dt: float) -> None:
        # Timestamps like i / rate differ in the last bits from step to step; F and Q for a dt within
        # 1e-9 of the cached one differ by far less than the filter's rounding, so reuse them.
        if self._dt is None or abs(dt - self._dt) > 1e-9 * self._dt:
            self._dt = dt
            self._F = ca_transition(dt)
            # Row-major vec(F P F^T) = (F kron F) vec(P): one (n, 9) @ (9, 9) product, far cheaper than
            # a stacked 3x3 matmul.  (np.kron itself is slow for 3x3.)
            self._FF = (self._F[:, None, :, None] * self._F[None, :, None, :]).reshape(9, 9).T
            self._Q = (self.jerk_psd * white_jerk_covariance(dt)).reshape(-1, 9)
            q = self._Q[0].tolist()  # plain floats: faster than numpy scalars
            self._Q1 = (q[0], q[1], q[2], q[4], q[5], q[8])
            self._h = 0.5 * dt * dt

    def _predict(self, dt: float) -> None:
        self._cache(dt)
        n = self.x.shape[0]
        self.x = self.x @ self._F.T
        if self._shared is None:
            self._P = (self._P.reshape(n, 9) @ self._FF + self._Q).reshape(n, 3, 3)
            return
        # F P F^T + Q on the six distinct entries; F = [[1, dt, h], [0, 1, dt], [0, 0, 1]].
        a, b, c, d, e, f = self._shared
        q00, q01, q02, q11, q12, q22 = self._Q1
        dt, h = self._dt, self._h
        r00, r01, r02 = a + dt * b + h * c, b + dt * d + h * e, c + dt * e + h * f
        r11, r12 = d + dt * e, e + dt * f
        self._shared = (r00 + dt * r01 + h * r02 + q00, r01 + dt * r02 + q01, r02 + q02,
                        r11 + dt * r12 + q11, r12 + q12, f + q22)

    def step(self, dt: float | None, y: np.ndarray) -> np.ndarray:
        """Advance ``dt`` seconds (None for the first sample) and take the measurements ``y`` (n,).

        Non-finite entries of ``y`` are missing: those channels only predict.
        A channel's first finite sample sets its state to [y, 0, 0] with
        covariance ``init_var``.  Returns the filtered positions (n,), a view
        of the state: angle channels are continuous, not wrapped.
        """
        y = np.asarray(y, dtype=float)
        if self._shared is None and self.all_started and self._uniform:
            self._try_share()
        if self._shared is not None:
            if dt is not None:
                self._predict(dt)
            innovation = y - self.x[:, 0]
            largest = np.abs(innovation).max()
            if largest < math.inf:  # else some sample is missing (NaN or inf)
                return self._update_shared(y, innovation, largest)
            if not np.isfinite(y).any():
                return self.x[:, 0]  # nothing measured: every channel only predicts, alike
            self._unshare()
            dt = None  # already predicted
        return self._step_general(dt, y)

    def _try_share(self) -> None:
        P = self._P
        if np.all(np.abs(P - P[0]) <= SHARE_RTOL * np.abs(P[0])):
            (a, b, c), (_, d, e), (_, _, f) = P[0].tolist()
            self._shared = (a, b, c, d, e, f)

    def _update_shared(self, y: np.ndarray, innovation: np.ndarray, largest: float) -> np.ndarray:
        """Every channel measured, one covariance for all: the gain is one (3,) vector."""
        a, b, c, d, e, f = self._shared
        scale = 1.0 / (a + float(self.meas_var[0]))
        k0, k1, k2 = a * scale, b * scale, c * scale
        self._shared = (a - k0 * a, b - k0 * b, c - k0 * c, d - k1 * b, e - k1 * c, f - k2 * c)
        # Innovations inside (-pi, pi) need no unwrapping (the common case).
        if self._any_angle and not largest < math.pi:
            y = self._unwrapped(y, self.x[:, 0])
            innovation = y - self.x[:, 0]
        self._last[:] = y
        self.x += innovation[:, None] * np.array((k0, k1, k2))
        return self.x[:, 0]

    def _unwrapped(self, y: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """``y`` (n,) with each angle channel's sample on the branch nearest its previous sample (else nearest
        ``predicted``)."""
        ref = np.where(np.isfinite(self._last), self._last, predicted)
        return np.where(self.angle_mask, ref + wrap_angle(y - ref), y)

    def _step_general(self, dt: float | None, y: np.ndarray) -> np.ndarray:
        valid = np.isfinite(y)
        if dt is not None:
            self._predict(dt)
        P = self._P
        predicted = self.x[:, 0]
        col = P[:, :, 0].copy()  # P is symmetric: column 0 is also row 0 (H P)
        scale = 1.0 / (col[:, 0] + self.meas_var)
        if valid.all() and self.all_started:
            measured = y  # every channel measured
        else:
            fresh = valid & ~self.started
            if fresh.any():
                self.x[fresh] = 0.0
                self.x[fresh, 0] = y[fresh]
                P[fresh] = self.init_cov
                self.started |= fresh
                self.all_started = bool(self.started.all())
            update = valid & ~fresh
            measured = np.where(update, y, predicted)  # a fresh channel's state is its sample: no innovation
            scale *= update
        if self._any_angle:
            measured = np.where(valid, self._unwrapped(measured, predicted), predicted)
        self._last = np.where(valid, measured, np.nan)
        innovation = measured - predicted
        gain = col * scale[:, None]
        self.x += gain * innovation[:, None]
        P -= gain[:, :, None] * col[:, None, :]
        # Kept exactly symmetric: rounding in P - K H P leaves an antisymmetric part that the transition (a
        # Jordan block) makes grow, so channels whose covariances once differed would never meet again.
        self._P = 0.5 * (P + P.transpose(0, 2, 1))
        return self.x[:, 0]


def _symmetric(p: tuple[float, ...]) -> np.ndarray:
    """(3, 3) symmetric matrix from its entries (00, 01, 02, 11, 12, 22)."""
    a, b, c, d, e, f = p
    return np.array([[a, b, c], [b, d, e], [c, e, f]])
