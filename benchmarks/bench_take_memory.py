"""Peak memory of one take's analysis against its length: the chunked path (``livezmp analyze`` /
``batch analyze`` of a BVH or a robot's joint CSV, :func:`livezmp.offline.take.stream_take`) beside the
whole-take path it replaced (read the whole file, analyse the arrays, then write zmp.csv and summarise),
on takes of 10k, 100k and 1M frames: BVH made from a shared Bandai walk (played forwards and backwards,
3 decimals so 1M frames of its 132 channels fit under the 1 GiB input limit), and joint CSVs of the
built-in robot ``livezmp_mini`` (20 joints, its demo motion repeated, 100 Hz, 6 significant digits;
its base placed from the joints, as a CSV without base columns is).

Each analysis runs in a fresh child process (zmp.csv written, summary computed); the table gives the
child's peak resident memory (``ru_maxrss``), its CPU time per frame for the analysis (without the
interpreter's start and imports), and whether the two paths wrote the same zmp.csv and summary.

    python benchmarks/bench_take_memory.py [--sizes 10000 100000 1000000] [--formats bvh csv] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from machine_load import load_averages

from livezmp.model.bvh import format_hierarchy, read_bvh
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.urdf_body import body_from_urdf

BANDAI = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "bvh" / "bandai"
WALK = BANDAI / "walk_normal_002.bvh"


def make_take(path: Path, frames: int) -> None:
    """The walk there and back, repeated to ``frames`` frames, written 100k rows at a time."""
    walk = read_bvh(WALK)
    cycle = np.vstack([walk.frames, walk.frames[::-1]])
    with open(path, "w", encoding="utf-8") as f:
        f.write(format_hierarchy(walk.joints))
        f.write(f"MOTION\nFrames: {frames}\nFrame Time: {walk.frame_time:.7g}\n")
        for lo in range(0, frames, 100_000):
            idx = np.arange(lo, min(lo + 100_000, frames)) % len(cycle)
            np.savetxt(f, cycle[idx], fmt="%.3f")


def make_csv_take(path: Path, frames: int) -> None:
    """The built-in robot's demo motion (it starts and ends at rest) repeated to ``frames`` frames at
    100 Hz, written 100k rows at a time."""
    body = body_from_urdf(demo_robot_path())
    demo = demo_trajectory(body.joint_names)
    with open(path, "w", encoding="utf-8") as f:
        f.write(",".join(["time", *body.joint_names]) + "\n")
        for lo in range(0, frames, 100_000):
            idx = np.arange(lo, min(lo + 100_000, frames))
            np.savetxt(f, np.column_stack([idx / 100.0, demo.q[idx % len(demo.q)]]), delimiter=",", fmt="%.6g")


def child(mode: str, take: str, out: str) -> None:
    """One analysis in this (fresh) process; prints JSON: peak RSS (MiB), CPU s, the summary."""
    from livezmp.offline.report import write_zmp_csv
    from livezmp.offline.take import TakeOptions, analyse_motion, stream_take

    options = TakeOptions(robot=str(demo_robot_path()) if take.endswith(".csv") else None)
    cpu = time.process_time()
    if mode == "chunked":
        summary = stream_take(take, options, out)
    else:
        a = analyse_motion(options.load(take), options)
        write_zmp_csv(a.body, a.result, out)
        summary = a.summary
    cpu = time.process_time() - cpu
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"peak_mib": peak, "cpu_s": cpu, "summary": summary}))


def measure(mode: str, take: Path, out: Path, script: str = __file__) -> dict:
    """``script --child MODE TAKE OUT`` in a fresh process: the JSON its child printed last."""
    run = subprocess.run([sys.executable, script, "--child", mode, str(take), str(out)], capture_output=True,
                         text=True, check=True)
    return json.loads(run.stdout.splitlines()[-1])


def start(keep: Path | None, prefix: str) -> Path:
    """The directory the takes are made in (``keep``, or a temporary one); prints the load average."""
    work = keep or Path(tempfile.mkdtemp(prefix=prefix))
    work.mkdir(parents=True, exist_ok=True)
    print(f"load average {load_averages(' ')} (shared machine), {os.cpu_count()} CPUs")
    return work


def bench_arguments(doc: str, sizes: list[int]) -> argparse.ArgumentParser:
    """The options both memory benchmarks take: ``--sizes`` (frames), ``--keep DIR``, the hidden ``--child``."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=sizes)
    ap.add_argument("--keep", type=Path, help="make the takes here and keep them (default: a temporary directory)")
    ap.add_argument("--child", nargs=3, metavar=("MODE", "TAKE", "OUT"), help=argparse.SUPPRESS)
    return ap


def main() -> None:
    ap = bench_arguments(__doc__, [10_000, 100_000, 1_000_000])
    ap.add_argument("--formats", nargs="+", choices=("bvh", "csv"), default=["bvh", "csv"])
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return
    work = start(args.keep, "take_memory_")
    print(f"{'take':>4} {'frames':>9} {'file MiB':>9} | {'whole peak MiB':>14} {'chunked peak MiB':>16} | "
          f"{'whole µs/frame':>14} {'chunked µs/frame':>16} | same zmp.csv, summary")
    for fmt, n in ((fmt, n) for fmt in args.formats for n in args.sizes):
        take = work / f"take_{n}.{fmt}"
        if not take.exists():
            (make_take if fmt == "bvh" else make_csv_take)(take, n)
        got = {mode: measure(mode, take, work / f"zmp_{mode}_{n}.csv") for mode in ("whole", "chunked")}
        same_csv = (work / f"zmp_whole_{n}.csv").read_bytes() == (work / f"zmp_chunked_{n}.csv").read_bytes()
        same_summary = got["whole"]["summary"] == got["chunked"]["summary"]
        w, c = got["whole"], got["chunked"]
        print(f"{fmt:>4} {n:>9} {take.stat().st_size / 2**20:>9.0f} | {w['peak_mib']:>14.0f} {c['peak_mib']:>16.0f} | "
              f"{1e6 * w['cpu_s'] / n:>14.1f} {1e6 * c['cpu_s'] / n:>16.1f} | {same_csv}, {same_summary}")
        for mode in ("whole", "chunked"):
            (work / f"zmp_{mode}_{n}.csv").unlink()
        if not args.keep:
            take.unlink()
    print(f"load average {load_averages(' ')} after")


if __name__ == "__main__":
    main()
