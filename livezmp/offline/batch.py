"""Offline analysis of a whole take over arrays: the per-frame pipeline's results, fast.

:func:`run_batch` (``livezmp analyze``, ``livezmp correct``) comes here. The take goes
through in chunks of frames; every stage works on a chunk's arrays and carries its state
to the next chunk, so memory stays bounded whatever the take's length, and the results
equal those of stepping the per-frame pipeline over the take (to rounding, about 1e-12 relative):

1. estimator (:mod:`livezmp.offline.estimator`): settled Kalman filter as a recursion,
   sliding spline as block matrix products;
2. kinematics and centroidal dynamics (:mod:`livezmp.offline.kinematics`), sole corners
   and their velocities;
3. contacts and ground (:mod:`livezmp.offline.contacts`), support polygons and the clamp
   of the ZMP (:mod:`livezmp.offline.support`).

The batch path needs uniformly sampled, complete input from the start of a stream:
irregular timestamps, missing samples (non-finite values), contacts from outside, a
take shorter than two spline windows, or an angle whose Kalman innovation reaches ±π
raise :class:`NotBatchable`, and :func:`run_batch` then steps the pipeline frame by frame,
naming why in the result's ``path``.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass

import numpy as np

from livezmp.balance.contacts import ContactDetector
from livezmp.balance.pipeline import FrameResult, Pipeline, PipelineConfig
from livezmp.balance.support import SUPPORT_LABELS, support_polygon
from livezmp.estimate.estimator import StreamingEstimator
from livezmp.model.body import BodyModel
from livezmp.offline.contacts import detect_contacts
from livezmp.offline.estimator import NotBatchable, estimate_stream
from livezmp.offline.kinematics import (
    BatchKinematics,
    UnsupportedModel,
    batch_sole_velocities,
    batch_soles,
    body_frame_ids,
)
from livezmp.offline.support import support_clamp

__all__ = ["DEFAULT_CHUNK", "BatchResult", "NotBatchable", "analyse_batch", "analyse_frames", "batch_chunks",
           "run_batch"]

DEFAULT_CHUNK = 8192  # frames per chunk: a few tens of MB of working arrays for a 132-channel skeleton
_NONE = SUPPORT_LABELS.index("none")


@dataclass
class BatchResult:
    """The analysis of N frames as arrays, internal frame (z up, metres); row i is frame ``index[i]``.

    ``zmp`` (N, 3) is valid where ``has_zmp`` (else zeros: flight); ``support`` (N,) int8
    indexes ``SUPPORT_LABELS`` ("left", "right", "double", "none"); ``inside``, ``clamped``
    (N, 3) and ``margin`` (N,) are valid where ``judged`` (a ZMP and some support; else
    False / zeros); ``soles`` {side: (N, k, 3)}; ``q``, ``v``, ``a`` (N, nq) only when kept
    (else None); ``path`` which path made it: "batch", or "per-frame: WHY". See
    :class:`livezmp.balance.pipeline.FrameResult` for each field."""

    index: np.ndarray
    t: np.ndarray
    zmp: np.ndarray
    has_zmp: np.ndarray
    com: np.ndarray
    support: np.ndarray
    judged: np.ndarray
    inside: np.ndarray
    clamped: np.ndarray
    margin: np.ndarray
    ground_z: np.ndarray
    load: np.ndarray
    soles: dict[str, np.ndarray]
    q: np.ndarray | None = None
    v: np.ndarray | None = None
    a: np.ndarray | None = None
    path: str = "batch"

    def __len__(self) -> int:
        return len(self.index)

    @property
    def labels(self) -> np.ndarray:
        """Support labels (N,) as strings."""
        return np.array(SUPPORT_LABELS)[self.support]

    def frame(self, i: int) -> FrameResult:
        """Row ``i`` as the per-frame pipeline's :class:`FrameResult` (needs the kept states)."""
        if self.q is None:
            raise ValueError("this BatchResult has no q, v, a: run it with keep_states=True")
        label = SUPPORT_LABELS[self.support[i]]
        soles = {side: s[i] for side, s in self.soles.items()}
        ground = float(self.ground_z[i])
        res = FrameResult(int(self.index[i]), float(self.t[i]), self.q[i], self.v[i], self.a[i],
                          self.zmp[i].copy() if self.has_zmp[i] else None, self.com[i].copy(), label,
                          support_polygon(soles["left"], soles["right"], label), soles, ground,
                          load=float(self.load[i]))
        if self.judged[i]:
            res.inside, res.margin, res.clamped = bool(self.inside[i]), float(self.margin[i]), self.clamped[i].copy()
        return res

    def select(self, rows: np.ndarray) -> BatchResult:
        """The rows ``rows`` (indices or a mask) as a result of their own."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return BatchResult(**{name: v[rows] if isinstance(v, np.ndarray) else v for name, v in fields.items()
                              if name != "soles"}, soles={side: s[rows] for side, s in self.soles.items()})

    @classmethod
    def concatenate(cls, parts: list[BatchResult]) -> BatchResult:
        """Results one after another, as one (``parts`` not empty)."""
        first = parts[0]
        fields = {f.name: getattr(first, f.name) for f in dataclasses.fields(first)}
        return cls(**{name: np.concatenate([getattr(p, name) for p in parts]) if isinstance(v, np.ndarray) else v
                      for name, v in fields.items() if name != "soles"},
                   soles={side: np.concatenate([p.soles[side] for p in parts]) for side in first.soles})

    def put(self, part: BatchResult) -> None:
        """Copy ``part`` (consecutive frames, e.g. one chunk of :func:`batch_chunks`) into its rows."""
        rows = slice(int(part.index[0]), int(part.index[-1]) + 1)
        for f in dataclasses.fields(self):  # every array field (q, v, a only when kept), as `select` takes
            mine = getattr(self, f.name)
            if isinstance(mine, np.ndarray):
                mine[rows] = getattr(part, f.name)
        for side, s in part.soles.items():
            self.soles[side][rows] = s

    def frames(self) -> list[FrameResult]:
        """Every row as a :class:`FrameResult`."""
        return [self.frame(i) for i in range(len(self))]

    @classmethod
    def from_frames(cls, results: list[FrameResult], keep_states: bool = True) -> BatchResult:
        """Pack per-frame results (in frame order) into arrays."""
        zero3 = np.zeros(3)
        sides = list(results[0].soles) if results else ["left", "right"]

        def stack(values, shape=(0,)):
            return np.array(values) if results else np.zeros(shape)

        return cls(
            index=np.array([r.index for r in results], dtype=np.int64),
            t=stack([r.t for r in results]),
            zmp=stack([zero3 if r.zmp is None else r.zmp for r in results], (0, 3)),
            has_zmp=np.array([r.zmp is not None for r in results], dtype=bool),
            com=stack([r.com for r in results], (0, 3)),
            support=np.array([SUPPORT_LABELS.index(r.support) for r in results], dtype=np.int8),
            judged=np.array([r.inside is not None for r in results], dtype=bool),
            inside=np.array([bool(r.inside) for r in results], dtype=bool),
            clamped=stack([zero3 if r.clamped is None else r.clamped for r in results], (0, 3)),
            margin=stack([0.0 if r.margin is None else r.margin for r in results]),
            ground_z=stack([r.ground_z for r in results]),
            load=stack([r.load for r in results]),
            soles={s: stack([r.soles[s] for r in results], (0, 0, 3)) for s in sides},
            q=stack([r.q for r in results], (0, 0)) if keep_states else None,
            v=stack([r.v for r in results], (0, 0)) if keep_states else None,
            a=stack([r.a for r in results], (0, 0)) if keep_states else None,
        )


def _empty(count: int, body: BodyModel, keep_states: bool) -> BatchResult:
    states = (np.empty((count, body.nq)) if keep_states else None for _ in range(3))
    return BatchResult(
        index=np.arange(count), t=np.empty(count), zmp=np.zeros((count, 3)), has_zmp=np.zeros(count, dtype=bool),
        com=np.empty((count, 3)), support=np.empty(count, dtype=np.int8), judged=np.zeros(count, dtype=bool),
        inside=np.zeros(count, dtype=bool), clamped=np.zeros((count, 3)), margin=np.zeros(count),
        ground_z=np.empty(count), load=np.empty(count),
        soles={side: np.empty((count, 4 if f.sole_local is None else len(f.sole_local), 3))
               for side, f in body.feet.items()},
        q=next(states), v=next(states), a=next(states),
    )


def _lowest(sole: np.ndarray, velocity: np.ndarray,
            belt: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """z (C,) of each frame's lowest sole corner (the first of equals) and its horizontal speed (C,), relative to
    the ``belt`` (vx, vy) m/s under the foot when given (:class:`PipelineConfig`)."""
    rows = np.arange(len(sole))
    low = np.argmin(sole[:, :, 2], axis=1)
    v = velocity[rows, low]
    if belt is not None:
        v = v - [belt[0], belt[1], 0.0]
    return sole[rows, low, 2], np.hypot(v[:, 0], v[:, 1])


def run_batch(pipeline: Pipeline, times: np.ndarray, frames: np.ndarray, chunk: int | None = None,
              keep_states: bool = False, progress: Callable[[int], None] | None = None) -> BatchResult:
    """Analyse a whole motion (``times`` (N,) s, ``frames`` (N, nq) raw channels) on ``pipeline``
    into arrays, one row per frame: what stepping every frame and flushing gives.

    At the start of a stream, uniformly sampled complete input goes through the batch path in
    chunks of ``chunk`` frames (the per-frame results to rounding, at a small fraction of the
    cost, in bounded memory); anything else (:class:`NotBatchable`, or frames already stepped)
    is stepped frame by frame, and the result's ``path`` says why. ``keep_states`` keeps q, v, a
    (N × nq each), which :meth:`BatchResult.frames` needs; ``progress(frames_done)`` is called as
    the work goes on. The pipeline's contact detector is left as stepping would leave it."""
    if pipeline.frames_in:
        reason = "the stream was already stepped"
    else:
        try:
            result, pipeline.contacts = analyse_batch(pipeline.body, pipeline.config, pipeline.estimator,
                                                      pipeline.contacts, times, frames, chunk or DEFAULT_CHUNK,
                                                      keep_states, progress)
            return result
        except NotBatchable as e:
            reason = str(e)
    result = BatchResult.from_frames(pipeline.run(times, frames, progress=progress), keep_states)
    result.path = f"per-frame: {reason}"
    return result


