"""A BVH take analysed in bounded memory (offline/take_stream.py, take.stream_take) against the
whole-take path it replaces for BVH: the same zmp.csv bytes and the same summary, across chunk
boundaries, on real walks and on a long take made from one; the per-frame fallback mid-take;
bad rows in a late chunk; and the bounded-memory parts (upper percentiles, plausibility, the
figure's series, the streaming reader) against their whole-array references."""

from __future__ import annotations

import gc
import math
import warnings
from dataclasses import replace

import numpy as np
import pytest
from data_paths import BANDAI

from livezmp.cli import main
from livezmp.estimate.estimator import FILE_CUTOFF_HZ, default_estimator
from livezmp.model import bvh as bvh_module
from livezmp.model.bvh import read_bvh, stream_bvh, write_bvh
from livezmp.offline.batch import BatchResult, run_batch
from livezmp.offline.plausibility import PlausibilityStats, plausibility
from livezmp.offline.plot import PlotSeries
from livezmp.offline.report import TakeStats, summarize, write_zmp_csv
from livezmp.offline.take import TakeOptions, analyse_motion, stream_take, take_config
from livezmp.offline.take_stream import analyse_stream, open_bvh_take
from livezmp.offline.upper_quantile import UpperQuantile

OPTIONS = TakeOptions()
WINDOW_30HZ = default_estimator(30.0, FILE_CUTOFF_HZ).window  # a file's spline window at 30 Hz: a chunk holds two


def whole(path, tmp_path, options=OPTIONS):
    """Today's whole-take path: its summary and zmp.csv bytes."""
    a = analyse_motion(options.load(path), options)
    write_zmp_csv(a.body, a.result, tmp_path / "whole.csv")
    return a.summary, (tmp_path / "whole.csv").read_bytes()


def chunked(path, tmp_path, chunk, options=OPTIONS):
    summary = stream_take(path, options, tmp_path / "chunked.csv", chunk=chunk)
    return summary, (tmp_path / "chunked.csv").read_bytes()


