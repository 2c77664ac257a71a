"""`livezmp batch`: a motion library analysed take by take on a Dask cluster (local or remote)."""

from __future__ import annotations

import argparse
import contextlib
import logging

from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from livezmp.commands.common import take_options
from livezmp.errors import InputError
from livezmp.offline.library import TABLE_CSV, TABLE_PARQUET, find_takes, run_library


@contextlib.contextmanager
def dask_client(args: argparse.Namespace):
    """A client of ``--scheduler``, or of a local cluster of ``--workers`` processes with one thread
    each, bound to loopback."""
    from distributed import Client, LocalCluster

    if args.scheduler:
        try:
            client = Client(args.scheduler, timeout="10s")
        except OSError as e:
            raise InputError(f"--scheduler {args.scheduler}: cannot connect ({e})") from None
        with client:
            yield client
        return
    if args.workers < 1:
        raise InputError(f"--workers must be at least 1, got {args.workers}")
    with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=args.dashboard_address, silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        yield client


def cmd_analyze(args: argparse.Namespace) -> int:
    options = take_options(args)
    takes = find_takes(args.sources, args.out, options)
    with dask_client(args) as client:
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
