"""A robot's joint CSV analysed in bounded memory (model/trajectory_csv.py scan_joint_csv and
joint_csv_blocks, offline/take_stream.py open_joint_csv_take) against the whole-take path: the same
zmp.csv bytes and summary across chunk boundaries (the floating base placed across them), on a time
column the batch path cannot take; every refusal the same one line as the whole reader's, wherever in
the file it is; and the time column's median period decided from counts as numpy's median decides it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from data_paths import BANDAI
from test_take_stream import chunked, whole

from livezmp.checks import FRAME_PERIOD_RANGE
from livezmp.cli import main
from livezmp.errors import InputError
from livezmp.estimate.estimator import FILE_CUTOFF_HZ, default_estimator
from livezmp.model import trajectory_csv
from livezmp.model.base_placement import BasePlacer, place_base
from livezmp.model.bvh import read_bvh, write_bvh
from livezmp.model.demo_robot import demo_robot_path
from livezmp.model.trajectory_csv import (
    JointTrajectory,
    TimeColumnCheck,
    read_joint_csv,
    scan_joint_csv,
    write_joint_csv,
)
from livezmp.model.urdf_body import body_from_urdf
from livezmp.offline.take import TakeOptions

ROBOT = demo_robot_path()
OPTIONS = TakeOptions(robot=str(ROBOT))
RATE = 100.0
WINDOW = default_estimator(RATE, FILE_CUTOFF_HZ).window  # a chunk of two windows: the smallest the batch path takes


@pytest.fixture(scope="module")
def body():
    return body_from_urdf(ROBOT)


def stepping(body, frames: int, rate: float = RATE) -> JointTrajectory:
    """The demo robot stepping in place, 0.8 steps a second per foot: each knee lifts its foot in turn
    while the hips sway the weight over the other (the stance passes from foot to foot)."""
    t = np.arange(frames) / rate
    phase = np.sin(2 * np.pi * 0.8 * t)
    q = np.zeros((frames, len(body.joint_names)))
    col = body.joint_names.index
    for side, lift in (("l", 0.5 * np.clip(phase, 0, None)), ("r", 0.5 * np.clip(-phase, 0, None))):
        q[:, col(f"{side}_knee")] = 2 * lift
        q[:, col(f"{side}_hip_pitch")] = -lift
        q[:, col(f"{side}_ank_pitch")] = -lift
        q[:, col(f"{side}_hip_roll")] = 0.06 * phase
        q[:, col(f"{side}_ank_roll")] = -0.06 * phase
    return JointTrajectory(t, q, list(body.joint_names))


@pytest.mark.parametrize("tail", [0, 1, 7])
def test_chunked_equals_whole_across_chunk_boundaries(body, tmp_path, tail):
    """5 chunks plus ``tail`` frames, the base placed from the joints (no base columns): the same bytes
    and summary as the whole take; the stance passes between feet, so a placer not carried across
    chunks would put the later chunks' base elsewhere."""
    chunk = 2 * WINDOW
    traj = stepping(body, 5 * chunk + tail)
    path = tmp_path / "steps.csv"
    write_joint_csv(traj, path)
    want = whole(path, tmp_path, OPTIONS)
    assert want[0]["frames"] == 5 * chunk + tail
    assert chunked(path, tmp_path, chunk, OPTIONS) == want
    placed = place_base(body, traj.q)
    assert not np.allclose(place_base(body, traj.q[2 * chunk:]), placed[2 * chunk:], atol=1e-3)  # a fresh placer
    carried = BasePlacer(body)
    assert np.array_equal(np.vstack([place_base(body, traj.q[lo:lo + chunk], carried)
                                     for lo in range(0, len(traj.q), chunk)]), placed)


