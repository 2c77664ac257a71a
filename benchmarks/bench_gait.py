"""Gait: live estimator per-frame cost against a naive batch baseline, and offline analysis cost.

Live: a recorded Bandai walk (66 rotation channels, 30 fps) is looped into a long session
and fed frame by frame to :class:`GaitLiveEstimator`. The baseline is the obvious way to
get the same numbers: at every frame, re-detect the cycles and re-fit every channel over
the last ``WINDOW`` s of history (the offline code on a sliding window). Both are timed
over the same frames in the same run; early and late frames are reported separately to
show whether the cost grows with the session.

Offline: loading a take (BVH parse, body model, channel axes) and computing its features,
per take, over the 18 Bandai walks used by ``gait analyze``.

    python benchmarks/bench_gait.py            # full run
    python benchmarks/bench_gait.py --quick    # fewer frames
"""

from __future__ import annotations

import argparse
import time
import tracemalloc
from pathlib import Path

import numpy as np

from livezmp.gait import harmonics as hm
from livezmp.gait.channels import reference_channel
from livezmp.gait.cycles import detect_cycles
from livezmp.gait.features import walk_features
from livezmp.gait.live import GaitLiveEstimator
from livezmp.gait.take import take_from_bvh
from livezmp.model.bvh import read_bvh

BANDAI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "bvh" / "bandai"
WINDOW = 4.0  # s of history the baseline re-analyses each frame (about 3.5 cycles)


def looped_stream(frames: int) -> tuple[np.ndarray, np.ndarray, int]:
    """(t, angles (F, C) rad, reference channel) of walk_normal_003 repeated over whole cycles."""
    take = take_from_bvh(read_bvh(BANDAI / "walk_normal_003.bvh"))
    feats = walk_features(take)
    inside = feats.cycles.window(take.t)
    one = take.angles[inside]
    reps = frames // len(one) + 1
    angles = np.tile(one, (reps, 1))[:frames]
    t = np.arange(frames) * float(take.t[1] - take.t[0])
    return t, angles, reference_channel(take.tags, take.source)


def live_cost(t: np.ndarray, x: np.ndarray, ref: int) -> tuple[np.ndarray, int]:
    est = GaitLiveEstimator(x.shape[1], ref, cycles=3)
    out = np.empty(len(t))
    tracemalloc.start()
    for i in range(len(t)):
        start = time.perf_counter()
        est.update(float(t[i]), x[i])
        out[i] = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return out, peak


def baseline_cost(t: np.ndarray, x: np.ndarray, ref: int, frames: range) -> np.ndarray:
    out = np.empty(len(frames))
    n = int(WINDOW / (t[1] - t[0]))
    for k, i in enumerate(frames):
        start = time.perf_counter()
        tw, xw = t[i - n : i + 1], x[i - n : i + 1]
        cyc = detect_cycles(tw, xw[:, ref], "baseline")
        inside = cyc.window(tw)
        hm.mean_and_amplitude(hm.fit(tw[inside], xw[inside], cyc.frequency, 5)[0], 5)
        out[k] = time.perf_counter() - start
    return out


def offline_cost() -> tuple[float, float, int]:
    files = sorted(p for p in BANDAI.glob("walk_*.bvh") if "exhausted" not in p.name)
    load = feat = 0.0
    for p in files:
        s = time.perf_counter()
        take = take_from_bvh(read_bvh(p))
        m = time.perf_counter()
        walk_features(take)
        load += m - s
        feat += time.perf_counter() - m
    return load / len(files), feat / len(files), len(files)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    frames = 20_000 if args.quick else 100_000
    base_frames = 300 if args.quick else 1000
    t, x, ref = looped_stream(frames)
    live, peak = live_cost(t, x, ref)
    early = range(200, 200 + base_frames)
    late = range(frames - base_frames, frames)
    base_early = baseline_cost(t, x, ref, early)
    base_late = baseline_cost(t, x, ref, late)
    print(f"live gait estimate, {x.shape[1]} channels at 30 fps, session of {frames} frames "
          f"({frames / 30 / 60:.0f} min)")
    print(f"{'method':44s} {'frames':>14s} {'median µs':>10s} {'p99 µs':>10s}")
    rows = [("GaitLiveEstimator.update", f"{early.start}-{early.stop}", live[early.start:early.stop]),
            ("GaitLiveEstimator.update", f"{late.start}-{late.stop}", live[late.start:late.stop]),
            (f"baseline: re-analyse last {WINDOW:g} s per frame", f"{early.start}-{early.stop}", base_early),
            (f"baseline: re-analyse last {WINDOW:g} s per frame", f"{late.start}-{late.stop}", base_late)]
    for name, span, v in rows:
        print(f"{name:44s} {span:>14s} {np.median(v) * 1e6:10.1f} {np.percentile(v, 99) * 1e6:10.1f}")
    print(f"live estimator peak traced memory over the whole session: {peak / 1024:.1f} KiB")
    load, feat, n = offline_cost()
    print(f"offline, per Bandai take ({n} takes): load + body model + channel axes {load * 1e3:.0f} ms, "
          f"features {feat * 1e3:.0f} ms")


if __name__ == "__main__":
    main()
