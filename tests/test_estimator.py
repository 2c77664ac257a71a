"""Streaming estimator: analytic signals, noise, gaps, wrap-around, irregular time, memory, offline parity."""

import math
import tracemalloc

import numpy as np
import pytest
from scipy.interpolate import make_smoothing_spline
from test_spline_diff import interior_response

from livezmp.estimate.estimator import EstimatorConfig, EstimatorError, StreamingEstimator, estimate_offline
from livezmp.estimate.kalman import wrap_angle
from livezmp.estimate.spline_diff import smoothing_lambda

CFG = EstimatorConfig()  # 120 Hz, window 0.4 s, lag 0.1 s, cutoff 6 Hz


def sines(t, freq, phases=(0.0, 0.7, 1.9)):
    w = 2 * math.pi * freq
    args = w * t[:, None] + np.array(phases)
    return np.sin(args), w * np.cos(args), -w * w * np.sin(args)


def steady(x, cfg=CFG, skip_s=1.0):
    """Frames away from the start-up and the flushed end of a take."""
    n = int(skip_s * cfg.rate_hz)
    return x[n:-n]


def relative_errors(estimates, truths, w, cfg=CFG):
    return [
        np.abs(steady(e - tr, cfg)).max() / w**k for k, (e, tr) in enumerate(zip(estimates, truths, strict=True))
    ]


@pytest.mark.parametrize(
    "freq, bounds",
    # Documented accuracy of the defaults (module docstring), relative to A, A w, A w^2.
    [(1.0, (0.004, 0.017, 0.035)), (2.0, (0.022, 0.045, 0.085))],
)
def test_sinusoid_derivatives_within_documented_accuracy(freq, bounds):
    t = np.arange(720) * CFG.dt
    truth = sines(t, freq)
    errors = relative_errors(estimate_offline(t, truth[0], None, CFG), truth, 2 * math.pi * freq)
    print(f"{freq} Hz sine, relative max error q/qd/qdd: " + " ".join(f"{e:.4f}" for e in errors))
    assert all(e <= b for e, b in zip(errors, bounds, strict=True))


def test_straight_line_is_exact_after_the_filter_settles():
    t = 5.0 + np.arange(300) * CFG.dt
    y = np.stack([0.2 - 1.5 * t, 3.0 + 0.25 * t], axis=1)
    q, qd, qdd = estimate_offline(t, y, None, CFG)
    settled = slice(int(0.5 * CFG.rate_hz), None)  # the Kalman start-up transient is gone by then
    np.testing.assert_allclose(q[settled], y[settled], atol=1e-9)
    np.testing.assert_allclose(qd[settled], np.broadcast_to([-1.5, 0.25], y.shape)[settled], atol=1e-7)
    np.testing.assert_allclose(qdd[settled], 0.0, atol=1e-5)


def interior_noise_gains(cfg):
    theta = np.linspace(-math.pi, math.pi, 100001)
    responses = interior_response(theta, cfg.dt, smoothing_lambda(cfg.dt, cfg.cutoff_hz))
    return np.array([math.sqrt(np.trapezoid(np.abs(r) ** 2, theta) / (2 * math.pi)) for r in responses])


def test_white_noise_output_matches_smoothing_spline_theory():
    # Lag in the middle of a long window and a Kalman corner at Nyquist: the chain is the pure spline.
    cfg = EstimatorConfig(window_s=1.0, lag_s=0.5, kalman_corner_hz=60.0)
    sigma = 1e-3
    y = sigma * np.random.default_rng(5).normal(size=(6000, 3))
    t = np.arange(6000) * cfg.dt
    measured = np.array([steady(x, cfg).std() for x in estimate_offline(t, y, None, cfg)])
    expected = sigma * interior_noise_gains(cfg)
    print("noise std q/qd/qdd measured", measured, "theory", expected)
    np.testing.assert_allclose(measured, expected, rtol=0.06)


