"""The batch path of the pipeline equals stepping it frame by frame: real Bandai walks (full and seed
ZMP, 30 Hz and resampled to 120 Hz, with a hop for flight frames), an OP3 joint trajectory, across
chunk boundaries; and the fallbacks (missing samples, irregular times, mid-stream)."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from data_paths import BANDAI
from scipy.interpolate import CubicSpline

from livezmp.balance.pipeline import FrameResult, Pipeline, default_config
from livezmp.errors import InputError
from livezmp.model.base_placement import place_base
from livezmp.model.bvh import read_bvh
from livezmp.model.bvh_body import body_from_bvh
from livezmp.offline.batch import BatchResult, NotBatchable, analyse_batch, analyse_frames, run_batch
from livezmp.offline.report import ZMP_COLUMNS, write_zmp_csv

CHUNK = 61  # small, so that a take crosses many chunk boundaries


def stepped(pipe: Pipeline, times: np.ndarray, frames: np.ndarray) -> list[FrameResult]:
    """The reference: every frame through ``step``, then ``flush``."""
    out = [pipe.step(float(t), f) for t, f in zip(times, frames, strict=True)]
    return [r for r in out if r is not None] + pipe.flush()


def assert_same(got: BatchResult, want: list[FrameResult], tol: float = 1e-9) -> dict:
    """Every field equal, to ``tol`` (m, or relative for velocities and accelerations); returns the
    largest differences found."""
    ref = BatchResult.from_frames(want)
    assert len(got) == len(ref) and np.array_equal(got.index, ref.index) and np.array_equal(got.t, ref.t)
    for name in ("support", "has_zmp", "judged"):
        assert np.array_equal(getattr(got, name), getattr(ref, name)), name
    assert np.array_equal(got.inside[ref.judged], ref.inside[ref.judged])
    worst = {}
    for name in ("zmp", "com", "clamped", "margin", "ground_z", "load", "q", "v", "a"):
        a, b = getattr(got, name), getattr(ref, name)
        scale = max(1.0, float(np.abs(b).max())) if name in ("v", "a") else 1.0
        worst[name] = float(np.abs(a - b).max()) / scale
        assert worst[name] <= tol, (name, worst[name])
    for side in ref.soles:
        assert np.abs(got.soles[side] - ref.soles[side]).max() <= tol
    # and back to FrameResults: the same polygons
    for r, w in zip(got.frames(), want, strict=True):
        assert r.polygon.shape == w.polygon.shape and np.abs(r.polygon - w.polygon).max(initial=0.0) <= tol
    return worst


def resampled(motion, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """The take at ``rate`` Hz, every channel interpolated by a cubic spline (angles unwrapped first)."""
    t = np.arange(len(motion.frames)) * motion.frame_time
    rot = np.array([c.endswith("rotation") for c in motion.channel_labels()])
    frames = motion.frames.copy()
    frames[:, rot] = np.unwrap(frames[:, rot], period=360.0, axis=0)
    new_t = np.arange(int(t[-1] * rate) + 1) / rate
    return new_t, CubicSpline(t, frames, axis=0)(new_t)


def with_hop(motion, times: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """The walk with a 0.5 s ballistic hop of the root (free fall: flight frames, no support)."""
    up = motion.channel_labels().index("joint_Root.Yposition")
    t0, v0, g = 2.0, 2.45, 9.81
    s = np.clip(times - t0, 0.0, 2 * v0 / g)
    out = frames.copy()
    out[:, up] += 100 * (v0 * s - 0.5 * g * s * s)  # cm
    return out


@pytest.mark.parametrize("mode", ["full", "seed"])
def test_bandai_walk_equals_per_frame(mode):
    motion = read_bvh(BANDAI / "walk_normal_002.bvh")
    body = body_from_bvh(motion)
    times = np.arange(len(motion.frames)) * motion.frame_time
    frames = with_hop(motion, times, motion.frames)
    cfg = default_config(body, motion.fps, mode)
    want = stepped(Pipeline(body, cfg, motion.frame_time), times, frames)
    got = run_batch(Pipeline(body, cfg, motion.frame_time), times, frames, chunk=CHUNK, keep_states=True)
    assert got.path == "batch"
    worst = assert_same(got, want)
    labels = set(got.labels)
    assert labels == {"left", "right", "double", "none"}  # every support, flight included
    # flight: the hop's step to free fall, smoothed at 3 Hz (30 Hz default), is near -g for 4 frames
    assert (~got.has_zmp).sum() >= 3 and got.judged.sum() > 150 and (~got.inside[got.judged]).sum() > 10
    print(f"\n{mode}: largest batch - per-frame differences {worst}")


def test_bandai_walk_at_120_hz_equals_per_frame():
    motion = read_bvh(BANDAI / "walk_normal_001.bvh")
    body = body_from_bvh(motion)
    times, frames = resampled(motion, 120.0)
    cfg = default_config(body, 120.0)
    want = stepped(Pipeline(body, cfg, 1 / 120), times, frames)
    got = run_batch(Pipeline(body, cfg, 1 / 120), times, frames, chunk=150, keep_states=True)
    worst = assert_same(got, want)
    assert len(set(got.labels)) >= 3
    print(f"\n120 Hz: largest batch - per-frame differences {worst}")


def test_robot_trajectory_equals_per_frame(op3_body):
    body = op3_body
    rate = 100.0
    t = np.arange(500) / rate
    rng = np.random.default_rng(0)
    q = np.zeros((len(t), len(body.joint_names)))
    for j in range(q.shape[1]):
        q[:, j] = rng.uniform(0.02, 0.15) * np.sin(2 * np.pi * rng.uniform(0.3, 1.2) * t + rng.uniform(0, 6))
    bend = 0.4 * (1 - np.cos(2 * np.pi * 0.5 * t))  # squat and rise: knees and ankles
    for joint, sign in (("l_hip_pitch", -1), ("l_knee", 2), ("l_ank_pitch", 1), ("r_hip_pitch", 1),
                        ("r_knee", -2), ("r_ank_pitch", -1)):
        q[:, body.joint_names.index(joint)] += sign * bend
    frames = np.hstack([place_base(body, q), q])
    cfg = default_config(body, rate)
    want = stepped(Pipeline(body, cfg, 1 / rate), t, frames)
    got = run_batch(Pipeline(body, cfg, 1 / rate), t, frames, chunk=CHUNK, keep_states=True)
    assert_same(got, want)
    assert got.judged.sum() > 100


def test_analyse_frames_is_the_batch_path_and_keeps_the_detector_state(bandai_walk):
    """``analyse_frames`` twice on one pipeline: the second take starts from the contact state the first left."""
    body = body_from_bvh(bandai_walk)
    times = np.arange(len(bandai_walk.frames)) * bandai_walk.frame_time
    cfg = default_config(body, bandai_walk.fps)
    ref, pipe = Pipeline(body, cfg, bandai_walk.frame_time), Pipeline(body, cfg, bandai_walk.frame_time)
    for frames in (bandai_walk.frames, bandai_walk.frames[::-1]):
        want = stepped(ref, times, frames)
        got = analyse_frames(pipe, times, frames)
        assert all(isinstance(r, FrameResult) for r in got)
        assert_same(BatchResult.from_frames(got), want)
        assert (pipe.contacts.left, pipe.contacts.right, pipe.contacts.frame) == \
            (ref.contacts.left, ref.contacts.right, ref.contacts.frame)


def test_missing_samples_irregular_times_and_mid_stream_fall_back(bandai_walk):
    body = body_from_bvh(bandai_walk)
    dt = bandai_walk.frame_time
    times = np.arange(len(bandai_walk.frames)) * dt
    cfg = default_config(body, bandai_walk.fps)
    gappy = bandai_walk.frames.copy()
    gappy[100:103, 10:20] = np.nan
    late = times.copy()
    late[120:] += 0.5 * dt
    pipe = Pipeline(body, cfg, dt)
    for t, f in ((times, gappy), (late, bandai_walk.frames)):
        with pytest.raises(NotBatchable):
            analyse_batch(body, cfg, pipe.estimator, pipe.contacts, t, f)
        want = stepped(Pipeline(body, cfg, dt), t, f)
        got = run_batch(Pipeline(body, cfg, dt), t, f, keep_states=True)
        assert got.path.startswith("per-frame: ")  # the choice is named
        assert_same(got, want, tol=0.0)  # the per-frame path itself
        assert not np.isnan(got.zmp).any()
    # frames already stepped: the rest of the stream continues frame by frame
    a, b = Pipeline(body, cfg, dt), Pipeline(body, cfg, dt)
    for t, f in zip(times[:50], bandai_walk.frames[:50], strict=True):
        a.step(float(t), f)
        b.step(float(t), f)
    got = run_batch(a, times[50:], bandai_walk.frames[50:], keep_states=True)
    assert got.path == "per-frame: the stream was already stepped"
    want = stepped(b, times[50:], bandai_walk.frames[50:])
    assert got.index[0] == 50 - a.lag
    assert_same(got, want, tol=0.0)


def test_progress_is_reported_up_to_the_whole_take(bandai_walk):
    body = body_from_bvh(bandai_walk)
    dt = bandai_walk.frame_time
    n = len(bandai_walk.frames)
    times = np.arange(n) * dt
    gappy = bandai_walk.frames.copy()
    gappy[100, 10] = np.nan  # the per-frame path
    for frames, last in ((bandai_walk.frames, n), (gappy, (n - 1) // 500 * 500)):
        seen = []
        run_batch(Pipeline(body, default_config(body, bandai_walk.fps), dt), times, frames, chunk=64,
                                                                            progress=seen.append)
        assert seen and seen == sorted(seen) and seen[-1] == last


def test_zmp_csv_is_the_row_by_row_text(tmp_path):
    """The vectorised writer gives byte for byte what csv.writer gives row by row (empty ZMP and clamp
    cells in flight), from the per-frame results of a walk with a hop."""
    motion = read_bvh(BANDAI / "walk_normal_002.bvh")
    body = body_from_bvh(motion)
    times = np.arange(len(motion.frames)) * motion.frame_time
    results = stepped(Pipeline(body, default_config(body, motion.fps), motion.frame_time), times,
                      with_hop(motion, times, motion.frames))

    def xyz(p):
        return ["", "", ""] if p is None else [f"{v:.6f}" for v in body.to_input_frame(p)]

    want = tmp_path / "want.csv"
    with open(want, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(ZMP_COLUMNS)
        for r in results:
            w.writerow([r.index, f"{r.t:.6f}", *xyz(r.zmp), *xyz(r.com), r.support,
                        "" if r.inside is None else int(r.inside), *xyz(r.clamped),
                        "" if r.margin is None else f"{r.margin:.6f}"])
    got = tmp_path / "got.csv"
    write_zmp_csv(body, BatchResult.from_frames(results, keep_states=False), got)
    assert got.read_bytes() == want.read_bytes()
    assert ",,,," in want.read_text()  # flight rows were compared too


def test_a_zmp_csv_refused_for_a_non_finite_cell_leaves_no_file(tmp_path, bandai_walk):
    """A result whose ZMP went non-finite is refused in one line naming the frame and column, before
    the file is opened: no header-only zmp.csv is left behind."""
    body = body_from_bvh(bandai_walk)
    times = np.arange(len(bandai_walk.frames)) * bandai_walk.frame_time
    cfg = default_config(body, bandai_walk.fps)
    pipe = Pipeline(body, cfg, bandai_walk.frame_time)
    result, _ = analyse_batch(body, cfg, pipe.estimator, pipe.contacts, times, bandai_walk.frames)
    k = int(np.flatnonzero(result.has_zmp)[5])
    result.zmp[k, 0] = np.nan
    path = tmp_path / "zmp.csv"
    with pytest.raises(InputError, match=rf"zmp.csv: frame {k} column zmp_\w is not finite"):
        write_zmp_csv(body, result, path)
    assert not path.exists()
