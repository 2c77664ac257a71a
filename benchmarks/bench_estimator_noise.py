"""ZMP error against measurement noise, per frame rate: the old fixed estimator settings
beside the per-rate defaults (issue 12).

A 9 s sine walk (livezmp.gait.sinewalk) is made of known sinusoids, so its exact joint
velocities and accelerations are known in closed form: the truth is the ZMP of those
(:func:`livezmp.balance.zmp.compute_zmp`), not a filtered estimate. Gaussian noise of
each ``--noise-deg`` level on every rotation channel (as ``sim_devices.mocap_streamer
--noise-deg`` adds) is analysed at 30, 60, 120 and 240 Hz with the old settings (6 Hz
cutoff, 0.4 s window, 0.1 s lag at every rate) and with the defaults per rate
(:func:`livezmp.estimate.estimator.default_estimator`). Each cell is the 95th percentile of
the horizontal ZMP error (mm) over the frames 0.5 s from either end; the 0-noise column
is the smoothing's own cost on clean data. ``--cutoffs`` adds rows with other cutoffs.

    python benchmarks/bench_estimator_noise.py [--noise-deg 0 0.1 0.3 1] [--cutoffs 5 3]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
from machine_load import load_averages

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.balance.zmp import compute_zmp
from livezmp.estimate.estimator import EstimatorConfig, default_estimator
from livezmp.gait.sinewalk import sine_bvh, sine_bvh_rates, walk_spec
from livezmp.model.bvh_body import body_from_bvh
from livezmp.offline.batch import run_batch

RATES = (30.0, 60.0, 120.0, 240.0)
FREQUENCY, SPEED, DURATION = 1.0, 1.2, 9.0


def exact_zmp(body, motion, spec) -> tuple[np.ndarray, np.ndarray]:
    """(N, 2) ZMP (m, internal frame) of the walk's exact state, and (N,) whether it has one."""
    rate, accel = sine_bvh_rates(motion, spec, FREQUENCY, SPEED)
    model, data = body.model, body.model.createData()
    zmp, has = np.zeros((len(rate), 2)), np.zeros(len(rate), bool)
    for k in range(len(rate)):
        q, v, a = (body.channels_to_q(x[k]) for x in (motion.frames, rate, accel))
        r = compute_zmp(model, data, q, v, a, 0.0)
        if r.zmp is not None:
            zmp[k], has[k] = r.zmp[:2], True
    return zmp, has


def analyse(body, frames, fps, est: EstimatorConfig):
    cfg = replace(default_config(body, fps), estimator=est, ground_z=0.0)
    return run_batch(Pipeline(body, cfg, 1.0 / fps), np.arange(len(frames)) / fps, frames)


def p95_error(truth: tuple[np.ndarray, np.ndarray], got, edge: int) -> float:
    """95th percentile of the horizontal ZMP distance (mm), frames ``edge`` from either end."""
    both = truth[1] & got.has_zmp
    both[:edge] = both[len(both) - edge:] = False
    return float(np.percentile(1000 * np.linalg.norm(got.zmp[both, :2] - truth[0][both], axis=1), 95))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise-deg", type=float, nargs="+", default=[0.0, 0.1, 0.3, 1.0])
    ap.add_argument("--cutoffs", type=float, nargs="*", default=[], help="extra rows: these cutoffs (Hz)")
    args = ap.parse_args()
    print(f"load average {load_averages(' ')}")
    print("p95 horizontal ZMP error (mm) against the exact ZMP of a sine walk, per added joint-angle noise")
    head = " ".join(f"{f'{n:g} deg':>8}" for n in args.noise_deg)
    print(f"{'rate Hz':>7} {'settings':>9} {'cutoff Hz':>9} {'lag ms':>7} {head}")
    spec = walk_spec()
    for fps in RATES:
        motion = sine_bvh(spec, FREQUENCY, SPEED, DURATION, fps=fps)
        body = body_from_bvh(motion)
        truth = exact_zmp(body, motion, spec)
        rot = np.array([c.endswith("rotation") for j in motion.joints for c in j.channels])
        rng = np.random.default_rng(0)
        noise = rng.normal(0.0, 1.0, (len(motion.frames), int(rot.sum())))
        rows = [("old", EstimatorConfig(rate_hz=fps)), ("default", default_estimator(fps))]
        rows += [("cutoff", default_estimator(fps, c)) for c in args.cutoffs if c < fps / 2]
        for label, est in rows:
            cells = []
            for level in args.noise_deg:
                noisy = motion.frames.copy()
                noisy[:, rot] += level * noise
                cells.append(p95_error(truth, analyse(body, noisy, fps, est), int(0.5 * fps)))
            print(f"{fps:>7.0f} {label:>9} {est.cutoff_hz:>9.2f} {1000 * est.lag / fps:>7.0f} "
                  + " ".join(f"{c:>8.1f}" for c in cells))


if __name__ == "__main__":
    main()
