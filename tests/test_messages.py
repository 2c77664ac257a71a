"""What the commands tell the user (issue 12, class 9): `correct` reports its progress,
`replay` says when the recording dropped messages (`gait synth --balance` saying what it
did is in test_gait_cli.py). Each was silent before."""

from __future__ import annotations

import re

import numpy as np

from livezmp.balance.pipeline import default_config
from livezmp.cli import main
from livezmp.gait.sinewalk import sine_bvh, walk_spec
from livezmp.model.body_spec import robot_body
from livezmp.model.bvh import write_bvh
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.motion_file import trajectory_frames
from livezmp.monitor.loop import Monitor
from livezmp.recording.writer import Recorder
from livezmp.sources.file_replay import FileReplaySource


def test_correct_reports_progress(tmp_path, capsys):
    walk = tmp_path / "w.bvh"
    write_bvh(sine_bvh(walk_spec(), 1.0, 100.0, 2.0), walk)
    assert main(["correct", str(walk), "-o", str(tmp_path / "c.bvh")]) == 0
    out = capsys.readouterr().out.splitlines()
    progress = [ln for ln in out if ln.startswith("correct: ")]
    assert progress[0] == "correct: analysing 60 frames"
    assert re.fullmatch(r"correct: \d+ frames outside the support polygon; solving", progress[1])
    assert progress[-1] == "correct: easing contact changes, final check"


def test_replay_says_the_recording_dropped_messages(tmp_path, capsys):
    body, spec = robot_body(demo_robot_path())
    traj = demo_trajectory(body.joint_names, duration=0.5)
    frames = trajectory_frames(body, traj)
    path = tmp_path / "r.mcap"
    rec = Recorder(path, spec, {"fps": 100.0}, body.channel_names)
    close = rec.close
    # what a loop recording whose writer queue overflowed writes in its totals
    rec.close = lambda totals=None: close({**(totals or {}), "recording": {"dropped_total": 3, "failed": 0}})
    Monitor(FileReplaySource("<demo>", body, spec, traj.t, frames, speed=0), default_config(body, 100.0),
            recorder=rec).run()
    assert main(["replay", str(path)]) == 0
    out = capsys.readouterr().out
    assert "same analysis" in out and "the recording dropped 3 messages" in out
    assert np.isfinite(len(out))
