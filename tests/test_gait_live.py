"""The streaming gait estimator: sinusoids with known cadence, DC and amplitude; stops and
restarts; bounded state; and agreement with the offline features on a real walk."""

import numpy as np
import pytest
from data_paths import BANDAI

from livezmp.errors import InputError
from livezmp.gait.channels import reference_channel
from livezmp.gait.features import walk_features
from livezmp.gait.live import GaitLiveEstimator
from livezmp.gait.take import take_from_bvh
from livezmp.model.bvh import read_bvh

DC = np.array([0.1, 3.1, -0.5])  # rad; channel 1 sits near +π and wraps
AMP = np.array([0.35, 0.2, 0.05])
PHASE = np.array([0.0, 1.0, 2.0])


def frame(t, f=0.9):
    x = DC + AMP * np.sin(2 * np.pi * f * t + PHASE)
    return (x + np.pi) % (2 * np.pi) - np.pi  # as a joint feed reports angles


def run(est, t0, t1, fs=100.0, f=0.9):
    state = None
    for t in np.arange(t0, t1, 1.0 / fs):
        state = est.update(float(t), frame(t, f))
    return state


def test_estimates_cadence_dc_and_amplitude_of_sinusoids():
    est = GaitLiveEstimator(3, ref=0, cycles=3)
    assert run(est, 0.0, 1.5) is None  # not one whole cycle yet
    s = run(est, 1.5, 20.0)
    assert s.n_cycles == 3
    assert s.stride_frequency == pytest.approx(0.9, rel=1e-3)
    assert s.cadence == pytest.approx(108.0, rel=1e-3)  # steps per minute = 2 × 60 × strides/s
    assert s.dc == pytest.approx(DC, abs=0.01 * AMP.max())
    assert s.amplitude == pytest.approx(AMP, rel=0.01)


def test_follows_a_change_of_cadence_and_forgets_after_a_stop():
    est = GaitLiveEstimator(3, ref=0, cycles=3)
    run(est, 0.0, 15.0, f=0.9)
    s = run(est, 15.0, 30.0, f=1.2)  # speeds up: after 3 new cycles only the new cadence counts
    assert s.stride_frequency == pytest.approx(1.2, rel=0.01)
    still = frame(30.0, 1.2)
    for t in np.arange(30.0, 34.0, 0.01):
        s = est.update(float(t), still)
    assert s is None  # standing for longer than max_period: no estimate
    s = run(est, 34.0, 45.0, f=0.8)
    assert s is not None and s.stride_frequency == pytest.approx(0.8, rel=0.01)


def test_state_stays_bounded_over_a_long_session():
    est = GaitLiveEstimator(3, ref=0, cycles=4)
    s = run(est, 0.0, 300.0, fs=50.0)  # 270 cycles
    assert s.n_cycles == 4


def test_bad_frames_are_clear_errors():
    est = GaitLiveEstimator(3, ref=0)
    est.update(0.0, np.zeros(3))
    with pytest.raises(InputError, match=r"shape \(2,\)"):
        est.update(0.01, np.zeros(2))
    with pytest.raises(InputError, match="must increase"):
        est.update(0.0, np.zeros(3))
    with pytest.raises(InputError, match="reference channel 5"):
        GaitLiveEstimator(3, ref=5)


def test_agrees_with_the_offline_features_on_a_recorded_walk():
    take = take_from_bvh(read_bvh(BANDAI / "walk_normal_003.bvh"))
    offline = walk_features(take)
    ref = reference_channel(take.tags, take.source)
    est = GaitLiveEstimator(len(take.tags), ref=ref, cycles=4)
    for t, x in zip(take.t, take.angles, strict=True):
        s = est.update(float(t), x)
    assert s.stride_frequency == pytest.approx(offline.frequency, rel=0.03)
    assert s.dc[ref] == pytest.approx(offline.dc[ref], abs=np.deg2rad(2.0))
    assert s.amplitude[ref] == pytest.approx(offline.amplitude[ref], rel=0.05)
