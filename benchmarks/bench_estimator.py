"""Streaming estimator: per-frame latency, offline throughput, memory, accuracy, against a naive baseline.

The baseline is what the issue names: at every frame re-fit a scipy cubic
spline through the whole history and differentiate it (here 60 s of history
at 120 Hz, 7200 samples).

    python benchmarks/bench_estimator.py            # full run, about a minute
    python benchmarks/bench_estimator.py --quick    # smaller counts
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np
from scipy.interpolate import CubicSpline, make_interp_spline

from livezmp.estimate.estimator import EstimatorConfig, StreamingEstimator, estimate_offline
from livezmp.estimate.spline_diff import GRID_WEIGHTS_BYTES, SlidingSplineDifferentiator, smoothing_lambda

RATE = 120.0


def stream(n_channels: int, frames: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Smooth random joint-like motion: a few sinusoids per channel, rad."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames) / RATE
    freq = rng.uniform(0.3, 3.0, (3, n_channels))
    amp = rng.uniform(0.05, 0.5, (3, n_channels))
    phase = rng.uniform(0, 2 * math.pi, (3, n_channels))
    y = sum(amp[k] * np.sin(2 * math.pi * freq[k] * t[:, None] + phase[k]) for k in range(3))
    return t, y


def step_latencies(n_channels: int, frames: int, jitter: float = 0.0) -> np.ndarray:
    """Seconds per StreamingEstimator.step, after the warm-up window."""
    t, y = stream(n_channels, frames)
    if jitter:
        t = np.cumsum(np.random.default_rng(1).uniform(1 - jitter, 1 + jitter, frames)) / RATE
    est = StreamingEstimator(n_channels, None, EstimatorConfig(rate_hz=RATE))
    out = np.empty(frames)
    clock = time.perf_counter
    for i in range(frames):
        start = clock()
        est.step(t[i], y[i])
        out[i] = clock() - start
    return out[est.config.window :]


def baseline_latencies(n_channels: int, history: int, frames: int, fit) -> np.ndarray:
    """Seconds per frame for the naive estimator: fit the whole history, evaluate q, qd, qdd at the newest."""
    t, y = stream(n_channels, history + frames)
    out = np.empty(frames)
    for i in range(frames):
        end = history + i
        start = time.perf_counter()
        spline = fit(t[:end], y[:end])
        for order in range(3):
            spline(t[end - 1], order)
        out[i] = time.perf_counter() - start
    return out


def offline_rate(n_channels: int, frames: int) -> float:
    """Frames per second through estimate_offline."""
    t, y = stream(n_channels, frames)
    start = time.perf_counter()
    estimate_offline(t, y, None, EstimatorConfig(rate_hz=RATE))
    return frames / (time.perf_counter() - start)


def skipped_deadline_cpu(grid_weights_bytes: int, frames: int, share: float) -> float:
    """CPU us per frame (push + estimate) of the live loop's spline at 1 kHz (window 0.2 s, lag 0.03 s,
    cutoff 8 Hz, 26 channels) on grid times with a ``share`` of the deadlines skipped at random, keeping
    the weights of windows with one gap up to ``grid_weights_bytes`` (0: an exact fit on every uneven
    window, the baseline)."""
    dt = 1e-3
    diff = SlidingSplineDifferentiator(26, 200, 30, dt, smoothing_lambda(dt, 8.0), 0.01, grid_weights_bytes)
    rng = np.random.default_rng(0)
    ys, skipped = rng.normal(size=(frames, 26)), rng.random(frames) < share
    index = 0
    c0 = time.process_time()
    for k in range(frames):
        index += 2 if skipped[k] else 1
        diff.push(index * dt, ys[k])
        if k >= 30:  # the lag's samples held
            diff.estimate()
    return 1e6 * (time.process_time() - c0) / frames


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def rss_growth(n_channels: int, frames: int) -> tuple[int, int]:
    """RSS (bytes) after 10 000 warm-up frames, and its growth over ``frames`` more streamed frames."""
    _, y = stream(n_channels, 1000)
    est = StreamingEstimator(n_channels, None, EstimatorConfig(rate_hz=RATE))
    for i in range(10_000):
        est.step(i / RATE, y[i % 1000])
    before = rss_bytes()
    for i in range(10_000, 10_000 + frames):
        est.step(i / RATE, y[i % 1000])
    return before, rss_bytes() - before


def accuracy_rows(lags_s: tuple[float, ...], freqs: tuple[float, ...]) -> list[tuple[float, float, list[float]]]:
    """Largest error on noise-free sinusoids, relative to A, A w, A w^2, away from the take's ends."""
    rows = []
    for lag in lags_s:
        cfg = EstimatorConfig(rate_hz=RATE, lag_s=lag)
        t = np.arange(int(6 * RATE)) / RATE
        for f in freqs:
            w = 2 * math.pi * f
            arg = w * t[:, None] + np.array([0.0, 0.7, 1.9])
            truth = (np.sin(arg), w * np.cos(arg), -w * w * np.sin(arg))
            est = estimate_offline(t, truth[0], None, cfg)
            inner = slice(int(RATE), -int(RATE))
            errs = [np.abs(e - tr)[inner].max() / w**k for k, (e, tr) in enumerate(zip(est, truth, strict=True))]
            rows.append((lag, f, errs))
    return rows


