"""`livezmp monitor / replay / recover` through the command's main and as a process:
record then replay gives the same analysis, Ctrl-C closes a complete recording, user
mistakes are one line with exit code 2."""

from __future__ import annotations

import io
import json
import os
import re
import signal
import socket
import subprocess
import sys
import threading
from dataclasses import replace

import pytest
from data_paths import BANDAI, ROOT
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from mcap.writer import Writer
from sim_support import wait_until

from livezmp.balance.pipeline import default_config
from livezmp.cli import main
from livezmp.estimate.estimator import EstimatorConfig, default_cutoff
from livezmp.model.body_spec import robot_body
from livezmp.model.bvh import read_bvh
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.motion_file import trajectory_frames
from livezmp.monitor.loop import Monitor
from livezmp.recording.reader import iter_messages, open_recording
from livezmp.recording.writer import Recorder
from livezmp.sources.file_replay import FileReplaySource
from sim_devices.mocap_streamer import Impairments, UdpStreamer

WALK = BANDAI / "walk_normal_001.bvh"


def test_record_then_replay_gives_the_same_analysis(tmp_path, capsys):
    path = tmp_path / "walk.mcap"
    assert main(["monitor", str(WALK), "--speed", "0", "--record", str(path), "--alarm-after", "100"]) == 0
    out = capsys.readouterr().out
    assert "monitor: 273 frames in, 273 analysed" in out
    rec = open_recording(path)
    assert rec.counts["/input"] == rec.counts["/result"] == 273
    assert rec.session["fps"] == pytest.approx(30.0, rel=1e-5) and rec.session["alarm_after"] == 0.1
    assert main(["replay", str(path)]) == 0
    out = capsys.readouterr().out
    assert "273 results compared" in out and "max ZMP difference 0.000000 mm, 0 support differences" in out
    assert "same analysis" in out
    raised = sum(m["event"] == "raised" for m in iter_messages(path, "/alarm"))
    assert f"{raised} alarm(s) recorded" in out and raised > 0


def copy_with(src, dst, change) -> None:
    """Copy a recording message by message (mcap reader and writer), passing each decoded
    JSON message through ``change(topic, message)`` (Foxglove's protobuf scene as it is)."""
    with open(src, "rb") as f, open(dst, "wb") as out:
        reader = make_reader(f)
        w = Writer(out)
        w.start()
        for a in reader.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        for m in reader.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        channels = {}
        for schema, channel, msg in reader.iter_messages(log_time_order=False):
            if channel.id not in channels:
                sid = w.register_schema(schema.name, schema.encoding, schema.data)
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding, sid)
            data = (json.dumps(change(channel.topic, json.loads(msg.data))).encode()
                    if channel.message_encoding == "json" else msg.data)
            w.add_message(channels[channel.id], msg.log_time, data, msg.publish_time, msg.sequence)
        w.finish()


def test_replay_notices_a_different_analysis(tmp_path, capsys):
    path, tampered = tmp_path / "demo.mcap", tmp_path / "tampered.mcap"
    assert main(["monitor", "--speed", "0", "--record", str(path)]) == 0

    def nudge(topic, m):
        if topic == "/result" and m["index"] == 500:
            m["zmp"]["x"] += 0.002
        return m

    copy_with(path, tampered, nudge)
    capsys.readouterr()
    assert main(["replay", str(tampered)]) == 1
    out = capsys.readouterr().out
    assert "max ZMP difference 2.000000 mm" in out and "DIFFERENT analysis" in out


