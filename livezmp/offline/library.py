"""A motion library processed take by take on Dask (``livezmp batch analyze | correct | gait``).

Each take is one task (:func:`run_take`, the same function a plain loop would call): it runs
the job (:mod:`livezmp.offline.jobs`) on the take into its own directory under ``OUT/takes/``,
writes the take's ``summary.json`` last, and returns one small row. A bad take becomes a row
with its error. The client keeps only a bounded window of tasks in flight and streams the
rows, as they complete, to the table (Parquet and CSV, written under temporary names and
renamed at the end). A take whose ``summary.json`` is newer than its input and was made by
the same job with the same options, beside its complete outputs, is up to date: a rerun
reads its row from there instead of running it again, so a killed run resumes where it stopped.
"""

from __future__ import annotations

import contextlib
import csv
import glob
import itertools
import json
import logging
import os
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path

from livezmp.checks import check_output_dir
from livezmp.errors import InputError
from livezmp.jsonfile import write_json
from livezmp.offline.jobs import Job

SUMMARY_JSON = "summary.json"
TABLE_PARQUET = "takes.parquet"
TABLE_CSV = "takes.csv"
ROWS_PER_BATCH = 256  # rows buffered before a Parquet record batch is written
# Dask's monitoring, sized for tasks of seconds rather than milliseconds: its defaults (a 20 ms
# event-loop tick check, a 10 ms stack-sampling profiler and a 1 ms GIL monitor in every worker)
# cost an idle 1-worker cluster ~3 % of a core in the worker and ~3 % in the scheduler
# (measured: 28 and 31 ms/s), ~0.6 % and ~1 % with these (benchmarks/bench_batch_library.py).
LOCAL_CLUSTER_CONFIG = {"distributed.admin.tick.interval": "1s", "distributed.worker.profile.enabled": False,
                        "distributed.admin.system-monitor.gil.enabled": False,
                        "distributed.admin.system-monitor.interval": "2s"}


@dataclass(frozen=True)
class Take:
    """A motion file and the directory of its outputs (under ``OUT/takes/``, mirroring the library)."""

    path: Path
    out_dir: Path


def find_takes(sources: Iterable[str], out: str | Path, job: Job) -> list[Take]:
    """The takes named by ``sources`` (files, directories searched recursively, glob patterns) that
    ``job`` takes (its suffixes, e.g. ``.bvh`` and ``.c3d``, ``.csv`` with a robot); sorted, without
    repeats, anything under ``out`` left out. ``out`` is checked first (:func:`check_output_dir`)."""
    check_output_dir(out, "--out")
    suffixes = job.suffixes()
    out = Path(out).resolve()
    found: set[Path] = set()
    for source in sources:
        matches = [Path(m) for m in sorted(glob.glob(source, recursive=True))] or [Path(source)]
        for m in matches:
            if m.is_dir():
                found.update(p for p in m.rglob("*") if p.suffix.lower() in suffixes and p.is_file())
            elif m.is_file():
                found.add(m)
            else:
                raise InputError(f"{source}: no such file, directory or matching pattern")
    paths = sorted(p.absolute() for p in found if not p.resolve().is_relative_to(out))
    if not paths:
        raise InputError(f"no takes ({', '.join(sorted(suffixes))}) in {' '.join(sources)}")
    root = Path(os.path.commonpath([p.parent for p in paths]))
    return [Take(p, out / "takes" / p.relative_to(root)) for p in paths]


def table_row(job: Job, path: Path, summary: dict) -> dict:
    """The library table's row of a take from its summary (or its error)."""
    row = {name: None for name, _ in job.table_columns()}
    row.update(file=str(path), format=path.suffix.lower().lstrip("."), error=summary.get("error"))
    if row["error"] is None:
        row.update(frames=summary["frames"], fps=summary["fps"], duration_s=summary["duration_s"],
                   **job.fields(summary))
    return row


def one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()) or "(no message)"
    return text if isinstance(error, InputError) else f"{type(error).__name__}: {text}"


def run_take(take: Take, job: Job) -> dict:
    """Run ``job`` on one take into ``take.out_dir``, then write its ``summary.json`` (with the job's
    fingerprint); return its table row. Never raises for a bad take: the row (and ``summary.json``)
    then carry the error in one line. Nor for a take whose directory or summary cannot be written (an
    immutable or read-only directory): its row says so and a rerun tries it again (the task's failure
    had filled the run's console with the worker's traceback)."""
    try:
        take.out_dir.mkdir(parents=True, exist_ok=True)
        try:
            summary = job.run(take.path, take.out_dir)
        except Exception as e:  # any failure of one take is that take's row, not the run's end
            summary = {"source": str(take.path), "error": one_line(e)}
            for name in job.outputs(take.path):
                (take.out_dir / name).unlink(missing_ok=True)
        summary["options"] = job.fingerprint()
        write_json(summary, take.out_dir / SUMMARY_JSON)
    except (OSError, InputError) as e:
        summary = {"error": f"{take.out_dir}: {e.strerror or e}" if isinstance(e, OSError) else one_line(e)}
    return table_row(job, take.path, summary)


def stored_row(take: Take, job: Job) -> dict | None:
    """The row of a take whose outputs are complete and up to date (a ``summary.json`` newer than
    the input, made by the same job and options, beside the job's outputs unless it records an
    error), else None."""
    summary_path = take.out_dir / SUMMARY_JSON
    try:
        if summary_path.stat().st_mtime_ns < take.path.stat().st_mtime_ns:
            return None
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if summary.get("options") != job.fingerprint():
        return None
    if summary.get("error") is None and not all((take.out_dir / n).is_file() for n in job.outputs(take.path)):
        return None
    return table_row(job, take.path, summary)


