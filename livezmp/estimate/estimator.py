"""Streaming estimate of position, velocity and acceleration for every channel of a pose stream.

The chain of the source paper, run per frame: an online Kalman filter
(:mod:`livezmp.estimate.kalman`) bridges missing samples and unwraps angle channels,
then a sliding-window smoothing spline (:mod:`livezmp.estimate.spline_diff`) gives the
position, velocity and acceleration ``lag`` frames behind the newest input.
Offline runs (:func:`estimate_offline`) go through the very same per-frame
code, so live and offline results agree.

Choosing the parameters (all in seconds or Hz, converted with ``rate_hz``):

* ``cutoff_hz``: the smoothing spline passes motion below it and has gain 1/2
  at it; velocity goes through one such stage, acceleration through two.
  6 Hz (the usual low-pass for human marker data) suits clean gait and
  whole-body motion; raise it for fast robot joints with clean encoders.  The
  analysis commands' defaults lower it with the frame rate so that measurement
  noise hurts equally at every rate (:func:`default_cutoff`).  Errors scale
  with (motion frequency / cutoff_hz), noise grows as cutoff_hz^2.5 in
  acceleration.
* ``lag_s``: delay of the output.  A smoothing spline is least accurate at
  the end of its window (its second derivative is forced to zero there), so
  the causal estimate (lag 0) is poor in acceleration.  lag_s = 0.6 / cutoff_hz
  (0.1 s at 6 Hz) reaches near-interior accuracy.
* ``window_s``: history the spline sees.  window_s = 2.4 / cutoff_hz (0.4 s at
  6 Hz) leaves the older end of the window out of reach of the estimate.
  Per-frame cost is proportional to window_s * rate_hz * channels.
* ``kalman_corner_hz``: the pole radius of the Kalman filter (whose
  continuous-time limit has Butterworth poles).  Motion at frequency f passes
  it with relative error about (f / corner)^3; its main job is filling gaps.
  Only the ratio of process to measurement noise shapes a Kalman filter's
  output, so this one frequency replaces both:
  jerk PSD / measurement variance = (2 pi corner)^6 / rate_hz.

Measured with the defaults at 120 Hz (benchmarks/bench_estimator.py), the
largest error on a noise-free sinusoid of amplitude A and angular frequency w,
relative to A, A w and A w^2 (position / velocity / acceleration):

    1 Hz: 0.3 % / 1.4 % / 3.1 %     2 Hz: 1.9 % / 3.9 % / 7.5 %
    4 Hz: 15 % / 20 % / 35 %  (the 6 Hz low-pass at work)

and within about one percentage point of that at 30-1000 Hz.  Acceleration error at 1 Hz against the lag:
55 % at 0, 47 % at 25 ms, 31 % at 50 ms, 3.1 % at 100 ms.  White measurement
noise of standard deviation s leaves 0.31 s, 6.5 s /s and 123 s /s^2 at
120 Hz (times sqrt(120 / rate_hz) at other rates).  Gaps are bridged by
constant-acceleration prediction, fine for tens of milliseconds; ``missing``
marks them.

Per-frame cost and memory: benchmarks/bench_estimator.py.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livezmp.errors import InputError
from livezmp.estimate.kalman import ConstantAccelerationKalman
from livezmp.estimate.spline_diff import SlidingSplineDifferentiator, smoothing_lambda


class EstimatorError(InputError):
    """A bad estimator configuration or input stream (the message names the field or sample)."""


MAX_WINDOW = 4096  # samples: the ring buffer is 2 x window x channels; refused before it is allocated


@dataclass(frozen=True)
class EstimatorConfig:
    """Estimator settings; see the module docstring for how to choose them.

    rate_hz: nominal input rate (Hz).  window_s, lag_s: spline window and
    output delay (s), rounded to whole samples.  cutoff_hz: smoothing-spline
    half-gain frequency (Hz), below rate_hz / 2.  kalman_corner_hz: Kalman
    filter bandwidth (Hz).  jitter_tol: windows whose sample intervals all lie
    within this fraction of 1 / rate_hz use the precomputed uniform weights;
    others get an exact fit on their actual times.
    """

    rate_hz: float = 120.0
    window_s: float = 0.4
    lag_s: float = 0.1
    cutoff_hz: float = 6.0
    kalman_corner_hz: float = 20.0
    jitter_tol: float = 0.01

    def __post_init__(self) -> None:
        for name in ("rate_hz", "window_s", "cutoff_hz", "kalman_corner_hz"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise EstimatorError(f"EstimatorConfig.{name} = {value!r}: must be a positive number")
        for name in ("lag_s", "jitter_tol"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise EstimatorError(f"EstimatorConfig.{name} = {value!r}: must be a number >= 0")
        if self.window < 3:
            raise EstimatorError(
                f"EstimatorConfig.window_s = {self.window_s} s is {self.window} samples at {self.rate_hz:g} Hz: "
                "need at least 3"
            )
        if self.window > MAX_WINDOW:
            raise EstimatorError(
                f"EstimatorConfig.window_s = {self.window_s} s is {self.window} samples at {self.rate_hz:g} Hz: "
                f"more than {MAX_WINDOW}"
            )
        if self.lag >= self.window:
            raise EstimatorError(
                f"EstimatorConfig.lag_s = {self.lag_s} s ({self.lag} samples) must be shorter than "
                f"window_s = {self.window_s} s ({self.window} samples)"
            )
        if self.cutoff_hz >= 0.5 * self.rate_hz:
            raise EstimatorError(
                f"EstimatorConfig.cutoff_hz = {self.cutoff_hz} Hz must be below the Nyquist frequency "
                f"{0.5 * self.rate_hz:g} Hz (rate_hz / 2)"
            )
        if self.jitter_tol >= 0.5:
            raise EstimatorError(f"EstimatorConfig.jitter_tol = {self.jitter_tol}: must be below 0.5")

    @property
    def dt(self) -> float:
        """Nominal sample period, s."""
        return 1.0 / self.rate_hz

    @property
    def window(self) -> int:
        """Spline window, samples."""
        return math.floor(self.window_s * self.rate_hz + 0.5)

    @property
    def lag(self) -> int:
        """Output delay, samples."""
        return math.floor(self.lag_s * self.rate_hz + 0.5)


REFERENCE_CUTOFF_HZ = 4.0  # the default cutoff at REFERENCE_RATE_HZ; see default_estimator
REFERENCE_RATE_HZ = 120.0
# The default for a whole take read from a file (analyze, correct, batch) at every rate: exported
# takes come filtered by the capture software, 6 Hz is gait analysis' usual cutoff, and it is what
# compares best with force plates here (docs/validation.md). Streams, whose noise is unknown, take
# default_cutoff; a noisy file takes --cutoff-hz.
FILE_CUTOFF_HZ = 6.0


def default_cutoff(rate_hz: float) -> float:
    """The default smoothing cutoff (Hz) for input at ``rate_hz`` (Hz).

    White noise of s per sample leaves about s * cutoff^2.5 / sqrt(rate) in acceleration
    (the spline's gain), so a fixed cutoff lets the same noise disturb the ZMP twice as
    much at 30 Hz as at 120 Hz.  The cutoff scales as rate^(1/5), which holds that noise
    constant: 4 Hz at 120 Hz, 3.0 at 30, 3.5 at 60, 4.6 at 240
    (benchmarks/bench_estimator_noise.py).
    """
    return REFERENCE_CUTOFF_HZ * (rate_hz / REFERENCE_RATE_HZ) ** 0.2


def default_estimator(rate_hz: float, cutoff_hz: float | None = None) -> EstimatorConfig:
    """Estimator settings for input at ``rate_hz`` (Hz): ``cutoff_hz`` (None: :func:`default_cutoff`),
    window 2.4 / cutoff and lag 0.6 / cutoff seconds (module docstring)."""
    if not (isinstance(rate_hz, int | float) and math.isfinite(rate_hz) and rate_hz > 0):
        raise EstimatorError(f"rate_hz = {rate_hz!r}: must be a positive number")
    cutoff = default_cutoff(rate_hz) if cutoff_hz is None else cutoff_hz
    # the window 2.4 / cutoff must hold MAX_WINDOW samples at most (3 at least: below Nyquist it does)
    lowest, nyquist = 2.4 * rate_hz / MAX_WINDOW, 0.5 * rate_hz
    if not (math.isfinite(cutoff) and lowest <= cutoff < nyquist):
        # named as the option that changes it, whether the user gave it or a file's default (6 Hz) set it
        raise EstimatorError(f"--cutoff-hz {cutoff:g} at {rate_hz:g} frames/s: must be at least {lowest:.3g} Hz "
                             f"(a smoothing window of 2.4 / cutoff s, {MAX_WINDOW} frames at most) and below "
                             f"the Nyquist frequency, {nyquist:g} Hz"
                             + (f" (a file's default is {FILE_CUTOFF_HZ:g} Hz: give --cutoff-hz below {nyquist:g})"
                                if cutoff >= nyquist else ""))
    return EstimatorConfig(rate_hz=rate_hz, window_s=2.4 / cutoff, lag_s=0.6 / cutoff, cutoff_hz=cutoff)


@dataclass
class Estimate:
    """One output frame, ``lag`` frames behind the newest input.

    index: input frame index (from 0 since start or reset) this estimate belongs to.
    t: its time, s.  q, qd, qdd: (n,) position, velocity, acceleration, in the
    channel's unit, per s, per s^2; angle channels are continuous (unwrapped).
    missing: (n,) True where this frame's input sample was missing and the
    value rests on the Kalman prediction (or, before a channel's first sample,
    on nothing: q = 0).
    """

    index: int
    t: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    missing: np.ndarray


class StreamingEstimator:
    """Per-frame estimator over ``n_channels`` channels; fixed memory and per-frame cost.

    ``angle_mask`` (n,) bool marks angle channels (rad, may wrap at +-pi);
    None means none.  Non-finite input values are missing samples.
    """

    def __init__(self, n_channels: int, angle_mask: np.ndarray | None = None, config: EstimatorConfig | None = None):
        if not (isinstance(n_channels, int | np.integer) and n_channels >= 1):
            raise EstimatorError(f"n_channels = {n_channels!r}: must be a positive integer")
        self.n_channels = int(n_channels)
        self.config = config if config is not None else EstimatorConfig()
        self.angle_mask = _angle_mask(angle_mask, self.n_channels)
        cfg = self.config
        dt = cfg.dt
        self.lag = cfg.lag
        # Unit measurement variance: only the ratio to the jerk PSD shapes the filter.  The start is
        # diffuse: velocity and acceleration priors far wider than one sample's noise per step.
        self.kalman = ConstantAccelerationKalman(
            self.angle_mask,
            jerk_psd=(2.0 * math.pi * cfg.kalman_corner_hz) ** 6 * dt,
            meas_var=1.0,
            init_var=[1.0, 1e4 / dt**2, 1e4 / dt**4],
        )
        self.spline = SlidingSplineDifferentiator(
            self.n_channels, cfg.window, cfg.lag, dt, smoothing_lambda(dt, cfg.cutoff_hz), cfg.jitter_tol
        )
        self._missing = np.zeros((cfg.lag + 1, self.n_channels), dtype=bool)
        self.reset()

    def reset(self) -> None:
        """Forget the stream: the next sample starts a new session at index 0."""
        self.kalman.reset()
        self.spline.reset()
        self._missing[:] = False
        self._count = 0
        self._t_last = -math.inf

    def step(self, t: float, y: np.ndarray) -> Estimate | None:
        """Take the sample ``y`` (n,) at time ``t`` (s, strictly after the previous one).

        Returns the estimate for the frame ``lag`` samples back, or None while
        fewer than lag + 1 samples have arrived.
        """
        y = np.asarray(y, dtype=float)
        if y.shape != (self.n_channels,):
            raise EstimatorError(f"step(): sample has shape {y.shape}, expected ({self.n_channels},)")
        if not math.isfinite(t):
            raise EstimatorError(f"step(): time {t!r} is not a finite number of seconds")
        if t <= self._t_last:
            raise EstimatorError(f"step(): time {t!r} s is not after the previous sample's {self._t_last!r} s")
        missing = self._missing[self._count % (self.lag + 1)]
        np.isfinite(y, out=missing)
        np.logical_not(missing, out=missing)
        newly = None if self.kalman.all_started else ~missing & ~self.kalman.started
        position = self.kalman.step(t - self._t_last if self._count else None, y)
        if newly is not None and self._count and newly.any():
            self.spline.backfill(newly, position)
        self.spline.push(t, position)
        self._t_last = t
        self._count += 1
        if self._count <= self.lag:
            return None
        return self._estimate(self.lag)

    def flush(self) -> list[Estimate]:
        """Estimates for the frames still pending at the end of a stream, oldest first; then reset.

        They come from the last window evaluated at lags lag - 1 ... 0 (all
        held frames if fewer than lag + 1 arrived).
        """
        pending = min(self.lag, self._count)
        out = [self._estimate(lag) for lag in range(pending - 1, -1, -1)]
        self.reset()
        return out

    def _estimate(self, lag: int) -> Estimate:
        qs = self.spline.estimate(None if lag == self.lag else lag)
        index = self._count - 1 - lag
        return Estimate(
            index=index,
            t=self.spline.time_at(lag),
            q=qs[0],
            qd=qs[1],
            qdd=qs[2],
            missing=self._missing[index % (self.lag + 1)].copy(),
        )


def _angle_mask(angle_mask: np.ndarray | None, n: int) -> np.ndarray:
    if angle_mask is None:
        return np.zeros(n, dtype=bool)
    mask = np.asarray(angle_mask)
    if mask.shape != (n,) or mask.dtype != bool:
        raise EstimatorError(f"angle_mask: expected a bool array of shape ({n},), got {mask.dtype} {mask.shape}")
    return mask.copy()


def estimate_offline(
    t: np.ndarray, Y: np.ndarray, angle_mask: np.ndarray | None = None, config: EstimatorConfig | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run the streaming estimator over a whole take; outputs aligned with the input frames.

    ``t``: (N,) strictly increasing times, s.  ``Y``: (N, n) samples, non-finite
    = missing; every channel needs at least one finite sample.  Returns q, qd,
    qdd, each (N, n) (unit, unit/s, unit/s^2), row i for input frame i.
    """
    t = np.asarray(t, dtype=float)
    Y = np.asarray(Y, dtype=float)
    if t.ndim != 1 or Y.ndim != 2 or Y.shape[0] != t.shape[0] or t.shape[0] == 0:
        raise EstimatorError(f"estimate_offline: need t (N,) and Y (N, n) with N >= 1, got {t.shape} and {Y.shape}")
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise EstimatorError(f"estimate_offline: t[{bad[0]}] = {t[bad[0]]} is not a finite time")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = back[0] + 1
        raise EstimatorError(f"estimate_offline: t[{i}] = {t[i]} s is not after t[{i - 1}] = {t[i - 1]} s")
    empty = np.flatnonzero(~np.isfinite(Y).any(axis=0))
    if empty.size:
        raise EstimatorError(f"estimate_offline: channel {empty[0]} has no finite sample")
    est = StreamingEstimator(Y.shape[1], angle_mask, config)
    out = np.empty((3,) + Y.shape)
    for ti, yi in zip(t, Y, strict=True):
        e = est.step(ti, yi)
        if e is not None:
            out[:, e.index] = e.q, e.qd, e.qdd
    for e in est.flush():
        out[:, e.index] = e.q, e.qd, e.qdd
    return out[0], out[1], out[2]
