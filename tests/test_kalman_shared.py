"""The shared-covariance path of the Kalman filter (channels with equal noise, all measured) equals the
per-channel filter, through gaps, late channels, irregular steps, angle wrap-around and outside edits of P."""

import math

import numpy as np

from livezmp.estimate.kalman import ConstantAccelerationKalman, wrap_angle

DT = 1.0 / 200.0
Q, R, INIT = (2 * math.pi * 20) ** 6 * DT, 1.0, [1.0, 1e4 / DT**2, 1e4 / DT**4]


def pair(angle: np.ndarray):
    """The filter under test, and a reference over the same channels plus one with another measurement
    noise, which keeps every channel on its own covariance (the general path)."""
    shared = ConstantAccelerationKalman(angle, Q, R, INIT)
    reference = ConstantAccelerationKalman(np.r_[angle, False], Q, np.r_[np.full(angle.size, R), 2 * R], INIT)
    return shared, reference


def stream(steps: int, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    dts = DT * rng.choice([1.0, 1.0, 1.0, 2.0, 0.7], steps)
    t = np.cumsum(dts)
    ys = np.sin(2 * math.pi * rng.uniform(0.2, 2.0, n) * t[:, None]) + 0.01 * rng.normal(size=(steps, n))
    ys[:, 0] = wrap_angle(3.0 * t)  # an angle spinning through +-pi
    return dts, ys


def run(kf, dts, ys, extra=None, first=True):
    """Positions after each step; ``extra``: the reference's additional channel's sample."""
    out = []
    for i, y in enumerate(ys):
        y = y if extra is None else np.r_[y, extra]
        out.append(kf.step(None if first and i == 0 else dts[i], y)[: ys.shape[1]].copy())
    return np.array(out)


def assert_same(shared, reference, got, expected):
    """Equal up to rounding: the covariance recursion is ill-conditioned (variances from 1 to 1e8), so its
    rounding differs by a few 1e-10 between the two paths; the positions by far less."""
    n = got.shape[1]
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-10)
    scale = np.abs(reference.x[:n]).max(axis=0)
    assert np.all(np.abs(shared.x - reference.x[:n]) <= 1e-8 * scale)
    p, p_ref = shared.P, reference.P[:n]
    sd = np.sqrt(np.diagonal(p_ref, axis1=1, axis2=2))
    assert np.all(np.abs(p - p_ref) <= 1e-8 * sd[:, :, None] * sd[:, None, :])


def test_shared_covariance_equals_per_channel_filter_on_a_clean_stream():
    angle = np.array([True, True, False, True])
    dts, ys = stream(600, 4, 0)
    shared, reference = pair(angle)
    got = run(shared, dts, ys)
    assert shared._shared is not None  # the shared path was taken
    assert reference._shared is None
    assert_same(shared, reference, got, run(reference, dts, ys, 0.0))


def test_shared_covariance_leaves_and_resumes_through_gaps_and_late_channels():
    angle = np.array([True, False, True, True, False])
    dts, ys = stream(800, 5, 1)
    ys[:20, 3] = np.nan  # starts late
    ys[200, 1] = np.nan  # one sample missing
    ys[300:305] = np.nan
    ys[400:420, 2] = np.inf  # a burst on one channel
    shared, reference = pair(angle)
    seen_shared = []
    got = []
    for i, y in enumerate(ys):
        got.append(shared.step(None if i == 0 else dts[i], y).copy())
        seen_shared.append(shared._shared is not None)
    got = np.array(got)
    # each partial gap leaves the shared covariance for a while; it returns once the channels converge
    assert not seen_shared[10] and seen_shared[150] and not seen_shared[201] and seen_shared[299]
    assert all(seen_shared[300:305])  # every channel missing: all predict alike, still shared
    assert not seen_shared[405] and seen_shared[-1]
    assert_same(shared, reference, got, run(reference, dts, ys, 0.0))


def test_edits_of_p_from_outside_are_used_by_the_next_step():
    angle = np.zeros(3, dtype=bool)
    dts, ys = stream(100, 3, 2)
    shared, reference = pair(angle)
    run(shared, dts[:50], ys[:50])
    run(reference, dts[:50], ys[:50], 0.0)
    for kf in (shared, reference):
        kf.P[1, 0, 0] += 5.0  # in place, through the array P hands out
    got = run(shared, dts[50:], ys[50:], first=False)
    assert_same(shared, reference, got, run(reference, dts[50:], ys[50:], 0.0, first=False))


def test_overflowing_samples_take_the_general_path():
    shared, reference = pair(np.zeros(2, dtype=bool))
    ys = np.array([[1.0, 2.0], [1.0, 2.0], [1e200, 2.0], [1.0, 2.0]])  # y @ y overflows at the third sample
    got = run(shared, np.full(4, DT), ys)
    np.testing.assert_allclose(got, run(reference, np.full(4, DT), ys, 0.0), rtol=1e-12)
    assert np.isfinite(got).all()
