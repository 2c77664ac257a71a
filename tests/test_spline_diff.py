"""Sliding smoothing-spline differentiator against scipy's smoothing spline and closed forms."""

import math

import numpy as np
import pytest
from scipy.interpolate import make_smoothing_spline

from livezmp.estimate import spline_diff
from livezmp.estimate.spline_diff import SlidingSplineDifferentiator, smoothing_lambda, uniform_weights, window_weights

DT = 1.0 / 120.0
LAM = smoothing_lambda(DT, 6.0)


def scipy_chain(t, y, lam, index):
    """Position, velocity, acceleration at t[index] by the paper's chain, built from scipy alone."""
    s1 = make_smoothing_spline(t, y, lam=lam)
    v1 = s1.derivative()
    s2 = make_smoothing_spline(t, v1(t), lam=lam)
    return np.array([s1(t[index]), v1(t[index]), s2.derivative()(t[index])])


@pytest.mark.parametrize("k", [5, 9, 40])
def test_window_weights_match_scipy_smoothing_spline_on_irregular_times(k):
    rng = np.random.default_rng(k)
    t = 3.0 + np.cumsum(rng.uniform(0.4, 1.6, k)) * DT
    y = rng.normal(size=(k, 4))
    for index in (0, k // 2, k - 1):
        expected = scipy_chain(t, y, LAM, index)
        got = window_weights(t, LAM, index) @ y
        np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def test_uniform_weights_match_scipy_on_the_same_window():
    window, lag = 48, 12
    t = np.arange(window) * DT
    y = np.random.default_rng(1).normal(size=(window, 3))
    expected = scipy_chain(t, y, LAM, window - 1 - lag)
    np.testing.assert_allclose(uniform_weights(window, lag, DT, LAM) @ y, expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("k", [2, 3, 4, 7])
def test_lines_are_reproduced_exactly_for_any_window(k):
    # A line has zero curvature: no smoothing spline changes it, whatever lam and spacing.
    t = np.cumsum(np.linspace(0.5, 1.5, k)) * DT
    y = (0.3 - 2.5 * t)[:, None]
    for index in range(k):
        got = window_weights(t, 10 * LAM, index) @ y
        np.testing.assert_allclose(got[:, 0], [0.3 - 2.5 * t[index], -2.5, 0.0], atol=1e-10)


def test_single_sample_gives_zero_derivatives():
    np.testing.assert_array_equal(window_weights(np.array([4.0]), LAM, 0), [[1.0], [0.0], [0.0]])


def interior_response(theta, dt, lam):
    """Closed-form gain of the cubic smoothing spline on an infinite uniform grid.

    Values g = B3 c with B-spline coefficients c; minimising |y - B3 c|^2 + lam/dt^3 * c^T (D2^T B3 D2) c
    gives H = 1 / (1 + lam/dt^3 (2 - 2 cos)^2 / B3), B3 = (2 + cos) / 3.  The slope at a knot is
    (c[k+1] - c[k-1]) / (2 dt), so velocity is j sin(theta) H / (dt B3); acceleration repeats it.
    """
    b3 = (2.0 + np.cos(theta)) / 3.0
    h = 1.0 / (1.0 + lam / dt**3 * (2.0 - 2.0 * np.cos(theta)) ** 2 / b3)
    hv = 1j * np.sin(theta) * h / (dt * b3)
    return h, hv, hv * hv


def test_interior_weights_have_the_closed_form_frequency_response():
    window, lag = 241, 120  # the estimate sits 1 s from both ends: far beyond the kernel's reach
    w = uniform_weights(window, lag, DT, LAM)
    offsets = np.arange(window) - (window - 1 - lag)
    for theta in (0.02, 0.3, 2 * math.pi * 6.0 * DT, 1.0, 2.5):
        measured = w @ np.exp(1j * theta * offsets)
        expected = np.array(interior_response(theta, DT, LAM))
        np.testing.assert_allclose(measured, expected, rtol=1e-5, atol=1e-9 * np.abs(expected).max())


def test_cutoff_frequency_has_gain_one_half():
    for dt, cutoff in ((1 / 30, 6.0), (1 / 120, 6.0), (1 / 1000, 40.0)):
        theta = 2 * math.pi * cutoff * dt
        h, _, _ = interior_response(theta, dt, smoothing_lambda(dt, cutoff))
        assert h == pytest.approx(0.5, rel=1e-12)


def test_interior_noise_gain_matches_closed_form_integral():
    # White noise of variance s^2 leaves with variance s^2 / (2 pi) * integral |H|^2 over (-pi, pi].
    w = uniform_weights(241, 120, DT, LAM)
    theta = np.linspace(-math.pi, math.pi, 200001)
    for row, response in zip(w, interior_response(theta, DT, LAM), strict=True):
        expected = np.trapezoid(np.abs(response) ** 2, theta) / (2 * math.pi)
        assert np.sum(row**2) == pytest.approx(expected, rel=1e-6)


def test_smoothing_lambda_rejects_cutoff_at_or_above_nyquist():
    with pytest.raises(ValueError, match="must lie in"):
        smoothing_lambda(DT, 60.0)


def reference_estimate(times, samples, lag):
    """Exact fit of the last samples, done directly."""
    return window_weights(np.array(times), LAM, len(times) - 1 - lag) @ np.array(samples)


def test_ring_buffer_estimate_equals_direct_fit_on_the_last_window():
    window, lag = 20, 4
    diff = SlidingSplineDifferentiator(3, window, lag, DT, LAM, jitter_tol=1e-3)
    rng = np.random.default_rng(2)
    times, samples = [], []
    t = 0.0
    for i in range(70):
        # Uniform stretches, a dropped frame and a jittery stretch.
        t += DT * (2.0 if i == 30 else 1.0 + (0.3 * rng.uniform(-1, 1) if 45 <= i < 50 else 0.0))
        y = rng.normal(size=3)
        diff.push(t, y)
        times, samples = (times + [t])[-window:], (samples + [y])[-window:]
        if len(times) > lag:
            np.testing.assert_allclose(diff.estimate(), reference_estimate(times, samples, lag), atol=1e-9)
            assert diff.time_at(lag) == times[-1 - lag]
        for other in range(min(lag, len(times))):
            np.testing.assert_allclose(diff.estimate(other), reference_estimate(times, samples, other), atol=1e-9)


def test_uniform_path_equals_exact_path_on_uniform_times():
    window, lag = 30, 5
    rng = np.random.default_rng(3)
    ys = rng.normal(size=(100, 2))
    fast = SlidingSplineDifferentiator(2, window, lag, DT, LAM, jitter_tol=1e-6)
    exact = SlidingSplineDifferentiator(2, window, lag, DT, LAM, jitter_tol=0.0)  # float noise forces exact
    for i, y in enumerate(ys):
        t = 100.0 + i * DT
        fast.push(t, y)
        exact.push(t, y)
        if i >= window:
            np.testing.assert_allclose(fast.estimate(), exact.estimate(), rtol=1e-8, atol=1e-8)
    # The fast path really is the precomputed one: it reproduces weights @ window bit for bit.
    np.testing.assert_array_equal(fast.estimate(), fast.weights @ ys[-window:])


def test_timing_jitter_within_tolerance_uses_uniform_weights_and_beyond_it_refits():
    window, lag = 12, 2
    ys = np.random.default_rng(4).normal(size=(window, 1))
    for jitter, uniform in ((0.009, True), (0.011, False)):
        diff = SlidingSplineDifferentiator(1, window, lag, DT, LAM, jitter_tol=0.01)
        times = np.arange(window) * DT
        times[5] += jitter * DT
        for t, y in zip(times, ys, strict=True):
            diff.push(t, y)
        exact = window_weights(times, LAM, window - 1 - lag) @ ys
        uniform_result = diff.weights @ ys
        np.testing.assert_array_equal(diff.estimate(), uniform_result if uniform else exact)


def test_backfill_replaces_a_channels_history():
    diff = SlidingSplineDifferentiator(2, 8, 0, DT, LAM, jitter_tol=1e-3)
    for i in range(5):
        diff.push(i * DT, np.array([i * 1.0, 0.0]))
    diff.backfill(np.array([False, True]), np.array([99.0, 7.0]))
    diff.push(5 * DT, np.array([5.0, 7.0]))
    est = diff.estimate()
    np.testing.assert_allclose(est[:, 1], [7.0, 0.0, 0.0], atol=1e-9)  # constant history: no motion
    np.testing.assert_allclose(est[:, 0], [5.0, 120.0, 0.0], atol=1e-6)  # untouched ramp channel


def test_memory_is_fixed_while_streaming():
    diff = SlidingSplineDifferentiator(26, 48, 12, DT, LAM, jitter_tol=1e-3)
    y = np.ones(26)
    diff.push(0.0, y)
    before = {name: (v.shape, v.nbytes) for name, v in vars(diff).items() if isinstance(v, np.ndarray)}
    for i in range(1, 10_000):
        diff.push(i * DT, y)
    after = {name: (v.shape, v.nbytes) for name, v in vars(diff).items() if isinstance(v, np.ndarray)}
    assert after == before


def test_windows_with_skipped_grid_samples_are_fitted_once_per_pattern(monkeypatch):
    """A loop that skips a deadline leaves a gap of whole periods in the window: each window is the exact fit
    on its times, but a pattern of gaps seen before (the next gap alike, as the window slides past it)
    reuses its weights instead of fitting again; the weights kept stay within their byte budget."""
    window, lag = 16, 3
    fits = []
    fit = spline_diff.window_weights
    monkeypatch.setattr(spline_diff, "window_weights", lambda *a: fits.append(1) or fit(*a))
    rng = np.random.default_rng(5)
    for budget, refits in ((spline_diff.GRID_WEIGHTS_BYTES, 0), (5 * 3 * window * 8, window - 1)):
        diff = SlidingSplineDifferentiator(2, window, lag, DT, LAM, jitter_tol=1e-3, grid_weights_bytes=budget)
        times, samples = [], []
        per_gap = []
        index = 0
        for gap in range(3):  # three gaps of one missing sample, each followed by a full window
            index += 2
            for _ in range(window + 2):
                t, y = 100.0 + index * DT, rng.normal(size=2)
                index += 1
                diff.push(t, y)
                times, samples = (times + [t])[-window:], (samples + [y])[-window:]
                if gap:
                    fits.clear()
                    np.testing.assert_allclose(diff.estimate(), fit(np.array(times), LAM, window - 1 - lag) @ samples,
                                               atol=1e-9)
                    per_gap.append(len(fits))
            assert len(diff._grid) <= diff._grid_kept
        # the second and third gaps: no fit with room for the patterns; without it one a window holding the gap
        assert sum(per_gap[window + 2:]) == refits



def dense_chain_weights(t, lam, index):
    """(3, k) weights of the paper's chain, from the Reinsch equations written out as dense matrices."""
    k = len(t)
    h = np.diff(t)
    q = np.zeros((k, k - 2))
    r = np.zeros((k - 2, k - 2))
    for j in range(k - 2):
        q[j : j + 3, j] = 1 / h[j], -1 / h[j] - 1 / h[j + 1], 1 / h[j + 1]
        r[j, j] = (h[j] + h[j + 1]) / 3
        if j < k - 3:
            r[j, j + 1] = r[j + 1, j] = h[j + 1] / 6
    c = np.zeros((k, k))  # knot second derivatives per unit sample
    c[1:-1] = np.linalg.solve(r + lam * q.T @ q, q.T)
    g = np.eye(k) - lam * q @ c[1:-1]  # knot values per unit sample
    v = np.zeros((k, k))  # knot slopes: an interval's at its left end, the last knot's at the right end of the last
    for i in range(k):
        a = min(i, k - 2)
        near, far = (-2, -1) if i < k - 1 else (1, 2)
        v[i] = (g[a + 1] - g[a]) / h[a] + (near * c[a] + far * c[a + 1]) * h[a] / 6
    return np.array([g[index], v[index], v[index] @ v])


@pytest.mark.parametrize("seed", range(4))
def test_exact_fit_of_a_window_with_skipped_deadlines_equals_the_dense_solution(seed):
    """The banded fit (rows of weights through LAPACK, one row in 1-D) against dense linear algebra, on the
    live loop's windows: grid times index * dt with several deadlines skipped, at every kind of index."""
    rng = np.random.default_rng(seed)
    dt, k = 1e-3, 60
    lam = smoothing_lambda(dt, 8.0)
    ticks = np.sort(rng.choice(np.arange(7000, 7000 + k + 12), size=k, replace=False))
    t = ticks * dt
    for index in (0, 1, k // 2, k - 31, k - 2, k - 1):
        expected = dense_chain_weights(t, lam, index)
        got = window_weights(t, lam, index)
        scale = np.abs(expected).max(axis=1, keepdims=True)
        np.testing.assert_allclose(got / scale, expected / scale, rtol=0, atol=1e-9)


@pytest.mark.parametrize("window, lag", [(17, 4), (60, 12)])
def test_windows_with_several_gaps_fit_from_kept_band_terms_bit_for_bit(monkeypatch, window, lag):
    """A window with several skipped deadlines (or jittered times) is fitted on its actual times from the band
    terms the ring keeps per interval, not formed again by `window_weights`: the same weights bit for bit."""
    fit = spline_diff.window_weights
    calls = []
    monkeypatch.setattr(spline_diff, "window_weights", lambda *a: calls.append(1) or fit(*a))
    rng = np.random.default_rng(window)
    diff = SlidingSplineDifferentiator(3, window, lag, DT, LAM, jitter_tol=0.01)
    times, samples = [], []
    tick, general = 7000, 0
    for _ in range(8 * window):
        tick += 1 + int(rng.random() < 0.15) * int(rng.integers(1, 4))  # deadlines skipped
        t = tick * DT + (rng.normal() * 3e-5 if rng.random() < 0.03 else 0.0)  # and a few jittered reads
        diff.push(t, rng.normal(size=3))
        times, samples = (times + [t])[-window:], (samples + [diff._y[diff._slot]])[-window:]
        periods = np.diff(times) / DT
        off = periods[np.abs(periods - 1.0) > 0.01]
        if len(times) <= lag or len(off) == 1 and abs(off[0] - round(off[0])) <= 0.01:
            continue  # the estimator's lag filling, and the kept weights of a window with one gap on the grid
        calls.clear()
        got = diff.estimate()
        assert not calls
        expected = fit(diff._t[diff._slot + window + 1 - len(times): diff._slot + window + 1], LAM,
                       len(times) - 1 - lag) @ np.array(samples)
        assert np.array_equal(got, expected)
        general += 1
    assert general > 2 * window


def slopes_adjoint_before(u, h):
    """`_slopes_adjoint` as it was (the reference): zeroes, each interval's terms added in place."""
    rate = u[..., :-1] / h
    zg = np.zeros(u.shape)
    zg[..., :-1] -= rate
    zg[..., 1:] += rate
    end_rate = u[..., -1] / h[-1]
    zg[..., -2] -= end_rate
    zg[..., -1] += end_rate
    arm = u[..., :-1] * h / 6.0
    zc = np.zeros(u.shape)
    zc[..., :-1] -= 2.0 * arm
    zc[..., 1:] -= arm
    end_arm = u[..., -1] * h[-1] / 6.0
    zc[..., -2] += end_arm
    zc[..., -1] += 2.0 * end_arm
    return zg, zc


def test_slopes_adjoint_gives_the_reference_values():
    """The knot-slope map's transpose in fewer numpy calls: its every value as the reference's, bit for bit on
    rows without zeros (a zero entry may come out as -0.0 where the reference had 0.0), one row or several."""
    rng = np.random.default_rng(3)
    for k in (2, 3, 4, 17, 200):
        h = DT * (1.0 + rng.integers(0, 3, k - 1) + rng.normal(0.0, 0.01, k - 1))
        for u in (rng.normal(size=k), rng.normal(size=(2, k)), np.where(rng.random(k) < 0.3, 0.0, rng.normal(size=k))):
            for got, expected in zip(spline_diff._slopes_adjoint(u, h), slopes_adjoint_before(u, h), strict=True):
                assert np.array_equal(got, expected)
                if u.all():
                    assert got.tobytes() == expected.tobytes()
