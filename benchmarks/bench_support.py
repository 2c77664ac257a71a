"""Support polygon, clamp and contact detection: time per call, against baselines run side by side.

Baselines: Qhull (scipy.spatial.ConvexHull) for the hull; the same clamp written with numpy
array operations over the edges (the obvious vectorised version, to check that plain Python floats
are the faster choice on 4-16 vertices); matplotlib's Path.contains_point for the inside test
alone. The contact detector's memory is measured after a short and a long stream.

    python benchmarks/bench_support.py            # about 15 s
    python benchmarks/bench_support.py --quick
"""

from __future__ import annotations

import argparse
import math
import time
import tracemalloc

import numpy as np
from matplotlib.path import Path
from scipy.spatial import ConvexHull

from livezmp.balance.contacts import ContactDetector
from livezmp.balance.support import clamp_to_polygon, convex_hull, support_polygon

LEFT = np.array([[0.0, 0.1], [0.25, 0.1], [0.25, 0.2], [0.0, 0.2]])
RIGHT = np.array([[0.3, -0.2], [0.55, -0.2], [0.55, -0.1], [0.3, -0.1]])


def circle(m: int, r: float = 0.15) -> np.ndarray:
    a = np.linspace(0.0, 2 * math.pi, m, endpoint=False)
    return np.c_[r * np.cos(a), r * np.sin(a)]


def clamp_numpy(p: np.ndarray, poly: np.ndarray):
    """Baseline: the clamp vectorised over the edges with numpy (counter-clockwise polygon)."""
    e = np.roll(poly, -1, axis=0) - poly
    w = p - poly
    length = np.hypot(e[:, 0], e[:, 1])
    cross = e[:, 0] * w[:, 1] - e[:, 1] * w[:, 0]
    if (cross >= 0).all():
        return p, True, float((cross / length).min())
    t = np.clip((w * e).sum(axis=1) / (length * length), 0.0, 1.0)
    q = poly + t[:, None] * e
    d = np.hypot(*(p - q).T)
    i = int(d.argmin())
    return q[i], False, -float(d[i])


def per_call_us(fn, n: int) -> float:
    """Best of 7 repeats of the mean time per call, in microseconds (the least disturbed by other load)."""
    times = []
    for _ in range(7):
        start = time.perf_counter()
        for _ in range(n):
            fn()
        times.append((time.perf_counter() - start) / n)
    return 1e6 * min(times)


def walk_frames(frames: int, fps: float = 120.0):
    """Per-frame inputs for ContactDetector.update: two 4-corner soles and per-corner velocities."""
    out = []
    for k in range(frames):
        t = (k / fps) % 1.0
        feet = []
        for start, y in ((0.0, 0.1), (0.5, -0.1)):
            u = (t - start) / 0.4
            lift = math.sin(math.pi * u) ** 2 if 0.0 <= u < 1.0 else 0.0
            sole = np.c_[LEFT[:, 0], LEFT[:, 1] - 0.15 + y, np.full(4, 0.12 * lift)]
            feet += [sole, np.tile([4.5 * lift, 0.0, 0.0], (4, 1))]
        out.append(feet)
    return out


def detector_memory(frames: int) -> int:
    """Bytes still allocated by a detector after ``frames`` updates (inputs made on the fly)."""
    inputs = walk_frames(120)
    tracemalloc.start()
    det = ContactDetector()
    base = tracemalloc.get_traced_memory()[0]
    for k in range(frames):
        det.update(*inputs[k % 120])
    used = tracemalloc.get_traced_memory()[0] - base
    tracemalloc.stop()
    return used


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    n = 1000 if parser.parse_args().quick else 5000

    both = np.vstack([LEFT, RIGHT])
    c16 = circle(16)
    double = support_polygon(LEFT, RIGHT, "double")
    inside, outside = np.array([0.2, 0.0]), np.array([0.9, 0.6])
    rows = [
        (
            "convex hull, 8 points (two soles)",
            per_call_us(lambda: convex_hull(both), n),
            "Qhull",
            per_call_us(lambda: ConvexHull(both).vertices, n),
        ),
        (
            "convex hull, 16 points",
            per_call_us(lambda: convex_hull(c16), n),
            "Qhull",
            per_call_us(lambda: ConvexHull(c16).vertices, n),
        ),
        ("support_polygon double", per_call_us(lambda: support_polygon(LEFT, RIGHT, "double"), n), "", None),
        ("support_polygon single", per_call_us(lambda: support_polygon(LEFT, RIGHT, "left"), n), "", None),
    ]
    for label, poly in (("6-gon", double), ("16-gon", c16)):
        for where, p in (("inside", inside if label == "6-gon" else np.zeros(2)), ("outside", outside)):
            rows.append(
                (
                    f"clamp {label} {where}",
                    per_call_us(lambda p=p, poly=poly: clamp_to_polygon(p, poly), n),
                    "numpy",
                    per_call_us(lambda p=p, poly=poly: clamp_numpy(p, poly), n),
                )
            )
        path = Path(poly)
        rows.append(
            (
                f"  inside test only, {label}",
                None,
                "matplotlib",
                per_call_us(lambda path=path: path.contains_point(inside), n),
            )
        )
    inputs = walk_frames(120)
    det = ContactDetector()
    k = iter(range(10**9))
    rows.append(
        (
            "ContactDetector.update (2 feet)",
            per_call_us(lambda: det.update(*inputs[next(k) % 120]), n),
            "",
            None,
        )
    )

    print(f"{'operation':38s} {'livezmp us':>11s}   {'baseline':10s} {'us':>8s}")
    for name, ours, base_name, base in rows:
        ours_s = f"{ours:11.2f}" if ours is not None else f"{'':11s}"
        base_s = f"{base:8.2f}" if base is not None else ""
        print(f"{name:38s} {ours_s}   {base_name:10s} {base_s}")
    short, long = (1000, 10000) if n == 1000 else (1000, 100000)
    print(
        f"\nContactDetector memory after {short} frames: {detector_memory(short)} B, "
        f"after {long} frames: {detector_memory(long)} B"
    )


if __name__ == "__main__":
    main()
