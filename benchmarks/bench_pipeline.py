"""The per-frame pipeline (estimate → ZMP → contacts → support → clamp): latency,
offline throughput and memory, with the naive baseline side by side.

Baseline (what the seed paper's chain does naively): at every frame re-fit a scipy
cubic spline through the whole history of every channel and differentiate it for
velocity and acceleration, then the same ZMP/support code.

    python benchmarks/bench_pipeline.py                 # about two minutes
    python benchmarks/bench_pipeline.py --rss-frames 1000000 --hour   # the full memory / one-hour runs
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from livezmp.body_bvh import body_from_bvh
from livezmp.body_urdf import body_from_urdf
from livezmp.bvh import read_bvh
from livezmp.estimator import Estimate
from livezmp.pipeline import Pipeline, default_config

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
OP3 = DATA / "robots" / "robotis_op3.urdf"
WALK = DATA / "bvh" / "bandai" / "walk_normal_001.bvh"


def op3_stream(body, frames: int, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """Smooth joint motion of the OP3 (rad), base standing."""
    rng = np.random.default_rng(0)
    t = np.arange(frames) / rate
    q = np.zeros((frames, body.nq))
    q[:, 2] = 0.28
    amp, freq = rng.uniform(0.02, 0.2, body.nq - 6), rng.uniform(0.2, 1.5, body.nq - 6)
    q[:, 6:] = amp * np.sin(2 * np.pi * freq * t[:, None])
    return t, q


def latencies(pipe: Pipeline, t: np.ndarray, frames: np.ndarray, warm: int) -> np.ndarray:
    out = np.empty(len(t))
    clock = time.perf_counter
    for k in range(len(t)):
        s = clock()
        pipe.step(float(t[k]), frames[k])
        out[k] = clock() - s
    return out[warm:]


class NaiveEstimatorPipeline(Pipeline):
    """The same pipeline with the naive estimator: whole-history cubic spline per frame."""

    def __init__(self, body, config, nominal_dt, history: np.ndarray, history_t: np.ndarray):
        super().__init__(body, config, nominal_dt)
        self.hist_q = list(body.channels_to_q(history))
        self.hist_t = list(history_t)

    def step(self, t, channels, contacts=None):
        self.hist_t.append(t)
        self.hist_q.append(self.body.channels_to_q(np.asarray(channels, dtype=float)))
        spline = CubicSpline(np.array(self.hist_t), np.array(self.hist_q), axis=0)
        est = Estimate(len(self.hist_t) - 1, t, spline(t), spline(t, 1), spline(t, 2), np.zeros(self.body.nq, bool))
        return self._analyse(est)


def row(name: str, lat: np.ndarray) -> tuple[str, float, float]:
    return name, 1e6 * float(np.percentile(lat, 50)), 1e6 * float(np.percentile(lat, 99))


def rss_mb() -> float:
    with open(f"/proc/{os.getpid()}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=4000, help="frames per latency run")
    ap.add_argument("--rss-frames", type=int, default=200_000, help="frames streamed for the memory figure")
    ap.add_argument("--hour", action="store_true", help="time a full one-hour take (else 10 minutes, scaled)")
    args = ap.parse_args()

    op3 = body_from_urdf(OP3)
    motion = read_bvh(WALK)
    walk = body_from_bvh(motion)
    rows = []
    rate = 200.0
    t, q = op3_stream(op3, args.frames, rate)
    op3_pipe = Pipeline(op3, default_config(op3, rate), 1 / rate)
    rows.append(row("OP3 (26 ch) step, 200 Hz", latencies(op3_pipe, t, q, 200)))
    reps = int(np.ceil(args.frames / len(motion.frames)))
    wf = np.tile(motion.frames, (reps, 1))[: args.frames]
    wt = np.arange(len(wf)) * motion.frame_time
    rows.append(row("Bandai skeleton (132 ch) step, 30 Hz",
                    latencies(Pipeline(walk, default_config(walk, motion.fps), motion.frame_time), wt, wf, 60)))
    # baseline at 60 s of history
    hist = int(60 * rate)
    th, qh = op3_stream(op3, hist + 300, rate)
    naive = NaiveEstimatorPipeline(op3, default_config(op3, rate), 1 / rate, qh[:hist], th[:hist])
    base = latencies(naive, th[hist:], qh[hist:], 0)
    rows.append(row("baseline: OP3, whole-history spline (60 s = 12000 samples)", base))
    print(f"\n{'per-frame latency':62s} {'p50 µs':>10s} {'p99 µs':>10s}")
    for name, p50, p99 in rows:
        print(f"{name:62s} {p50:10.1f} {p99:10.1f}")
    print(f"speed-up over the baseline at 60 s of history (p50): {rows[2][1] / rows[0][1]:.0f}x")

    # offline throughput on a long take: the walk repeated to one hour (or 10 minutes)
    seconds = 3600 if args.hour else 600
    n = int(seconds * motion.fps)
    frames = np.tile(motion.frames, (int(np.ceil(n / len(motion.frames))), 1))[:n]
    times = np.arange(n) * motion.frame_time
    pipe = Pipeline(walk, default_config(walk, motion.fps), motion.frame_time)
    s = time.perf_counter()
    pipe.run(times, frames)
    el = time.perf_counter() - s
    print(f"\noffline: {seconds / 60:.0f} min Bandai take ({n} frames at 30 Hz) in {el:.1f} s = {n / el:,.0f} frames/s"
          f"; a one-hour 120 Hz take (432,000 frames) would take {432000 / (n / el):.0f} s")

    # memory over a long stream
    pipe = Pipeline(op3, default_config(op3, rate), 1 / rate)
    t1, q1 = op3_stream(op3, 2000, rate)
    for k in range(2000):
        pipe.step(float(t1[k]), q1[k])
    before = rss_mb()
    s = time.perf_counter()
    for k in range(args.rss_frames):
        pipe.step(10.0 + k / rate, q1[k % 2000])
    after = rss_mb()
    print(f"memory: RSS {before:.1f} MB → {after:.1f} MB after {args.rss_frames:,} more streamed frames "
          f"(growth {after - before:+.2f} MB, {time.perf_counter() - s:.0f} s)")


if __name__ == "__main__":
    sys.exit(main())
