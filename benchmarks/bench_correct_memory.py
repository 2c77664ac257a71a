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

import json
import resource
import time

from bench_take_memory import bench_arguments, make_take, measure, start
from machine_load import load_averages


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


def main() -> None:
    args = bench_arguments(__doc__, [265, 530, 1000]).parse_args()
    if args.child:
        child(*args.child)
        return
    work = start(args.keep, "correct_memory_")
    print(f"{'frames':>7} | {'load peak MiB':>13} {'correct peak MiB':>16} | {'solve KiB/frame':>15} "
          f"{'slope KiB/frame':>15} | {'correct CPU ms/frame':>19} | outside before → after")
    last = None
    for n in sorted(args.sizes):
        take = work / f"take_{n}.bvh"
        if not take.exists():
            make_take(take, n)
        base = measure("load", take, work / "out.bvh", __file__)
        got = measure("correct", take, work / "out.bvh", __file__)
        solve = got["peak_mib"] - base["peak_mib"]
        slope = "" if last is None else f"{1024 * (solve - last[1]) / (n - last[0]):.1f}"
        print(f"{n:>7} | {base['peak_mib']:>13.0f} {got['peak_mib']:>16.0f} | {1024 * solve / n:>15.1f} {slope:>15} | "
              f"{1000 * got['cpu_s'] / n:>19.1f} | {got['outside'][0]} → {got['outside'][1]}")
        last = (n, solve)
        if not args.keep:
            take.unlink()
    print(f"load average {load_averages(' ')} after")


if __name__ == "__main__":
    main()
