"""BVH joints near gimbal lock: re-expressed in another rotation order, the same poses, a sane ZMP."""

from __future__ import annotations

import threading
import time

import numpy as np
import pinocchio as pin
import pytest
from scipy.spatial.transform import Rotation
from test_body import make_bvh

from livezmp.balance.pipeline import Pipeline
from livezmp.model.bvh import parse_bvh, read_bvh, write_bvh
from livezmp.model.bvh_body import body_from_bvh
from livezmp.model.euler_orders import clear_of_gimbal_lock, near_lock
from livezmp.model.motion_file import load_motion, write_motion
from livezmp.offline.batch import run_batch
from livezmp.offline.take import take_config
from livezmp.offline.take_stream import open_bvh_take
from livezmp.sources.factory import SourceOptions, open_source
from sim_devices.mocap_streamer import TcpStreamer, UdpStreamer

RATE = 100.0


def knee_past_90(frames: int = 300):
    """The test skeleton standing on its right leg while its left knee flexes from 0 to 115° and back (3 s), the
    knee turned 6° about its long axis, written as an exporter writes it: ZXY Euler angles with the middle one in
    [-90°, 90°], so the angles flip and spin where the flexion passes 90°."""
    motion = parse_bvh(make_bvh(frames=frames), "knee.bvh")
    names = [j.name for j in motion.joints]
    knee = motion.joints[names.index("LeftLeg")]
    t = np.arange(frames) / RATE
    flexion = np.radians(115.0) * np.sin(np.pi * t / t[-1]) ** 2
    true = Rotation.from_euler("x", flexion[:, None]) * Rotation.from_euler("y", np.radians(6.0))
    motion.frames[:, knee.first_channel:knee.first_channel + 3] = true.as_euler("ZXY", degrees=True)
    motion.frame_time = 1.0 / RATE
    return motion


def loads(motion, body=None, frames=None) -> tuple[np.ndarray, np.ndarray]:
    """Vertical ground force / weight and where a ZMP was found, every frame, through the analysis pipeline (the
    body and frames of ``motion``, or those given)."""
    body = body or body_from_bvh(motion)
    frames = motion.frames if frames is None else frames

    class Loaded:  # what take_config reads of a take
        pass

    loaded = Loaded()
    loaded.body, loaded.fps = body, RATE
    pipe = Pipeline(body, take_config(loaded, "full", None, None), nominal_dt=1.0 / RATE)
    r = run_batch(pipe, np.arange(len(frames)) / RATE, frames)
    return r.load, r.has_zmp


def test_the_knee_is_found_near_gimbal_lock_and_re_expressed():
    motion = knee_past_90()
    names = [j.name for j in motion.joints]
    assert {names[k] for k in near_lock(motion.joints, motion.frames)} == {"LeftLeg"}
    fixed = clear_of_gimbal_lock(motion)
    changed = [a.name for a, b in zip(motion.joints, fixed.joints, strict=True) if a.channels != b.channels]
    assert changed == ["LeftLeg"]
    k = fixed.joints[names.index("LeftLeg")]
    assert np.max(np.abs(np.diff(fixed.frames[:, k.first_channel:k.first_channel + 3], axis=0))) < 5.0  # deg/frame
    # a standing take is left as it is
    still = parse_bvh(make_bvh(frames=5), "still.bvh")
    assert clear_of_gimbal_lock(still) is still


def test_re_expressed_joints_give_the_same_poses():
    motion = knee_past_90()
    fixed = clear_of_gimbal_lock(motion)
    a, b = body_from_bvh(motion), body_from_bvh(fixed)
    da, db = a.model.createData(), b.model.createData()
    for i in range(0, len(motion.frames), 7):
        pin.framesForwardKinematics(a.model, da, a.channels_to_q(motion.frames[i]))
        pin.framesForwardKinematics(b.model, db, b.channels_to_q(fixed.frames[i]))
        for name in ("LeftFoot", "LeftToeBase.end", "Head.end"):
            pa = da.oMf[a.model.getFrameId(name)].translation
            pb = db.oMf[b.model.getFrameId(name)].translation
            assert np.allclose(pa, pb, atol=1e-9)


