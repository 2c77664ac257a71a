"""One take's analysis in bounded memory: ``livezmp analyze`` and ``livezmp batch analyze`` of a BVH
or of a robot's joint CSV.

The file is read a chunk of frames at a time (:func:`livezmp.model.bvh.stream_bvh`; a joint CSV,
which has no frame count and whose times are a column, is first checked from end to end in bounded
memory, :func:`livezmp.model.trajectory_csv.scan_joint_csv`, then read again a chunk at a time), a
BVH's body is made from its first seconds (all :func:`livezmp.model.bvh_body.body_from_bvh` reads), and each
chunk goes through the batch path (:func:`livezmp.offline.batch.batch_chunks`, the estimator's and
contact detector's state carried from chunk to chunk) to the consumers: the zmp.csv writer, the
summary statistics, the figure's series. A worker's peak memory is then a few chunks, whatever the
take's length, and the results equal the whole-take path's (:func:`livezmp.offline.take.analyse_loaded`
and :func:`livezmp.offline.report.summarize`) to rounding. A take the batch path cannot reproduce
(:class:`NotBatchable`, e.g. an angle's Kalman innovation reaching ±π in a late chunk) is read again
from the start and stepped frame by frame, the consumers restarted, as the whole-take path does.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Protocol

import numpy as np

from livezmp.balance.pipeline import Pipeline, PipelineConfig
from livezmp.checks import check_input_file
from livezmp.errors import InputError
from livezmp.model.base_placement import BasePlacer
from livezmp.model.body import BodyModel
from livezmp.model.bvh import BvhMotion, stream_bvh
from livezmp.model.bvh_body import CALIBRATION_S, BvhBodyOptions, body_from_bvh
from livezmp.model.euler_orders import reexpress, reordered_joints, scan_orders
from livezmp.model.loop_cycle import MAX_LOOP_S, Loop, find_loop
from livezmp.model.motion_file import trajectory_frames
from livezmp.model.rest_pose import hold_rest, without_rest_pose
from livezmp.model.trajectory_csv import joint_csv_blocks, scan_joint_csv
from livezmp.model.urdf_body import UrdfBodyOptions, body_from_urdf
from livezmp.offline.batch import DEFAULT_CHUNK, BatchResult, NotBatchable, batch_chunks


class Consumer(Protocol):
    """Takes a take's results chunk by chunk; ``start`` (again) forgets what it was given."""

    def start(self) -> None: ...

    def add(self, part: BatchResult) -> None: ...


@dataclass
class TakeStream:
    """A take read lazily: its ``body``, frame rate ``fps`` (Hz, as :class:`LoadedMotion` computes it),
    ``total`` frames, ``source``; ``pieces(chunk)`` reads it (again) from its first frame as
    (times (c,) s, frames (c, nq) raw channels), ``chunk`` frames each but the last; ``rest_frames`` a BVH's
    leading rest-pose frames, held at its first moving pose (:mod:`livezmp.model.rest_pose`); ``loop`` a looped
    cycle's, whose ``pieces`` then play ``lead`` frames of the loop before the take's first and after its last
    (:mod:`livezmp.model.loop_cycle`; their results are dropped)."""

    body: BodyModel
    fps: float
    total: int
    source: str
    pieces: Callable[[int], Iterator[tuple[np.ndarray, np.ndarray]]]
    rest_frames: int = 0
    loop: Loop | None = None
    lead: int = 0

    def check_length(self) -> None:
        """Refuse a take too short to analyse (:func:`check_enough_frames`)."""
        check_enough_frames(self.source, self.total)


def check_enough_frames(source: str | Path, frames: int) -> None:
    """Refuse a take of fewer than 2 frames, before its rate (0 Hz for one frame) is used."""
    if frames < 2:
        raise InputError(f"{source}: need at least 2 frames, got {frames}")


