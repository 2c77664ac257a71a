"""The offline side as a hostile user meets it (audit 11): a wrong unit, a take with no foot on the ground, a NaN
threshold, an output over the input. Each case failed on main: exit 0 with a body no person has, or NaN in an
output, or a verdict left unsaid, or the input overwritten."""

from __future__ import annotations

import re

import numpy as np
import pytest
from data_paths import DATA

from livezmp.cli import main
from livezmp.gait.sinewalk import sine_bvh, walk_spec
from livezmp.model.bvh import write_bvh
from livezmp.model.c3d_write import _latin1_text, _trim_channels

PIG = DATA / "c3d" / "walk_plugingait_forceplates.c3d"


def refused(capsys, *argv, says: str) -> None:
    """exit 2, exactly one stderr line saying ``says`` (regex)."""
    rc = main([str(a) for a in argv])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2, err
    assert len(err) == 1 and re.search(says, err[0]), err


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    """A 2 s sine walk at 100 Hz (a person's size in centimetres)."""
    p = tmp_path_factory.mktemp("walk") / "walk.bvh"
    write_bvh(sine_bvh(walk_spec(), 1.0, 100.0, 2.0), p)
    return p


@pytest.mark.parametrize("units", ["mm", "m", "in"])
def test_bvh_units_that_make_no_person_are_refused(walk, capsys, units):
    """A skeleton in centimetres read as mm is 17 cm tall, as m or inches 171 m or 4.3 m: main analysed it, exit 0
    (Bandai's walk read as mm: every frame inside, "plausible for walking")."""
    refused(capsys, "analyze", walk, "--units", units,
            says=rf"{re.escape(str(walk))}: --units {units} makes the skeleton's estimated stature .* no human's "
                 r"\(0.4-3 m\); the skeleton's size reads as cm$")


def test_bvh_units_given_as_detected_still_analyses(walk, capsys):
    assert main(["analyze", str(walk), "--units", "cm"]) == 0


def test_all_flight_take_says_its_verdict(walk, tmp_path, capsys):
    """A take with no frame on the ground (the same walk told to be at 1000 Hz: its feet never settle) printed
    no verdict at all on main, only "inside n/a"; the summary had it."""
    fast = tmp_path / "fast.bvh"
    fast.write_text(re.sub(r"Frame Time:\s*\S+", "Frame Time: 0.001", walk.read_text()))
    assert main(["analyze", str(fast)]) == 0
    out = capsys.readouterr().out
    assert "inside n/a" in out
    assert re.search(r"^  motion: not physically plausible", out, re.M), out


@pytest.mark.parametrize("option, value, says", [
    ("--threshold", "nan", r"--threshold \(%\): nan is outside \[0, 1e\+06\]"),
    ("--threshold", "-5", r"--threshold \(%\): -5 is outside"),
    ("--min-base", "inf", r"--min-base \(deg\): inf is outside \[0, 360\]"),
    ("--min-change", "nan", r"--min-change \(%\): nan is outside"),
])
@pytest.mark.parametrize("command", [["gait", "analyze"], ["batch", "gait"]])
def test_gait_population_thresholds_refused_before_work(walk, tmp_path, capsys, command, option, value, says):
    """main wrote ``"threshold_cv_percent": NaN`` into features.json (not JSON) with exit 0; batch gait ran every
    take on the cluster first. No take is read: the walk here has no condition in its name."""
    refused(capsys, *command, walk, "--base", "normal", "--variant", "fast=active", "--out", tmp_path / "g",
            option, value, says=says)
    assert not (tmp_path / "g").exists()


def test_gait_analyze_out_a_file_refused_before_work(walk, tmp_path, capsys):
    (tmp_path / "g").write_text("")
    refused(capsys, "gait", "analyze", walk, "--base", "normal", "--variant", "fast=active", "--out", tmp_path / "g",
            says=r"--out .*g: .* is a file, not a directory")


def test_c3d_points_in_metres_labelled_mm_refused(tmp_path, capsys):
    """The Plug-in Gait walk's points divided by 1000 (a converter that wrote metres and left POINT:UNITS mm):
    main sized the body by the file's height (1.64 m) around a 0.3 mm pelvis and said "plausible for walking",
    every frame inside, exit 0."""
    from livezmp.model.c3d import open_c3d

    c = open_c3d(PIG)
    _latin1_text(c["parameters"])
    _trim_channels(c["parameters"]["ANALOG"], c["data"]["analogs"].shape[1])
    c["data"]["points"][:3] /= 1000.0
    bad = tmp_path / "in_m.c3d"
    c.write(str(bad))
    refused(capsys, "analyze", bad, says=rf"{re.escape(str(bad))}: the leg markers make a stature of 0.0\d+ m "
                                         r".*the file's height is 1.639 m: are the points in another unit than "
                                         r"POINT:UNITS \(mm\)\?")
    assert np.isfinite(c["data"]["points"][:3]).any()