def test_noisy_sinusoid_error_is_bias_plus_spline_noise():
    sigma = 1e-3
    t = np.arange(2400) * CFG.dt
    truth = sines(t, 1.0)
    noisy = truth[0] + sigma * np.random.default_rng(6).normal(size=truth[0].shape)
    estimates = estimate_offline(t, noisy, None, CFG)
    rms = np.array([np.sqrt(np.mean(steady(e - tr) ** 2)) for e, tr in zip(estimates, truth, strict=True)])
    w = 2 * math.pi
    bias = np.array([0.004, 0.017 * w, 0.035 * w * w])  # documented noise-free accuracy
    # Noise at lag 0.1 s is within 25 % of the interior (closed-form) spline noise.
    bound = bias + 1.25 * sigma * interior_noise_gains(CFG)
    print("noisy 1 Hz sine rms error q/qd/qdd", rms, "bound", bound)
    assert np.all(rms <= bound)
    assert np.all(rms >= 0.5 * sigma * interior_noise_gains(CFG))  # the noise really went through


def test_each_output_is_the_smoothing_spline_of_the_filtered_window():
    cfg = EstimatorConfig(window_s=0.1, lag_s=0.025)  # 12-sample window, lag 3
    rng = np.random.default_rng(7)
    y = np.cumsum(rng.normal(size=(60, 2)), axis=0)
    t = 2.0 + np.arange(60) * cfg.dt
    est = StreamingEstimator(2, None, cfg)
    kalman = StreamingEstimator(2, None, cfg).kalman  # the same filter, run on its own
    filtered = np.array([kalman.step(None if i == 0 else cfg.dt, yi).copy() for i, yi in enumerate(y)])
    lam = smoothing_lambda(cfg.dt, cfg.cutoff_hz)
    for i, yi in enumerate(y):
        out = est.step(t[i], yi)
        if i + 1 < cfg.window:
            continue
        window = slice(i + 1 - cfg.window, i + 1)
        tw, fw = t[window], filtered[window]
        s1 = make_smoothing_spline(tw, fw, lam=lam)
        s2 = make_smoothing_spline(tw, s1.derivative()(tw), lam=lam)
        te = tw[-1 - cfg.lag]
        assert out.index == i - cfg.lag and out.t == te
        np.testing.assert_allclose(out.q, s1(te), atol=1e-9)
        np.testing.assert_allclose(out.qd, s1.derivative()(te), atol=1e-7)
        np.testing.assert_allclose(out.qdd, s2.derivative()(te), atol=1e-5)


def test_nan_bursts_and_dropped_frames_stay_finite_and_accurate():
    t_all = np.arange(1200) * CFG.dt
    keep = np.ones(1200, dtype=bool)
    keep[[300, 500, 501, 700, 702, 704]] = False  # dropped frames: never delivered
    t = t_all[keep]
    truth = sines(t, 1.0)
    y = truth[0].copy()
    y[400:406, 0] = np.nan  # a 50 ms burst on one channel
    y[600:604] = np.nan  # every channel missing for 33 ms
    y[800, 2] = np.inf
    est = StreamingEstimator(3, None, CFG)
    outputs = [o for ti, yi in zip(t, y, strict=True) if (o := est.step(ti, yi)) is not None] + est.flush()
    assert [o.index for o in outputs] == list(range(len(t)))
    q, qd, qdd = (np.array([getattr(o, f) for o in outputs]) for f in ("q", "qd", "qdd"))
    assert np.isfinite(q).all() and np.isfinite(qd).all() and np.isfinite(qdd).all()
    missing = np.array([o.missing for o in outputs])
    np.testing.assert_array_equal(missing, ~np.isfinite(y))
    errors = relative_errors((q, qd, qdd), truth, 2 * math.pi)
    print("1 Hz sine with gaps, relative max error q/qd/qdd: " + " ".join(f"{e:.4f}" for e in errors))
    # Gaps cost accuracy: CA extrapolation through 50 ms, then the spline sees the predicted samples.
    assert errors[0] <= 0.004 and errors[1] <= 0.03 and errors[2] <= 0.12


def test_irregular_timestamps_use_the_actual_times():
    rng = np.random.default_rng(8)
    t = np.cumsum(rng.uniform(0.6, 1.4, 900)) * CFG.dt  # +-40 % jitter on every interval
    truth = sines(t, 1.0)
    errors = relative_errors(estimate_offline(t, truth[0], None, CFG), truth, 2 * math.pi)
    print("1 Hz sine, jittered times, relative max error q/qd/qdd: " + " ".join(f"{e:.4f}" for e in errors))
    # Uneven spacing changes the spline's local smoothing a little, most visibly in acceleration.
    assert errors[0] <= 0.006 and errors[1] <= 0.025 and errors[2] <= 0.1
    # Ignoring the jitter (pretending the samples are uniform) is far worse: the times matter.
    uniform_t = np.arange(900) * CFG.dt
    wrong = estimate_offline(uniform_t, truth[0], None, CFG)
    assert np.abs(steady(wrong[1] - truth[1])).max() > 5 * errors[1] * 2 * math.pi


