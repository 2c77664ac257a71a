"""File replay (BVH, CSV + URDF) paced and looped, the factory's choices and one-line
errors, and body specs that rebuild exactly the body they came from."""

from __future__ import annotations

import time

import numpy as np
import pytest
from data_paths import BANDAI, OP3_URDF

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.errors import InputError
from livezmp.model.body_spec import body_from_spec, read_skeleton, robot_body, skeleton_body
from livezmp.model.bvh import read_bvh
from livezmp.model.bvh_body import BvhBodyOptions
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.euler_orders import clear_of_gimbal_lock
from livezmp.model.motion_file import trajectory_frames
from livezmp.model.trajectory_csv import JointTrajectory, write_joint_csv
from livezmp.model.urdf_body import UrdfBodyOptions
from livezmp.sources.factory import SourceOptions, open_source

WALK = BANDAI / "walk_normal_001.bvh"


def read_all(src, limit: int = 100000) -> list:
    out = []
    while not src.finished and len(out) < limit:
        f = src.read(0.5)
        if f is not None:
            out.append(f)
    return out


def test_bvh_replay_gives_the_file_frames_at_their_times_no_earlier_than_due():
    motion = clear_of_gimbal_lock(read_bvh(WALK))  # its spine at 83-85 deg of gimbal lock: analysed re-expressed
    src = open_source(str(WALK), SourceOptions(speed=20.0))
    frames = read_all(src)
    assert len(frames) == len(motion.frames) and src.finished and src.read(0.01) is None
    np.testing.assert_array_equal(np.array([f.channels for f in frames]), motion.frames)
    t = np.array([f.t for f in frames])
    np.testing.assert_allclose(t, np.arange(len(t)) * motion.frame_time)
    sent = np.array([f.received for f in frames])
    assert np.all(sent - sent[0] >= t / 20.0 - 1e-6)  # real time / 20: never ahead of schedule
    assert src.nominal_dt == pytest.approx(motion.frame_time)


def test_loop_keeps_time_increasing(tmp_path):
    traj = demo_trajectory(robot_body(demo_robot_path())[0].joint_names, duration=0.5)
    path = tmp_path / "short.csv"
    write_joint_csv(traj, path)
    src = open_source(str(path), SourceOptions(robot=str(demo_robot_path()), speed=0, loop=True))
    frames = read_all(src, limit=3 * len(traj.t) + 5)
    assert not src.finished
    t = np.array([f.t for f in frames])
    np.testing.assert_allclose(np.diff(t), 0.01, atol=1e-9)  # 100 Hz, also across the wrap
    n = len(traj.t)
    np.testing.assert_array_equal(frames[n].channels, frames[0].channels)
    src.close()
    assert src.finished and src.read(0.01) is None


@pytest.mark.parametrize("spec, options, message", [
    ("nowhere.bvh", SourceOptions(), r"nowhere.bvh: no such file"),
    ("ftp://host:1", SourceOptions(), r"unknown source scheme 'ftp'"),
    ("udp://127.0.0.1", SourceOptions(), r"need HOST:PORT"),
    ("udp://127.0.0.1:0", SourceOptions(), r"needs the body it carries: --skeleton FILE.bvh or --robot"),
    ("tcp://127.0.0.1:1", SourceOptions(robot=str(OP3_URDF)), r"--skeleton FILE.bvh \(its BVH hierarchy\)"),
    ("udp://127.0.0.1:0", SourceOptions(robot=str(OP3_URDF)), r"frame rate is unknown.*give --fps"),
    ("udp://127.0.0.1:0?port=3", SourceOptions(robot=str(OP3_URDF), fps=50), r"unknown parameter 'port'"),
    ("udp://127.0.0.1:0?allow=10.0.0.300", SourceOptions(robot=str(OP3_URDF), fps=50), r"allow: '10.0.0.300'"),
    ("udp://127.0.0.1:0?max_bytes=-5", SourceOptions(robot=str(OP3_URDF), fps=50), r"max_bytes: need a positive"),
    (str(WALK), SourceOptions(speed=-1), r"replay speed must be ≥ 0"),
    ("udp://127.0.0.1:0", SourceOptions(robot=str(OP3_URDF), fps=-3), r"--fps must be positive"),
    ("tcp://127.0.0.1:1", SourceOptions(skeleton=str(WALK)), r"cannot connect"),
])
def test_factory_errors_are_one_line(spec, options, message):
    with pytest.raises(InputError, match=message) as e:
        open_source(spec, options)
    assert "\n" not in str(e.value)