@pytest.mark.parametrize("argv, option", [
    (["analyze", "{w}", "--out", "{w}"], "--out"),
    (["analyze", "{w}", "--summary-json", "{link}"], "--summary-json"),
    (["analyze", "{w}", "--out", "{hard}"], "--out"),
    (["correct", "{w}", "-o", "{w}"], "-o"),
    (["correct", "{w}", "-o", "{tmp}/o.bvh", "--report", "{hard}"], "--report"),
    (["calibrate", "{w}", "-o", "{w}"], "-o"),
    (["gait", "synth", "{w}", "--features", "{tmp}/f.json", "--to", "fast", "-o", "{link}"], "-o"),
    (["replay", "{w}", "--record", "{w}"], "--record"),
    (["monitor", "{w}", "--summary-json", "{w}"], "--summary-json"),
])
def test_output_that_is_an_input_refused(walk, tmp_path, capsys, argv, option):
    """An output naming the input, or a link to it (symbolic or hard): main overwrote the take with its zmp.csv,
    summary or correction (``calibrate w.c3d -o w.c3d``: the trial replaced by its subject file), exit 0."""
    w = tmp_path / "w.bvh"
    w.write_bytes(walk.read_bytes())
    (tmp_path / "link.bvh").symlink_to(w)
    (tmp_path / "hard.bvh").hardlink_to(w)
    names = {"w": w, "link": tmp_path / "link.bvh", "hard": tmp_path / "hard.bvh", "tmp": tmp_path}
    refused(capsys, *[a.format(**names) for a in argv],
            says=rf"^livezmp: error: {option} .*: the same file as the input .*w\.bvh; write the output to a file of "
                 "its own$")
    assert w.read_bytes() == walk.read_bytes()


@pytest.mark.parametrize("argv", [
    ["correct", "{w}", "-o", "{tmp}/o.csv"],
    ["correct", "{w}", "-o", "{tmp}/o"],
    ["gait", "synth", "{w}", "--features", "{tmp}/f.json", "--to", "fast", "-o", "{tmp}/o.csv"],
])
def test_written_back_format_needs_its_suffix(walk, tmp_path, capsys, argv):
    """main corrected the walk for a minute and wrote BVH text into o.csv (read back: a CSV without a time
    column); refused before any work now."""
    refused(capsys, *[a.format(w=walk, tmp=tmp_path) for a in argv],
            says=r"o(\.csv)?: .*walk\.bvh is written back in its own format; give -o ending in \.bvh$")
    assert not list(tmp_path.iterdir())


def test_output_that_cannot_be_replaced_is_one_line(walk, tmp_path, capsys, monkeypatch):
    """zmp.csv over a file the system will not let go (an immutable file, a read-only mount): main's rename
    ended the analysis in a PermissionError traceback, exit 1; no temporary file is left beside it."""
    import livezmp.jsonfile as jsonfile

    def refuse(src, dst):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(jsonfile.os, "replace", refuse)
    out = tmp_path / "z.csv"
    out.write_text("kept\n")
    refused(capsys, "analyze", walk, "--out", out,
            says=rf"{re.escape(str(out))}: cannot write: Operation not permitted$")
    assert out.read_text() == "kept\n"
    assert [p.name for p in tmp_path.iterdir()] == ["z.csv"]


def test_batch_take_whose_summary_cannot_be_written_is_a_row(walk, tmp_path, monkeypatch):
    """A take whose directory will not take its summary (an immutable directory): main's ``run_take`` raised, the
    worker logged the task's traceback on the run's console and the client made a "task failed" row; now the
    take's own row says which file could not be written, and nothing is raised."""
    import livezmp.offline.library as library
    from livezmp.errors import InputError
    from livezmp.offline.jobs import AnalyzeJob
    from livezmp.offline.take import TakeOptions

    def refuse(data, path):
        raise InputError(f"{path}: cannot write: Operation not permitted")

    monkeypatch.setattr(library, "write_json", refuse)
    take = library.Take(walk, tmp_path / "takes" / "walk.bvh")
    row = library.run_take(take, AnalyzeJob(TakeOptions()))
    assert row["error"] == f"{take.out_dir / 'summary.json'}: cannot write: Operation not permitted"
    assert row["frames"] is None