class TableWriter:
    """Rows streamed to ``takes.parquet`` and ``takes.csv`` under temporary names, renamed on close."""

    def __init__(self, out: Path, columns: tuple[tuple[str, str], ...]):
        """``columns``: (name, Arrow type name such as "float64") in table order."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        self._pa = pa
        self.schema = pa.schema([(name, pa.type_for_alias(kind)) for name, kind in columns])
        self._final = [out / TABLE_PARQUET, out / TABLE_CSV]
        self._tmp = [p.with_name(f".{p.name}.part") for p in self._final]
        self._parquet = pq.ParquetWriter(self._tmp[0], self.schema)
        self._csv_file = open(self._tmp[1], "w", newline="", encoding="utf-8")
        self._csv = csv.DictWriter(self._csv_file, [name for name, _ in columns])
        self._csv.writeheader()
        self._rows: list[dict] = []

    def write(self, row: dict) -> None:
        self._csv.writerow(row)
        self._rows.append(row)
        if len(self._rows) >= ROWS_PER_BATCH:
            self._flush()

    def _flush(self) -> None:
        if self._rows:
            self._parquet.write_batch(self._pa.RecordBatch.from_pylist(self._rows, schema=self.schema))
            self._rows = []

    def close(self, complete: bool = True) -> None:
        """Finish both files; with ``complete`` False (the run failed) they are discarded."""
        self._flush()
        self._parquet.close()
        self._csv_file.close()
        for tmp, final in zip(self._tmp, self._final, strict=True):
            if complete:
                os.replace(tmp, final)
            else:
                tmp.unlink(missing_ok=True)


@dataclass
class Progress:
    """Counts of a library run; ``rate`` in takes/s over the takes analysed in this run."""

    total: int
    done: int = 0
    failed: int = 0
    skipped: int = 0
    frames: int = 0
    started: float = 0.0

    @property
    def remaining(self) -> int:
        return self.total - self.done

    @property
    def rate(self) -> float:
        elapsed = time.perf_counter() - self.started
        return (self.done - self.skipped) / elapsed if elapsed > 0 else 0.0

    def count(self, row: dict) -> None:
        self.done += 1
        self.failed += row["error"] is not None
        self.frames += row["frames"] or 0


def max_local_workers() -> int:
    """The most worker processes a local cluster starts: 4 a CPU (a take's analysis keeps one CPU busy; beyond
    that, workers only add memory, ~0.2 GB each), and never fewer than the default 2."""
    return max(2, 4 * (os.cpu_count() or 1))


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int = 2, dashboard_address: str = "127.0.0.1:0",
                config: dict | None = None):
    """A Dask client of the running ``scheduler`` (``tcp://HOST:PORT``), or else of a local cluster of
    ``workers`` processes with one thread each, bound to loopback, with the Dask ``config`` (default
    :data:`LOCAL_CLUSTER_CONFIG`); closed (with its cluster) on exit."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, ValueError) as e:  # ValueError: not an address ("missing port number")
            raise InputError(f"--scheduler {scheduler}: cannot connect ({one_line(e)})") from None
        with client:
            yield client
        return
    most = max_local_workers()
    if not 1 <= workers <= most:
        raise InputError(f"--workers must be 1 to {most} (4 a CPU: each is a process holding a take), got {workers}")
    with dask.config.set(LOCAL_CLUSTER_CONFIG if config is None else config), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                         dashboard_address=dashboard_address, silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        yield client


def _rows(client, todo: list[Take], job: Job, window: int) -> Iterator[dict]:
    """Rows of ``todo`` analysed on the Dask ``client``, as they complete, with at most
    ``window`` tasks submitted at a time (so neither the scheduler nor the client holds the library)."""
    from distributed import as_completed

    queue = iter(todo)
    running = as_completed()
    submitted = {}

    def submit(take: Take) -> None:
        fut = client.submit(run_take, take, job, pure=False, key=f"{job.name}-{take.path}")
        submitted[fut.key] = take
        running.add(fut)

    for take in itertools.islice(queue, window):
        submit(take)
    for fut in running:
        take = submitted.pop(fut.key)
        try:
            row = fut.result()
        except Exception as e:  # the worker died or the task could not run: the take's row says so
            row = table_row(job, take.path, {"error": f"task failed: {one_line(e)}"})
        fut.release()
        yield row
        nxt = next(queue, None)
        if nxt is not None:
            submit(nxt)


def run_library(client, takes: list[Take], out: str | Path, job: Job, window: int | None = None,
                on_row: Callable[[Progress], None] | None = None) -> Progress:
    """Run ``job`` on ``takes`` on the Dask ``client`` (or in this process when ``client`` is None),
    skipping the up-to-date ones; write the table under ``out``; call ``on_row(progress)`` after every row."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    progress = Progress(total=len(takes), started=time.perf_counter())
    writer = TableWriter(out, job.table_columns())
    try:
        todo = []
        for take in takes:
            row = stored_row(take, job)
            if row is None:
                todo.append(take)
                continue
            progress.skipped += 1
            progress.count(row)
            writer.write(row)
            if on_row:
                on_row(progress)
        if client is None:
            rows = (run_take(t, job) for t in todo)
        else:
            workers = max(1, len(client.scheduler_info().get("workers", {})))
            rows = _rows(client, todo, job, window or 4 * workers)
        for row in rows:
            progress.count(row)
            writer.write(row)
            if on_row:
                on_row(progress)
    except BaseException:
        writer.close(complete=False)
        raise
    writer.close()
    return progress