def test_uneven_time_column_with_a_base(body, tmp_path):
    """Base columns and a time column with jitter (the batch path refuses it after the first chunk):
    the take is stepped frame by frame from a second read, equal to the whole-take path."""
    traj = stepping(body, 4 * 2 * WINDOW)
    rng = np.random.default_rng(1)
    t = traj.t + rng.uniform(-0.002, 0.002, len(traj.t)) * (np.arange(len(traj.t)) >= 3 * WINDOW)
    base = place_base(body, traj.q)[:, [0, 1, 2, 5, 4, 3]]  # the CSV's x, y, z, roll, pitch, yaw
    path = tmp_path / "jitter.csv"
    write_joint_csv(JointTrajectory(t, traj.q, traj.joint_names, base), path)
    want = whole(path, tmp_path, OPTIONS)
    assert chunked(path, tmp_path, 2 * WINDOW, OPTIONS) == want


ROWS = 40  # rows a block in the error tests: a 200-frame take spans five blocks


def take_lines(body, tmp_path) -> list[str]:
    write_joint_csv(stepping(body, 200), tmp_path / "t.csv")
    return (tmp_path / "t.csv").read_text().splitlines()


def with_field(lines: list[str], line: int, column: int, value: str) -> list[str]:
    fields = lines[line - 1].split(",")
    fields[column] = value
    return lines[:line - 1] + [",".join(fields)] + lines[line:]


def with_time(lines: list[str], line: int, value: str) -> list[str]:
    return with_field(lines, line, 0, value)


KNEE = 1 + 5  # l_knee's column (time first)
CASES = {
    "decimal comma late": (lambda ls: with_field(ls, 190, KNEE, "1,5"), ":190: 22 fields, header has 21"),
    "text late": (lambda ls: with_field(ls, 190, KNEE, "x"), ":190: field l_knee: not a number: 'x'"),
    "nan late": (lambda ls: with_field(ls, 150, KNEE, " nan"), ":150: field l_knee: nan is not finite"),
    "time back at a block's first row": (lambda ls: with_time(ls, 2 + 3 * ROWS, "0"),
                                         f":{2 + 3 * ROWS}: field time: not increasing"),
    "time back early, a bad field later": (lambda ls: with_field(with_time(ls, 10, "0"), 180, KNEE, "x"),
                                           ":180: field l_knee: not a number"),
    "two times back": (lambda ls: with_time(with_time(ls, 170, "0"), 60, "0"), ":60: field time: not increasing"),
    "blank rows counted": (lambda ls: ls[:50] + ["", " , "] + with_field(ls, 150, KNEE, "x")[50:],
                           ":152: field l_knee: not a number"),
    "milliseconds": (lambda ls: [ls[0]] + [",".join([str(1000 * float(ln.split(",")[0]))] + ln.split(",")[1:])
                                           for ln in ls[1:]], ": field time: frame period 10 s is outside"),
    "duplicated column": (lambda ls: [ls[0].replace("head_pan", "l_knee")] + ls[1:],
                          ":1: column 'l_knee' appears more than once"),
    "header only": (lambda ls: ls[:1] + ["", ""], ":2: zero frames"),
    "empty": (lambda ls: [], ":1: empty file"),
}


