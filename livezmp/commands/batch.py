"""`livezmp batch analyze | correct | gait`: a motion library processed take by take on a Dask
cluster (local or remote); see :mod:`livezmp.offline.library`."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from livezmp.commands.common import check_population_options, limits_from_args, take_options
from livezmp.errors import InputError
from livezmp.gait.features import WalkFeatures
from livezmp.gait.population import analyze
from livezmp.gait.tables import write_outputs
from livezmp.gait.takeset import read_manifest, takes_from_paths
from livezmp.offline.jobs import FEATURES_JSON, AnalyzeJob, CorrectJob, GaitJob, Job
from livezmp.offline.library import TABLE_CSV, TABLE_PARQUET, Take, dask_client, find_takes, run_library


def _run(args: argparse.Namespace, job: Job, takes: list[Take], verb: str) -> None:
    """Run ``job`` over ``takes`` on the cluster the command line names, with a progress bar."""
    with dask_client(args.scheduler, args.workers, args.dashboard_address) as client:
        workers = len(client.scheduler_info().get("workers", {}))
        print(f"{len(takes)} takes, {workers} workers at {client.scheduler.address}, "
              f"dashboard {client.dashboard_link or 'off (install bokeh)'}", flush=True)
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), transient=True) as bar:
            task = bar.add_task(verb, total=len(takes))

            def show(p) -> None:
                bar.update(task, completed=p.done, description=(
                    f"done {p.done} failed {p.failed} remaining {p.remaining} · {p.rate:.1f} takes/s"))

            progress = run_library(client, takes, args.out, job, on_row=show)
    print(f"{progress.done} takes ({progress.skipped} up to date, {progress.failed} failed), "
          f"{progress.frames} frames; {progress.rate:.2f} takes/s {verb}; "
          f"table {args.out}/{TABLE_PARQUET} and {TABLE_CSV}")


def _sources(args: argparse.Namespace) -> list[str]:
    if not args.sources:
        raise InputError(f"batch {args.batch_command}: give the library's directories, files or glob patterns")
    return args.sources


def cmd_analyze(args: argparse.Namespace) -> int:
    job = AnalyzeJob(take_options(args), args.plot)
    _run(args, job, find_takes(_sources(args), args.out, job), "analysed")
    return 0


def cmd_correct(args: argparse.Namespace) -> int:
    job = CorrectJob(take_options(args), limits_from_args(args))
    _run(args, job, find_takes(_sources(args), args.out, job), "corrected")
    return 0


def cmd_gait(args: argparse.Namespace) -> int:
    """Each take's features on the cluster, then the population statistics here, from the takes'
    ``features.json`` files (a few numbers per channel and take)."""
    check_population_options(args)
    job = GaitJob(args.up, args.units, args.urdf, args.markers, args.static)
    if args.manifest:
        if args.sources:
            raise InputError("batch gait: give either --manifest or the library's sources, not both")
        specs = read_manifest(args.manifest)
        takes = find_takes([str(s.path) for s in specs], args.out, job)
        where = args.manifest
    else:
        takes = find_takes(_sources(args), args.out, job)
        specs = takes_from_paths([t.path for t in takes], args.pattern)
        where = ", ".join(args.sources)
    _run(args, job, takes, "measured")
    by_path = {t.path.resolve(): t for t in takes}
    items, failed = [], 0
    for spec in specs:
        out_dir = by_path[spec.path.resolve()].out_dir
        try:
            feats = WalkFeatures.from_json(json.loads((out_dir / FEATURES_JSON).read_text(encoding="utf-8")))
        except FileNotFoundError:  # the take failed: its row in the table says why
            failed += 1
            continue
        items.append((spec, feats))
    a = analyze(items, args.base, dict(args.variant), args.threshold, args.min_base, args.min_change, where)
    print(f"population: {len(items)} takes ({failed} failed, left out)")
    for p in write_outputs(a, Path(args.out)):
        print(f"wrote {p}")
    return 0
