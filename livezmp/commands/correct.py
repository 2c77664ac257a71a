"""`livezmp correct`: balance-correct a motion file (BVH, joint-trajectory CSV + URDF, or a gait-lab C3D)."""

from __future__ import annotations

import argparse

from livezmp.checks import check_output_paths, check_same_format, given_inputs
from livezmp.commands.common import limits_from_args, load_from_args, take_options
from livezmp.errors import InputError
from livezmp.jsonfile import write_json
from livezmp.offline.take import correct_c3d_take, correct_loaded


def cmd_correct(args: argparse.Namespace) -> int:
    if args.motion is None:
        raise InputError("correct: give a motion file (.bvh, or .csv with --robot)")
    check_output_paths((args.output, "-o"), (args.report, "--report"), inputs=given_inputs(args))
    c3d_in, c3d_out = (str(p).lower().endswith(".c3d") for p in (args.motion, args.output))
    if c3d_in:
        if not (c3d_out or str(args.output).lower().endswith(".bvh")):
            raise InputError(f"{args.output}: a C3D take is written as C3D (its markers moved) or BVH (its segments); "
                             "give -o ending in .c3d or .bvh")
        return _correct_c3d(args, c3d_out)
    if c3d_out:
        raise InputError(f"{args.output}: only a C3D take can be written as C3D (its markers are moved); "
                         f"{args.motion} is written in its own format")
    check_same_format(args.motion, args.output)
    report = correct_loaded(load_from_args(args), args.output, take_options(args), limits_from_args(args),
                            progress=lambda message: print(f"correct: {message}", flush=True))
    _tell(report, args)
    return 0


def _correct_c3d(args: argparse.Namespace, as_c3d: bool) -> int:
    """A gait-lab take: its marker body corrected as a chain, written as C3D (markers moved) or BVH."""
    report = correct_c3d_take(args.motion, args.output, take_options(args), limits_from_args(args),
                              progress=lambda message: print(f"correct: {message}", flush=True))
    _tell(report, args)
    if report["points_unchanged"] and as_c3d:
        print(f"copied unchanged (angles, loads, or never seen): {len(report['points_unchanged'])} points; "
              "model outputs describe the motion before the correction")
    return 0


def _tell(report: dict, args: argparse.Namespace) -> None:
    if args.report:
        write_json(report, args.report)
    print(f"{report['source']}: {report['out_of_support_before']} → {report['out_of_support_after']} of "
          f"{report['support_frames']} support frames outside; root rotation max "
          f"{report['max_root_rotation_deg']:.2f}°, rms {report['rms_root_rotation_deg']:.2f}°; stance feet moved "
          f"≤ {report['max_foot_displacement_mm']:.3f} mm; judged at {report['estimator']['cutoff_hz']:g} Hz "
          f"(analyze --cutoff-hz to compare); wrote {args.output}")
    if report["infeasible_frames"]:
        print(f"not fully corrected within the limits: frames {report['infeasible_frames']}")