def test_exact_path_equals_uniform_weights_when_times_are_uniform():
    y = np.random.default_rng(9).normal(size=(300, 4))
    t = 7.0 + np.arange(300) * CFG.dt
    fast = estimate_offline(t, y, None, CFG)
    exact = estimate_offline(t, y, None, EstimatorConfig(jitter_tol=0.0))  # float rounding forces refits
    for a, b in zip(fast, exact, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-8 * np.abs(a).max())


def test_angle_channel_unwraps_through_pi():
    t = np.arange(600) * CFG.dt
    truth = 3.0 + 4.0 * t  # rad, crosses pi, 3 pi, ... many times
    y = np.stack([wrap_angle(truth), truth], axis=1)
    q, qd, qdd = estimate_offline(t, y, np.array([True, False]), CFG)
    settled = slice(int(0.5 * CFG.rate_hz), None)
    np.testing.assert_allclose(q[settled, 0], truth[settled], atol=1e-9)
    np.testing.assert_allclose(qd[settled, 0], 4.0, atol=1e-7)
    np.testing.assert_allclose(qdd[settled, 0], 0.0, atol=1e-5)
    assert np.all(np.abs(np.diff(q[:, 0])) < 0.1)  # continuous from the first frame on


def test_warm_up_from_a_single_sample():
    est = StreamingEstimator(2, None, EstimatorConfig(lag_s=0.0))
    first = est.step(0.0, np.array([1.5, -2.0]))
    np.testing.assert_array_equal(first.q, [1.5, -2.0])
    np.testing.assert_array_equal(first.qd, [0.0, 0.0])
    np.testing.assert_array_equal(first.qdd, [0.0, 0.0])
    for i in range(1, 60):
        out = est.step(i * CFG.dt, np.array([1.5 + i * CFG.dt, -2.0]))
        assert out.index == i
        assert np.isfinite(out.q).all() and np.isfinite(out.qd).all() and np.isfinite(out.qdd).all()


def test_lagged_output_starts_after_lag_samples_and_flush_completes_the_take():
    est = StreamingEstimator(1, None, CFG)
    results = [est.step(i * CFG.dt, np.array([float(i)])) for i in range(CFG.lag + 3)]
    assert results[: CFG.lag] == [None] * CFG.lag
    assert [r.index for r in results[CFG.lag :]] == [0, 1, 2]
    assert [r.index for r in est.flush()] == list(range(3, CFG.lag + 3))
    assert est.step(100.0, np.array([0.0])) is None  # flush reset the estimator: a new take starts


def test_channel_missing_at_start_is_flagged_then_joins_without_a_jump():
    est = StreamingEstimator(2, None, EstimatorConfig(lag_s=0.0))
    outs = []
    for i in range(40):
        y = np.array([np.nan if i == 0 else 0.5 * i * CFG.dt, np.nan if i < 10 else 2.0])  # frame 0 empty
        outs.append(est.step(i * CFG.dt, y))
    assert all(np.isfinite(o.q).all() and np.isfinite(o.qd).all() and np.isfinite(o.qdd).all() for o in outs)
    assert outs[0].missing.all() and not outs[1].missing[0]
    assert all(o.missing[1] for o in outs[:10]) and not any(o.missing[1] for o in outs[10:])
    assert all(o.q[1] == 0.0 for o in outs[:10])
    np.testing.assert_allclose([o.q[1] for o in outs[10:]], 2.0, atol=1e-9)  # history back-filled
    np.testing.assert_allclose([o.qd[1] for o in outs[10:]], 0.0, atol=1e-6)


def test_offline_equals_streaming_step_by_step():
    rng = np.random.default_rng(10)
    t = np.cumsum(rng.uniform(0.9, 1.1, 200)) * CFG.dt
    y = np.cumsum(rng.normal(size=(200, 3)), axis=0)
    y[50:55, 1] = np.nan
    offline = estimate_offline(t, y, np.array([False, True, False]), CFG)
    est = StreamingEstimator(3, np.array([False, True, False]), CFG)
    outputs = [o for ti, yi in zip(t, y, strict=True) if (o := est.step(ti, yi)) is not None] + est.flush()
    for name, values in zip(("q", "qd", "qdd"), offline, strict=True):
        np.testing.assert_array_equal(np.array([getattr(o, name) for o in outputs]), values)


