"""Force plates in the monitor: each input's measured centre of pressure is paired with
the analysed frame of the same input (the analysis runs `lag` frames behind), compared
with its ZMP (summary cop_vs_zmp), recorded beside it and shown on the dashboard.

Truth: plates that measure exactly the offline ZMP of each frame (moved by a known
offset), so the distance is the offset to rounding; a pairing off by even one frame
would show the ZMP's motion over a frame instead."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.model.body_spec import robot_body
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.motion_file import trajectory_frames
from livezmp.monitor.loop import Monitor
from livezmp.recording.reader import iter_messages
from livezmp.recording.writer import Recorder
from livezmp.sources.file_replay import FileReplaySource

OFFSET = np.array([0.004, -0.003, 0.0])  # 5 mm horizontally


class PlateSource:
    """The demo replay with plates reading ``cops[k]`` (input world frame) at input k."""

    def __init__(self, inner: FileReplaySource, cops: np.ndarray):
        self.inner, self.cops, self.k = inner, cops, 0

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def read(self, timeout: float):
        f = self.inner.read(timeout)
        if f is not None:
            f = dataclasses.replace(f, cop=self.cops[self.k])
            self.k += 1
        return f


class Published:
    def __init__(self):
        self.pairs = []

    def publish(self, r, cop=None):
        self.pairs.append((r.index, cop))

    def alarm(self, ev):
        pass


@pytest.fixture(scope="module")
def demo():
    body, spec = robot_body(demo_robot_path())
    traj = demo_trajectory(body.joint_names)
    frames = trajectory_frames(body, traj)
    offline = Pipeline(body, default_config(body, 100.0), 0.01).run(traj.t, frames)
    zmp = np.full((len(frames), 3), np.nan)
    for r in offline:
        if r.zmp is not None:
            zmp[r.index] = r.zmp
    cops = body.to_input_frame(zmp + OFFSET)  # plates report in the input's world frame
    return body, spec, traj.t, frames, cops, zmp


def test_plate_cop_paired_with_its_frame_compared_recorded_and_published(demo, tmp_path):
    body, spec, times, frames, cops, zmp = demo
    src = PlateSource(FileReplaySource("<demo>", body, spec, times, frames, speed=0), cops)
    rec = Recorder(tmp_path / "p.mcap", spec, {"fps": 100.0}, body.channel_names)
    seen = Published()
    mon = Monitor(src, default_config(body, 100.0), recorder=rec, listeners=[seen])
    mon.run()
    s = mon.summary_json()["cop_vs_zmp"]
    compared = int(np.count_nonzero(~np.isnan(zmp[:, 0])))
    assert s["frames"] == compared > 1000 and s["readings"] == len(frames)
    assert s["no_cop"] == len(frames) - compared  # unloaded plates (NaN) where the analysis had no ZMP
    assert s["mean_mm"] == pytest.approx(5.0, abs=1e-6) and s["max_mm"] == pytest.approx(5.0, abs=1e-6)
    for index, cop in seen.pairs:  # the dashboard gets each frame's own CoP, internal frame
        assert (cop is None) == np.isnan(zmp[index, 0])
        if cop is not None:
            np.testing.assert_allclose(cop, zmp[index] + OFFSET, atol=1e-12)
    recorded = {m["index"]: m.get("cop") for m in iter_messages(tmp_path / "p.mcap", "/result")}
    k = next(i for i in recorded if recorded[i] is not None)
    np.testing.assert_allclose([recorded[k][a] for a in "xyz"], zmp[k] + OFFSET, atol=1e-12)


def test_without_plates_there_is_no_comparison(demo):
    body, spec, times, frames, _, _ = demo
    mon = Monitor(FileReplaySource("<demo>", body, spec, times[:300], frames[:300], speed=0),
                  default_config(body, 100.0))
    mon.run()
    assert mon.summary_json()["cop_vs_zmp"] is None
