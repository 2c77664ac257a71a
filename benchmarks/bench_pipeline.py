"""The pipeline (estimate → ZMP → contacts → support → clamp): offline throughput of the
per-frame path and the batch path side by side on a one-hour 120 Hz take, per-frame
latency and streaming memory, with the naive baseline side by side.

Offline take: the Bandai walk resampled to 120 Hz (a cubic spline through each channel,
angles unwrapped first), played forth and back (so every channel stays continuous)
until one hour long: 432,000 frames. The per-frame path is ``Pipeline.step`` on every
frame then ``flush``; the batch path is ``livezmp.offline.batch.run_batch`` (chunks over arrays).
Both run on the same take in the same process, and their results are compared.

Latency baseline (what the seed paper's chain does naively): at every frame re-fit a
scipy cubic spline through the whole history of every channel and differentiate it for
velocity and acceleration, then the same ZMP/support code.

    python benchmarks/bench_pipeline.py                  # about four minutes (the per-frame hour: 1-2 min)
    python benchmarks/bench_pipeline.py --minutes 10     # a shorter take (the printout says so)
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.balance.support import SUPPORT_LABELS
from livezmp.estimate.estimator import Estimate
from livezmp.live.realtime import LOOP_PRIORITY, realtime_priority
from livezmp.model.bvh import read_bvh
from livezmp.model.bvh_body import body_from_bvh
from livezmp.model.urdf_body import body_from_urdf
from livezmp.offline.batch import BatchResult, run_batch
from livezmp.offline.report import write_zmp_csv

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


def load_average() -> str:
    """The 1-minute load average."""
    return Path("/proc/loadavg").read_text().split()[0]


def long_take(motion, rate: float, minutes: float) -> tuple[np.ndarray, np.ndarray]:
    """The walk resampled to ``rate`` Hz (cubic spline per channel, angles unwrapped), played forth
    and back until ``minutes`` long: (times (N,), frames (N, channels))."""
    t = np.arange(len(motion.frames)) * motion.frame_time
    rot = np.array([c.endswith("rotation") for c in motion.channel_labels()])
    frames = motion.frames.copy()
    frames[:, rot] = np.unwrap(frames[:, rot], period=360.0, axis=0)
    clip = CubicSpline(t, frames, axis=0)(np.arange(int(t[-1] * rate) + 1) / rate)
    loop = np.concatenate([clip, clip[-2:0:-1]])  # forth and back: no jump where it repeats
    n = int(round(minutes * 60 * rate))
    return np.arange(n) / rate, np.tile(loop, (n // len(loop) + 1, 1))[:n]


def per_frame_take(body, cfg, rate: float, times: np.ndarray, frames: np.ndarray) -> tuple[float, BatchResult]:
    """Seconds for ``step`` on every frame then ``flush``, and the results (key fields only)."""
    n = len(times)
    zmp, has, support = np.zeros((n, 3)), np.zeros(n, bool), np.zeros(n, np.int8)
    judged, inside, margin = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n)
    label = {s: i for i, s in enumerate(SUPPORT_LABELS)}

    def keep(r) -> None:
        i = r.index
        if r.zmp is not None:
            zmp[i], has[i] = r.zmp, True
        support[i] = label[r.support]
        if r.inside is not None:
            judged[i], inside[i], margin[i] = True, r.inside, r.margin

    pipe = Pipeline(body, cfg, 1 / rate)
    start = time.perf_counter()
    for k in range(n):
        r = pipe.step(float(times[k]), frames[k])
        if r is not None:
            keep(r)
    for r in pipe.flush():
        keep(r)
    elapsed = time.perf_counter() - start
    empty = np.zeros((n, 3))
    return elapsed, BatchResult(np.arange(n), times, zmp, has, empty, support, judged, inside, empty, margin,
                                np.zeros(n), np.zeros(n), {})


def offline(motion, walk, minutes: float, repeats: int, per_frame: bool) -> None:
    rate = 120.0
    times, frames = long_take(motion, rate, minutes)
    n = len(times)
    cfg = default_config(walk, rate)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    run_batch(Pipeline(walk, cfg, 1 / rate), times[:2000], frames[:2000])  # imports and first-call costs
    runs = []
    for _ in range(repeats):
        start = time.perf_counter()
        batch = run_batch(Pipeline(walk, cfg, 1 / rate), times, frames)
        runs.append((time.perf_counter() - start, load_average()))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        write_zmp_csv(walk, batch, Path(tmp) / "zmp.csv")
        csv_s = time.perf_counter() - start
        csv_mb = (Path(tmp) / "zmp.csv").stat().st_size / 2**20
    secs = sorted(r[0] for r in runs)
    median = secs[len(secs) // 2]
    label = f"{minutes:g} min" + ("" if minutes == 60 else " (not one hour: --minutes)")
    print(f"\noffline: Bandai walk at {rate:.0f} Hz, forth and back, {label}: {n:,} frames, 132 channels, full ZMP")
    print(f"{'path':44s} {'seconds':>9s} {'frames/s':>11s}  runs (s @ 1-min load average)")
    print(f"{'batch: run_batch':44s} {median:9.2f} {n / median:11,.0f}  "
          + ", ".join(f"{s:.2f} @ {ld}" for s, ld in runs))
    if per_frame:
        el, ref = per_frame_take(walk, cfg, rate, times, frames)
        load = load_average()
        print(f"{'per-frame: step on every frame, then flush':44s} {el:9.2f} {n / el:11,.0f}  1 run @ {load}"
              f"  (batch {el / median:.0f}x faster)")
        both = batch.has_zmp & ref.has_zmp
        print(f"batch vs per-frame: max |ZMP difference| {np.abs(batch.zmp[both] - ref.zmp[both]).max():.1e} m, "
              f"max |margin difference| {np.abs(batch.margin - ref.margin).max():.1e} m; frames differing in "
              f"support label {int(np.sum(batch.support != ref.support))}, "
              f"in flight {int(np.sum(batch.has_zmp != ref.has_zmp))}, "
              f"in inside flag {int(np.sum(batch.inside != ref.inside))}")
    print(f"batch peak RSS {peak:.0f} MB (before the take's analysis {before:.0f} MB; the take's input array "
          f"{frames.nbytes / 2**20:.0f} MB)")
    print(f"zmp.csv of the take ({n:,} rows, {csv_mb:.0f} MB) written in {csv_s:.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=4000, help="frames per latency run")
    ap.add_argument("--rss-frames", type=int, default=200_000, help="frames streamed for the memory figure")
    ap.add_argument("--minutes", type=float, default=60.0, help="length of the offline take (default one hour)")
    ap.add_argument("--repeats", type=int, default=3, help="batch runs of the offline take (the median is shown)")
    ap.add_argument("--no-per-frame", action="store_true", help="skip the per-frame run of the offline take")
    args = ap.parse_args()

    op3 = body_from_urdf(OP3)
    motion = read_bvh(WALK)
    walk = body_from_bvh(motion)
    # the offline take first: the process's peak RSS is then the batch run's
    offline(motion, walk, args.minutes, args.repeats, not args.no_per_frame)
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
    # as the live loop runs it: under SCHED_FIFO (other programs on the machine cannot preempt it)
    with realtime_priority(LOOP_PRIORITY) as refused:
        how = "SCHED_FIFO" if refused is None else f"real-time priority {refused}"
        rt_rows = [row(f"OP3 step, 200 Hz, {how}", latencies(Pipeline(op3, default_config(op3, rate), 1 / rate),
                                                              t, q, 200)),
                   row(f"Bandai step, 30 Hz, {how}",
                       latencies(Pipeline(walk, default_config(walk, motion.fps), motion.frame_time), wt, wf, 60))]
    # baseline at 60 s of history
    hist = int(60 * rate)
    th, qh = op3_stream(op3, hist + 300, rate)
    naive = NaiveEstimatorPipeline(op3, default_config(op3, rate), 1 / rate, qh[:hist], th[:hist])
    base = latencies(naive, th[hist:], qh[hist:], 0)
    rows.append(row("baseline: OP3, whole-history spline (60 s = 12000 samples)", base))
    print(f"\n{'per-frame latency':62s} {'p50 µs':>10s} {'p99 µs':>10s}   (load average {os.getloadavg()[0]:.2f})")
    for name, p50, p99 in rows + rt_rows:
        print(f"{name:62s} {p50:10.1f} {p99:10.1f}")
    print(f"speed-up over the baseline at 60 s of history (p50): {rows[2][1] / rows[0][1]:.0f}x")

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
