"""`livezmp batch`: a motion library analysed take by take on a Dask cluster (local or remote)."""

from __future__ import annotations

import argparse

from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from livezmp.commands.common import take_options
from livezmp.offline.library import TABLE_CSV, TABLE_PARQUET, dask_client, find_takes, run_library


def cmd_analyze(args: argparse.Namespace) -> int:
    options = take_options(args)
    takes = find_takes(args.sources, args.out, options)
    with dask_client(args.scheduler, args.workers, args.dashboard_address) as client:
        workers = len(client.scheduler_info().get("workers", {}))
        print(f"{len(takes)} takes, {workers} workers at {client.scheduler.address}, "
              f"dashboard {client.dashboard_link or 'off (install bokeh)'}", flush=True)
        with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), transient=True) as bar:
            task = bar.add_task("analysing", total=len(takes))

            def show(p) -> None:
                bar.update(task, completed=p.done, description=(
                    f"done {p.done} failed {p.failed} remaining {p.remaining} · {p.rate:.1f} takes/s"))

            progress = run_library(client, takes, args.out, options, on_row=show)
    print(f"{progress.done} takes ({progress.skipped} up to date, {progress.failed} failed), "
          f"{progress.frames} frames; {progress.rate:.2f} takes/s analysed; "
          f"table {args.out}/{TABLE_PARQUET} and {TABLE_CSV}")
    return 0
