"""`livezmp analyze`: run the pipeline over a motion file and write the results.

The take goes through :func:`livezmp.offline.batch.run_batch`: in chunks over arrays when it is
uniformly sampled and complete (an hour at 120 Hz in seconds), frame by frame otherwise;
the results are the same. A BVH or a robot's joint CSV is read a chunk at a time too
(:func:`livezmp.offline.take.stream_take`), so memory stays bounded whatever its length. A C3D gait
trial goes through :mod:`livezmp.offline.gaitlab`: its markers make the body, and its force plates,
when present, are compared with the ZMP.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.progress import Progress

from livezmp.checks import check_figure_path, check_output_paths, given_inputs
from livezmp.commands.common import load_from_args, take_options
from livezmp.jsonfile import write_json
from livezmp.offline.report import write_zmp_csv
from livezmp.offline.take import (
    TakeAnalysis,
    TakeOptions,
    analyse_c3d,
    analyse_motion,
    check_not_c3d_options,
    stream_take,
)

PROGRESS_FRAMES = 20_000  # takes this long or longer get a progress bar (a few seconds on the per-frame path)


def _analyse(args: argparse.Namespace) -> TakeAnalysis:
    """The analysis of the command line's motion (or of the built-in demo)."""
    options = take_options(args)
    if args.motion is not None and Path(args.motion).suffix.lower() == ".c3d":
        return analyse_c3d(args.motion, options)
    check_not_c3d_options(options, args.motion)
    loaded = load_from_args(args)
    if len(loaded.frames) < PROGRESS_FRAMES:
        return analyse_motion(loaded, options)
    with Progress(transient=True) as bar:  # a long take: show how far the analysis is
        task = bar.add_task("analysing", total=len(loaded.frames))
        return analyse_motion(loaded, options, progress=lambda done: bar.update(task, completed=done))


def _stream(args: argparse.Namespace, options: TakeOptions) -> dict:
    """A BVH or a robot's joint CSV analysed in bounded memory, its zmp.csv and figure written as it
    goes (the summary)."""
    take = options.open(args.motion)
    if take.total < PROGRESS_FRAMES:
        return stream_take(take, options, args.out, args.plot)
    with Progress(transient=True) as bar:  # a long take: show how far the analysis is
        task = bar.add_task("analysing", total=take.total)
        return stream_take(take, options, args.out, args.plot, progress=lambda done: bar.update(task, completed=done))


def _give_or_take(cv: dict) -> str:
    """' ± U' (ms, the half-width of the lag's 95 % interval), or nothing where it has none."""
    return "" if cv.get("lag_uncertainty_ms") is None else f" ± {cv['lag_uncertainty_ms']:.0f}"


def cmd_analyze(args: argparse.Namespace) -> int:
    check_output_paths((args.out, "--out"), (args.summary_json, "--summary-json"), (args.plot, "--plot"),
                       inputs=given_inputs(args))
    check_figure_path(args.plot, "--plot")
    options = take_options(args)
    if options.streams(args.motion):
        summary = _stream(args, options)
    else:
        a = _analyse(args)
        summary = a.summary
        if args.out:
            write_zmp_csv(a.body, a.result, args.out, a.columns)
        if args.plot:
            from livezmp.offline.plot import plot_analysis  # matplotlib: only when a figure is asked for

            plot_analysis(a.body, a.result, args.plot, title=f"{Path(a.source).name} ({args.mode} ZMP)", cop=a.cop,
                          complete=a.complete)
    source = summary["source"]
    if args.summary_json:
        write_json(summary, args.summary_json)
    inside = summary["inside_fraction"]
    print(f"{source}: {summary['frames']} frames at {summary['fps']:.1f} Hz, "
          f"{summary['support_frames']} with support, {summary['flight_frames']} flight, "
          f"{summary['out_of_support_frames']} out of support, inside "
          f"{'n/a' if inside is None else f'{100 * inside:.1f} %'}, "
          f"max excursion {1000 * summary['max_excursion_m']:.1f} mm")
    if summary.get("rest_pose_frames"):
        print(f"  the first {summary['rest_pose_frames']} frame(s) are the skeleton's rest pose (rotations zero), not "
              "motion: analysed at the first moving frame's pose")
    if summary.get("loop"):
        print(f"  a looped cycle (its last frame repeats its first): analysed as the loop played on, "
              f"{summary['loop']['padded_frames']} frames of it before and after")
    verdict = (summary.get("plausibility") or {}).get("verdict")
    if inside is not None:
        print(f"  within {summary['tolerance_mm']:g} mm of support (the ZMP's validated error): "
              f"{100 * summary['inside_fraction_tol']:.1f} %; motion: {verdict}")
    elif verdict:  # every frame in flight: no support to be inside, but the verdict says why (a floor not found)
        print(f"  motion: {verdict}")
    cv = summary.get("cop_vs_zmp")
    if cv and cv["frames"]:
        print(f"  ZMP vs plate CoP over {cv['frames']} complete frames: RMS {cv['rms_mm']:.1f} mm, "
              f"p95 {cv['p95_mm']:.1f} mm, bias fore-aft {cv['bias_mm'][0]:+.1f} / lateral {cv['bias_mm'][1]:+.1f} mm, "
              + (f"lag {cv['lag_ms']:+.1f}{_give_or_take(cv)} ms" if cv["lag_ms"] is not None
                 else "lag not determined (its halves give "
                 + " / ".join("-" if h is None else f"{h:+.0f}" for h in cv["lag_halves_ms"]) + " ms; all frames "
                 + ("-" if cv["lag_estimate_ms"] is None else f"{cv['lag_estimate_ms']:+.0f}")
                 + f"{_give_or_take(cv)})"))
    if tm := summary.get("treadmill"):
        print(f"  treadmill: belts at {' / '.join(f'{v:.2f}' for v in tm['belt_mps'])} m/s (left / right, "
              f"{tm['source']}), the body travelling {tm['body_mps']:.2f} m/s over the take: contacts, support and "
              "plausibility judged on the belts")
    if "markers" in summary:
        print(f"  {summary['markers']['hat']}")
        if "note" in summary["mass"]:
            print(f"  mass: {summary['mass']['note']}")
        if "floor" in summary["markers"]:
            print(f"  floor: {summary['markers']['floor']['why']}")
        if static := summary["markers"].get("from_static_trial"):
            print(f"  from the static trial {Path(static['file']).name}, carried by their clusters: "
                  + ", ".join(static["landmarks"]))
        if "no_complete_frame" in (summary.get("plates") or {}):
            print(f"  no ZMP vs plate CoP: {summary['plates']['no_complete_frame']}")
        for w in (summary.get("cop_under_foot") or {}).get("warnings", []):
            print(f"  {w}")
        for p in (summary.get("plates") or {}).get("set_aside", []):
            print(f"  plate {p['plate']} set aside: {p['reason']}")
    return 0
