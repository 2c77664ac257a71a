"""``livezmp gait analyze | synth | compare``: the command-line front end of :mod:`livezmp.gait`.

:func:`add_gait_commands` registers the ``gait`` command on an argparse subparsers
object (``livezmp.cli`` does); each leaf sets ``func(args) -> int`` and raises
:class:`InputError` for user mistakes, which the ``livezmp`` command prints as one line
with exit code 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from livezmp.errors import InputError
from livezmp.gait.compare import compare
from livezmp.gait.features import walk_features
from livezmp.gait.population import analyze
from livezmp.gait.synth import synth_take, to_bvh, to_trajectory
from livezmp.gait.tables import read_features, write_outputs
from livezmp.gait.take import GaitTake, load_take
from livezmp.gait.takeset import DEFAULT_PATTERN, read_manifest, takes_from_paths
from livezmp.model.bvh import write_bvh
from livezmp.model.trajectory_csv import write_joint_csv

GROUND = {"y": "xz", "z": "xy"}


def _input_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--up", choices=("y", "z"), default="y", help="BVH up axis (default y; ground = the other two)")
    p.add_argument("--units", choices=("m", "cm", "mm", "in"), help="BVH length unit (default: detect)")
    p.add_argument("--urdf", help="robot URDF, for joint-trajectory CSV walks")


def _variant(text: str) -> tuple[str, str]:
    label, sep, cond = text.partition("=")
    if not sep or not label or not cond:
        raise argparse.ArgumentTypeError(f"expected LABEL=CONDITION (e.g. fast=active), got {text!r}")
    return label, cond


def _load(path: str | Path, args: argparse.Namespace) -> GaitTake:
    return load_take(path, args.up, args.units, args.urdf)


def _pct(s) -> str:
    if s.mu is None:
        return f"n/a ({s.note})"
    cv = "n/a" if s.cv is None else f"{s.cv:.1f} %"
    return f"μ {s.mu:+.1f} % (σ {s.sigma:.1f} %, CV {cv}{', feature' if s.feature else ''})"


def cmd_analyze(args: argparse.Namespace) -> int:
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

            motion = correct_bvh(motion)
        write_bvh(motion, out)
        print(f"wrote {out}: {len(motion.frames)} frames at {motion.fps:g} fps, up {args.up}, "
              f"ground plane {GROUND[args.up]}")
    else:
        if args.balance:
            raise InputError("--balance: balance correction works on BVH walks only")
        write_joint_csv(to_trajectory(take, t, q), out)
        print(f"wrote {out}: {len(t)} samples, up z, ground plane xy")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    a = _load(args.walk, args)
    fa = walk_features(a)
    print(f"A: {a.source}: {fa.frequency:.3f} Hz, {fa.speed:.3f} m/s, {fa.cycles.n_cycles} cycles")
    results = []
    for path in args.others:
        b = _load(path, args)
        fb = walk_features(b)
        c = compare(a, fa, b, fb)
        results.append(c)
        print(f"B: {b.source}: {fb.frequency:.3f} Hz, {fb.speed:.3f} m/s; total RMS error {c.total:.2f}°")
    several = len(results) > 1
    print("cycle-normalised joint-angle RMS error per joint (deg)" + (", mean over B walks" if several else ""))
    for joint in dict.fromkeys(j for r in results for j in r.per_joint):
        print(f"  {joint}: {np.mean([r.per_joint[joint] for r in results if joint in r.per_joint]):.2f}")
    mean_total = float(np.mean([r.total for r in results]))
    print(f"total RMS error (deg){f', mean over {len(results)} walks' if several else ''}: {mean_total:.2f}")
    return 0


def add_gait_commands(subparsers) -> argparse.ArgumentParser:
    """Register ``gait analyze|synth|compare`` on an argparse ``subparsers`` object."""
    gait = subparsers.add_parser("gait", help="walking analysis and speed control (paper 003)",
                                 description="Gait features across people, and walking-speed control.")
    sub = gait.add_subparsers(dest="gait_command", required=True)

    p = sub.add_parser("analyze", help="features common across people: K, μ, σ, CV, feature parts")
    p.add_argument("inputs", nargs="*", help="walk files or directories (labelled by --pattern)")
    p.add_argument("--manifest", help="CSV with columns path,subject,condition instead of inputs")
    p.add_argument("--pattern", default=DEFAULT_PATTERN,
                   help="regex on file names with groups (?P<condition>) and optionally (?P<subject>)")
    p.add_argument("--base", required=True, help="base condition, e.g. normal")
    p.add_argument("--variant", type=_variant, action="append", required=True, metavar="LABEL=CONDITION",
                   help="a variant, e.g. fast=active (repeatable)")
    p.add_argument("--out", required=True, help="output directory for tables, plot and features.json")
    p.add_argument("--threshold", type=float, default=250.0, help="feature parts: |CV| ≤ this, %% (default 250)")
    p.add_argument("--min-base", type=float, default=1.0,
                   help="DC or amplitude below this (deg) in the base: no ratio (default 1)")
    p.add_argument("--min-change", type=float, default=1.0,
                   help="feature parts also need |μ| ≥ this, %% (default 1; 0 = the paper's rule)")
    _input_options(p)
    p.set_defaults(func=cmd_analyze)

    p = sub.add_parser("synth", help="change a base walk towards a variant using only its feature parts")
    p.add_argument("base_walk", help="BVH file, or joint-trajectory CSV with --urdf")
    p.add_argument("--features", required=True, help="features.json from gait analyze")
    p.add_argument("--to", required=True, help="variant label, e.g. fast")
    p.add_argument("--amount", type=float, default=1.0, help="0 = base walk … 1 = the variant (default 1)")
    p.add_argument("-o", "--output", required=True, help="output walk (same format as the input)")
    p.add_argument("--balance", action="store_true", help="pass the result through the balance correction")
    _input_options(p)
    p.set_defaults(func=cmd_synth)

    p = sub.add_parser("compare", help="cycle-normalised joint-angle RMS error of walk A against walks B")
    p.add_argument("walk", help="walk A")
    p.add_argument("others", nargs="+", help="walk(s) B; with several, the mean error is the last number")
    _input_options(p)
    p.set_defaults(func=cmd_compare)
    return gait
