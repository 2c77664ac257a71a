"""``livezmp gait analyze | synth | compare``: the command-line front end of :mod:`livezmp.gait`
(grammar in :mod:`livezmp.cli`). Each handler returns the exit code and raises
:class:`InputError` for user mistakes, which the ``livezmp`` command prints as one line
with exit code 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from livezmp.checks import check_output_dir, check_output_paths, check_same_format, given_inputs
from livezmp.commands.common import check_population_options
from livezmp.errors import InputError
from livezmp.gait.compare import compare
from livezmp.gait.features import walk_features
from livezmp.gait.population import analyze
from livezmp.gait.synth import synth_take, to_bvh, to_trajectory
from livezmp.gait.tables import read_features, write_outputs
from livezmp.gait.take import GaitTake, load_take
from livezmp.gait.takeset import read_manifest, takes_from_paths
from livezmp.model.bvh import write_bvh
from livezmp.model.trajectory_csv import write_joint_csv
from livezmp.offline.treadmill import parse_treadmill

GROUND = {"y": "xz", "z": "xy"}


def _load(path: str | Path, args: argparse.Namespace) -> GaitTake:
    return load_take(path, args.up, args.units, args.urdf, args.markers, args.static,
                     parse_treadmill(getattr(args, "treadmill", "auto")))


def _pct(s) -> str:
    if s.mu is None:
        return f"n/a ({s.note})"
    cv = "n/a" if s.cv is None else f"{s.cv:.1f} %"
    return f"μ {s.mu:+.1f} % (σ {s.sigma:.1f} %, CV {cv}{', feature' if s.feature else ''})"


def _on_belt(take: GaitTake) -> str:
    """", on a treadmill's belt at S m/s" for a treadmill walk (its speed is the belt's frame's), else ""."""
    return "" if take.belt is None else f" on a treadmill's belt at {np.hypot(*take.belt):.3f} m/s"


def cmd_analyze(args: argparse.Namespace) -> int:
    check_population_options(args)
    check_output_dir(args.out, "--out")
    if args.manifest:
        if args.inputs:
            raise InputError("give either --manifest or input files/directories, not both")
        specs, where = read_manifest(args.manifest), args.manifest
    elif args.inputs:
        specs, where = takes_from_paths(args.inputs, args.pattern), ", ".join(args.inputs)
    else:
        raise InputError("gait analyze: give input files/directories or --manifest")
    variants = dict(args.variant)
    wanted = {args.base, *variants.values()}
    ignored: dict[str, int] = {}
    for s in specs:
        if s.condition not in wanted:
            ignored[s.condition] = ignored.get(s.condition, 0) + 1
    items = [(s, walk_features(_load(s.path, args))) for s in specs if s.condition in wanted]
    a = analyze(items, args.base, variants, args.threshold, args.min_base, args.min_change, where)
    counts = {c: sum(s.condition == c for s, _ in items) for c in wanted}
    print(f"takes: {counts[args.base]} {args.base} (base), "
          + ", ".join(f"{counts[c]} {c} → {lab}" for lab, c in variants.items())
          + (f"; ignored: {', '.join(f'{c} ({n})' for c, n in sorted(ignored.items()))}" if ignored else ""))
    for v in a.variants:
        print(f"{v.label} ({v.condition}): pairing {v.pairing}")
        for k, s in v.walk.items():
            print(f"  {k}: {s.base:.3f} → {s.variant:.3f}: {_pct(s)}")
        for what, stats in (("posture (DC)", v.dc), ("size (amplitude)", v.amplitude)):
            na = sum(s.mu is None for s in stats)
            print(f"  {what}: {sum(s.feature for s in stats)} feature parts of {len(stats)} channels"
                  f" (|CV| ≤ {a.threshold:g} %, |μ| ≥ {a.min_change:g} %); {na} not computed, base ≈ 0")
    for p in write_outputs(a, args.out):
        print(f"wrote {p}")
    return 0


def cmd_synth(args: argparse.Namespace) -> int:
    check_output_paths((args.output, "-o"), inputs=given_inputs(args))
    if Path(args.base_walk).suffix.lower() == ".c3d":
        raise InputError(f"{args.base_walk}: gait synth changes BVH or CSV walks; a C3D take can be analysed "
                         "and compared, not synthesised")
    check_same_format(args.base_walk, args.output)
    analysis = read_features(args.features)
    take = _load(args.base_walk, args)
    t, q, plan = synth_take(take, analysis, args.to, args.amount, args.features)
    n_dc = int(np.sum(plan.dc_ratio != 1.0))
    n_amp = int(np.sum(plan.amp_ratio != 1.0))
    print(f"{take.source} → {args.to} (amount {args.amount:g}): frequency ×{plan.frequency_ratio:.4f}, "
          f"stride ×{plan.stride_ratio:.4f}; changed posture of {n_dc} and size of {n_amp} channels"
          + (f"; {len(plan.unmatched)} channels not in the features" if plan.unmatched else ""))
    out = Path(args.output)
    if take.body.kind == "bvh":
        motion = to_bvh(take, q)
        if args.balance:
            from livezmp.correct.solver import correct_bvh  # imported here: heavy, and only for --balance

            motion, result = correct_bvh(motion)
            rep = result.report()
            print(f"balanced: {rep['out_of_support_before']} → {rep['out_of_support_after']} of "
                  f"{rep['support_frames']} support frames outside; root rotation max "
                  f"{rep['max_root_rotation_deg']:.2f}°; stance feet moved ≤ {rep['max_foot_displacement_mm']:.3f} mm")
        write_bvh(motion, out)
        print(f"wrote {out}: {len(motion.frames)} frames at {motion.fps:g} fps, up {take.body.up_axis}, "
              f"ground plane {GROUND[take.body.up_axis]}")
    else:
        if args.balance:
            raise InputError("--balance: balance correction works on BVH walks only")
        write_joint_csv(to_trajectory(take, t, q), out)
        print(f"wrote {out}: {len(t)} samples, up z, ground plane xy")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    a = _load(args.walk, args)
    fa = walk_features(a)
    print(f"A: {a.source}: {fa.frequency:.3f} Hz, {fa.speed:.3f} m/s{_on_belt(a)}, {fa.cycles.n_cycles} cycles")
    results = []
    for path in args.others:
        b = _load(path, args)
        fb = walk_features(b)
        c = compare(a, fa, b, fb)
        results.append(c)
        print(f"B: {b.source}: {fb.frequency:.3f} Hz, {fb.speed:.3f} m/s{_on_belt(b)}; total RMS error {c.total:.2f}°")
    several = len(results) > 1
    print("cycle-normalised joint-angle RMS error per joint (deg)" + (", mean over B walks" if several else ""))
    for joint in dict.fromkeys(j for r in results for j in r.per_joint):
        print(f"  {joint}: {np.mean([r.per_joint[joint] for r in results if joint in r.per_joint]):.2f}")
    mean_total = float(np.mean([r.total for r in results]))
    print(f"total RMS error (deg){f', mean over {len(results)} walks' if several else ''}: {mean_total:.2f}")
    return 0