def analyse_frames(pipeline: Pipeline, times: np.ndarray, frames: np.ndarray,
                   contacts: list[tuple[bool, bool]] | None = None) -> list[FrameResult]:
    """:func:`run_batch` as a list of :class:`FrameResult`; with ``contacts`` (left, right) per
    frame from outside, which only the per-frame path takes, :meth:`Pipeline.run`."""
    if contacts is not None:
        return pipeline.run(times, frames, contacts)
    return run_batch(pipeline, times, frames, keep_states=True).frames()


def analyse_batch(body: BodyModel, config: PipelineConfig, estimator: StreamingEstimator, detector: ContactDetector,
                  times: np.ndarray, frames: np.ndarray, chunk: int = DEFAULT_CHUNK,
                  keep_states: bool = False,
                  progress: Callable[[int], None] | None = None) -> tuple[BatchResult, ContactDetector]:
    """Analyse a whole take (``times`` (N,) s, ``frames`` (N, nq) raw channels) as the per-frame
    pipeline would, chunk by chunk (see the module docstring), into one result.

    ``estimator``: the pipeline's fresh estimator (used for the first frames, reset at the
    end); ``detector``: the pipeline's contact detector, left as it was. Returns the result and
    a copy of the detector in the state the per-frame pipeline would leave it.
    ``keep_states`` keeps q, v, a of every frame (N × nq × 3 floats); ``progress(frames_done)``
    is called after each chunk. Raises :class:`NotBatchable` when the take needs the per-frame path."""
    times = np.asarray(times, dtype=float)
    frames = np.asarray(frames, dtype=float)
    count = len(times)
    if frames.ndim != 2 or frames.shape != (count, body.nq):
        raise NotBatchable(f"frames of shape {frames.shape} for {count} times and {body.nq} channels")
    if not all(np.isfinite(frames[i:i + chunk]).all() for i in range(0, count, chunk)):
        raise NotBatchable("missing samples")
    out = _empty(count, body, keep_states)
    detector = copy.deepcopy(detector)
    pieces = ((times[i:i + chunk], frames[i:i + chunk]) for i in range(0, count, chunk))
    for part in batch_chunks(body, config, estimator, detector, count, pieces, chunk, keep_states):
        out.put(part)
        if progress is not None:
            progress(int(part.index[-1]) + 1)
    return out, detector


