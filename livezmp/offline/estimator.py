"""The streaming estimator's output for a whole take, computed chunk by chunk over arrays.

On uniformly sampled, complete input the per-frame chain of :mod:`livezmp.estimate.estimator`
is linear and, once the Kalman gain has settled, time-invariant:

* Kalman filter: every channel has the same noise and is measured at every step, so
  all share one covariance, whose gain settles (to 1e-12) within a few hundred
  samples. The frames before that go through the estimator's own filter object, one
  at a time; from then on the filter is a fixed third-order recursion per channel,
  run by ``scipy.signal.lfilter``. Angle channels are unwrapped first, so the
  filter's wrapped innovation is the plain one: that is checked on every frame
  (|innovation| < π), and a take where it fails raises :class:`NotBatchable`.
* Sliding spline: at a full, regular window the estimate is a fixed weight vector
  over the window (``spline.weights``), i.e. a sliding dot product, done as block
  matrix products. The first frames (window filling) and the last ``lag`` ones (the
  flush at the end of the take) get the per-window weights of the per-frame path.

The result equals the per-frame path to rounding (about 1e-12 relative). Memory is
O(chunk × channels) whatever the take's length.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator

import numpy as np
from scipy.signal import lfilter, lfiltic, ss2tf

from livezmp.estimate.estimator import StreamingEstimator
from livezmp.estimate.kalman import ConstantAccelerationKalman, ca_transition
from livezmp.estimate.spline_diff import window_weights

GAIN_TOL = 1e-12  # relative change per step below which the Kalman gain counts as settled
SETTLE_STEPS = 5  # ... for this many steps in a row
MAX_SETTLE = 100_000
WRAP_MARGIN = 1e-6  # rad: innovations this close to ±π are left to the per-frame path
BLOCK = 64  # output frames per block of the sliding dot product


class NotBatchable(Exception):
    """The take needs the per-frame path; the message says why."""


def uniform_step(times: np.ndarray, estimator: StreamingEstimator, before: float | None = None,
                 dt0: float | None = None) -> float:
    """The take's sample period (s) if the batch path reproduces the per-frame estimator on it.

    The per-frame Kalman filter reuses its transition while each interval stays within
    1e-9 of the first, and the spline its precomputed weights while each lies within
    ``jitter_tol`` of the nominal period: both must hold for every interval. A take read in
    pieces is checked piece by piece: ``before`` the previous piece's last time (s) and ``dt0``
    the first interval (s), None for the first piece. Raises :class:`NotBatchable` otherwise."""
    if before is not None:
        times = np.concatenate([[before], times])
    if len(times) < 2 or not np.isfinite(times).all():
        raise NotBatchable("fewer than two frames or a non-finite time")
    steps = np.diff(times)
    dt0 = float(steps[0]) if dt0 is None else dt0
    cfg = estimator.config
    if not dt0 > 0 or np.max(np.abs(steps - dt0)) > 1e-9 * dt0:
        raise NotBatchable("timestamps are not uniform")
    if np.max(np.abs(steps - cfg.dt)) > cfg.jitter_tol * cfg.dt:
        raise NotBatchable(f"sample period {dt0} s is not the nominal {cfg.dt} s")
    return dt0


def settled_gain(kalman: ConstantAccelerationKalman, dt: float) -> tuple[int, np.ndarray]:
    """(steps, gain): after ``steps`` samples ``dt`` s apart the filter's gain (3,) no longer changes.

    Found on a one-channel filter with the same noise and prior (the covariance does not
    depend on the data); the gain is P⁺ Hᵀ / r from the posterior covariance."""
    if np.ptp(kalman.jerk_psd) != 0.0 or np.ptp(kalman.meas_var) != 0.0:
        raise NotBatchable("channels have different Kalman noise parameters")
    r = float(kalman.meas_var[0])
    probe = ConstantAccelerationKalman(np.zeros(1, bool), float(kalman.jerk_psd[0, 0, 0]), r, np.diag(kalman.init_cov))
    zero = np.zeros(1)
    probe.step(None, zero)
    gain = probe.P[0][:, 0] / r
    calm = 0
    for step in range(2, MAX_SETTLE):
        probe.step(dt, zero)
        new = probe.P[0][:, 0] / r
        calm = calm + 1 if np.all(np.abs(new - gain) <= GAIN_TOL * np.abs(new)) else 0
        gain = new
        if calm == SETTLE_STEPS:
            return step, gain
    raise NotBatchable("the Kalman gain does not settle")


def kalman_recursion(gain: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(b, a): the settled filter y -> filtered position as a recursion for ``lfilter``.

    The state follows x_k = A x_(k-1) + K y_k with A = (I - K H) F; the position is H x_k."""
    h = np.array([[1.0, 0.0, 0.0]])
    a_mat = (np.eye(3) - gain[:, None] @ h) @ ca_transition(dt)
    num, den = ss2tf(a_mat, gain[:, None], h @ a_mat, h @ gain[:, None])
    return num[0], den


