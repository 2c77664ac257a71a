"""The estimator's defaults per frame rate (issue 12): a 30 Hz walk with 0.3° of joint-angle
noise, as the README's streamer example sends, analysed with the defaults against the walk's
exact ZMP (its channels are known sinusoids, so their derivatives are known in closed form)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.balance.zmp import compute_zmp
from livezmp.cli import main
from livezmp.correct.limits import CORRECTION_CUTOFF_HZ
from livezmp.estimate.estimator import FILE_CUTOFF_HZ, EstimatorConfig, default_cutoff, default_estimator
from livezmp.gait.sinewalk import sine_bvh, sine_bvh_rates, walk_spec
from livezmp.model.bvh import write_bvh
from livezmp.model.bvh_body import body_from_bvh
from livezmp.offline.batch import run_batch

FPS, FREQUENCY, SPEED = 30.0, 1.0, 1.2


@pytest.fixture(scope="module")
def walk():
    spec = walk_spec()
    motion = sine_bvh(spec, FREQUENCY, SPEED, 6.0, fps=FPS)
    body = body_from_bvh(motion)
    rate, accel = sine_bvh_rates(motion, spec, FREQUENCY, SPEED)
    data = body.model.createData()
    truth = np.array([compute_zmp(body.model, data, *(body.channels_to_q(x[k]) for x in (motion.frames, rate, accel)),
                                  0.0).zmp[:2] for k in range(len(rate))])
    rot = np.array([c.endswith("rotation") for j in motion.joints for c in j.channels])
    noisy = motion.frames.copy()
    noisy[:, rot] += np.random.default_rng(1).normal(0.0, 0.3, (len(noisy), int(rot.sum())))
    return motion, body, truth, noisy


def p95_error_mm(walk, frames, est: EstimatorConfig) -> float:
    motion, body, truth, _ = walk
    cfg = replace(default_config(body, FPS), estimator=est, ground_z=0.0)
    got = run_batch(Pipeline(body, cfg, 1.0 / FPS), np.arange(len(frames)) / FPS, frames)
    edge = int(0.5 * FPS)  # the ends, where the spline extrapolates, are left out
    ok = got.has_zmp[edge:-edge]
    return float(np.percentile(1000 * np.linalg.norm(got.zmp[edge:-edge, :2][ok] - truth[edge:-edge][ok], axis=1), 95))


def test_noisy_30hz_walk_is_followed_within_25_mm(walk):
    noisy = walk[3]
    new = p95_error_mm(walk, noisy, default_config(walk[1], FPS).estimator)
    old = p95_error_mm(walk, noisy, EstimatorConfig(rate_hz=FPS))  # the fixed 6 Hz settings before issue 12
    assert new < 25.0 and old > 50.0, (new, old)


def test_clean_walk_is_not_harmed(walk):
    motion = walk[0]
    new = p95_error_mm(walk, motion.frames, default_config(walk[1], FPS).estimator)
    old = p95_error_mm(walk, motion.frames, EstimatorConfig(rate_hz=FPS))
    assert new < 3.0 and new < old + 2.0, (new, old)


def test_cutoff_rule_holds_the_noise_gain_across_rates():
    # noise in acceleration ~ cutoff^2.5 / sqrt(rate): the same at every rate
    gains = [default_cutoff(r) ** 2.5 / np.sqrt(r) for r in (30.0, 60.0, 120.0, 240.0, 1000.0)]
    assert np.allclose(gains, gains[0])
    est = default_estimator(30.0)
    assert (est.cutoff_hz, est.window_s, est.lag_s) == pytest.approx((3.03, 0.792, 0.198), abs=5e-3)


def test_analyze_reports_the_settings_and_takes_the_override(walk, tmp_path, capsys):
    path, summary = tmp_path / "walk.bvh", tmp_path / "s.json"
    write_bvh(walk[0], path)
    assert main(["analyze", str(path), "--summary-json", str(summary)]) == 0
    # a file's default at every rate, the one `correct` judges with: analyze reads a corrected take as
    # the correction saw it
    assert json.loads(summary.read_text())["estimator"]["cutoff_hz"] == FILE_CUTOFF_HZ == CORRECTION_CUTOFF_HZ
    assert main(["analyze", str(path), "--cutoff-hz", "5", "--summary-json", str(summary)]) == 0
    est = json.loads(summary.read_text())["estimator"]
    assert (est["cutoff_hz"], est["window_s"], est["lag_s"]) == pytest.approx((5.0, 0.48, 0.12))
    capsys.readouterr()
    assert main(["analyze", str(path), "--cutoff-hz", "20"]) == 2  # above 15 Hz, the Nyquist frequency at 30 Hz
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--cutoff-hz 20 at 30 frames/s" in err and "Nyquist frequency, 15 Hz" in err
    slow = tmp_path / "slow.bvh"  # 10 frames/s: a file's default cutoff, 6 Hz, is above its Nyquist frequency
    write_bvh(replace(walk[0], frames=walk[0].frames[::3], frame_time=3 * walk[0].frame_time), slow)
    assert main(["analyze", str(slow)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a file's default is 6 Hz: give --cutoff-hz below 5" in err
