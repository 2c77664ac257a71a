"""A motion library analysed take by take on Dask (``livezmp batch analyze``).

Each take is one task (:func:`run_take`, the same function a plain loop would call): it
analyses the take with :func:`livezmp.offline.take.analyse_take` into its own directory
under ``OUT/takes/`` and returns one small row. A bad take becomes a row with its error.
The client keeps only a bounded window of tasks in flight and streams the rows, as they
complete, to the table (Parquet and CSV, written under temporary names and renamed at the
end). A take whose ``summary.json`` is newer than its input and was made with the same
options is up to date: a rerun reads its row from there instead of analysing it again,
so a killed run resumes where it stopped.
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

from livezmp.errors import InputError
from livezmp.offline.report import write_json
from livezmp.offline.take import SUMMARY_JSON, ZMP_CSV, TakeOptions, analyse_take

TABLE_COLUMNS = ("file", "format", "frames", "fps", "duration_s", "inside_fraction", "max_excursion_mm", "error")
TABLE_PARQUET = "takes.parquet"
TABLE_CSV = "takes.csv"
ROWS_PER_BATCH = 256  # rows buffered before a Parquet record batch is written


@dataclass(frozen=True)
class Take:
    """A motion file and the directory of its outputs (under ``OUT/takes/``, mirroring the library)."""

    path: Path
    out_dir: Path


def find_takes(sources: Iterable[str], out: str | Path, options: TakeOptions) -> list[Take]:
    """The takes named by ``sources`` (files, directories searched recursively, glob patterns):
    ``.bvh`` files, and ``.csv`` joint trajectories when ``options.robot`` is given; sorted, without
    repeats, anything under ``out`` left out."""
    suffixes = {".bvh"} | ({".csv"} if options.robot else set())
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


def table_row(path: Path, summary: dict) -> dict:
    """The library table's row of a take from its summary (or its error)."""
    error = summary.get("error")
    if error is not None:
        return {"file": str(path), "format": path.suffix.lower().lstrip("."), "frames": None, "fps": None,
                "duration_s": None, "inside_fraction": None, "max_excursion_mm": None, "error": error}
    return {"file": str(path), "format": path.suffix.lower().lstrip("."), "frames": summary["frames"],
            "fps": summary["fps"], "duration_s": summary["duration_s"],
            "inside_fraction": summary["inside_fraction"],
            "max_excursion_mm": round(1000 * summary["max_excursion_m"], 3), "error": None}


def one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()) or "(no message)"
    return text if isinstance(error, InputError) else f"{type(error).__name__}: {text}"


def run_take(take: Take, options: TakeOptions) -> dict:
    """Analyse one take into ``take.out_dir``; return its table row. Never raises for a bad take:
    the row (and ``summary.json``) then carry the error in one line."""
    try:
        summary = analyse_take(take.path, take.out_dir, options)
    except Exception as e:  # any failure of one take is that take's row, not the run's end
        summary = {"source": str(take.path), "error": one_line(e), "options": options.fingerprint()}
        take.out_dir.mkdir(parents=True, exist_ok=True)
        (take.out_dir / ZMP_CSV).unlink(missing_ok=True)
        write_json(summary, take.out_dir / SUMMARY_JSON)
    return table_row(take.path, summary)


def stored_row(take: Take, fingerprint: str) -> dict | None:
    """The row of a take whose outputs are complete and up to date (a ``summary.json`` newer than
    the input, made with the same options, beside its ``zmp.csv`` unless it records an error), else None."""
    summary_path = take.out_dir / SUMMARY_JSON
    try:
        if summary_path.stat().st_mtime_ns < take.path.stat().st_mtime_ns:
            return None
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if summary.get("options") != fingerprint:
        return None
    if summary.get("error") is None and not (take.out_dir / ZMP_CSV).is_file():
        return None
    return table_row(take.path, summary)


class TableWriter:
    """Rows streamed to ``takes.parquet`` and ``takes.csv`` under temporary names, renamed on close."""

    def __init__(self, out: Path):
        import pyarrow as pa
        import pyarrow.parquet as pq

        self._pa = pa
        self.schema = pa.schema([("file", pa.string()), ("format", pa.string()), ("frames", pa.int64()),
                                 ("fps", pa.float64()), ("duration_s", pa.float64()),
                                 ("inside_fraction", pa.float64()), ("max_excursion_mm", pa.float64()),
                                 ("error", pa.string())])
        self._final = [out / TABLE_PARQUET, out / TABLE_CSV]
        self._tmp = [p.with_name(f".{p.name}.part") for p in self._final]
        self._parquet = pq.ParquetWriter(self._tmp[0], self.schema)
        self._csv_file = open(self._tmp[1], "w", newline="", encoding="utf-8")
        self._csv = csv.DictWriter(self._csv_file, TABLE_COLUMNS)
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


@contextlib.contextmanager
def dask_client(scheduler: str | None = None, workers: int = 2, dashboard_address: str = "127.0.0.1:0"):
    """A Dask client of the running ``scheduler`` (``tcp://HOST:PORT``), or else of a local cluster of
    ``workers`` processes with one thread each, bound to loopback; closed (with its cluster) on exit."""
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="10s")
        except OSError as e:
            raise InputError(f"--scheduler {scheduler}: cannot connect ({one_line(e)})") from None
        with client:
            yield client
        return
    if workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=dashboard_address, silence_logs=logging.ERROR) as cluster, \
            Client(cluster) as client:
        yield client


def _rows(client, todo: list[Take], options: TakeOptions, window: int) -> Iterator[dict]:
    """Rows of ``todo`` analysed on the Dask ``client``, as they complete, with at most
    ``window`` tasks submitted at a time (so neither the scheduler nor the client holds the library)."""
    from distributed import as_completed

    queue = iter(todo)
    running = as_completed()
    submitted = {}

    def submit(take: Take) -> None:
        fut = client.submit(run_take, take, options, pure=False, key=f"take-{take.path}")
        submitted[fut.key] = take
        running.add(fut)

    for take in itertools.islice(queue, window):
        submit(take)
    for fut in running:
        take = submitted.pop(fut.key)
        try:
            row = fut.result()
        except Exception as e:  # the worker died or the task could not run: the take's row says so
            row = table_row(take.path, {"error": f"task failed: {one_line(e)}"})
        fut.release()
        yield row
        nxt = next(queue, None)
        if nxt is not None:
            submit(nxt)


def run_library(client, takes: list[Take], out: str | Path, options: TakeOptions, window: int | None = None,
                on_row: Callable[[Progress], None] | None = None) -> Progress:
    """Analyse ``takes`` on the Dask ``client`` (or in this process when ``client`` is None), skipping
    the up-to-date ones; write the table under ``out``; call ``on_row(progress)`` after every row."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fingerprint = options.fingerprint()
    progress = Progress(total=len(takes), started=time.perf_counter())
    writer = TableWriter(out)
    try:
        todo = []
        for take in takes:
            row = stored_row(take, fingerprint)
            if row is None:
                todo.append(take)
                continue
            progress.skipped += 1
            progress.count(row)
            writer.write(row)
            if on_row:
                on_row(progress)
        if client is None:
            rows = (run_take(t, options) for t in todo)
        else:
            workers = max(1, len(client.scheduler_info().get("workers", {})))
            rows = _rows(client, todo, options, window or 4 * workers)
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
