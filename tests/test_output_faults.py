"""Outputs that cannot be written as asked: a recording's disk filling up during a session, two options naming
one file, a device or FIFO given as a file. The session goes on and its summary is written; what the recording
held before the fault stays readable; nothing given is replaced by something else."""

from __future__ import annotations

import json
import os
import resource
import stat
import subprocess
import sys

import pytest

from livezmp.checks import check_output_paths
from livezmp.errors import InputError
from livezmp.recording.recover import recover

BVH = "/work/shared/data/bvh/bandai/walk_active_001.bvh"
# bytes a file may grow to: a loop recording's start and its first 0.5 s chunk (about 50 kB at 500 Hz) fit, 6 s of
# its messages (about 580 kB at 500 Hz, 120 kB even at the 100 Hz a loaded machine gives) do not
ROOM = 100_000
MONITOR_LIMIT = 150_000  # the monitor's recording of BVH: 92 kB with one frame, 257 kB with its 207


def _livezmp(*args: str, limit: int | None = None) -> subprocess.CompletedProcess:
    """`livezmp ARGS`; ``limit``: files may grow to that many bytes (a full disk's EFBIG without filling a disk)."""
    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.getrlimit(resource.RLIMIT_FSIZE)[1]))
    return subprocess.run([sys.executable, "-m", "livezmp", *args], capture_output=True, text=True, timeout=120,
                          preexec_fn=None if limit is None else limited)


def _recovered(path, tmp_path) -> int:
    return recover(path, tmp_path / "fixed.mcap").messages


def test_a_loop_whose_recording_cannot_grow_runs_on_and_writes_its_summary(tmp_path):
    """main: the writer thread died of OSError (a traceback), the run's end raised it again: exit 1, no summary."""
    rec, summary = tmp_path / "run.mcap", tmp_path / "s.json"
    p = _livezmp("demo", "--link", "mock", "--scenario", "stand", "--duration", "6", "--quiet",
                 "--realtime-priority", "0", "--record", str(rec), "--summary-json", str(summary), limit=ROOM)
    # 3: the loop starved of CPU on a loaded machine (the link's own verdict, told apart); main: 1, the traceback
    assert p.returncode in (0, 3), p.stderr
    assert "Traceback" not in p.stderr
    s = json.loads(summary.read_text())
    assert s["stopped_by"] in ("duration", "fell") and "File too large" in s["recording"]["file_error"]
    assert "livezmp recover" in p.stderr  # told, with how to read what it holds
    assert _recovered(rec, tmp_path) > 0  # what was written before the fault is kept


def test_a_monitor_whose_recording_cannot_grow_analyses_on(tmp_path):
    """main: the OSError ended the monitor with a traceback, no summary."""
    rec, summary = tmp_path / "m.mcap", tmp_path / "s.json"
    # in real time (7 s): chunks close every 0.5 s, so the limit falls after some are written
    p = _livezmp("monitor", BVH, "--speed", "1", "--record", str(rec), "--summary-json", str(summary),
                 limit=MONITOR_LIMIT)
    assert p.returncode == 0, p.stderr
    assert "Traceback" not in p.stderr
    s = json.loads(summary.read_text())
    assert s["analysed_frames"] == s["frames_in"] > 0
    assert "File too large" in s["recording"]["file_error"]
    assert _recovered(rec, tmp_path) > 0


@pytest.mark.parametrize("command", [
    ["demo", "--link", "mock", "--duration", "0.2", "--quiet", "--realtime-priority", "0"],
    ["monitor", BVH, "--speed", "0", "--frames", "20"],
])
def test_a_summary_named_as_the_recording_is_refused(tmp_path, command):
    """main: the summary, written last, replaced the recording (exit 0)."""
    out = tmp_path / "same.mcap"
    p = _livezmp(*command, "--record", str(out), "--summary-json", str(out))
    assert p.returncode == 2 and p.stderr.strip().splitlines()[-1] == (
        f"livezmp: error: --summary-json {out}: the same file as --record; give each output a file of its own")
    assert not out.exists()


@pytest.mark.parametrize("command", [
    ["demo", "--link", "mock", "--duration", "0.2", "--quiet", "--realtime-priority", "0"],
    ["monitor", BVH, "--speed", "0", "--frames", "20"],
])
def test_a_summary_given_a_fifo_leaves_it_a_fifo(tmp_path, command):
    """main: the summary was renamed over the FIFO (as it would be over /dev/null for root), exit 0."""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    p = _livezmp(*command, "--summary-json", str(fifo))
    assert p.returncode == 2 and "not a regular file" in p.stderr and "Traceback" not in p.stderr
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_a_monitor_summary_in_a_missing_directory_is_refused_before_the_session(tmp_path):
    """main: the whole session ran, then the summary's write failed."""
    p = _livezmp("monitor", BVH, "--speed", "0", "--summary-json", str(tmp_path / "no" / "s.json"))
    assert p.returncode == 2 and "does not exist" in p.stderr and "source:" not in p.stdout


def test_outputs_checked_together(tmp_path):
    (tmp_path / "a").mkdir()
    link = tmp_path / "link.json"
    link.symlink_to(tmp_path / "s.json")
    check_output_paths((tmp_path / "r.mcap", "--record"), (None, "--summary-json"), (tmp_path / "s.json", "--out"))
    with pytest.raises(InputError, match="the same file as --out"):
        check_output_paths((tmp_path / "s.json", "--out"), (link, "--summary-json"))


def test_a_summary_that_cannot_be_written_is_one_line(tmp_path):
    """Its directory gone since the command checked it (or the disk full: the same OSError path): main raised
    FileNotFoundError / OSError out of the command, a traceback after the run."""
    from livezmp.jsonfile import write_json

    with pytest.raises(InputError, match="s.json: cannot write: No such file or directory"):
        write_json({"cycles": 1}, tmp_path / "gone" / "s.json")