def _fir_matrix(weights: np.ndarray) -> np.ndarray:
    """Block form of the sliding dot product: (3, BLOCK + W - 1, BLOCK) matrices taking a block's
    samples to its BLOCK outputs of derivative d, output i being sum_j weights[d, j] s[i + j]."""
    w = weights.shape[1]
    t = np.zeros((3, BLOCK + w - 1, BLOCK))
    for i in range(BLOCK):
        t[:, i:i + w, i] = weights
    return t


def _sliding(samples: np.ndarray, matrix: np.ndarray, count: int) -> np.ndarray:
    """(3, n, >= count) sliding dot products over ``samples`` (n, count + W - 1): per derivative, one
    matrix product over all channels and blocks (the overlapping blocks copied side by side)."""
    n = samples.shape[0]
    blocks = -(-count // BLOCK)
    span = matrix.shape[1]
    padded = np.zeros((n, blocks * BLOCK + span - BLOCK))
    padded[:, :samples.shape[1]] = samples
    step = padded.strides[1]
    windows = np.lib.stride_tricks.as_strided(padded, (n, blocks, span), (padded.strides[0], BLOCK * step, step))
    windows = np.ascontiguousarray(windows).reshape(n * blocks, span)
    out = np.empty((3, n * blocks, BLOCK))
    for d in range(3):
        np.matmul(windows, matrix[d], out=out[d])
    return out.reshape(3, n, blocks * BLOCK)


def estimate_chunks(estimator: StreamingEstimator, times: np.ndarray, frames: np.ndarray, scale: np.ndarray,
                    chunk: int) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """:func:`estimate_stream` over whole arrays: ``times`` (N,) s, ``frames`` (N, n)."""
    pieces = ((times[i:i + chunk], frames[i:i + chunk]) for i in range(0, len(times), chunk))
    return estimate_stream(estimator, len(times), pieces, scale, chunk)


def estimate_stream(estimator: StreamingEstimator, total: int, pieces: Iterable[tuple[np.ndarray, np.ndarray]],
                    scale: np.ndarray, chunk: int) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """The per-frame estimator's output over a take of ``total`` frames read in ``pieces``, chunk by chunk.

    ``estimator``: a fresh :class:`StreamingEstimator` (its filter runs the first frames;
    it is reset at the end). ``pieces``: (times (c,) s, frames (c, n) raw samples) of consecutive
    frames, ``chunk`` each but the last; times uniform (see :func:`uniform_step`), samples finite,
    times ``scale`` (n,) = the estimator's input. Yields (first frame index, times (k,) s,
    (3, n, k) position / velocity / acceleration), channel-major, for consecutive frames.
    Memory: O(chunk × n) whatever ``total``. Raises :class:`NotBatchable` if the take is not
    uniform or an angle's innovation reaches ±π (possibly after some chunks were yielded)."""
    cfg = estimator.config
    win, lag = cfg.window, cfg.lag
    if total < 2 * win or chunk < 2 * win:
        raise NotBatchable("take or chunk shorter than two spline windows")
    lam = estimator.spline.lam
    angles = estimator.angle_mask
    state = None  # (lfilter state (n, 3), last unwrapped sample (n,), its wrap count (n,))
    kept = np.empty((len(scale), 0))  # filtered positions from frame ``first_kept`` on
    recent = kept  # the last samples before the chunk
    pending = np.empty(0)  # times of the frames not estimated yet
    last_t = dt = None
    first_kept = 0
    done = 0  # frames estimated so far
    start = 0
    try:
        for times, frames in pieces:
            stop = start + len(times)
            if start == 0:
                dt = uniform_step(times, estimator)
                settle, gain = settled_gain(estimator.kalman, dt)
                head = max(settle, 3)
                recursion = kalman_recursion(gain, dt)
                matrix = _fir_matrix(estimator.spline.weights)
                period = 1.0 - float(gain[0])  # innovation = (y - filtered position) / period
                head_times = times[:win]  # the window filling: its weights use the first times
                tail_times = np.empty(0)
            else:
                uniform_step(times, estimator, last_t, dt)
            tail_times = np.concatenate([tail_times, times])[-win:]  # the flush's weights: the last times
            y = np.ascontiguousarray((frames * scale).T)
            pos = np.empty_like(y)
            exact = min(max(head - start, 0), stop - start)
            for k in range(exact):
                step = None if start + k == 0 else float(times[k]) - float(times[k - 1] if k else last_t)
                pos[:, k] = estimator.kalman.step(step, y[:, k])
            if exact < stop - start:
                if state is None:
                    state = _recursion_state(recursion, np.hstack([kept, pos[:, :exact]])[:, -3:],
                                             np.hstack([recent, y[:, :exact]])[:, -3:], angles)
                pos[:, exact:], state = _filter(recursion, state, y[:, exact:], angles, period)
            last_t = float(times[-1])
            kept = np.hstack([kept, pos])
            recent = y[:, -3:]
            pending = np.concatenate([pending, times])
            end = total if stop == total else stop - lag  # frames estimable now
            yield done, pending[:end - done], _estimates(kept, first_kept, done, end, total, head_times, tail_times,
                                                         lam, lag, win, matrix)
            pending = pending[end - done:]
            done = end
            first_kept = max(0, done + lag - win + 1)
            kept = kept[:, first_kept - (stop - kept.shape[1]):]
            start = stop
    finally:
        estimator.reset()


def _recursion_state(recursion: tuple[np.ndarray, np.ndarray], pos: np.ndarray, y: np.ndarray,
                     angles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """lfilter state after the exactly filtered frames, from their last three positions and samples
    (n, 3) (angle samples moved by whole turns next to the filtered position, as the filter saw them)."""
    b, a = recursion
    turns = np.where(angles[:, None], np.rint((pos - y) / (2 * math.pi)), 0.0)
    seen = y + 2 * math.pi * turns
    zi = np.array([lfiltic(b, a, p[::-1], s[::-1]) for p, s in zip(pos, seen, strict=True)])
    return zi, y[:, -1].copy(), turns[:, -1].copy()


def _filter(recursion, state, y: np.ndarray, angles: np.ndarray, period: float):
    """Settled Kalman filter over samples y (n, c): filtered positions and the next state."""
    b, a = recursion
    zi, last, turns = state
    seen = y
    if angles.any():
        # whole turns that keep each step within ±π, counted on from the previous chunk
        ya = y[angles]
        jumps = np.rint(np.diff(np.hstack([last[angles, None], ya]), axis=1) / (2 * math.pi))
        count = np.broadcast_to(turns[angles, None], ya.shape)
        if jumps.any():
            count = count - np.cumsum(jumps, axis=1)
        if count.any():
            seen = y.copy()
            seen[angles] = ya + 2 * math.pi * count
        turns = turns.copy()
        turns[angles] = count[:, -1]
    pos, zf = lfilter(b, a, seen, axis=1, zi=zi)
    if angles.any():
        worst = np.max(np.abs(pos[angles] - seen[angles]))
        if not worst < period * (math.pi - WRAP_MARGIN):
            raise NotBatchable("an angle channel's Kalman innovation reaches ±π")
    return pos, (zf, y[:, -1].copy(), turns)


def _estimates(pos: np.ndarray, first: int, start: int, end: int, total: int, head_times: np.ndarray,
               tail_times: np.ndarray, lam: float, lag: int, win: int, matrix: np.ndarray) -> np.ndarray:
    """(3, n, end - start) estimates of frames [start, end) from the filtered positions ``pos``
    of frames [first, first + pos.shape[1]); ``head_times`` the take's first ``win`` times (s),
    ``tail_times`` its last ``win`` ones (read only for the flush, in the last chunk)."""

    def window(lo: int, hi: int) -> np.ndarray:
        return pos[:, lo - first:hi - first]

    regular_lo, regular_hi = max(start, win - lag - 1), min(end, total - lag)
    if (regular_lo, regular_hi) == (start, end):  # the common case: a full window for every frame
        return _sliding(window(start + lag - win + 1, end + lag), matrix, end - start)[:, :, :end - start]
    out = np.empty((3, pos.shape[0], end - start))
    for i in range(start, regular_lo):  # the window still filling: fits on the first i + lag + 1 samples
        out[:, :, i - start] = (window(0, i + lag + 1) @ window_weights(head_times[:i + lag + 1], lam, i).T).T
    if regular_hi > regular_lo:
        samples = window(regular_lo + lag - win + 1, regular_hi + lag)
        count = regular_hi - regular_lo
        out[:, :, regular_lo - start:regular_hi - start] = _sliding(samples, matrix, count)[:, :, :count]
    k = min(total, win)
    for i in range(max(start, total - lag), end):  # the flush: the last window at lags lag - 1 ... 0
        out[:, :, i - start] = (window(total - k, total) @ window_weights(tail_times[-k:], lam, i - total + k).T).T
    return out
