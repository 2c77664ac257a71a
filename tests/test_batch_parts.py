"""The batch path's estimator, contact and support stages against the per-frame code they replace."""

from __future__ import annotations

import math

import numpy as np
import pytest

from livezmp.balance.contacts import ContactConfig, ContactDetector, FootContact, GroundConfig, step_foot
from livezmp.balance.support import SUPPORT_LABELS, clamp_to_polygon, support_polygon
from livezmp.estimate.estimator import EstimatorConfig, StreamingEstimator
from livezmp.offline.contacts import detect_contacts, foot_contacts
from livezmp.offline.estimator import NotBatchable, estimate_chunks
from livezmp.offline.support import support_clamp


def per_frame_estimates(cfg: EstimatorConfig, angles: np.ndarray, t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(3, N, n) estimates from stepping the streaming estimator."""
    est = StreamingEstimator(y.shape[1], angles, cfg)
    out = np.full((3,) + y.shape, np.nan)
    for ti, yi in zip(t, y, strict=True):
        e = est.step(float(ti), yi)
        if e is not None:
            out[:, e.index] = e.q, e.qd, e.qdd
    for e in est.flush():
        out[:, e.index] = e.q, e.qd, e.qdd
    return out


def batch_estimates(cfg: EstimatorConfig, angles: np.ndarray, t: np.ndarray, y: np.ndarray, chunk: int) -> np.ndarray:
    est = StreamingEstimator(y.shape[1], angles, cfg)
    out = np.full((3,) + y.shape, np.nan)
    for start, times, block in estimate_chunks(est, t, y, np.ones(y.shape[1]), chunk):
        assert np.array_equal(times, t[start:start + block.shape[2]])  # each estimate's own times
        out[:, start:start + block.shape[2]] = block.transpose(0, 2, 1)
    return out


@pytest.mark.parametrize("rate", [30.0, 120.0, 500.0])
def test_estimator_equals_the_streaming_one_across_chunks_and_angle_wraps(rate):
    """Smooth channels, a joint turning steadily (its raw samples wrap at ±π every half turn) and
    a noisy one; chunks shorter than the Kalman settling at 500 Hz."""
    cfg = EstimatorConfig(rate_hz=rate)
    t = np.arange(int(3 * rate)) / rate
    rng = np.random.default_rng(0)
    y = np.column_stack([
        0.4 * np.sin(2 * np.pi * 0.7 * t),
        np.angle(np.exp(1j * (5.0 * t + 0.3 * np.sin(3 * t)))),  # wrapped to (-pi, pi]
        1.5 + 0.01 * rng.normal(size=t.size) + 0.2 * t,
        np.angle(np.exp(1j * (3.1 + 0.05 * np.sin(2 * t)))),  # sits at the ±pi seam
    ])
    angles = np.array([True, True, False, True])
    want = per_frame_estimates(cfg, angles, t, y)
    got = batch_estimates(cfg, angles, t, y, chunk=2 * cfg.window + 7)
    assert not np.isnan(got).any()
    for d in range(3):
        scale = np.abs(want[d]).max()
        assert np.abs(got[d] - want[d]).max() <= 1e-11 * scale, d


def test_estimator_refuses_a_wrapped_innovation():
    """A one-frame spike of 3 rad: the filter's prediction then overshoots by more than π, where the
    per-frame filter wraps the innovation and a linear filter on unwrapped samples would not."""
    cfg = EstimatorConfig(rate_hz=100.0)
    t = np.arange(400) / 100
    y = np.zeros((400, 1))
    y[200] = 3.0
    with pytest.raises(NotBatchable, match="±π"):
        batch_estimates(cfg, np.array([True]), t, y, chunk=128)
    # the same spike on a length channel is linear throughout
    want = per_frame_estimates(cfg, np.array([False]), t, y)
    got = batch_estimates(cfg, np.array([False]), t, y, chunk=128)
    assert np.abs(got - want).max() <= 1e-11 * np.abs(want).max()


@pytest.mark.parametrize("bad", ["jitter", "irregular", "off-nominal"])
def test_estimator_refuses_non_uniform_times(bad):
    cfg = EstimatorConfig(rate_hz=100.0)
    t = np.arange(300) / 100
    if bad == "jitter":
        t[150] += 1e-5
    elif bad == "irregular":
        t[150:] += 0.01  # a dropped frame
    else:
        t = t * 1.05
    with pytest.raises(NotBatchable):
        batch_estimates(cfg, None, t, np.zeros((300, 2)), chunk=128)


@pytest.mark.parametrize("min_frames", [1, 2, 3, 5])
def test_foot_state_machine_equals_step_foot(min_frames):
    cfg = ContactConfig(min_frames=min_frames)
    rng = np.random.default_rng(min_frames)
    # heights and speeds hovering around the thresholds, in runs of various lengths
    height = np.repeat(rng.uniform(0.0, 0.07, 600), rng.integers(1, 6, 600))[:1000]
    speed = np.repeat(rng.uniform(0.0, 1.3, 600), rng.integers(1, 6, 600))[:1000]
    for start in (FootContact(), FootContact(True, min_frames - 1), FootContact(False, min_frames - 1)):
        state, want = start, []
        for h, s in zip(height, speed, strict=True):
            state = step_foot(state, h, s, cfg)
            want.append(state.in_contact)
        got, state_b = [], start
        for lo in range(0, len(height), 97):  # chunks
            flags, state_b = foot_contacts(state_b, height[lo:lo + 97], speed[lo:lo + 97], cfg)
            got += flags.tolist()
        assert got == want and state_b == state
        assert 0 < sum(want) < len(want)


@pytest.mark.parametrize("override", [None, 0.02])
def test_contact_detector_state_and_labels(override):
    rng = np.random.default_rng(5)
    n = 700
    low = {s: 0.01 + np.abs(np.cumsum(rng.normal(0, 0.01, n))) % 0.08 for s in ("left", "right")}
    speed = {s: np.abs(np.cumsum(rng.normal(0, 0.2, n))) % 1.5 for s in ("left", "right")}
    cfg, ground_cfg = ContactConfig(min_frames=2), GroundConfig(warmup_frames=60, override=override)
    ref = ContactDetector(cfg, ground_cfg)
    labels, ground = [], []
    for k in range(n):
        sole = {s: np.array([[0.0, 0.0, low[s][k]], [0.1, 0.0, low[s][k] + 0.01]]) for s in low}
        vel = {s: np.array([[speed[s][k], 0.0, 0.0], [0.0, 0.0, 0.0]]) for s in low}
        labels.append(ref.update(sole["left"], vel["left"], sole["right"], vel["right"]))
        ground.append(ref.ground_height)
    det = ContactDetector(cfg, ground_cfg)
    codes, heights = [], []
    for lo in range(0, n, 128):
        part = slice(lo, lo + 128)
        c, g = detect_contacts(det, low["left"][part], speed["left"][part], low["right"][part], speed["right"][part])
        codes += c.tolist()
        heights += g.tolist()
    assert [SUPPORT_LABELS[c] for c in codes] == labels
    assert heights == ground  # the same scalar recurrence: bit for bit
    assert (det.left, det.right, det.frame, det.ground_height) == (ref.left, ref.right, ref.frame, ref.ground_height)
    assert len(set(labels)) == 4


def sole(center: np.ndarray, heading: float, rng: np.random.Generator) -> np.ndarray:
    """A 0.25 x 0.1 m rectangle of corners (4, 3), slightly tilted (z varies)."""
    c, s = math.cos(heading), math.sin(heading)
    local = np.array([[-0.05, -0.05], [0.2, -0.05], [0.2, 0.05], [-0.05, 0.05]])
    xy = center + local @ np.array([[c, s], [-s, c]])
    return np.column_stack([xy, rng.uniform(0, 0.02, 4)])


def test_support_clamp_equals_the_per_frame_polygon_and_clamp():
    rng = np.random.default_rng(6)
    n = 3000
    left = np.array([sole(rng.uniform(-1, 1, 2), rng.uniform(-3, 3), rng) for _ in range(n)])
    right = np.array([sole(left[i, 0, :2] + rng.uniform(-0.4, 0.4, 2), rng.uniform(-3, 3), rng) for i in range(n)])
    # degenerate frames for the per-frame fallback: coincident soles, a corner on the other sole's edge
    right[0] = left[0]
    right[1, 0] = left[1, 0] + 0.5 * (left[1, 1] - left[1, 0])
    zmp = left[:, 0, :2] + rng.uniform(-0.15, 0.3, (n, 2))
    codes = rng.integers(0, 4, n).astype(np.int8)
    codes[:2] = 2
    judged = (codes != 3) & (rng.uniform(size=n) < 0.9)
    judged[:2] = True
    clamped, inside, margin = support_clamp(zmp, codes, {"left": left, "right": right}, judged)
    for i in range(n):
        if not judged[i]:
            assert not inside[i] and margin[i] == 0.0
            continue
        poly = support_polygon(left[i], right[i], SUPPORT_LABELS[codes[i]])
        want = clamp_to_polygon(zmp[i], poly)
        assert inside[i] == want.inside
        assert abs(margin[i] - want.margin) <= 1e-12
        assert np.abs(clamped[i] - want.point).max() <= 1e-12
    assert 0.1 < inside[judged].mean() < 0.9
