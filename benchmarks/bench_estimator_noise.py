"""ZMP error against measurement noise, per frame rate and estimator cutoff (issue 12).

A 9 s sine walk (livezmp.gait.sinewalk) is analysed clean with the default estimator:
that ZMP is the truth. Gaussian noise of ``--noise-deg`` on every rotation channel (as
``sim_devices.mocap_streamer --noise-deg`` adds) is then analysed with spline cutoffs of
6 Hz (the default), 4 Hz and 3 Hz (window 2.4 / cutoff, lag 0.6 / cutoff, as the
estimator's docstring says), at 30, 60, 120 and 240 Hz. The table gives the median and
95th-percentile horizontal ZMP error (mm) with noise, and the 95th percentile without
noise (the smoothing's own bias against the 6 Hz truth: the price of a lower cutoff).

    python benchmarks/bench_estimator_noise.py [--noise-deg 0.3]
"""

from __future__ import annotations

import argparse
import os
from dataclasses import replace

import numpy as np

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.estimate.estimator import EstimatorConfig
from livezmp.gait.sinewalk import sine_bvh, walk_spec
from livezmp.model.bvh_body import body_from_bvh
from livezmp.offline.batch import run_batch

RATES = (30.0, 60.0, 120.0, 240.0)
CUTOFFS = (6.0, 4.0, 3.0)


def analyse(body, frames, fps, cutoff):
    cfg = default_config(body, fps)
    est = EstimatorConfig(rate_hz=fps, cutoff_hz=cutoff, window_s=2.4 / cutoff, lag_s=0.6 / cutoff)
    cfg = replace(cfg, estimator=est)
    times = np.arange(len(frames)) / fps
    return run_batch(Pipeline(body, cfg, 1.0 / fps), times, frames)


def zmp_error(truth, got) -> np.ndarray:
    """Horizontal ZMP distance (mm) on the frames where both have a ZMP."""
    both = truth.has_zmp & got.has_zmp
    return 1000 * np.linalg.norm(got.zmp[both, :2] - truth.zmp[both, :2], axis=1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise-deg", type=float, default=0.3)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}; noise {args.noise_deg} deg")
    print(f"{'rate Hz':>7} {'cutoff Hz':>9} {'median mm':>10} {'p95 mm':>8} {'clean p95 mm':>13}")
    for fps in RATES:
        motion = sine_bvh(walk_spec(), 1.0, 1.2, 9.0, fps=fps)
        body = body_from_bvh(motion)
        truth = analyse(body, motion.frames, fps, 6.0)
        rot = np.array([c.endswith("rotation") for j in motion.joints for c in j.channels])
        noisy = motion.frames.copy()
        noisy[:, rot] += rng.normal(0.0, args.noise_deg, (len(noisy), int(rot.sum())))
        for cutoff in CUTOFFS:
            err = zmp_error(truth, analyse(body, noisy, fps, cutoff))
            bias = zmp_error(truth, analyse(body, motion.frames, fps, cutoff))
            print(f"{fps:>7.0f} {cutoff:>9.1f} {np.median(err):>10.1f} {np.percentile(err, 95):>8.1f} "
                  f"{np.percentile(bias, 95):>13.1f}")


if __name__ == "__main__":
    main()
