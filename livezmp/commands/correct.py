"""`livezmp correct`: balance-correct a motion file (BVH, or joint-trajectory CSV + URDF)."""

from __future__ import annotations

import argparse

from livezmp.checks import check_output_path
from livezmp.commands.common import limits_from_args, load_from_args, pipeline_config
from livezmp.correct.solver import correct_motion
from livezmp.errors import InputError
from livezmp.model.motion_file import write_motion
from livezmp.offline.report import write_json


def cmd_correct(args: argparse.Namespace) -> int:
    if args.motion is None:
        raise InputError("correct: give a motion file (.bvh, or .csv with --robot)")
    if str(args.motion).lower().endswith(".c3d"):
        raise InputError(f"{args.motion}: correct does not take C3D marker takes yet (their segments move "
                         "freely, with no joint chain for the hip re-solve); `livezmp analyze` reads them")
    check_output_path(args.output, "-o")
    check_output_path(args.report, "--report")
    loaded = load_from_args(args)
    cfg = pipeline_config(args, loaded)
    result = correct_motion(loaded.body, loaded.times, loaded.frames, cfg, limits_from_args(args),
                            nominal_dt=1.0 / loaded.fps,
                            progress=lambda message: print(f"correct: {message}", flush=True))
    write_motion(loaded, result.frames, args.output)
    report = {"source": loaded.source, "output": args.output, "mode": cfg.mode, **result.report()}
    if args.report:
        write_json(report, args.report)
    print(f"{loaded.source}: {report['out_of_support_before']} → {report['out_of_support_after']} of "
          f"{report['support_frames']} support frames outside; root rotation max "
          f"{report['max_root_rotation_deg']:.2f}°, rms {report['rms_root_rotation_deg']:.2f}°; stance feet moved "
          f"≤ {report['max_foot_displacement_mm']:.3f} mm; wrote {args.output}")
    if report["infeasible_frames"]:
        print(f"not fully corrected within the limits: frames {report['infeasible_frames']}")
    return 0