def long_take(tmp_path, frames: int, name: str = "long.bvh"):
    """A walk played forwards and backwards (no jump at the turns) to ``frames`` frames."""
    walk = read_bvh(BANDAI / "walk_normal_002.bvh")
    there_and_back = np.vstack([walk.frames, walk.frames[::-1]])
    rows = np.vstack([there_and_back] * (frames // len(there_and_back) + 1))[:frames]
    path = tmp_path / name
    write_bvh(replace(walk, frames=rows), path)
    return path


@pytest.mark.parametrize("name", ["walk_normal_002.bvh", "walk_active_001.bvh", "walk_elderly_003.bvh"])
def test_chunked_equals_whole_on_real_walks(tmp_path, name):
    """Many chunks (the last a partial one): the same bytes and summary as the whole take."""
    assert chunked(BANDAI / name, tmp_path, 2 * WINDOW_30HZ + 5) == whole(BANDAI / name, tmp_path)


@pytest.mark.parametrize("tail", [0, 1, 7])
def test_chunk_boundaries(tmp_path, tail):
    """A take of 5 chunks plus ``tail`` frames: a multiple of the chunk, one frame after it (the
    flush and the CoM differences spanning the last two chunks), a few frames after it."""
    chunk = 2 * WINDOW_30HZ
    path = long_take(tmp_path, 5 * chunk + tail)
    assert chunked(path, tmp_path, chunk) == whole(path, tmp_path)


def test_long_generated_take(tmp_path):
    """3000 frames (the walk there and back, several times) in chunks of 256 and of the default size."""
    path = long_take(tmp_path, 3000)
    want = whole(path, tmp_path)
    assert want[0]["frames"] == 3000
    assert chunked(path, tmp_path, 256) == want
    assert stream_take(path, OPTIONS) == want[0]


class Collect:
    def start(self):
        self.parts = []

    def add(self, part):
        self.parts.append(part)


def test_per_frame_fallback_after_some_chunks(tmp_path):
    """A rotation turning by exactly 180° at frame 120 (the Kalman innovation reaches ±π there):
    the batch path gives up in a late chunk, the take is read again and stepped frame by frame,
    equal to the whole-take path's fallback; without the restart the consumers would hold the
    first chunks twice."""
    walk = read_bvh(BANDAI / "walk_normal_002.bvh")
    frames = walk.frames.copy()
    rot = walk.channel_labels().index(next(c for c in walk.channel_labels() if c.endswith("rotation")
                                           and not c.startswith(walk.joints[0].name)))
    frames[120:, rot] += 180.0
    path = tmp_path / "flip.bvh"
    write_bvh(replace(walk, frames=frames), path)
    take = open_bvh_take(path, OPTIONS.bvh_options())
    cfg = take_config(take, "full", None)
    got, stats = Collect(), TakeStats(take.total, take.fps)
    path_taken = analyse_stream(take, cfg, [got, stats], chunk=2 * WINDOW_30HZ)
    loaded = OPTIONS.load(path)
    from livezmp.balance.pipeline import Pipeline

    want = run_batch(Pipeline(loaded.body, cfg, nominal_dt=1 / loaded.fps), loaded.times, loaded.frames)
    assert path_taken.startswith("per-frame") and want.path == path_taken
    result = BatchResult.concatenate(got.parts)
    assert np.array_equal(result.index, np.arange(len(frames)))
    for name in ("t", "zmp", "com", "support", "judged", "inside", "clamped", "margin", "ground_z"):
        assert np.array_equal(getattr(result, name), getattr(want, name)), name
    assert stats.summary(loaded.body, "full") == summarize(loaded.body, want, loaded.fps, "full")


def bad_late_row(tmp_path, frames: int, bad_frame: int):
    path = long_take(tmp_path, frames, "bad.bvh")
    lines = path.read_text().splitlines()
    first_row = lines.index(next(ln for ln in lines if ln.startswith("Frame Time:"))) + 1
    tokens = lines[first_row + bad_frame].split()
    lines[first_row + bad_frame] = " ".join(["nan", *tokens[1:]])
    path.write_text("\n".join(lines) + "\n")
    return path, first_row + bad_frame + 1  # 1-based line number


def test_bad_row_in_a_late_chunk_is_one_line_and_leaves_no_file(tmp_path, capsys):
    """`analyze --out` of a take whose frame 9000 (the second chunk of 8192) is bad: exit 2, one line
    naming the file and the row's line, no zmp.csv and no temporary file left."""
    path, line = bad_late_row(tmp_path, 9100, 9000)
    out = tmp_path / "out"
    out.mkdir()
    rc = main(["analyze", str(path), "--out", str(out / "zmp.csv")])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1, err
    assert err[0].startswith(f"livezmp: error: {path}:{line}: value nan in frame 9000 is not finite"), err[0]
    assert list(out.iterdir()) == []


def test_truncated_and_extra_rows_after_the_chunks(tmp_path, capsys):
    path = long_take(tmp_path, 100)
    text = path.read_text()
    for changed, says in ((text.replace("Frames: 100", "Frames: 101"), "truncated: header says Frames: 101"),
                          (text.replace("Frames: 100", "Frames: 99"), "extra rows: header says Frames: 99")):
        path.write_text(changed)
        assert main(["analyze", str(path), "--out", str(tmp_path / "z.csv")]) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and says in err[0], err
        assert not (tmp_path / "z.csv").exists()


def test_stream_reader_equals_read_bvh_with_small_text_blocks(tmp_path, monkeypatch):
    """Text blocks of 100 bytes (a multi-byte character and CRLF line ends split between blocks):
    the frames and a late bad byte's line number as the whole-text reader gives them."""
    walk = read_bvh(BANDAI / "walk_normal_002.bvh")
    path = tmp_path / "w.bvh"
    write_bvh(replace(walk, joints=[replace(walk.joints[0], name="Hüfte"), *walk.joints[1:]]), path)
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r\n"))
    monkeypatch.setattr(bvh_module, "MOTION_BLOCK_CHARS", 100)
    header, blocks = stream_bvh(path, rows=50)
    got = np.vstack(list(blocks))
    assert header.n_frames == len(got) and np.array_equal(got, read_bvh(path).frames)
    data = path.read_bytes()
    bad = data[:len(data) - 500] + b"\xff" + data[len(data) - 499:]
    path.write_bytes(bad)
    with pytest.raises(Exception) as whole_error:
        read_bvh(path)
    with pytest.raises(Exception) as stream_error:
        list(stream_bvh(path, rows=50)[1])
    assert str(stream_error.value) == str(whole_error.value) and "not UTF-8" in str(whole_error.value)


def test_upper_quantile_is_numpys_percentile():
    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(1, 2000))
        x = np.round(rng.standard_normal(n), int(rng.integers(0, 4)))  # with ties
        q = float(rng.choice([50, 95, 99, 99.9, 100]))
        u = UpperQuantile(n + int(rng.integers(0, 40)), q)  # fewer values than announced, too
        for piece in np.array_split(x, int(rng.integers(1, 40))):
            u.add(piece)
        assert u.value() == float(np.percentile(x, q))
        assert len(u.top) <= math.ceil(n * (1 - q / 100)) + 42


def test_plausibility_in_chunks_down_to_one_frame():
    rng = np.random.default_rng(4)
    n, dt = 500, 1 / 120
    com = np.cumsum(rng.standard_normal((n, 3)) * 0.01, axis=0)
    zmp = com + rng.standard_normal((n, 3)) * 0.1
    has = rng.random(n) < 0.9
    want = plausibility(com, zmp, has, dt)
    cuts = np.sort(rng.choice(np.arange(1, n), 120, replace=False))
    cuts = np.concatenate([[1, 2, 3], cuts[cuts > 3]])  # 1-frame chunks at the start too
    stats = PlausibilityStats(n, dt)
    for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, n], strict=True):
        stats.add(com[lo:hi], zmp[lo:hi], has[lo:hi])
    assert stats.result() == want


