"""Balance correction's cost per frame: this checkout against a baseline revision, same takes, one run.

Each take is corrected as `livezmp correct` does (``correct_bvh``) twice, in a fresh process
each: with the baseline revision's ``livezmp`` (extracted with ``git archive``) and with this
checkout's. Printed per take: CPU ms per frame (process time, so the machine's other load
counts less than in wall-clock; the load average is printed beside), the speed-up, and how
far the results agree: frames outside after, max root rotation, max loaded-foot displacement,
and the largest difference of the corrected channels (raw BVH units: cm and degrees). The
Gauss-Newton iterations are printed beside the times: where the two runs take different paths
(below) their counts differ, and the cost per frame with them.

The correction's outcome is sensitive to rounding (each Gauss-Newton step is an iterative
least-squares solve stopped at its iteration cap, and a Levenberg-Marquardt step is kept or
damped on a strict cost comparison), so a change that only reorders floating-point sums moves
some walks' corrections by degrees. ``--noise-floor`` adds, as the yardstick, the baseline run
on the take's channels × (1 + 1e-14): the baseline's own difference under rounding-level noise.

    python benchmarks/bench_correction_speed.py [--baseline 8623454] [--walks walk_active_004.bvh ...]
        [--skeletons] [--frames 90] [--noise-floor]

``--skeletons`` adds the first ``--frames`` frames of walk_normal_001 on the generated skeleton
variants (tests/skeleton_variants.py, as ``bench_correction.py --skeletons``). The default
baseline is the last revision before the legs' solve was batched.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BANDAI = ROOT.parent / "shared" / "data" / "bvh" / "bandai"
WALKS = ["walk_active_004.bvh", "walk_elderly_001.bvh", "walk_exhausted_001.bvh", "walk_normal_001.bvh"]


def worker(path: str, out: str, noise: str) -> None:
    """Correct one take (its channels × (1 + ``noise``)) with whichever ``livezmp`` is first on
    the path; save what the table needs."""
    from livezmp.correct.solver import correct_bvh
    from livezmp.model.bvh import read_bvh

    motion = read_bvh(path)
    motion = replace(motion, frames=motion.frames * (1.0 + float(noise)))
    t0 = time.process_time()
    _, result = correct_bvh(motion)
    cpu = time.process_time() - t0
    np.savez(out, frames=result.frames, cpu=cpu, report=json.dumps(result.report()))


def run(path: Path, code_root: Path, out: Path, noise: float = 0.0) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code_root))
    subprocess.run([sys.executable, __file__, "--worker", str(path), str(out), str(noise)], env=env, check=True)
    z = np.load(out)
    return {"frames": z["frames"], "cpu": float(z["cpu"]), "report": json.loads(str(z["report"]))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline", default="8623454", help="git revision to compare with")
    ap.add_argument("--walks", nargs="*", default=WALKS)
    ap.add_argument("--skeletons", action="store_true", help="add walk_normal_001 on the skeleton variants")
    ap.add_argument("--frames", type=int, default=90, help="frames of the skeleton variants")
    ap.add_argument("--noise-floor", action="store_true",
                    help="add the baseline on the channels x (1 + 1e-14): its own sensitivity to rounding")
    ap.add_argument("--worker", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(*args.worker)
        return
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = tmp / "baseline"
        base.mkdir()
        tar = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline, "livezmp"], check=True,
                             capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=tar, check=True)
        takes = {w: BANDAI / w for w in args.walks}
        if args.skeletons:
            sys.path.insert(0, str(Path(__file__).parent))
            from bench_correction import variant_motions

            from livezmp.model.bvh import write_bvh

            for i, (name, motion) in enumerate(variant_motions("walk_normal_001.bvh", args.frames).items()):
                takes[name] = tmp / f"variant{i}.bvh"
                write_bvh(motion, takes[name])
        print(f"baseline {args.baseline} against this checkout; CPU ms per frame")
        print(f"{'take':30s} {'frames':>6s} {'baseline':>9s} {'now':>7s} {'speed-up':>8s} {'GN iterations':>13s} "
              f"{'outside after':>13s} "
              f"{'max rot °':>15s} {'feet mm':>13s} {'max |Δ channel|':>15s} {'load':>5s}"
              + ("   baseline ×(1+1e-14): outside, max rot °, feet mm, max |Δ channel|" if args.noise_floor else ""))
        for name, path in takes.items():
            old = run(path, base, tmp / "old.npz")
            new = run(path, ROOT, tmp / "new.npz")
            ro, rn = old["report"], new["report"]
            n = len(new["frames"])
            ms_old, ms_new = 1000 * old["cpu"] / n, 1000 * new["cpu"] / n
            print(f"{name:30s} {n:>6d} {ms_old:>9.1f} {ms_new:>7.1f} {ms_old / ms_new:>8.1f} "
                  f"{len(ro['outside_after_iteration']):>6d} {len(rn['outside_after_iteration']):>6d} "
                  f"{ro['out_of_support_after']:>6d} {rn['out_of_support_after']:>6d} "
                  f"{ro['max_root_rotation_deg']:>7.3f} {rn['max_root_rotation_deg']:>7.3f} "
                  f"{ro['max_foot_displacement_mm']:>6.3f} {rn['max_foot_displacement_mm']:>6.3f} "
                  f"{np.abs(old['frames'] - new['frames']).max():>15.2e} {os.getloadavg()[0]:>5.2f}"
                  + (_noise_floor(path, base, tmp, old) if args.noise_floor else ""), flush=True)


def _noise_floor(path: Path, base: Path, tmp: Path, old: dict) -> str:
    r = run(path, base, tmp / "noise.npz", 1e-14)
    rep = r["report"]
    return (f"   {rep['out_of_support_after']:>6d} {rep['max_root_rotation_deg']:>7.3f} "
            f"{rep['max_foot_displacement_mm']:>6.3f} {np.abs(old['frames'] - r['frames']).max():>9.2e}")


if __name__ == "__main__":
    main()
