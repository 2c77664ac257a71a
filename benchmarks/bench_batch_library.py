"""`livezmp batch analyze` throughput: a library of >= 500 takes (the shared Bandai walks, trimmed
to varied lengths under varied names) analysed on a local Dask cluster of 1 and 2 worker
processes, against a plain loop calling the same per-take function (:func:`run_take`) in one
process. Prints takes/s, frames/s, the speed-up and scaling efficiency of 2 workers over 1,
the overhead of Dask at 1 worker, and the load average (the machine is shared).

    python benchmarks/bench_batch_library.py [--takes 500]

Each run starts from an empty output directory (nothing is up to date). "run s" counts from the
first task submitted to the last row written (the workers' first imports included); "start s"
is the cluster's start-up, listed apart. Beside the wall times, the CPU seconds each run used:
the plain loop's process, and for Dask the workers' processes ("task CPU") and the client's
process with the scheduler ("client CPU"); on a shared machine the CPU seconds say what Dask
costs when the wall times mostly say how busy the machine was. Last, the CPU an idle 1-worker
cluster burns per second with Dask's default monitoring and with livezmp's settings
(:data:`livezmp.offline.library.LOCAL_CLUSTER_CONFIG`).
"""

from __future__ import annotations

import argparse
import os

# one thread per process in the plain loop too, as Dask sets for its workers (a fair baseline)
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import resource  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from livezmp.model.bvh import read_bvh, write_bvh  # noqa: E402
from livezmp.offline.jobs import AnalyzeJob  # noqa: E402
from livezmp.offline.library import LOCAL_CLUSTER_CONFIG, dask_client, find_takes, run_library  # noqa: E402

BANDAI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "bvh" / "bandai"


def make_library(root: Path, count: int, seed: int = 0) -> int:
    """``count`` takes under ``root``: every fourth a symlink to a whole walk, the others trimmed
    copies (100 frames to the whole walk, from a random start); returns the total frames."""
    rng = np.random.default_rng(seed)
    walks = [read_bvh(p) for p in sorted(BANDAI.glob("*.bvh"))]
    sources = sorted(BANDAI.glob("*.bvh"))
    total = 0
    for i in range(count):
        k = i % len(walks)
        folder = root / f"session_{i // 100:02d}"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"take_{i:04d}_{sources[k].stem}.bvh"
        n_all = len(walks[k].frames)
        if i % 4 == 0:
            path.symlink_to(sources[k])
            total += n_all
            continue
        n = int(rng.integers(100, n_all + 1))
        start = int(rng.integers(0, n_all - n + 1))
        write_bvh(replace(walks[k], frames=walks[k].frames[start:start + n]), path)
        total += n
    return total


def cpu_s() -> float:
    """CPU seconds used so far by this process (user + system)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def workers_cpu_s(client) -> float:
    return sum(client.run(cpu_s).values()) if client is not None else 0.0


def timed_run(client, library: Path, out: Path) -> tuple[float, int, int, float, float]:
    """(wall s, takes, frames, task CPU s, client CPU s) of one run."""
    job = AnalyzeJob()
    takes = find_takes([str(library)], out, job)
    c0, w0 = cpu_s(), workers_cpu_s(client)
    t0 = time.perf_counter()
    progress = run_library(client, takes, out, job)
    wall = time.perf_counter() - t0
    client_cpu, task_cpu = cpu_s() - c0, workers_cpu_s(client) - w0
    if client is None:  # the plain loop: all of it is the task's
        client_cpu, task_cpu = 0.0, client_cpu
    return wall, progress.done, progress.frames, task_cpu, client_cpu


def idle_cpu(config: dict, seconds: float = 10.0) -> tuple[float, float]:
    """CPU ms per second an idle 1-worker local cluster uses with Dask ``config``: (worker, client + scheduler)."""
    with dask_client(workers=1, config=config) as client:
        time.sleep(1.0)
        c0, w0 = cpu_s(), workers_cpu_s(client)
        time.sleep(seconds)
        return 1000 * (workers_cpu_s(client) - w0) / seconds, 1000 * (cpu_s() - c0) / seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--takes", type=int, default=500)
    args = ap.parse_args()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        frames = make_library(tmp / "lib", args.takes)
        rows = [("plain loop, 1 process", 0.0, *timed_run(None, tmp / "lib", tmp / "loop"))]
        for workers in (1, 2):
            t0 = time.perf_counter()
            with dask_client(workers=workers) as client:
                start_s = time.perf_counter() - t0
                run = timed_run(client, tmp / "lib", tmp / f"dask{workers}")
            rows.append((f"dask, {workers} worker{'s' * (workers > 1)}", start_s, *run))
    load_after = os.getloadavg()
    print(f"library: {args.takes} takes, {frames} frames (Bandai walks at 30 Hz, 100 frames to whole walks)")
    print(f"{'run':24} {'start s':>8} {'run s':>8} {'takes/s':>8} {'frames/s':>9} {'per take ms':>12} "
          f"{'task CPU s':>11} {'client CPU s':>13}")
    for name, start_s, run_s, n, f, task_cpu, client_cpu in rows:
        print(f"{name:24} {start_s:8.2f} {run_s:8.2f} {n / run_s:8.2f} {f / run_s:9.0f} {1000 * run_s / n:12.1f} "
              f"{task_cpu:11.1f} {client_cpu:13.1f}")
    loop, one, two = rows
    speedup = one[2] / two[2]
    print(f"2 workers over 1: {speedup:.2f}x (target >= 1.8x), scaling efficiency {100 * speedup / 2:.0f} %")
    print(f"dask overhead at 1 worker against the plain loop: {100 * (one[2] / loop[2] - 1):+.1f} % of run time "
          f"(target <= 5 %), {100 * ((one[2] + one[1]) / loop[2] - 1):+.1f} % with the cluster's start-up; "
          f"in CPU: workers {100 * (one[5] / loop[5] - 1):+.1f} %, workers + client "
          f"{100 * ((one[5] + one[6]) / loop[5] - 1):+.1f} %")
    for name, config in (("Dask's defaults", {}), ("livezmp's settings", LOCAL_CLUSTER_CONFIG)):
        worker_ms, client_ms = idle_cpu(config)
        print(f"idle 1-worker cluster, {name}: worker {worker_ms:.1f} ms/s, client + scheduler {client_ms:.1f} ms/s")
    print(f"load average before {load_before[0]:.2f} {load_before[1]:.2f} {load_before[2]:.2f}, "
          f"after {load_after[0]:.2f} {load_after[1]:.2f} {load_after[2]:.2f} ({os.cpu_count()} CPUs)")


if __name__ == "__main__":
    main()
