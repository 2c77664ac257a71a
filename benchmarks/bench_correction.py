"""Balance correction: the sequence solver against the seed paper's fixed-step search.

On the same frames of a Bandai walk: the seed searches, frame by frame, root rotations
on a fixed grid (0.5°) holding each frame's velocities and accelerations, and keeps the
smallest that puts that frame's ZMP inside; the solver corrects the whole take at once
(smooth, rate-limited, accounting for the accelerations its own rotations cause).
Printed side by side: rotation size on the frames both treat, time per frame, and how
many frames are inside when each result is re-analysed as a motion.

    python benchmarks/bench_correction.py [--walk walk_normal_001.bvh] [--frames 120]

With ``--skeletons`` it corrects the walk's first ``--frames`` frames re-expressed exactly on
other skeletons (tests/skeleton_variants.py) and prints, per skeleton, how far the
weight-bearing feet move with the final check on the feet (livezmp.correct.edit.hold_feet)
and without it (the solver's first-order rotation bounds alone), and the frames outside:

    python benchmarks/bench_correction.py --skeletons [--frames 90]

With ``--every-walk`` it corrects each of the 24 Bandai walks whole with `livezmp correct`, re-analyses the result
at the correction's cutoff and prints, per walk, the frames outside before and after, the largest root rotation,
how far the loaded feet move and the solver's time a frame (two walks at a time; minutes). The suite checks the
six hardest (tests/test_correction_bandai.py):

    python benchmarks/bench_correction.py --every-walk
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from unittest import mock

import numpy as np
from machine_load import load_averages

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.correct.edit import apply_delta
from livezmp.correct.limits import CORRECTION_CUTOFF_HZ, stance_weights
from livezmp.correct.root_motion import RootMover
from livezmp.correct.seed_search import seed_grid_search
from livezmp.correct.solver import correct_motion
from livezmp.model.bvh import BvhMotion, read_bvh
from livezmp.model.bvh_body import body_from_bvh

BANDAI = Path(__file__).resolve().parents[2] / "shared" / "data" / "bvh" / "bandai"
TESTS = Path(__file__).resolve().parents[1] / "tests"


def variant_motions(walk: str, frames: int) -> dict[str, BvhMotion]:
    """The walk's first ``frames`` frames re-expressed exactly on other skeletons (tests/skeleton_variants.py)."""
    sys.path.insert(0, str(TESTS))
    import skeleton_variants as sv

    s = sv.decompose(read_bvh(BANDAI / walk))
    s.trans, s.rot = s.trans[:frames], s.rot[:frames]
    short = sv.decompose(read_bvh(BANDAI / walk))  # from frame 40, as the test: the walk's first frames are inside
    short.trans, short.rot = short.trans[40: 40 + frames // 4 + 1], short.rot[40: 40 + frames // 4 + 1]
    thighs = {"L": "UpperLeg_L", "R": "UpperLeg_R"}
    variants = {
        "bandai (cm, y up, ZXY, 30 Hz)": s,
        "CMU-style hip joints, ZYX": sv.channel_orders(sv.cmu_hip_joints(sv.positions_below_root_dropped(s), thighs),
                                                       "ZYX"),
        "rotations YXZ, positions ZYX": sv.channel_orders(s, "YXZ", "ZYX"),
        "z up, metres, XYZ": sv.channel_orders(sv.scaled(sv.z_up(s), 0.01), "XYZ", "ZXY"),
        "120 Hz (slerped)": sv.resampled(short, 4),
    }
    return {name: sv.compose(v) for name, v in variants.items()}


def skeleton_table(walk: str, frames: int) -> None:
    print(f"load average {load_averages(' ')}; {walk}, first {frames} frames "
          f"(120 Hz: {frames // 4 + 1} from frame 40, resampled)")
    print(f"{'skeleton':32s} {'frames':>6s} {'outside before':>14s} {'after':>6s} "
          f"{'loaded feet mm: feet check':>27s} {'without':>8s} {'frames held':>11s}")
    for name, motion in variant_motions(walk, frames).items():
        body = body_from_bvh(motion)
        times = np.arange(len(motion.frames)) * motion.frame_time
        cfg = default_config(body, motion.fps, cutoff_hz=CORRECTION_CUTOFF_HZ)  # as `livezmp correct`
        with_check = correct_motion(body, times, motion.frames, cfg, nominal_dt=motion.frame_time).report()
        with mock.patch("livezmp.correct.solver.hold_feet", lambda mover, body, fr, delta, *a: (delta, [])):
            without = correct_motion(body, times, motion.frames, cfg, nominal_dt=motion.frame_time).report()
        print(f"{name:32s} {len(motion.frames):>6d} {with_check['out_of_support_before']:>14d} "
              f"{with_check['out_of_support_after']:>6d} {with_check['max_foot_displacement_mm']:>27.3f} "
              f"{without['max_foot_displacement_mm']:>8.3f} {len(with_check['foot_held_frames']):>11d}")


def every_walk_table() -> None:
    """Every Bandai walk corrected and re-analysed, as tests/test_correction_bandai.py does for the hardest."""
    sys.path.insert(0, str(TESTS))
    from bandai_correction import correct_and_reanalyse, table

    files = sorted(str(p) for p in BANDAI.glob("*.bvh"))
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=2) as pool:
        results = dict(zip(files, pool.map(correct_and_reanalyse, files), strict=True))
    print(f"load average {load_averages(' ')}; {len(files)} walks in {time.perf_counter() - start:.0f} s")
    print(table(results))
    good = sum(r["after"]["inside_fraction"] >= 0.99 and r["report"]["max_foot_displacement_mm"] <= 1.0
               for r in results.values())
    print(f"{good} of {len(files)} walks at least 99 % inside after with the loaded feet moved at most 1 mm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--walk", default="walk_normal_001.bvh")
    ap.add_argument("--frames", type=int, default=120, help="frames of the walk to use (from its start)")
    ap.add_argument("--step-deg", type=float, default=0.5)
    ap.add_argument("--skeletons", action="store_true",
                    help="the walk on other skeletons: loaded feet, with and without the final check")
    ap.add_argument("--every-walk", action="store_true",
                    help="every Bandai walk corrected whole and re-analysed (the suite checks the hardest six)")
    args = ap.parse_args()
    if args.every_walk:
        every_walk_table()
        return
    if args.skeletons:
        skeleton_table(args.walk, args.frames)
        return
    motion = read_bvh(BANDAI / args.walk)
    body = body_from_bvh(motion)
    frames = motion.frames[: args.frames]
    times = np.arange(len(frames)) * motion.frame_time
    cfg = default_config(body, motion.fps, cutoff_hz=CORRECTION_CUTOFF_HZ)  # as `livezmp correct`

    s = time.perf_counter()
    solved = correct_motion(body, times, frames, cfg, nominal_dt=motion.frame_time)
    t_solver = time.perf_counter() - s
    before = solved.before
    outside = [r.index for r in before if r.inside is False]

    s = time.perf_counter()
    seed = seed_grid_search(body, cfg, before, outside, step_deg=args.step_deg)
    t_seed = time.perf_counter() - s
    delta_seed = np.zeros((len(frames), 3))
    for k, d in seed.items():
        delta_seed[k] = d
    w = stance_weights(before, 1)
    seed_frames = apply_delta(RootMover(body), body, frames, delta_seed, w)
    seed_after = Pipeline(body, cfg, motion.frame_time).run(times, seed_frames)

    both = sorted(seed)
    mag_seed = np.degrees(np.linalg.norm(delta_seed[both], axis=1))
    mag_solver = np.degrees(np.linalg.norm(solved.delta[both], axis=1))

    def inside(results):
        judged = [r for r in results if r.inside is not None]
        return sum(r.inside for r in judged), len(judged)

    i_seed, n = inside(seed_after)
    i_solver, _ = inside(solved.after)
    i_before, _ = inside(before)
    print(f"\n{args.walk}, first {len(frames)} frames: {len(outside)} outside before "
          f"({i_before}/{n} inside); the seed found a grid point for {len(seed)} of them\n")
    print(f"{'':44s} {'seed grid search':>18s} {'sequence solver':>18s}")
    print(f"{'mean |rotation| on those frames (deg)':44s} {mag_seed.mean():18.2f} {mag_solver.mean():18.2f}")
    print(f"{'max |rotation| on those frames (deg)':44s} {mag_seed.max():18.2f} {mag_solver.max():18.2f}")
    jerk_seed = np.degrees(np.abs(np.diff(delta_seed, 2, axis=0)).max()) * motion.fps**2
    jerk_solver = np.degrees(np.abs(np.diff(solved.delta, 2, axis=0)).max()) * motion.fps**2
    print(f"{'max rotational acceleration (deg/s²)':44s} {jerk_seed:18.0f} {jerk_solver:18.0f}")
    print(f"{'time per corrected frame (ms)':44s} {1000 * t_seed / max(len(outside), 1):18.1f} "
          f"{1000 * t_solver / max(len(outside), 1):18.1f}")
    print(f"{'frames inside when re-analysed':44s} {f'{i_seed}/{n}':>18s} {f'{i_solver}/{n}':>18s}")
    print(f"\nsolver / seed time ratio: {t_solver / t_seed:.2f}")


if __name__ == "__main__":
    main()