def test_csv_needs_its_robot(tmp_path):
    path = tmp_path / "m.csv"
    path.write_text("time,a\n0,0\n")
    with pytest.raises(InputError, match="needs --robot"):
        open_source(str(path))


def results(body, frames, dt):
    return Pipeline(body, default_config(body, 1 / dt), dt).run(np.arange(len(frames)) * dt, frames)


def test_skeleton_spec_rebuilds_the_same_body():
    motion = read_bvh(WALK)
    body, spec = skeleton_body(read_skeleton(WALK))
    again = body_from_spec(spec)
    assert again.channel_names == body.channel_names and again.units == "cm" and again.up_axis == "y"
    assert again.feet["left"].ankle_height == body.feet["left"].ankle_height  # calibrated from the same frames
    a, b = results(body, motion.frames, motion.frame_time), results(again, motion.frames, motion.frame_time)
    assert all(np.array_equal(x.zmp, y.zmp) and x.support == y.support for x, y in zip(a, b, strict=True))


def test_hierarchy_alone_is_a_skeleton(tmp_path):
    text = WALK.read_text()
    path = tmp_path / "skeleton.bvh"
    path.write_text(text[: text.index("MOTION")])
    sk = read_skeleton(path)
    assert not sk.has_motion and sk.motion.frames.shape == (1, 132)
    hips = sk.motion.joints[sk.motion.joint_index("Hips")]
    rest = sk.motion.frames[0, hips.first_channel: hips.first_channel + 6]
    np.testing.assert_array_equal(rest, [*hips.offset, 0, 0, 0])  # position channels hold the offset
    with pytest.raises(InputError, match="cannot tell the up axis"):  # Bandai's rest pose lies along x
        skeleton_body(sk)
    body, spec = skeleton_body(sk, BvhBodyOptions(up_axis="y"))
    assert body_from_spec(spec).channel_names == body.channel_names


def test_robot_spec_carries_its_config(tmp_path):
    """A custom robot config (longer soles) travels in the spec: the rebuilt body has its
    soles, not the built-in ones, and analyses the same."""
    custom = tmp_path / "custom.toml"
    custom.write_text((demo_robot_path().with_suffix(".toml")).read_text().replace("length = 0.12", "length = 0.20"))
    body, spec = robot_body(demo_robot_path(), UrdfBodyOptions(config=str(custom)))
    builtin, _ = robot_body(demo_robot_path())
    assert spec.files["robot.toml"] == custom.read_text()
    again = body_from_spec(spec)
    length = lambda b: np.ptp(b.feet["left"].sole_local[:, 0])  # noqa: E731
    assert length(again) == pytest.approx(0.20) and length(builtin) == pytest.approx(0.12)
    frames = trajectory_frames(body, demo_trajectory(body.joint_names, duration=2.0))
    a, b = results(body, frames, 0.01), results(again, frames, 0.01)
    assert all(np.array_equal(x.polygon, y.polygon) and x.inside == y.inside for x, y in zip(a, b, strict=True))


def test_replay_of_a_robot_trajectory_matches_its_frames(tmp_path):
    body = robot_body(demo_robot_path())[0]
    traj = JointTrajectory(np.arange(50) * 0.02, np.zeros((50, len(body.joint_names))), body.joint_names)
    path = tmp_path / "still.csv"
    write_joint_csv(traj, path)
    start = time.monotonic()
    frames = read_all(open_source(str(path), SourceOptions(robot=str(demo_robot_path()), speed=0)))
    assert len(frames) == 50 and frames[-1].t == pytest.approx(0.98)
    assert frames[-1].received >= start