@pytest.mark.parametrize("case", CASES)
def test_refusals_are_the_whole_readers_wherever_they_are(body, tmp_path, capsys, monkeypatch, case):
    """Each bad file: the scan (blocks of 40 rows) raises the whole reader's message, naming the
    right line; `analyze --robot --out` exits 2 with that one line and leaves no file."""
    monkeypatch.setattr(trajectory_csv, "JOINT_CSV_BLOCK_ROWS", ROWS)
    change, says = CASES[case]
    path = tmp_path / "bad.csv"
    lines = change(take_lines(body, tmp_path))
    path.write_text("\n".join(lines) + "\n" if lines else "")
    with pytest.raises(InputError) as whole_error:
        read_joint_csv(path, body.joint_names)
    with pytest.raises(InputError) as scan_error:
        scan_joint_csv(path, body.joint_names)
    assert str(scan_error.value) == str(whole_error.value)
    assert str(whole_error.value).startswith(f"{path}{says}"), str(whole_error.value)
    out = tmp_path / "out"
    out.mkdir()
    assert main(["analyze", str(path), "--robot", str(ROBOT), "--out", str(out / "zmp.csv")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"livezmp: error: {whole_error.value}"]
    assert list(out.iterdir()) == []


def test_late_bad_byte_and_crlf(body, tmp_path, monkeypatch):
    """CRLF line ends, text read 100 bytes at a time: the frames as the whole reader reads them; a bad
    byte near the end is reported on its line."""
    monkeypatch.setattr(trajectory_csv, "JOINT_CSV_BLOCK_ROWS", ROWS)
    monkeypatch.setattr(trajectory_csv, "JOINT_CSV_TEXT_BYTES", 100)
    lines = take_lines(body, tmp_path)
    path = tmp_path / "crlf.csv"
    path.write_bytes("\r\n".join(lines).encode() + b"\r\n")
    scan = scan_joint_csv(path, body.joint_names)
    traj = read_joint_csv(path, body.joint_names)
    assert (scan.count, scan.first_t, scan.last_t) == (200, traj.t[0], traj.t[-1])
    assert scan.fps == pytest.approx(RATE, rel=1e-9)
    blocks = list(trajectory_csv.joint_csv_blocks(path, body.joint_names, 33))
    assert [len(b.t) for b in blocks] == [33] * 6 + [2]
    assert np.array_equal(np.vstack([b.q for b in blocks]), traj.q)
    path.write_bytes(path.read_bytes().replace(lines[190].encode(), lines[190].encode() + b"\xff"))
    with pytest.raises(InputError, match=rf"{path}:191: not UTF-8 text \(byte 0xff\)"):
        scan_joint_csv(path, body.joint_names)


def test_median_period_from_counts_is_numpys():
    """Differences around both bounds of the period range (the median on either side of one, or the
    mean of the two middle ones straddling it), in blocks: the decision of np.median, every time."""
    lo, hi = FRAME_PERIOD_RANGE
    near = np.array([lo * 0.5, lo * (1 - 1e-12), lo, lo * (1 + 1e-12), lo * 1.5, 0.01,
                     hi * 0.5, hi * (1 - 1e-12), hi, hi * (1 + 1e-12), hi * 1.5, 1.0])
    rng = np.random.default_rng(7)
    seen = set()
    for _ in range(1000):
        n = int(rng.integers(1, 12))
        d = rng.choice(near, n)
        t = np.concatenate([[0.0], np.cumsum(d)])
        check = TimeColumnCheck("t")
        cuts = np.sort(rng.choice(np.arange(1, n + 1), int(rng.integers(0, min(n, 3) + 1)), replace=False))
        for lo_i, hi_i in zip(np.r_[0, cuts], np.r_[cuts, n + 1], strict=True):
            if hi_i > lo_i:
                check.add(np.arange(lo_i, hi_i) + 2, t[lo_i:hi_i])
        got = check.median_in_range()
        want = bool(lo <= np.median(np.diff(t)) <= hi)
        assert got == want, (d, got, want)
        seen.add(want)
    assert seen == {True, False}


def test_a_one_frame_take_is_refused_before_its_rate_is_used(body, tmp_path, capsys):
    """One frame (a rate of 0 Hz): the whole-take path's one line, for a joint CSV and for a BVH."""
    write_joint_csv(stepping(body, 1), tmp_path / "one.csv")
    walk = read_bvh(BANDAI / "walk_normal_002.bvh")
    write_bvh(replace(walk, frames=walk.frames[:1]), tmp_path / "one.bvh")
    for path, extra in ((tmp_path / "one.csv", ["--robot", str(ROBOT)]), (tmp_path / "one.bvh", [])):
        assert main(["analyze", str(path), *extra, "--out", str(tmp_path / "zmp.csv")]) == 2
        assert capsys.readouterr().err.splitlines() == [f"livezmp: error: {path}: need at least 2 frames, got 1"]
        assert not (tmp_path / "zmp.csv").exists()
