"""`livezmp batch correct` and `batch gait`, and C3D takes in `batch analyze`: each take's row and
outputs are what the single-take command gives for that file (the same per-take function), a bad
take is a row with its error, and a rerun finds every take up to date."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from livezmp.cli import main
from livezmp.gait.sinewalk import sine_bvh, walk_spec
from livezmp.model.bvh import read_bvh, write_bvh
from livezmp.offline.jobs import AnalyzeJob, CorrectJob
from livezmp.offline.library import find_takes, run_library
from tests.data_paths import BANDAI, C3D


def rows_of(out: Path) -> dict[str, dict]:
    return {Path(r["file"]).name: r for r in pq.read_table(out / "takes.parquet").to_pylist()}


def test_batch_correct_writes_what_correct_writes(tmp_path):
    lib = tmp_path / "lib"
    lib.mkdir()
    m = read_bvh(BANDAI / "walk_normal_001.bvh")
    write_bvh(replace(m, frames=m.frames[60:100]), lib / "walk_normal_001.bvh")
    (lib / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    out = tmp_path / "out"
    job = CorrectJob()
    progress = run_library(None, find_takes([str(lib)], out, job), out, job)
    assert (progress.done, progress.failed) == (2, 1)
    rows = rows_of(out)
    assert rows["broken.bvh"]["error"] and rows["broken.bvh"]["out_of_support_after"] is None
    single = tmp_path / "single.bvh"
    assert main(["correct", str(lib / "walk_normal_001.bvh"), "-o", str(single),
                 "--report", str(tmp_path / "r.json")]) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    row = rows["walk_normal_001.bvh"]
    corrected = next(out.glob("takes/walk_normal_001.bvh/corrected.bvh"))
    assert corrected.read_bytes() == single.read_bytes()
    assert row["output"] == str(corrected) and row["frames"] == 40
    for k in ("out_of_support_before", "out_of_support_after", "max_root_rotation_deg",
              "max_foot_displacement_mm"):
        assert row[k] == report[k]
    assert row["out_of_support_before"] > row["out_of_support_after"]  # the correction did something
    assert row["max_foot_displacement_mm"] <= 1.0
    # the batch analysis of the corrected file agrees with its row: fewer frames outside
    job_a = AnalyzeJob()
    run_library(None, find_takes([str(corrected)], tmp_path / "check", job_a), tmp_path / "check", job_a)
    after = next(iter(rows_of(tmp_path / "check").values()))
    assert after["inside_fraction"] > 1 - row["out_of_support_before"] / row["support_frames"]
    assert run_library(None, find_takes([str(lib)], out, job), out, job).skipped == 2


SUBJECTS = {"s1": ((0.90, 1.10, 20.0, 30.0), (1.00, 1.40, 24.0, 33.0)),
            "s2": ((0.95, 1.20, 22.0, 28.0), (1.02, 1.45, 25.0, 31.0)),
            "s3": ((0.85, 1.00, 18.0, 32.0), (0.97, 1.35, 23.0, 36.0))}


def test_batch_gait_population_equals_gait_analyze(tmp_path, capsys):
    """Features measured on a local cluster's worker, read back from each take's features.json:
    the population tables are those of `gait analyze` over the same walks."""
    lib = tmp_path / "lib"
    lib.mkdir()
    for s, (base, fast) in SUBJECTS.items():
        for cond, (f, v, hip, knee) in (("normal", base), ("fast", fast)):
            write_bvh(sine_bvh(walk_spec(hip_amp=hip, knee_dc=knee), f, v, 6.0), lib / f"walk_{cond}_{s}.bvh")
    pattern = r"walk_(?P<condition>[a-z]+)_(?P<subject>s\d)\.bvh"
    common = ["--pattern", pattern, "--base", "normal", "--variant", "quick=fast"]
    assert main(["gait", "analyze", str(lib), "--out", str(tmp_path / "single"), *common]) == 0
    (lib / "walk_fast_s9.bvh").write_text("not a bvh\n")  # a bad take: a row, left out of the population
    assert main(["batch", "gait", str(lib), "--out", str(tmp_path / "batch"), "--workers", "1", *common]) == 0
    printed = capsys.readouterr().out
    assert "population: 6 takes (1 failed, left out)" in printed
    rows = rows_of(tmp_path / "batch")
    assert rows["walk_fast_s9.bvh"]["error"]
    assert rows["walk_normal_s1.bvh"]["frequency_hz"] == pytest.approx(0.90, rel=1e-3)
    assert rows["walk_fast_s2.bvh"]["speed_mps"] == pytest.approx(1.45, rel=1e-2)
    single = json.loads((tmp_path / "single" / "tables.json").read_text())
    batch = json.loads((tmp_path / "batch" / "tables.json").read_text())
    assert batch == single


def test_batch_analyze_reads_c3d_takes_with_their_plates(tmp_path):
    lib = tmp_path / "lib"
    lib.mkdir()
    (lib / "trial.c3d").symlink_to(C3D / "cgm24_walking01_forceplate.c3d")
    m = read_bvh(BANDAI / "walk_normal_001.bvh")
    write_bvh(replace(m, frames=m.frames[:60]), lib / "walk.bvh")
    out = tmp_path / "out"
    job = AnalyzeJob(plot=True)
    run_library(None, find_takes([str(lib)], out, job), out, job)
    assert main(["analyze", str(lib / "trial.c3d"), "--summary-json", str(tmp_path / "s.json")]) == 0
    for take in ("trial.c3d", "walk.bvh"):  # the figures asked for, complete
        assert (out / "takes" / take / "zmp.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert run_library(None, find_takes([str(lib)], out, AnalyzeJob()), out, AnalyzeJob()).skipped == 0
    single = json.loads((tmp_path / "s.json").read_text())
    rows = rows_of(out)
    c3d, bvh = rows["trial.c3d"], rows["walk.bvh"]
    assert c3d["format"] == "c3d" and c3d["frames"] == single["frames"]
    cv = single["cop_vs_zmp"]
    assert (c3d["cop_frames"], c3d["cop_rms_mm"], c3d["cop_lag_ms"]) == (cv["frames"], cv["rms_mm"], cv["lag_ms"])
    assert c3d["cop_rms_mm"] < 60  # a real walk against its plates
    assert c3d["plausible"] is True and c3d["inside_fraction_tol"] >= c3d["inside_fraction"]
    assert bvh["cop_rms_mm"] is None and bvh["plausibility"]  # no plates; the verdict is for every take
    zmp_csv = (out / "takes" / "trial.c3d" / "zmp.csv").read_text().splitlines()
    assert "cop_x" in zmp_csv[0] and len(zmp_csv) == single["frames"] + 1