def test_take_shorter_than_the_lag_comes_out_of_flush():
    t = np.arange(4) * CFG.dt
    y = (1.0 + 2.0 * t)[:, None]
    q, qd, qdd = estimate_offline(t, y, None, CFG)
    # The Kalman prior on velocity is diffuse, not absent: a trace of it remains this early.
    np.testing.assert_allclose(q, y, rtol=1e-5)
    np.testing.assert_allclose(qd, 2.0, rtol=1e-3)


def array_layout(est):
    parts = {"estimator": est, "kalman": est.kalman, "spline": est.spline}
    return {
        (part, name): (value.shape, value.nbytes)
        for part, obj in parts.items()
        for name, value in vars(obj).items()
        if isinstance(value, np.ndarray)
    }


def test_memory_is_bounded_over_a_long_stream():
    est = StreamingEstimator(26, None, CFG)
    rng = np.random.default_rng(11)
    frames = rng.normal(size=(64, 26))
    for i in range(2000):
        est.step(i * CFG.dt, frames[i % 64])
    layout = array_layout(est)
    tracemalloc.start()
    base, _ = tracemalloc.get_traced_memory()
    for i in range(2000, 10_000):
        est.step(i * CFG.dt, frames[i % 64])
    grown = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    assert array_layout(est) == layout
    assert grown < 16_000, f"{grown} bytes kept over 8000 frames"


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"rate_hz": 0.0}, "EstimatorConfig.rate_hz"),
        ({"window_s": 0.01}, "EstimatorConfig.window_s"),
        ({"lag_s": 0.4}, "EstimatorConfig.lag_s"),
        ({"lag_s": -0.1}, "EstimatorConfig.lag_s"),
        ({"cutoff_hz": 60.0}, "EstimatorConfig.cutoff_hz .* Nyquist"),
        ({"kalman_corner_hz": float("nan")}, "EstimatorConfig.kalman_corner_hz"),
        ({"jitter_tol": 0.7}, "EstimatorConfig.jitter_tol"),
    ],
)
def test_bad_config_names_the_field(kwargs, message):
    with pytest.raises(EstimatorError, match=message):
        EstimatorConfig(**kwargs)


@pytest.mark.parametrize("rate", [30.0, 60.0, 120.0, 250.0, 500.0, 1000.0])
def test_defaults_work_from_30_to_1000_hz(rate):
    cfg = EstimatorConfig(rate_hz=rate)
    t = np.arange(int(3 * rate)) / rate
    truth = sines(t, 1.0)
    errors = relative_errors(estimate_offline(t, truth[0], None, cfg), truth, 2 * math.pi, cfg)
    assert errors[0] <= 0.004 and errors[1] <= 0.017 and errors[2] <= 0.045


def test_bad_stream_input_is_a_clear_error():
    est = StreamingEstimator(3, None, CFG)
    with pytest.raises(EstimatorError, match=r"shape \(2,\), expected \(3,\)"):
        est.step(0.0, np.zeros(2))
    with pytest.raises(EstimatorError, match="not a finite"):
        est.step(float("nan"), np.zeros(3))
    est.step(1.0, np.zeros(3))
    with pytest.raises(EstimatorError, match="not after the previous sample"):
        est.step(1.0, np.zeros(3))
    with pytest.raises(EstimatorError, match="angle_mask"):
        StreamingEstimator(3, np.array([1, 0, 0]), CFG)
    with pytest.raises(EstimatorError, match="n_channels"):
        StreamingEstimator(0)


def test_bad_offline_input_names_the_sample_or_channel():
    t = np.arange(10) * CFG.dt
    y = np.zeros((10, 2))
    with pytest.raises(EstimatorError, match=r"t\[4\] .* is not after t\[3\]"):
        estimate_offline(np.where(np.arange(10) == 4, t[3], t), y)
    y[:, 1] = np.nan
    with pytest.raises(EstimatorError, match="channel 1 has no finite sample"):
        estimate_offline(t, y)
    with pytest.raises(EstimatorError, match=r"\(10,\) and \(9, 2\)"):
        estimate_offline(t, y[:9])
