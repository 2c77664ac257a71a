"""Velocities and accelerations from noisy poses: Kalman filter, sliding spline differentiator, streaming estimator."""
