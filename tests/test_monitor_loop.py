"""The monitor loop against the offline analysis of the same frames: every frame
analysed once, the same results recorded, alarms where the out-of-support runs say;
the alarm tracker on hand-made runs, the alarm command, and the terminal view."""

from __future__ import annotations

import io
import sys
import time
from dataclasses import replace

import numpy as np
import pytest
from rich.console import Console

from livezmp.balance.pipeline import FrameResult, Pipeline, default_config
from livezmp.errors import InputError
from livezmp.model.body_spec import robot_body
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.motion_file import trajectory_frames
from livezmp.monitor.alarms import AlarmCommand, AlarmEvent, AlarmTracker
from livezmp.monitor.loop import Monitor
from livezmp.monitor.tui import TerminalView
from livezmp.recording.reader import iter_messages
from livezmp.recording.writer import Recorder
from livezmp.sources.file_replay import FileReplaySource


@pytest.fixture(scope="module")
def demo():
    body, spec = robot_body(demo_robot_path())
    traj = demo_trajectory(body.joint_names)
    return body, spec, traj.t, trajectory_frames(body, traj)


def expected_alarms(results: list[FrameResult], threshold: float) -> list[tuple[str, int]]:
    """(event, frame index) from maximal runs of frames outside the polygon."""
    out = np.array([r.inside is False for r in results])
    t = np.array([r.t for r in results])
    edges = np.flatnonzero(np.diff(np.r_[0, out.astype(int), 0]))
    events = []
    for start, stop in zip(edges[::2], edges[1::2], strict=True):  # run = frames start..stop-1
        due = np.flatnonzero(t[start:stop] - t[start] >= threshold)
        if due.size:
            events.append(("raised", results[start + due[0]].index))
            if stop < len(results):
                events.append(("cleared", results[stop].index))
    return events


def test_monitor_matches_the_offline_analysis(tmp_path, demo):
    body, spec, times, frames = demo
    cfg = default_config(body, 100.0)
    offline = Pipeline(body, cfg, 0.01).run(times, frames)
    rec = Recorder(tmp_path / "demo.mcap", spec, {"fps": 100.0}, body.channel_names)
    src = FileReplaySource("<demo>", body, spec, times, frames, speed=0)
    mon = Monitor(src, cfg, alarm_after=0.2, recorder=rec, correct=True)
    summary = mon.run()
    assert summary.inputs == summary.results == len(frames)
    assert summary.out_of_support == sum(r.inside is False for r in offline) > 50
    want = expected_alarms(offline, 0.2)
    assert [(e.event, e.index) for e in summary.events] == want and len(want) == 2
    raised = summary.events[0]
    assert raised.duration >= 0.2 and raised.worst_margin < -0.01
    path = tmp_path / "demo.mcap"
    got = list(iter_messages(path, "/result"))
    assert [m["index"] for m in got] == [r.index for r in offline]
    for m, r in zip(got, offline, strict=True):
        assert m["support"] == r.support and m["inside"] == r.inside
        assert (m["zmp"] is None) == (r.zmp is None)
        if r.zmp is not None:
            # offline `run` takes the batch path (arrays over the whole take): the same to rounding
            np.testing.assert_allclose([m["zmp"]["x"], m["zmp"]["y"], m["zmp"]["z"]], r.zmp, rtol=0, atol=1e-9)
    alarms = list(iter_messages(path, "/alarm"))
    assert [(a["event"], a["index"]) for a in alarms] == want
    corr = list(iter_messages(path, "/correction"))
    assert len(corr) == len(offline)
    leaning = [c for c in corr if raised.since <= c["t"] <= raised.t + 1.0]
    assert max(abs(c["delta"]["y"]) for c in leaning) > 0.01  # the corrector pushes back while out
    assert all(name in body.channel_names for c in corr for name in c["offsets"])


def test_result_reaches_the_dashboard_before_it_is_recorded_and_every_frame_is_recorded(tmp_path, demo):
    """Recording is not on the way from a frame to its result on the dashboard: a listener has result k
    while the recording holds results up to k - 1 (and inputs up to the frame before the one that
    completed k); afterwards the recording holds every input and every result."""
    body, spec, times, frames = demo
    cfg = default_config(body, 100.0)
    rec = Recorder(tmp_path / "order.mcap", spec, {"fps": 100.0}, body.channel_names)
    src = FileReplaySource("<demo>", body, spec, times, frames, speed=0)
    mon = Monitor(src, cfg, alarm_after=1e9, recorder=rec)
    seen = []

    class Dashboard:
        def publish(self, r, cop=None):
            seen.append((r.index, rec.counts["/result"], rec.counts["/input"], mon.inputs))

        def alarm(self, ev):
            pass

    mon.listeners.append(Dashboard())
    summary = mon.run()
    assert len(seen) == summary.results == summary.inputs == len(frames)
    streaming = [s for s in seen if s[3] < len(frames)]  # before the flush at the end
    assert len(streaming) > len(frames) - 2 * mon.pipeline.lag
    assert all(recorded == k and inputs == n - 1 for k, recorded, inputs, n in streaming)
    assert [m["index"] for m in iter_messages(tmp_path / "order.mcap", "/result")] == list(range(len(frames)))
    assert [m["index"] for m in iter_messages(tmp_path / "order.mcap", "/input")] == list(range(len(frames)))


