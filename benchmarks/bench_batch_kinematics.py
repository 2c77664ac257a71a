"""Whole-take batch analysis: the numpy kinematics pass against Pinocchio called frame by frame.

The batch path (:func:`livezmp.offline.batch.run_batch`) gets each chunk's kinematics and centroidal
dynamics (CoM, rate of centroidal momentum, the foot frames' placements and velocities) from
:class:`livezmp.offline.kinematics.BatchKinematics`, a forward pass in numpy vectorised over the
chunk's frames. Is that twin of Pinocchio worth its code? Rows, in the same run on the same take:

- (a) the batch path as it is (numpy pass);
- (b) the same batch path with that one stage computed by Pinocchio frame by frame: what the
  per-frame pipeline calls (``computeCentroidalMomentumTimeVariation``, ``updateFramePlacements``,
  ``getFrameVelocity`` of the foot frames), packed into the same arrays; estimator, contacts,
  support and clamp are the batch path's own;
- the per-frame pipeline (``Pipeline.step`` on every frame, then ``flush``) as the streaming
  baseline.

(b)'s ZMP, margins and support labels are compared with (a)'s. Pinocchio's only batched
dynamics in the installed version (4.x) are ``rneaInParallel`` / ``abaInParallel`` (OpenMP over a
``ModelPool``): joint torques or accelerations only, no CoM, centroidal momentum or frame
placements, so they cannot give the ZMP and the soles alone. The stage table times them on one
chunk beside the two stages above, as the bound on what a batched-Pinocchio path could gain.

Takes: the Bandai walk resampled to 120 Hz and played forth and back
(:func:`bench_pipeline.long_take`), 132 channels; the ROBOTIS OP3 (26 channels) with smooth joint
motion at 120 Hz (:func:`bench_pipeline.op3_stream`).

    python benchmarks/bench_batch_kinematics.py                 # 10-minute takes, about 2 minutes
    python benchmarks/bench_batch_kinematics.py --minutes 60    # the one-hour take

Measured (2026-11-25, pinocchio 4.1.0, 2 CPUs shared with other jobs; median of 3 runs unless said;
the first three rows on the flat layout just before the package move, same code):

    take                          load   (a) numpy pass        (b) Pinocchio per frame  (b)/(a)  step loop
    Bandai 60 min (1 run, no OP3) 1.6    5.59 s   77,300 f/s   21.75 s  19,900 f/s      3.9
    Bandai 10 min                 1.7    1.53 s   47,000 f/s    3.85 s  18,700 f/s      2.5      7.61 s
    OP3 10 min                    1.6    0.28 s  261,000 f/s    1.19 s  60,800 f/s      4.3      5.27 s
    Bandai 10 min, 5 runs         2-4    2.90 s   24,800 f/s    8.85 s   8,100 f/s      3.1      20.0 s
    OP3 10 min, 5 runs            4-5    1.48 s   48,500 f/s    3.85 s  18,700 f/s      2.6       9.6 s

(b) gives (a)'s ZMP, CoM and margins to 4e-15 m, with no support, flight or inside flag differing.
The stage alone on one 8192-frame Bandai chunk (load 1.6): numpy pass 30 ms; Pinocchio per frame
294 ms, of which the bare ``computeCentroidalMomentumTimeVariation`` calls are 165 ms (5x the whole
numpy stage); ``rneaInParallel`` 160 ms on 1 thread, 112 ms on 2, for torques alone. So no leaner
per-frame Pinocchio stage comes within 2x on the skeleton: with nothing read back at all, the hour
would take 5.59 - 1.61 + 8.72 = 12.7 s (2.3x). Decision: the numpy pass stays.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pinocchio as pin
from bench_pipeline import OP3, WALK, load_average, long_take, op3_stream

import livezmp.offline.batch
from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.model.bvh import read_bvh
from livezmp.model.bvh_body import body_from_bvh
from livezmp.model.urdf_body import body_from_urdf
from livezmp.offline.batch import DEFAULT_CHUNK, BatchResult, run_batch
from livezmp.offline.kinematics import BatchKinematics, Dynamics, FrameMotion, body_frame_ids

RATE = 120.0


class PinocchioPerFrame:
    """The kinematics stage of the batch path from Pinocchio, one frame at a time: the interface of
    :class:`BatchKinematics` (``mass``, ``dynamics(q, v, a)`` on (nq, C) channel-major states)."""

    def __init__(self, model: pin.Model, frame_ids: list[int]):
        self.model, self.data = model, model.createData()
        self.frame_ids = list(frame_ids)
        self.mass = pin.computeTotalMass(model)

    def dynamics(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> Dynamics:
        model, data = self.model, self.data
        qs, vs, accs = (np.ascontiguousarray(x.T) for x in (q, v, a))
        n, nf = len(qs), len(self.frame_ids)
        com, dhg = np.empty((n, 3)), np.empty((n, 6))
        pos, rot, twist = np.empty((nf, n, 3)), np.empty((nf, n, 3, 3)), np.empty((nf, n, 6))
        for c in range(n):
            pin.computeCentroidalMomentumTimeVariation(model, data, qs[c], vs[c], accs[c])
            pin.updateFramePlacements(model, data)
            com[c], dhg[c] = data.com[0], data.dhg.vector
            for k, f in enumerate(self.frame_ids):
                placement = data.oMf[f]
                pos[k, c], rot[k, c] = placement.translation, placement.rotation
                # world axes, linear part at the world origin: the per-frame path's sole velocities
                twist[k, c] = pin.getFrameVelocity(model, data, f, pin.WORLD).vector
        origin = np.zeros((n, 3))
        frames = {f: FrameMotion(pos[k], rot[k], twist[k, :, 3:], origin, twist[k, :, :3])
                  for k, f in enumerate(self.frame_ids)}
        return Dynamics(com, dhg[:, :3], dhg[:, 3:], self.mass, frames)


@contextmanager
def kinematics_stage(cls: type) -> Iterator[None]:
    """The batch path with its kinematics stage computed by ``cls`` (restored on the way out)."""
    original = livezmp.offline.batch.BatchKinematics
    livezmp.offline.batch.BatchKinematics = cls
    try:
        yield
    finally:
        livezmp.offline.batch.BatchKinematics = original


def batch_run(body, cfg, times: np.ndarray, frames: np.ndarray, keep_states: bool = False) -> tuple[float, BatchResult]:
    """Seconds for :func:`run_batch` on the take, and its result (the batch path, never the fallback)."""
    pipe = Pipeline(body, cfg, 1 / RATE)
    start = time.perf_counter()
    result = run_batch(pipe, times, frames, keep_states=keep_states)
    elapsed = time.perf_counter() - start
    if result.path != "batch":
        raise SystemExit(f"the take went {result.path}")
    return elapsed, result


def step_run(body, cfg, times: np.ndarray, frames: np.ndarray) -> float:
    """Seconds for ``step`` on every frame, then ``flush``."""
    pipe = Pipeline(body, cfg, 1 / RATE)
    start = time.perf_counter()
    for k in range(len(times)):
        pipe.step(float(times[k]), frames[k])
    pipe.flush()
    return time.perf_counter() - start


def take_table(title: str, body, times: np.ndarray, frames: np.ndarray, repeats: int, step: bool) -> None:
    n = len(times)
    cfg = default_config(body, RATE)
    variants = {"(a) batch, numpy kinematics pass": BatchKinematics,
                "(b) batch, Pinocchio per frame": PinocchioPerFrame}
    runs: dict[str, list[tuple[float, str]]] = {name: [] for name in variants}
    results = {}
    for cls in variants.values():  # first calls (imports, caches) outside the timing
        with kinematics_stage(cls):
            batch_run(body, cfg, times[:2000], frames[:2000])
    for _ in range(repeats):  # interleaved, so that both see the same load
        for name, cls in variants.items():
            with kinematics_stage(cls):
                secs, results[name] = batch_run(body, cfg, times, frames)
            runs[name].append((secs, load_average()))
    if step:
        runs["per-frame: Pipeline.step, then flush"] = [(step_run(body, cfg, times, frames), load_average())]
    a_runs = [s for s, _ in runs["(a) batch, numpy kinematics pass"]]
    base, base_best = float(np.median(a_runs)), min(a_runs)
    print(f"\n{title}: {n:,} frames at {RATE:.0f} Hz ({n / RATE / 60:g} min), {body.nq} channels, full ZMP")
    print(f"{'path (median of the runs)':40s} {'seconds':>8s} {'frames/s':>10s} {'time / (a)':>10s} "
          f"{'best / (a) best':>15s}  runs: s @ 1-min load average")
    for name, rs in runs.items():
        secs = [s for s, _ in rs]
        median = float(np.median(secs))
        print(f"{name:40s} {median:8.2f} {n / median:10,.0f} {median / base:10.2f} {min(secs) / base_best:15.2f}  "
              + ", ".join(f"{s:.2f} @ {ld}" for s, ld in rs))
    a, b = results.values()
    both = a.has_zmp & b.has_zmp
    print(f"(b) vs (a): max |ZMP difference| {np.abs(a.zmp[both] - b.zmp[both]).max():.1e} m, "
          f"max |CoM difference| {np.abs(a.com - b.com).max():.1e} m, "
          f"max |margin difference| {np.abs(a.margin - b.margin).max():.1e} m; frames differing in support label "
          f"{int(np.sum(a.support != b.support))}, in flight {int(np.sum(a.has_zmp != b.has_zmp))}, "
          f"in inside flag {int(np.sum(a.inside != b.inside))}")


def stage_table(title: str, body, times: np.ndarray, frames: np.ndarray) -> None:
    """The kinematics stage alone on one chunk of the take's estimated states."""
    cfg = default_config(body, RATE)
    n = min(DEFAULT_CHUNK, len(times))
    _, kept = batch_run(body, cfg, times[:n], frames[:n], keep_states=True)
    q, v, a = (np.ascontiguousarray(x.T) for x in (kept.q, kept.v, kept.a))  # (nq, C), as the stage gets them
    model, ids = body.model, body_frame_ids(body)
    pool = pin.ModelPool(model, 2)
    numpy_pass, per_frame = BatchKinematics(model, ids), PinocchioPerFrame(model, ids)
    data, states = model.createData(), [np.ascontiguousarray(x) for x in (kept.q, kept.v, kept.a)]

    def centroidal_calls() -> None:  # (b)'s floor: the Pinocchio call alone, nothing read back
        for qc, vc, ac in zip(*states, strict=True):
            pin.computeCentroidalMomentumTimeVariation(model, data, qc, vc, ac)

    stages = {
        "numpy pass: CoM, dh/dt, foot frames": lambda: numpy_pass.dynamics(q, v, a),
        "Pinocchio per frame: the same": lambda: per_frame.dynamics(q, v, a),
        "Pinocchio per frame: dynamics call only": centroidal_calls,
        "rneaInParallel, 1 thread: torques only": lambda: pin.rneaInParallel(1, pool, q, v, a),
        "rneaInParallel, 2 threads: torques only": lambda: pin.rneaInParallel(2, pool, q, v, a),
    }
    print(f"\n{title}, kinematics stage alone on one chunk of {n:,} frames (best of 3)")
    print(f"{'stage':40s} {'ms':>8s} {'frames/s':>10s}  1-min load average")
    for name, fn in stages.items():
        best = np.inf
        for _ in range(3):
            start = time.perf_counter()
            fn()
            best = min(best, time.perf_counter() - start)
        print(f"{name:40s} {1e3 * best:8.1f} {n / best:10,.0f}  {load_average()}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=10.0, help="length of each take (default 10 min)")
    ap.add_argument("--repeats", type=int, default=3, help="batch runs per variant (the median is shown)")
    ap.add_argument("--no-step", action="store_true", help="skip the per-frame Pipeline.step baseline")
    ap.add_argument("--no-op3", action="store_true", help="only the Bandai skeleton")
    args = ap.parse_args()
    print(f"pinocchio {pin.__version__}, {os.cpu_count()} CPUs, 1-min load average at start {load_average()}")
    motion = read_bvh(WALK)
    walk = body_from_bvh(motion)
    takes = [("Bandai walk", walk, *long_take(motion, RATE, args.minutes))]
    if not args.no_op3:
        op3 = body_from_urdf(OP3)
        takes.append(("OP3", op3, *op3_stream(op3, int(round(args.minutes * 60 * RATE)), RATE)))
    for title, body, times, frames in takes:
        take_table(title, body, times, frames, args.repeats, not args.no_step)
    for title, body, times, frames in takes:
        stage_table(title, body, times, frames)


if __name__ == "__main__":
    sys.exit(main())