def batch_chunks(body: BodyModel, config: PipelineConfig, estimator: StreamingEstimator, detector: ContactDetector,
                 total: int, pieces: Iterable[tuple[np.ndarray, np.ndarray]], chunk: int = DEFAULT_CHUNK,
                 keep_states: bool = False) -> Iterator[BatchResult]:
    """The batch path over a take of ``total`` frames read in ``pieces`` (times (c,) s, frames (c, nq)
    raw channels; ``chunk`` frames each but the last): one result per chunk of consecutive frames,
    in order, each equal to those rows of :func:`analyse_batch`'s. Memory: O(chunk) whatever ``total``.

    ``estimator``: the pipeline's fresh estimator; ``detector``: updated in place as stepping would.
    Raises :class:`NotBatchable` (possibly after some chunks) when the take needs the per-frame path."""
    model = body.model if config.mode == "full" else body.point_model
    try:
        kin = BatchKinematics(model, body_frame_ids(body))
    except UnsupportedModel as e:
        raise NotBatchable(str(e)) from None
    gravity = np.array(model.gravity.linear)
    weight = kin.mass * -gravity[2]
    chunks = estimate_stream(estimator, total, _complete(pieces), body.channel_scale, chunk)
    try:
        for start, times, est in chunks:
            count = len(times)
            out = _empty(count, body, keep_states)
            out.index += start
            out.t[:] = times
            dyn = kin.dynamics(*est)
            soles = batch_soles(body, dyn.frames)
            vel = batch_sole_velocities(body, dyn.frames, soles)
            belt = config.belt or (None, None)
            codes, ground = detect_contacts(detector, *_lowest(soles["left"], vel["left"], belt[0]),
                                            *_lowest(soles["right"], vel["right"], belt[1]))
            force = dyn.momentum_rate - kin.mass * gravity
            zmp, has = _zmp(dyn.com, force, dyn.moment, ground, config.flight_fraction * weight)
            judged = has & (codes != _NONE)
            clamped, inside, margin = support_clamp(zmp[:, :2], codes, soles, judged)
            out.zmp, out.has_zmp, out.com, out.support = zmp, has, dyn.com, codes
            out.judged, out.inside, out.margin = judged, inside, margin
            out.clamped[:, :2], out.clamped[:, 2] = clamped, np.where(judged, ground, 0.0)
            out.ground_z, out.load = ground, force[:, 2] / weight
            out.soles = soles
            if keep_states:
                out.q, out.v, out.a = (x.T for x in est)
            yield out
    finally:
        chunks.close()