def test_the_zmp_dynamics_stay_sane_and_fail_without_it():
    motion = knee_past_90()
    load, has = loads(clear_of_gimbal_lock(motion))
    assert has.all()
    assert np.all(np.abs(load - 1.0) < 0.15)  # a slow knee flexion: the ground carries the weight
    # the file's own angles spin up to 180° a frame: 280 times the weight until the per-frame Kalman filter unwrapped
    # each sample against the previous one (held-out C3D round 5); now 0.038 of it, 5.6 times the re-expressed
    # angles' error, and only these keep the batch path (the spins' innovations reach ±π)
    raw_load, raw_has = loads(motion)
    assert np.max(np.abs(raw_load - 1.0)) > 3 * np.max(np.abs(load - 1.0))


@pytest.mark.parametrize("chunk", [7, 1000])
def test_the_streamed_take_reads_the_same_frames(tmp_path, chunk):
    path = tmp_path / "knee.bvh"
    write_bvh(knee_past_90(), path)
    whole = load_motion(path)
    take = open_bvh_take(path, None)
    # the take's own rows (this generated take closes on itself: a loop, played with a cycle's pads around it)
    streamed = np.concatenate([block for _, block in take.pieces(chunk)])[take.lead: take.lead + take.total]
    load, has = loads(None, whole.body, whole.frames)  # what `livezmp correct` analyses
    assert has.all() and np.all(np.abs(load - 1.0) < 0.15)
    assert np.allclose(streamed, whole.frames, atol=1e-9)


def test_correct_writes_the_files_own_rotation_orders_back(tmp_path):
    """A re-expressed joint goes back to the file's order on writing: a joint the correction leaves alone gets its
    own angles back, whatever order the analysis used."""
    path = tmp_path / "knee.bvh"
    motion = knee_past_90()
    write_bvh(motion, path)
    loaded = load_motion(path)
    assert loaded.bvh_orders
    write_motion(loaded, loaded.frames, tmp_path / "back.bvh")
    back = read_bvh(tmp_path / "back.bvh")
    assert [j.channels for j in back.joints] == [j.channels for j in motion.joints]
    assert np.allclose(back.frames, read_bvh(path).frames, atol=1e-6)


def streamed(motion, skeleton, scheme: str):
    """``motion``'s frames as a live ``scheme`` source given ``skeleton`` delivers them (over a loopback socket from
    the simulated streamer), and the source's body."""
    if scheme == "tcp":
        server = TcpStreamer(motion, speed=0)
        src = open_source(f"tcp://127.0.0.1:{server.port}", SourceOptions(skeleton=str(skeleton)))
    else:
        src = open_source("udp://127.0.0.1:0", SourceOptions(skeleton=str(skeleton)))
        server = UdpStreamer(motion, ("127.0.0.1", src.port), speed=5.0)  # paced: datagrams are not queued
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    out, end = [], time.monotonic() + 10
    while len(out) < len(motion.frames) and time.monotonic() < end:
        if (f := src.read(0.05)) is not None:
            out.append(f.channels)
    server.stop.set()
    thread.join(5)
    src.close()
    return np.array(out), src.body


@pytest.mark.parametrize("scheme", ["tcp", "udp"])
def test_a_live_stream_is_analysed_clear_of_gimbal_lock(tmp_path, scheme):
    """The knee take streamed live with itself as the skeleton (`monitor tcp://... --skeleton knee.bvh`): its
    rows are re-expressed one at a time into the orders the skeleton's frames call for, and the ground carries
    the weight, as for the file (in the file's orders: 280 times the weight, above)."""
    motion = knee_past_90()
    path = tmp_path / "knee.bvh"
    write_bvh(motion, path)
    rows, body = streamed(motion, path, scheme)
    assert len(rows) == len(motion.frames)
    load, has = loads(None, body, rows)
    assert has.all() and np.all(np.abs(load - 1.0) < 0.15)
