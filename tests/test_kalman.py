"""Constant-acceleration Kalman filter against closed forms, the Riccati equation and a textbook filter."""

import math

import numpy as np
import pytest
from scipy.integrate import quad_vec
from scipy.linalg import expm, solve_discrete_are

from livezmp.estimate.estimator import EstimatorConfig, StreamingEstimator
from livezmp.estimate.kalman import ConstantAccelerationKalman, ca_transition, white_jerk_covariance, wrap_angle

DT = 1.0 / 120.0
DIFFUSE = [1e-4, 1e6, 1e10]


def test_transition_composes_over_time():
    np.testing.assert_allclose(ca_transition(0.3) @ ca_transition(0.2), ca_transition(0.5), atol=1e-15)


def test_white_jerk_covariance_is_the_integral_of_the_continuous_model():
    a = np.diag([1.0, 1.0], k=1)  # d/dt [p, v, a] = [v, a, jerk]
    b = np.array([[0.0], [0.0], [1.0]])
    for dt in (0.004, 0.1, 1.3):
        integral, _ = quad_vec(lambda s: expm(a * s) @ b @ b.T @ expm(a * s).T, 0.0, dt)
        np.testing.assert_allclose(white_jerk_covariance(dt), integral, rtol=1e-10)


def test_wrap_angle_range_is_half_open_at_minus_pi():
    got = wrap_angle(np.array([math.pi, -math.pi, 3 * math.pi, 0.5, -0.5 - 4 * math.pi]))
    np.testing.assert_allclose(got, [math.pi, math.pi, math.pi, 0.5, -0.5], atol=1e-12)


def test_steady_state_covariance_solves_the_riccati_equation():
    q, r = 500.0, 1e-4
    kf = ConstantAccelerationKalman(np.zeros(2, dtype=bool), q, r, DIFFUSE)
    rng = np.random.default_rng(0)
    for i in range(3000):
        kf.step(None if i == 0 else DT, rng.normal(size=2))
    f = ca_transition(DT)
    h = np.array([[1.0, 0.0, 0.0]])
    prior = solve_discrete_are(f.T, h.T, q * white_jerk_covariance(DT), np.array([[r]]))
    posterior = prior - np.outer(prior[:, 0], prior[0]) / (prior[0, 0] + r)
    for p in kf.P:
        np.testing.assert_allclose(p, posterior, rtol=1e-7)


def textbook_filter(ts, ys, q, r, init_var, angle):
    """One channel, plain matrices, Joseph-form update: the reference the vectorised filter must equal."""
    x = P = None
    h = np.array([[1.0, 0.0, 0.0]])
    out = []
    for i, (t, y) in enumerate(zip(ts, ys, strict=True)):
        if x is not None and i:
            dt = t - ts[i - 1]
            f = ca_transition(dt)
            x = f @ x
            P = f @ P @ f.T + q * white_jerk_covariance(dt)
        if np.isfinite(y):
            if x is None:
                x, P = np.array([y, 0.0, 0.0]), np.diag(init_var)
            else:
                innovation = y - x[0]
                if angle:
                    innovation = (innovation + math.pi) % (2 * math.pi) - math.pi
                s = (h @ P @ h.T)[0, 0] + r
                k = P @ h.T / s
                x = x + k[:, 0] * innovation
                ikh = np.eye(3) - k @ h
                P = ikh @ P @ ikh.T + r * k @ k.T
        out.append(np.nan if x is None else x[0])
    return np.array(out)


def test_vectorised_filter_equals_textbook_filter_with_gaps_and_irregular_steps():
    rng = np.random.default_rng(1)
    n, steps = 5, 400
    ts = np.cumsum(rng.uniform(0.5, 3.0, steps)) * DT
    ys = np.cumsum(rng.normal(size=(steps, n)) * 0.05, axis=0)
    ys[:7, 3] = np.nan  # channel 3 starts late
    ys[100:130, 1] = np.nan  # a burst on one channel
    ys[200:205] = np.nan  # every channel missing
    ys[rng.random((steps, n)) < 0.05] = np.nan  # scattered drop-outs
    ys[300, 2] = np.inf
    angle = np.array([False, False, False, False, True])
    ys[:, 4] = wrap_angle(np.cumsum(rng.uniform(0.0, 0.3, steps)))  # spins through +-pi many times
    q, r = np.array([1.0, 10.0, 100.0, 1e3, 1e4]), 1e-3
    kf = ConstantAccelerationKalman(angle, q, r, [r, 100.0, 1e4])
    got = np.array([kf.step(None if i == 0 else ts[i] - ts[i - 1], y).copy() for i, y in enumerate(ys)])
    for c in range(n):
        expected = textbook_filter(ts, ys[:, c], q[c], r, [r, 100.0, 1e4], angle[c])
        started = np.isfinite(expected)
        np.testing.assert_allclose(got[started, c], expected[started], rtol=1e-7, atol=1e-9)
        assert np.all(got[~started, c] == 0.0)
        assert np.isfinite(got[:, c]).all()


