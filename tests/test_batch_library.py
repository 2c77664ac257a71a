"""`livezmp batch analyze` over a small library of real walks (shortened Bandai takes), with a
corrupt and an empty take: on a local Dask cluster of two worker processes, on a real
`dask scheduler` + `dask worker` started as separate processes on loopback, killed halfway
and resumed, and in one process (the same per-take function, no Dask)."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from livezmp.cli import main
from livezmp.model.bvh import read_bvh, write_bvh
from livezmp.offline.jobs import AnalyzeJob
from livezmp.offline.library import find_takes, run_library
from livezmp.offline.take import TakeOptions
from tests.data_paths import BANDAI
from tests.sim_support import wait_until

LENGTHS = {"normal_001": 120, "active_001": 100, "elderly_001": 150, "exhausted_001": 110}


def make_library(root: Path, copies: int = 1) -> dict[str, int]:
    """Shortened walks (under two folders), a truncated take and an empty one; {file name: frames}."""
    frames = {}
    for k in range(copies):
        for name, n in LENGTHS.items():
            motion = read_bvh(BANDAI / f"walk_{name}.bvh")
            sub = root / ("fast" if "active" in name else "base")
            sub.mkdir(parents=True, exist_ok=True)
            path = sub / f"walk_{name}_{k}.bvh"
            write_bvh(replace(motion, frames=motion.frames[k:k + n]), path)
            frames[str(path)] = n
    text = (BANDAI / "walk_normal_002.bvh").read_text()
    (root / "corrupt.bvh").write_text(text[: len(text) // 2])  # cut mid-frame: the header's frame count is wrong
    (root / "empty.bvh").write_text("")
    return frames


def read_table(out: Path) -> list[dict]:
    rows = pq.read_table(out / "takes.parquet").to_pylist()
    with open(out / "takes.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == len(rows)
    return sorted(rows, key=lambda r: r["file"])


def check_table(rows: list[dict], frames: dict[str, int], out: Path) -> None:
    by_file = {r["file"]: r for r in rows}
    assert len(rows) == len(frames) + 2
    assert "truncated" in by_file[next(f for f in by_file if f.endswith("corrupt.bvh"))]["error"]
    assert "empty" in by_file[next(f for f in by_file if f.endswith("empty.bvh"))]["error"]
    for path, n in frames.items():
        row = by_file[path]
        assert row["error"] is None and row["format"] == "bvh"
        assert row["frames"] == n and row["fps"] == pytest.approx(30.0, rel=1e-5)
        assert row["duration_s"] == pytest.approx((n - 1) / 30.0, rel=1e-5)
        assert 0.0 <= row["inside_fraction"] <= 1.0
        zmp_csv = next(out.glob(f"takes/**/{Path(path).name}/zmp.csv"))
        assert len(zmp_csv.read_text().splitlines()) == n + 1  # header + one row per frame: complete


@pytest.fixture(scope="module")
def library(tmp_path_factory) -> tuple[Path, dict[str, int]]:
    root = tmp_path_factory.mktemp("library")
    return root, make_library(root)


@pytest.fixture(scope="module")
def reference(library, tmp_path_factory) -> list[dict]:
    """The library analysed in this process, take after take, without Dask."""
    root, frames = library
    out = tmp_path_factory.mktemp("reference")
    progress = run_library(None, find_takes([str(root)], out, AnalyzeJob()), out, AnalyzeJob())
    assert (progress.done, progress.failed, progress.skipped) == (len(frames) + 2, 2, 0)
    rows = read_table(out)
    check_table(rows, frames, out)
    return rows


def test_rows_are_those_of_single_take_analyze(library, reference, tmp_path):
    """Each good row carries the summary that `livezmp analyze --summary-json` writes for the take."""
    root, frames = library
    for row in reference:
        if row["error"] is None:
            assert main(["analyze", row["file"], "--summary-json", str(tmp_path / "s.json")]) == 0
            single = json.loads((tmp_path / "s.json").read_text())
            assert (row["frames"], row["inside_fraction"]) == (single["frames"], single["inside_fraction"])
            assert row["max_excursion_mm"] == pytest.approx(1000 * single["max_excursion_m"], abs=1e-3)


def test_local_cluster_of_two_worker_processes(library, reference, tmp_path, capsys):
    root, frames = library
    assert main(["batch", "analyze", str(root), "--out", str(tmp_path), "--workers", "2"]) == 0
    printed = capsys.readouterr().out
    assert "2 workers at tcp://127.0.0.1:" in printed and "dashboard http://127.0.0.1:" in printed
    assert f"{len(frames) + 2} takes (0 up to date, 2 failed)" in printed
    assert read_table(tmp_path) == reference
    # a rerun finds every take up to date and writes the same table
    assert main(["batch", "analyze", str(root), "--out", str(tmp_path), "--workers", "1"]) == 0
    assert f"({len(frames) + 2} up to date, 2 failed)" in capsys.readouterr().out
    assert read_table(tmp_path) == reference


def test_outputs_out_of_date_when_input_or_options_change(tmp_path):
    make_library(tmp_path / "lib")
    out = tmp_path / "out"
    takes = find_takes([str(tmp_path / "lib")], out, AnalyzeJob())
    run_library(None, takes, out, AnalyzeJob())
    assert run_library(None, takes, out, AnalyzeJob()).skipped == len(takes)
    assert run_library(None, takes, out, AnalyzeJob(TakeOptions(mass=80.0))).skipped == 0  # other options
    newer = (takes[0].out_dir / "summary.json").stat().st_mtime_ns + 10**9
    os.utime(takes[0].path, ns=(newer, newer))  # the input changed after its outputs
    assert run_library(None, takes, out, AnalyzeJob(TakeOptions(mass=80.0))).skipped == len(takes) - 1


def test_real_scheduler_and_worker_processes(library, reference, tmp_path, capsys):
    from distributed import Client

    root, frames = library
    sched_file = tmp_path / "scheduler.json"
    dask = Path(sys.executable).with_name("dask")
    procs = [subprocess.Popen([dask, "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", sched_file], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        assert wait_until(sched_file.exists, timeout=30)
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        procs.append(subprocess.Popen([dask, "worker", address, "--nthreads", "1", "--host", "127.0.0.1",
                                       "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        with Client(address, timeout="20s") as client:
            client.wait_for_workers(1, timeout=30)
        assert main(["batch", "analyze", str(root), "--out", str(tmp_path / "out"), "--scheduler", address]) == 0
        assert f"1 workers at {address}" in capsys.readouterr().out
        assert read_table(tmp_path / "out") == reference
    finally:
        for p in reversed(procs):
            p.terminate()
            p.wait(timeout=20)


def test_killed_run_resumes_to_the_uninterrupted_table(tmp_path):
    root = tmp_path / "lib"
    frames = make_library(root, copies=2)
    total = len(frames) + 2
    ref_out, out = tmp_path / "ref", tmp_path / "out"
    run_library(None, find_takes([str(root)], ref_out, AnalyzeJob()), ref_out, AnalyzeJob())
    cmd = [Path(sys.executable).with_name("livezmp"), "batch", "analyze", str(root), "--out", str(out),
           "--workers", "1"]
    run = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        assert wait_until(lambda: len(list(out.glob("takes/**/summary.json"))) >= 3, timeout=40)
    finally:
        os.killpg(run.pid, signal.SIGKILL)  # the client, its cluster and its worker, mid-run
        run.wait()
    done = len(list(out.glob("takes/**/summary.json")))
    assert 3 <= done < total and not (out / "takes.parquet").exists()
    for zmp_csv in out.glob("takes/**/zmp.csv"):  # whatever was written is whole
        rows = zmp_csv.read_text().splitlines()
        assert len(rows) - 1 == frames[str(root / zmp_csv.parent.relative_to(out / "takes"))]
    resumed = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert resumed.returncode == 0, resumed.stderr
    skipped = int(resumed.stdout.split(" up to date")[0].rsplit("(", 1)[1])
    assert skipped == done  # summary.json comes last: a take with one is complete
    assert read_table(out) == read_table(ref_out)
    check_table(read_table(out), frames, out)
