"""`livezmp analyze`: run the pipeline over a motion file and write the results.

The take goes through :func:`livezmp.offline.batch.run_batch`: in chunks over arrays when it is
uniformly sampled and complete (an hour at 120 Hz in seconds), frame by frame otherwise;
the results are the same. A C3D gait trial goes through :mod:`livezmp.offline.gaitlab`:
its markers make the body, and its force plates, when present, are compared with the ZMP.
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from rich.progress import Progress

from livezmp.checks import check_output_path
from livezmp.commands.common import check_body_options, load_from_args
from livezmp.model.c3d import read_c3d
from livezmp.model.markers import MarkerBodyOptions
from livezmp.offline.calibrate import load_subject
from livezmp.offline.gaitlab import LabAnalysis, LabOptions, analyse_lab_take
from livezmp.offline.plot import plot_analysis
from livezmp.offline.report import summarize, write_json, write_zmp_csv
from livezmp.offline.take import analyse_loaded, take_config

PROGRESS_FRAMES = 20_000  # takes this long or longer get a progress bar (a few seconds on the per-frame path)


def _analyse_file(args: argparse.Namespace):
    """(body, result, fps, source, extra summary, extra CSV columns, plate CoP and complete frames or None)
    of the command line's motion."""
    if args.motion is not None and Path(args.motion).suffix.lower() == ".c3d":
        markers = load_subject(args.subject).marker_options() if args.subject else MarkerBodyOptions()
        lab = analyse_lab_take(read_c3d(args.motion), LabOptions(mass=args.mass, mode=args.mode, markers=markers))
        plates = None if lab.plates is None else (lab.plates.cop, lab.complete)
        return lab.take.body, lab.result, lab.rate, args.motion, lab.summary, _lab_columns(lab), plates
    loaded = load_from_args(args)
    if len(loaded.frames) < PROGRESS_FRAMES:
        results = analyse_loaded(loaded, args.mode, args.ground)
    else:  # a long take: show how far the analysis is
        with Progress(transient=True) as bar:
            task = bar.add_task("analysing", total=len(loaded.frames))
            results = analyse_loaded(loaded, args.mode, args.ground,
                                     progress=lambda done: bar.update(task, completed=done))
    # the estimator's settings, so a user sees what smoothed the take (README: choosing them)
    estimator = replace(take_config(loaded, args.mode, args.ground).estimator, rate_hz=loaded.fps)
    return loaded.body, results, loaded.fps, loaded.source, {"estimator": asdict(estimator)}, None, None


def _lab_columns(lab: LabAnalysis) -> dict[str, np.ndarray] | None:
    """zmp.csv's plate columns: CoP (input frame, m; empty where unloaded), plate vertical force (N), complete."""
    if lab.plates is None:
        return None
    cop = lab.take.body.to_input_frame(lab.plates.cop)
    return {"cop_x": cop[:, 0], "cop_y": cop[:, 1], "cop_z": cop[:, 2], "plate_fz": lab.plates.force[:, 2],
            "complete": lab.complete.astype(float)}


def cmd_analyze(args: argparse.Namespace) -> int:
    for path, option in ((args.out, "--out"), (args.summary_json, "--summary-json"), (args.plot, "--plot")):
        check_output_path(path, option)
    check_body_options(args)
    body, results, fps, source, lab_summary, columns, plates = _analyse_file(args)
    summary = {"source": source, **summarize(body, results, fps, args.mode, args.tolerance_mm), **lab_summary}
    if args.out:
        write_zmp_csv(body, results, args.out, columns)
    if args.summary_json:
        write_json(summary, args.summary_json)
    if args.plot:
        cop, complete = plates or (None, None)
        plot_analysis(body, results, args.plot, title=f"{Path(source).name} ({args.mode} ZMP)", cop=cop,
                      complete=complete)
    inside = summary["inside_fraction"]
    print(f"{source}: {summary['frames']} frames at {summary['fps']:.1f} Hz, "
          f"{summary['support_frames']} with support, {summary['flight_frames']} flight, "
          f"{summary['out_of_support_frames']} out of support, inside "
          f"{'n/a' if inside is None else f'{100 * inside:.1f} %'}, "
          f"max excursion {1000 * summary['max_excursion_m']:.1f} mm")
    if inside is not None:
        print(f"  within {summary['tolerance_mm']:g} mm of support (the ZMP's validated error): "
              f"{100 * summary['inside_fraction_tol']:.1f} %; motion: {summary['plausibility']['verdict']}")
    cv = summary.get("cop_vs_zmp")
    if cv and cv["frames"]:
        print(f"  ZMP vs plate CoP over {cv['frames']} complete frames: RMS {cv['rms_mm']:.1f} mm, "
              f"p95 {cv['p95_mm']:.1f} mm, bias fore-aft {cv['bias_mm'][0]:+.1f} / lateral {cv['bias_mm'][1]:+.1f} mm, "
              f"lag {cv['lag_ms']:+.1f} ms")
    if "markers" in lab_summary:
        print(f"  {lab_summary['markers']['hat']}")
        if "note" in lab_summary["mass"]:
            print(f"  mass: {lab_summary['mass']['note']}")
    return 0