def test_plausibility_reads_its_spill_back_in_blocks(monkeypatch):
    """The path's means read the spilled velocities and accelerations back block by block with a margin of two
    means' reach: blocks of 37 frames give the figures of one block."""
    from livezmp.offline import plausibility as module

    rng = np.random.default_rng(5)
    n, dt = 700, 1 / 100
    t = np.arange(n) * dt
    com = np.column_stack([np.cos(t), np.sin(t), np.full(n, 0.9)]) + rng.standard_normal((n, 3)) * 0.002
    want = plausibility(com, com, np.ones(n, bool), dt)
    monkeypatch.setattr(module, "BLOCK_FRAMES", 37)
    got = plausibility(com, com, np.ones(n, bool), dt)
    assert got["com_acc_p99_mps2"] == pytest.approx(want["com_acc_p99_mps2"], abs=1e-3)
    assert got["path_acc_p99_mps2"] == pytest.approx(want["path_acc_p99_mps2"], abs=1e-3) != 0


def test_plot_series_keeps_every_kth_frame_within_the_bound(monkeypatch):
    from livezmp.offline import plot

    monkeypatch.setattr(plot, "PLOT_FRAMES", 100)
    rows = 1000
    result = BatchResult.from_frames([], keep_states=False)
    series = PlotSeries()
    for lo in range(0, rows, 37):
        part = result.concatenate([result])  # an empty result's shape, filled below
        n = min(37, rows - lo)
        part = replace(part, index=np.arange(lo, lo + n), t=np.arange(lo, lo + n) / 100.0, zmp=np.zeros((n, 3)),
                       has_zmp=np.ones(n, bool), com=np.zeros((n, 3)), support=np.zeros(n, np.int8),
                       judged=np.ones(n, bool), inside=np.ones(n, bool), clamped=np.zeros((n, 3)),
                       margin=np.zeros(n), ground_z=np.zeros(n), load=np.ones(n), soles={})
        series.add(part)
    kept = series.result().index
    assert np.array_equal(kept, np.arange(0, rows, 16))  # 1000 frames / 100: every 16th (a power of 2)


def test_correct_refuses_a_take_longer_than_its_limit(tmp_path, capsys, monkeypatch):
    """correct holds a take whole: above MAX_CORRECT_FRAMES it refuses in one line, before solving."""
    from livezmp.offline import take

    monkeypatch.setattr(take, "MAX_CORRECT_FRAMES", 264)
    walk = BANDAI / "walk_normal_002.bvh"  # 265 frames
    assert main(["correct", str(walk), "-o", str(tmp_path / "c.bvh")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and f"{walk}: 265 frames; correct solves a whole take at once" in err[0], err
    assert list(tmp_path.iterdir()) == []


def test_c3d_input_has_the_input_size_limit(tmp_path, capsys, monkeypatch):
    """ezc3d reads a C3D whole: the input limit applies to it (refused before ezc3d runs)."""
    from data_paths import C3D

    from livezmp import checks

    monkeypatch.setattr(checks, "MAX_FILE_BYTES", 100_000)
    trial = C3D / "sample01_gait_forceplates.c3d"  # 156 672 bytes
    assert main(["analyze", str(trial)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and f"{trial}: 156672 bytes, more than the 0 MiB limit for a C3D file" in err[0], err


def test_a_restarted_takes_stats_leave_no_spill_file_open(tmp_path):
    """TakeStats starts on creation and again when the stream starts it: the first start's plausibility spill (a
    temporary file) was dropped unclosed, one ResourceWarning ("unclosed file") per analysed take."""
    stats = TakeStats(10, 100.0)
    first = stats.plausibility.spill
    stats.start()
    assert first.closed and not stats.plausibility.spill.closed
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        assert main(["analyze", str(BANDAI / "walk_normal_006.bvh"), "--out", str(tmp_path / "z.csv")]) == 0
        gc.collect()
    assert not [w for w in said if w.category is ResourceWarning]