def _complete(pieces: Iterable[tuple[np.ndarray, np.ndarray]]) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """``pieces`` as floats, refusing (:class:`NotBatchable`) a piece with a missing (non-finite) sample."""
    for times, frames in pieces:
        frames = np.asarray(frames, dtype=float)
        if not np.isfinite(frames).all():
            raise NotBatchable("missing samples")
        yield np.asarray(times, dtype=float), frames


def _zmp(com: np.ndarray, force: np.ndarray, moment: np.ndarray, ground: np.ndarray,
         min_fz: float) -> tuple[np.ndarray, np.ndarray]:
    """ZMP (C, 3) on the ground plane z = ``ground`` (C,) of the contact wrench (``force`` (C, 3) N,
    ``moment`` (C, 3) N·m about the CoM ``com`` (C, 3)) and where there is one (F_z >= ``min_fz``):
    :func:`livezmp.balance.zmp.compute_zmp` on z = 0, then :func:`livezmp.balance.zmp.zmp_on_plane`."""
    fz = force[:, 2]
    has = fz >= min_fz
    fz = np.where(has, fz, 1.0)
    h = com[:, 2]
    x = com[:, 0] - (moment[:, 1] + h * force[:, 0]) / fz
    y = com[:, 1] + (moment[:, 0] - h * force[:, 1]) / fz
    zmp = np.stack([x + ground * force[:, 0] / fz, y + ground * force[:, 1] / fz, ground], axis=1)
    zmp[~has] = 0.0
    return zmp, has