def open_bvh_take(path: str | Path, options: BvhBodyOptions) -> TakeStream:
    """A BVH file as a :class:`TakeStream`: the header and the first seconds are read now (the body),
    the frames when ``pieces`` is iterated. Bad rows raise :class:`InputError` when they are reached. Joints near
    gimbal lock are re-expressed as :func:`livezmp.model.euler_orders.clear_of_gimbal_lock` does (the file is
    scanned for them first); leading rest-pose frames are held as :func:`livezmp.model.motion_file.load_motion`
    holds them."""
    path = check_input_file(path, "motion file")
    header, blocks = stream_bvh(path)
    # the first seconds make the body; a take short enough to be a looped cycle is read whole to be judged one
    needed = header.n_frames if header.n_frames * header.frame_time <= MAX_LOOP_S else 1
    needed = max(needed, round(CALIBRATION_S / header.frame_time))
    first, count = [], 0
    for block in blocks:
        first.append(block)
        count += len(block)
        if count >= needed:
            break
    blocks.close()
    orders = scan_orders(header.joints, lambda: stream_bvh(path)[1])
    held, rest = without_rest_pose(BvhMotion(header.joints, header.frame_time, np.concatenate(first), header.source))
    first_moving = held.frames[rest]
    start = reexpress(header.joints, held.frames, orders)
    body = body_from_bvh(BvhMotion(reordered_joints(header.joints, orders), header.frame_time, start, header.source),
                         options)
    ends = np.array([0, header.n_frames - 1]) * header.frame_time  # as load_motion's times
    fps = float((header.n_frames - 1) / (ends[1] - ends[0])) if header.n_frames > 1 else 0.0
    loop = find_loop(held.channel_labels(), held.frames, header.frame_time) if count == header.n_frames else None
    if loop is not None:  # the whole (short) take is in hand: the loop is played from it
        loop = replace(loop, positions=body.input_rows(loop.positions))
        rows, lead = body.input_rows(start), loop.pad_frames(header.frame_time)

        def looped(chunk: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
            for a in range(-lead, header.n_frames + lead, chunk):
                b = min(a + chunk, header.n_frames + lead)
                yield np.arange(a, b) * header.frame_time, loop.rows(rows, a, b)

        return TakeStream(body, fps, header.n_frames, header.source, looped, rest, loop, lead)

    def pieces(chunk: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        start, previous = 0, None
        for block in stream_bvh(path, rows=chunk)[1]:
            block = hold_rest(block, rest, first_moving, start)
            if orders:
                block = reexpress(header.joints, block, orders, previous)
                previous = block[-1]
            yield np.arange(start, start + len(block)) * header.frame_time, body.input_rows(block)
            start += len(block)

    return TakeStream(body, fps, header.n_frames, header.source, pieces, rest)


def open_joint_csv_take(path: str | Path, robot: str | Path, options: UrdfBodyOptions) -> TakeStream:
    """A robot's joint CSV (with its URDF ``robot``) as a :class:`TakeStream`: the file is checked from
    end to end now (:func:`scan_joint_csv`: its frame count and rate, every bad row, time column or
    period reported as :func:`read_joint_csv` reports it), its frames read again when ``pieces`` is
    iterated, the floating base placed as the whole take's is when the file has none."""
    p = check_input_file(path, "motion file")
    body = body_from_urdf(robot, options)
    scan = scan_joint_csv(p, body.joint_names)

    def pieces(chunk: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        placer = BasePlacer(body)
        for traj in joint_csv_blocks(p, body.joint_names, chunk):
            yield traj.t, trajectory_frames(body, traj, placer)

    return TakeStream(body, scan.fps, scan.count, str(p), pieces)


def analyse_stream(take: TakeStream, config: PipelineConfig, consumers: Sequence[Consumer],
                   chunk: int = DEFAULT_CHUNK, progress: Callable[[int], None] | None = None) -> str:
    """Run the pipeline (``config``) over ``take`` chunk by chunk, giving each chunk's results to every
    consumer; returns which path made them ("batch", or "per-frame: WHY" as
    :func:`livezmp.offline.batch.run_batch` says). ``progress(frames_done)`` after each chunk."""
    take.check_length()
    pipe = Pipeline(take.body, config, nominal_dt=1.0 / take.fps)
    fed = take.total + 2 * take.lead
    try:
        parts = batch_chunks(take.body, config, pipe.estimator, pipe.contacts, fed, take.pieces(chunk), chunk)
        _feed(_own_frames(parts, take), consumers, progress)
        return "batch"
    except NotBatchable as e:
        reason = str(e)
    parts = _stepped(Pipeline(take.body, config, nominal_dt=1.0 / take.fps), take.pieces(chunk), chunk)
    _feed(_own_frames(parts, take), consumers, progress)
    return f"per-frame: {reason}"


def _own_frames(parts: Iterator[BatchResult], take: TakeStream) -> Iterator[BatchResult]:
    """The parts' rows that are the take's own frames (:func:`within_take`); a part all padding is left out."""
    for part in parts:
        own = within_take(part, take.lead, take.total)
        if len(own):
            yield own


def within_take(part: BatchResult, lead: int, total: int) -> BatchResult:
    """The rows of ``part`` that are the take's own frames when ``lead`` padding frames were analysed before its
    ``total`` (and as many after), numbered from the take's first frame."""
    if not lead:
        return part
    out = part.select((part.index >= lead) & (part.index < lead + total))
    out.index = out.index - lead
    return out


def _feed(parts: Iterator[BatchResult], consumers: Sequence[Consumer],
          progress: Callable[[int], None] | None) -> None:
    for c in consumers:
        c.start()
    for part in parts:
        for c in consumers:
            c.add(part)
        if progress is not None:
            progress(int(part.index[-1]) + 1)


def _stepped(pipe: Pipeline, pieces: Iterator[tuple[np.ndarray, np.ndarray]], chunk: int) -> Iterator[BatchResult]:
    """The per-frame pipeline over the pieces (as :meth:`Pipeline.run`), ``chunk`` results at a time."""
    done = []
    for times, frames in pieces:
        for t, f in zip(times, frames, strict=True):
            r = pipe.step(float(t), f)
            if r is not None:
                done.append(r)
            if len(done) == chunk:
                yield BatchResult.from_frames(done, keep_states=False)
                done = []
    done += pipe.flush()
    if done:
        yield BatchResult.from_frames(done, keep_states=False)