def fake(index: int, t: float, inside: bool | None, margin: float | None = None) -> FrameResult:
    z = np.zeros(3)
    return FrameResult(index, t, z, z, z, None if inside is None else z, z, "double", np.zeros((4, 2)), {}, 0.0,
                       inside, None, margin if margin is not None else (None if inside is None else
                                                                       (0.01 if inside else -0.02)))


def test_alarm_tracker_on_hand_made_runs():
    pattern = [True, True] + [False] * 6 + [True] + [False, False] + [None] + [False] * 3
    track = AlarmTracker(0.05)
    events = [(k, ev) for k, ins in enumerate(pattern) if (ev := track.update(fake(k, k * 0.01, ins))) is not None]
    # run 1: frames 2..7 (t 0.02..0.07), due at t = 0.07; cleared at frame 8. Run 2 is 2 frames;
    # the frame without a verdict (flight) ends it; run 3 lasts 0.02 s: no alarm.
    assert [(k, ev.event) for k, ev in events] == [(7, "raised"), (8, "cleared")]
    assert events[0][1].since == 0.02 and events[1][1].duration == pytest.approx(0.06)
    assert events[0][1].worst_margin == -0.02 and track.count == 1 and not track.raised
    zero = AlarmTracker(0.0)
    assert zero.update(fake(0, 0.0, False)).event == "raised"
    with pytest.raises(InputError, match="threshold"):
        AlarmTracker(-1)


def test_alarm_command_gets_the_event(tmp_path):
    out = tmp_path / "events.txt"
    code = "import os, sys; open(sys.argv[1], 'a').write(os.environ['LIVEZMP_ALARM'] + ' ' + " \
           "os.environ['LIVEZMP_ALARM_DURATION'] + '\\n')"
    cmd = AlarmCommand(f"{sys.executable} -c \"{code}\" {out}")
    ev = AlarmEvent("raised", 5, 1.25, 1.0, 0.25, -0.03)
    cmd.run(ev)
    cmd.close()
    assert out.read_text() == "raised 0.25\n"
    slow = AlarmCommand(f"{sys.executable} -c \"import signal; signal.pause()\"")
    slow.run(ev)
    slow.run(ev)  # the first is still running: skipped, not piled up
    assert (slow.started, slow.skipped) == (1, 1)
    start = time.monotonic()
    slow.close(timeout=0.1)
    assert time.monotonic() - start < 10
    with pytest.raises(InputError, match="command not found"):
        AlarmCommand("no-such-command-livezmp --x")


def test_terminal_view_shows_the_status_and_alarms(demo):
    body, spec, times, frames = demo
    buf = io.StringIO()
    view = TerminalView(Console(file=buf, force_terminal=True, width=100, color_system=None))
    src = FileReplaySource("<demo>", body, spec, times[:800], frames[:800], speed=0)
    mon = Monitor(src, default_config(body, 100.0), alarm_after=0.2, view=view)
    summary = mon.run()
    text = buf.getvalue()
    assert "livezmp monitor — <demo>" in text
    assert f"{summary.inputs} in, {summary.results} analysed" in text
    assert "ALARM: ZMP out of support for 210 ms" in text  # the demo leans out at t ≈ 6.6 s
    assert f"{summary.out_of_support} frames" in text


class ClockStartsOver(FileReplaySource):
    """The take twice, its second pass on a clock that starts over (a capture server restarted: its frames
    come marked ``restart``, their times back at the first pass's)."""

    def read(self, timeout: float):
        f = super().read(timeout)
        return f if f is None else replace(f, t=f.t - (self._k - 1) // len(self.frames) * self.period)


def test_a_stream_whose_clock_starts_over_is_analysed_again_from_there(demo):
    """The restart finishes the first pass and starts every per-time state over (estimator, cadence, alarm):
    both passes give the same results and alarms."""
    body, spec, times, frames = demo
    cfg = default_config(body, 100.0)
    src = ClockStartsOver("<demo>", body, spec, times, frames, speed=0, loop=True)
    seen: list[FrameResult] = []
    mon = Monitor(src, cfg, alarm_after=0.2, max_inputs=2 * len(frames))
    mon._record = lambda r, *_: seen.append(r)
    summary = mon.run()
    n = len(frames)
    assert summary.inputs == summary.results == 2 * n
    first, second = seen[:n], seen[n:]
    np.testing.assert_allclose([r.t for r in second], [r.t for r in first])
    # the floor found on the first pass stays (the pipeline's, as at a looped file's wrap): the ZMP's height
    # differs by up to 1 mm, the horizontal ZMP by less
    np.testing.assert_allclose([r.zmp[:2] for r in second], [r.zmp[:2] for r in first], atol=1e-3)
    assert summary.alarms == 2 * sum(e == "raised" for e, _ in expected_alarms(first, 0.2)) > 0