def us(x: float) -> str:
    return f"{x * 1e6:10.1f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller frame counts")
    parser.add_argument("--rss-frames", type=int, default=None, help="frames for the RSS run (default 1 000 000)")
    args = parser.parse_args()
    frames = 3000 if args.quick else 20_000
    base_frames = 10 if args.quick else 40
    rss_frames = args.rss_frames or (100_000 if args.quick else 1_000_000)
    history = int(60 * RATE)
    cfg = EstimatorConfig(rate_hz=RATE)
    print(f"defaults: {RATE:g} Hz, window {cfg.window} samples, lag {cfg.lag} samples, cutoff {cfg.cutoff_hz} Hz")
    print()
    print(f"{'per-frame latency (us)':54s} {'p50':>10s} {'p99':>10s} {'speed-up':>9s}")
    for n, what in ((26, "20-joint robot + floating base"), (132, "22-joint skeleton x 6 channels")):
        base = {
            name: baseline_latencies(n, history, base_frames, fit)
            for name, fit in (
                ("make_interp_spline", lambda t, y: make_interp_spline(t, y, k=3)),
                ("CubicSpline", CubicSpline),
            )
        }
        fastest_base = min(np.median(b) for b in base.values())
        for name, b in base.items():
            label = f"BASELINE {name}, {history} samples, {n} ch"
            print(f"{label:54s} {us(np.median(b))} {us(np.percentile(b, 99))}")
        for label, lat in (
            (f"step, {n} ch ({what})", step_latencies(n, frames)),
            (f"step, {n} ch, +-30 % timing jitter (exact refit)", step_latencies(n, frames // 4, jitter=0.3)),
        ):
            p50 = np.median(lat)
            print(f"{label:54s} {us(p50)} {us(np.percentile(lat, 99))} {fastest_base / p50:8.0f}x")
    print("(speed-up: p50 of the faster baseline / p50 of step)")
    print()
    for n in (26, 132):
        print(f"offline throughput, {n} ch: {offline_rate(n, frames):,.0f} frames/s")
    print()
    skips = frames // 4
    print(f"live loop's spline at 1 kHz (window 200), deadlines skipped at random, 26 ch, CPU us per frame "
          f"({skips} frames, load {os.getloadavg()[0]:.1f}):")
    for share in (0.002, 0.01, 0.05):
        print(f"  {100 * share:3g} % skipped: {skipped_deadline_cpu(0, skips, share):5.1f} fitting each uneven window "
              f"exactly (baseline), {skipped_deadline_cpu(GRID_WEIGHTS_BYTES, skips, share):5.1f} keeping the weights "
              "of windows with one gap")
    print()
    before, grown = rss_growth(26, rss_frames)
    print(f"RSS over {rss_frames:,} streamed frames, 26 ch: {before / 2**20:.1f} MiB at start, "
          f"growth {grown / 2**20:+.2f} MiB")
    print()
    print("accuracy, noise-free sines, max error relative to A / A w / A w^2 (position / velocity / acceleration)")
    print(f"{'lag (ms)':>9s} {'freq (Hz)':>10s} {'q':>8s} {'qd':>8s} {'qdd':>8s}")
    for lag, f, errs in accuracy_rows((0.0, 0.025, 0.05, 0.1), (1.0, 2.0, 4.0)):
        print(f"{lag * 1e3:9.0f} {f:10.1f} " + " ".join(f"{100 * e:7.2f}%" for e in errs))


if __name__ == "__main__":
    main()