def test_quadratic_motion_is_tracked_without_error():
    # A constant-acceleration model has no steady-state error on a parabola.
    kf = ConstantAccelerationKalman(np.zeros(1, dtype=bool), 1e3, 1e-4, DIFFUSE)
    for i in range(600):
        t = i * DT
        kf.step(None if i == 0 else DT, np.array([1.0 + 2.0 * t - 3.0 * t * t]))
    np.testing.assert_allclose(kf.x[0], [1.0 + 2.0 * t - 3.0 * t * t, 2.0 - 6.0 * t, -6.0], rtol=1e-8)


def test_missing_frames_only_predict():
    kf = ConstantAccelerationKalman(np.zeros(2, dtype=bool), 1e3, 1e-4, DIFFUSE)
    for i in range(200):
        t = i * DT
        kf.step(None if i == 0 else DT, np.array([t * t, 1.0 - t]))
    state, cov = kf.x.copy(), kf.P.copy()
    for _ in range(10):
        kf.step(DT, np.array([np.nan, np.nan]))
    f = np.linalg.matrix_power(ca_transition(DT), 10)
    np.testing.assert_allclose(kf.x, state @ f.T, rtol=1e-12)
    assert np.all(np.diagonal(kf.P, axis1=1, axis2=2) > np.diagonal(cov, axis1=1, axis2=2))
    # A dropped frame is the same prediction taken in one step.
    kf2 = ConstantAccelerationKalman(np.zeros(2, dtype=bool), 1e3, 1e-4, DIFFUSE)
    kf2.x, kf2.P, kf2.started[:] = state.copy(), cov.copy(), True
    kf2.step(10 * DT, np.array([np.nan, np.nan]))
    np.testing.assert_allclose(kf2.x, kf.x, rtol=1e-12)
    np.testing.assert_allclose(kf2.P, kf.P, rtol=1e-9)


def test_angle_state_stays_continuous_through_pi():
    rate = 3.0  # rad/s
    kf = ConstantAccelerationKalman(np.array([True]), 1e3, 1e-4, DIFFUSE)
    t = np.arange(600) * DT
    truth = 2.5 + rate * t  # passes +pi, 3pi, 5pi ...
    out = np.array([kf.step(None if i == 0 else DT, wrap_angle(truth[i : i + 1]))[0] for i in range(600)])
    np.testing.assert_allclose(out, truth, atol=1e-9)
    assert kf.x[0, 1] == pytest.approx(rate, rel=1e-9)


def test_an_angle_glitch_does_not_leave_the_rate_whole_turns_off():
    """UNIPD Walking5's left foot yaw at 60 Hz (MOtoNMS' BTS walk read with its toes mapped): a marker glitch swings it
    1.7 rad and back within a few frames. Unwrapped against the prediction, the rate it drove past half a turn per step
    was never taken back (every later prediction whole turns off, the innovation near 0): the state ran away by
    thousands of turns. Unwrapped against the previous sample, it settles where the measurement does."""
    dt = 1.0 / 60.0
    kf = StreamingEstimator(1, np.array([True]), EstimatorConfig(rate_hz=60.0)).kalman
    glitch = [0.07, 0.17, -0.42, 1.28, 1.89, 1.23, 0.88, 0.66, 0.49, 0.65, 0.32]
    yaw = np.array([0.0] * 60 + glitch + [0.1] * 120)
    out = np.array([kf.step(None if i == 0 else dt, yaw[i:i + 1])[0] for i in range(len(yaw))])
    assert np.abs(out[-60:] - 0.1).max() < 1e-3 and abs(kf.x[0, 1]) < 1e-2


def test_late_channel_starts_at_its_first_sample():
    kf = ConstantAccelerationKalman(np.zeros(2, dtype=bool), 1e3, 1e-4, DIFFUSE)
    kf.step(None, np.array([1.0, np.nan]))
    kf.step(DT, np.array([1.0, np.nan]))
    assert list(kf.started) == [True, False]
    out = kf.step(DT, np.array([1.0, 42.0]))
    np.testing.assert_array_equal(out, [1.0, 42.0])
    np.testing.assert_array_equal(kf.x[1], [42.0, 0.0, 0.0])
