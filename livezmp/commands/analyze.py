"""`livezmp analyze`: run the pipeline over a motion file and write the results.

The take goes through :func:`livezmp.offline.batch.run_batch`: in chunks over arrays when it is
uniformly sampled and complete (an hour at 120 Hz in seconds), frame by frame otherwise;
the results are the same.
"""

from __future__ import annotations

import argparse

from rich.progress import Progress

from livezmp.balance.pipeline import Pipeline
from livezmp.commands.common import load_from_args, pipeline_config
from livezmp.errors import InputError
from livezmp.offline.batch import run_batch
from livezmp.offline.plot import plot_analysis
from livezmp.offline.report import summarize, write_json, write_zmp_csv

PROGRESS_FRAMES = 20_000  # takes this long or longer get a progress bar (a few seconds on the per-frame path)


def cmd_analyze(args: argparse.Namespace) -> int:
    loaded = load_from_args(args)
    if len(loaded.frames) < 2:
        raise InputError(f"{loaded.source}: need at least 2 frames, got {len(loaded.frames)}")
    cfg = pipeline_config(args, loaded)
    pipe = Pipeline(loaded.body, cfg, nominal_dt=1.0 / loaded.fps)
    if len(loaded.frames) < PROGRESS_FRAMES:
        results = run_batch(pipe, loaded.times, loaded.frames)
    else:  # a long take: show how far the analysis is
        with Progress(transient=True) as bar:
            task = bar.add_task("analysing", total=len(loaded.frames))
            results = run_batch(pipe, loaded.times, loaded.frames,
                                     progress=lambda done: bar.update(task, completed=done))
    summary = {"source": loaded.source, **summarize(loaded.body, results, loaded.fps, cfg.mode)}
    if args.out:
        write_zmp_csv(loaded.body, results, args.out)
    if args.summary_json:
        write_json(summary, args.summary_json)
    if args.plot:
        plot_analysis(loaded.body, results, args.plot, title=f"{loaded.source} ({cfg.mode} ZMP)")
    inside = summary["inside_fraction"]
    print(f"{loaded.source}: {summary['frames']} frames at {summary['fps']:.1f} Hz, "
          f"{summary['support_frames']} with support, {summary['flight_frames']} flight, "
          f"{summary['out_of_support_frames']} out of support, inside "
          f"{'n/a' if inside is None else f'{100 * inside:.1f} %'}, "
          f"max excursion {1000 * summary['max_excursion_m']:.1f} mm")
    return 0