def test_a_recovered_recording_replays_the_same(tmp_path, capsys):
    path, broken, fixed = tmp_path / "demo.mcap", tmp_path / "broken.mcap", tmp_path / "fixed.mcap"
    body, spec = robot_body(demo_robot_path())
    traj = demo_trajectory(body.joint_names)
    cfg = default_config(body, 100.0)
    rec = Recorder(path, spec, {"fps": 100.0, "mode": "full", "ground_z": None, "alarm_after": 0.2, "correct": False,
                                "cutoff_hz": cfg.estimator.cutoff_hz}, body.channel_names, chunk_bytes=16384)
    Monitor(FileReplaySource("<demo>", body, spec, traj.t, trajectory_frames(body, traj), speed=0),
            cfg, recorder=rec).run()
    total = sum(open_recording(path).counts.values())
    data = path.read_bytes()
    broken.write_bytes(data[: len(data) // 2])  # the summary and the last chunks are gone
    capsys.readouterr()
    assert main(["recover", str(broken), "-o", str(fixed)]) == 0
    out = capsys.readouterr().out
    kept = int(out.split(": ")[1].split()[0])
    assert 0 < kept < total and "stopped" in out
    assert main(["replay", str(fixed)]) == 0
    out = capsys.readouterr().out
    assert "same analysis" in out



def test_a_recording_without_a_cutoff_replays_at_the_old_6_hz(tmp_path, capsys):
    """Monitor recordings made before the per-rate defaults (issue 12) carry no cutoff: they ran at the
    fixed 6 Hz settings (0.4 s window, 0.1 s lag), and replay re-runs with those and reproduces them; the
    same results said to be made at the per-rate default (3.9 Hz at 100 Hz) replay as different."""
    body, spec = robot_body(demo_robot_path())
    traj = demo_trajectory(body.joint_names, duration=7.5)  # its lean (from 6 s) goes out of support
    fixed_6_hz = replace(default_config(body, 100.0), estimator=EstimatorConfig(rate_hz=100.0))  # the settings then
    session = {"fps": 100.0, "mode": "full", "ground_z": None, "alarm_after": 0.2, "correct": False}  # as then
    paths = {}
    for name, extra in (("old", {}), ("labelled_per_rate", {"cutoff_hz": default_cutoff(100.0)})):
        paths[name] = tmp_path / f"{name}.mcap"
        Monitor(FileReplaySource("<demo>", body, spec, traj.t, trajectory_frames(body, traj), speed=0), fixed_6_hz,
                recorder=Recorder(paths[name], spec, {**session, **extra}, body.channel_names)).run()
    assert "cutoff_hz" not in open_recording(paths["old"]).session
    assert sum(m["event"] == "raised" for m in iter_messages(str(paths["old"]), "/alarm")) >= 1
    capsys.readouterr()
    assert main(["replay", str(paths["old"])]) == 0
    out = capsys.readouterr().out
    assert "max ZMP difference 0.000000 mm, 0 support differences" in out and "same analysis" in out
    assert main(["replay", str(paths["labelled_per_rate"])]) == 1
    assert "DIFFERENT analysis" in capsys.readouterr().out

@pytest.mark.parametrize("argv, message", [
    (["monitor", "--dashboard", "0.0.0.0:0"], "serving beyond loopback needs --allow-remote"),
    (["monitor", "--dashboard", "nonsense"], "need HOST:PORT"),
    (["monitor", "udp://127.0.0.1:0"], "needs the body it carries"),
    (["monitor", "--alarm-after", "-5"], "--alarm-after must be ≥ 0"),
    (["monitor", "--speed", "0", "--alarm-command", "no-such-command-livezmp"], "command not found"),
    # checked with the other outputs before the source opens (audit 10)
    (["monitor", "--record", "/nonexistent-dir/x.mcap"], "--record /nonexistent-dir/x.mcap: directory"),
    (["monitor", "--record", "."], "--record .: is a directory; give a file name"),
    (["replay", "missing.mcap"], "missing.mcap: no such file"),
    (["recover", "missing.mcap", "-o", "out.mcap"], "missing.mcap: no such file"),
    (["monitor", "--realtime-priority", "100"], "--realtime-priority 100: must be 1-99"),
])
def test_user_mistakes_are_one_line(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and err.startswith("livezmp: error:")


def test_replay_of_an_unfinished_recording_points_to_recover(tmp_path, capsys):
    path = tmp_path / "cut.mcap"
    assert main(["monitor", "--speed", "0", "--record", str(path)]) == 0
    path.write_bytes(path.read_bytes()[:-200])
    capsys.readouterr()
    assert main(["replay", str(path)]) == 2
    err = capsys.readouterr().err
    assert "livezmp recover" in err and err.count("\n") == 1


def test_replay_needs_a_monitor_session(tmp_path, capsys):
    body, spec = robot_body(demo_robot_path())
    Recorder(tmp_path / "bare.mcap", spec, {}, body.channel_names).close()
    assert main(["replay", str(tmp_path / "bare.mcap")]) == 2
    assert "session has no frame rate" in capsys.readouterr().err


def wait_for(cond, deadline: float = 30.0) -> None:
    if not wait_until(cond, timeout=deadline, interval=0.02):
        raise TimeoutError("condition not met in time")


def test_ctrl_c_stops_cleanly_with_a_complete_recording(tmp_path):
    path = tmp_path / "session.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "livezmp", "monitor", "--loop", "--speed", "4", "--tui",
                             "--record", str(path)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "COLUMNS": "100"})
    try:
        wait_for(lambda: path.exists() and path.stat().st_size > 20000)  # some chunks are on disk
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "monitor:" in out and "frames in" in out
    assert "livezmp monitor" in err  # the terminal view was drawn
    rec = open_recording(path)  # finished: no recover needed
    assert rec.counts["/input"] > 50
    assert [m["index"] for m in iter_messages(path, "/input")] == list(range(rec.counts["/input"]))


def count_inputs(path) -> int:
    """/input messages already on disk in a recording still being written."""
    n, inputs = 0, set()
    try:
        for r in StreamReader(io.BytesIO(path.read_bytes())).records:
            if isinstance(r, Channel) and r.topic == "/input":
                inputs.add(r.id)
            n += isinstance(r, Message) and r.channel_id in inputs
    except McapError:
        pass
    return n


def test_udp_stream_with_impairments_recorded_and_replayed(tmp_path, capsys):
    """The simulated streamer (noise, drops, late and duplicated frames) into `livezmp
    monitor udp://...`; Ctrl-C; the recording holds every frame delivered, and replaying
    it re-runs the same analysis."""
    motion = read_bvh(WALK)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    path = tmp_path / "udp.mcap"
    imp = Impairments(noise_deg=0.2, drop=0.05, late=0.05, duplicate=0.05, seed=2)
    streamer = UdpStreamer(motion, ("127.0.0.1", port), "binary", imp, speed=0)

    def stream_then_stop():
        wait_for(lambda: path.exists() and path.stat().st_size > 0)  # the monitor is listening
        c = streamer.run()
        wait_for(lambda: count_inputs(path) >= c.sent - c.duplicated - c.delayed)  # on disk
        signal.raise_signal(signal.SIGINT)  # handled in the main thread: a clean stop

    helper = threading.Thread(target=stream_then_stop)
    helper.start()
    summary_path = tmp_path / "summary.json"
    rc = main(["monitor", f"udp://127.0.0.1:{port}", "--skeleton", str(WALK), "--record", str(path),
               "--summary-json", str(summary_path)])
    helper.join(10)
    out = capsys.readouterr().out
    assert rc == 0 and f"source: udp://127.0.0.1:{port}" in out
    c = streamer.counters
    dup, late = (int(re.search(rf"{k} (\d+)", out).group(1)) for k in ("duplicate", "late"))
    inputs = open_recording(path).counts["/input"]
    assert dup == c.duplicated and inputs + dup + late == c.sent
    summary = json.loads(summary_path.read_text())
    assert summary["frames_in"] == summary["analysed_frames"] == inputs  # the last `lag` frames flushed at exit
    assert summary["dropped"] == {"malformed": 0, "oversized": 0, "duplicate": dup, "late": late, "rejected": 0,
                                  "overflow": 0, "jumps": 0, "total": dup + late}
    assert summary["bad_markers"] == 0  # kept frames with markers left out: not among the dropped
    assert summary["lost"] == c.dropped + late  # numbers skipped: the dropped frames and those that came late
    lat = summary["latency"]["result_after_input"]
    assert 0 < lat["p50_ms"] <= lat["p99_ms"] <= lat["max_ms"]
    assert summary["latency"]["result_after_source_stamp"] is None  # UDP frames' times are the sender's clock
    est = summary["estimator"]  # 30 Hz skeleton: cutoff 3.03 Hz, lag 0.6 / cutoff = 0.198 s, 6 frames
    assert est["cutoff_hz"] == pytest.approx(4.0 * 0.25**0.2) and est["lag_s"] == pytest.approx(0.6 / est["cutoff_hz"])
    assert (est["lag_frames"], est["lag_ms"]) == (6, pytest.approx(200.0))
    assert main(["replay", str(path)]) == 0
    assert "same analysis" in capsys.readouterr().out


def test_monitor_realtime_priority_runs_the_loop_under_sched_fifo_and_gives_it_back(monkeypatch, capsys):
    """--realtime-priority N: every frame is processed by a thread under SCHED_FIFO at N (root here; a
    refusal would be told in one line and the run goes on); normal scheduling again afterwards."""
    import os

    from livezmp.monitor.loop import Monitor

    seen = set()
    step = Monitor.step
    monkeypatch.setattr(Monitor, "step", lambda self: seen.add((os.sched_getscheduler(0),
                                                                 os.sched_getparam(0).sched_priority)) or step(self))
    before = os.sched_getscheduler(0)
    assert main(["monitor", "--speed", "0", "--frames", "40", "--realtime-priority", "7"]) == 0
    out = capsys.readouterr().out
    if "running at normal priority" in out:  # not root: refused, said, and run as usual
        assert seen == {(before, 0)}
    else:
        assert seen == {(os.SCHED_FIFO, 7)}
    assert os.sched_getscheduler(0) == before
    seen.clear()
    assert main(["monitor", "--speed", "0", "--frames", "40"]) == 0
    assert seen == {(before, 0)}
