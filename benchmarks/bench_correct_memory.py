"""Peak memory and CPU time of ``livezmp correct`` against a take's length: what the whole-take solve
(:func:`livezmp.correct.solver.correct_motion`) holds, and so what :data:`MAX_CORRECT_FRAMES` rests on.

Takes of N frames are made from a shared Bandai walk (played forwards and backwards, as
``bench_take_memory.py`` makes them). Each size runs twice in fresh child processes: the baseline
loads the take and imports the correction's modules, the other also corrects it and writes the
result. The table gives both peak resident memories (``ru_maxrss``), the solve's own (their
difference) per frame, the slope between consecutive sizes, and the correction's CPU time per frame.

    python benchmarks/bench_correct_memory.py [--sizes 265 530 1000] [--keep DIR]
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

from bench_take_memory import make_take


def child(mode: str, take: str, out: str) -> None:
    """Load (and with ``mode`` "correct", correct) the take in this fresh process; prints JSON: peak
    RSS (MiB), CPU s of the correction, frames outside before and after."""
    import livezmp.correct.solver  # noqa: F401 (the baseline holds the correction's modules too)
    from livezmp.correct.limits import CorrectionLimits
    from livezmp.offline.take import TakeOptions, correct_loaded

    options = TakeOptions()
    loaded = options.load(take)
    cpu = time.process_time()
    report = correct_loaded(loaded, out, options, CorrectionLimits()) if mode == "correct" else {}
    cpu = time.process_time() - cpu
    print(json.dumps({"peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "cpu_s": cpu,
                      "outside": [report.get("out_of_support_before"), report.get("out_of_support_after")]}))


def measure(mode: str, take: Path, out: Path) -> dict:
    run = subprocess.run([sys.executable, __file__, "--child", mode, str(take), str(out)], capture_output=True,
                         text=True, check=True)
    return json.loads(run.stdout.splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[265, 530, 1000])
    ap.add_argument("--keep", type=Path, help="make the takes here and keep them (default: a temporary directory)")
    ap.add_argument("--child", nargs=3, metavar=("MODE", "TAKE", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(*args.child)
        return
    work = args.keep or Path(tempfile.mkdtemp(prefix="correct_memory_"))
    work.mkdir(parents=True, exist_ok=True)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} (shared machine), {os.cpu_count()} CPUs")
    print(f"{'frames':>7} | {'load peak MiB':>13} {'correct peak MiB':>16} | {'solve KiB/frame':>15} "
          f"{'slope KiB/frame':>15} | {'correct CPU ms/frame':>19} | outside before → after")
    last = None
    for n in sorted(args.sizes):
        take = work / f"take_{n}.bvh"
        if not take.exists():
            make_take(take, n)
        base = measure("load", take, work / "out.bvh")
        got = measure("correct", take, work / "out.bvh")
        solve = got["peak_mib"] - base["peak_mib"]
        slope = "" if last is None else f"{1024 * (solve - last[1]) / (n - last[0]):.1f}"
        print(f"{n:>7} | {base['peak_mib']:>13.0f} {got['peak_mib']:>16.0f} | {1024 * solve / n:>15.1f} {slope:>15} | "
              f"{1000 * got['cpu_s'] / n:>19.1f} | {got['outside'][0]} → {got['outside'][1]}")
        last = (n, solve)
        if not args.keep:
            take.unlink()
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())} after")


if __name__ == "__main__":
    main()
