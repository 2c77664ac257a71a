"""Sliding-window smoothing-spline differentiator.

Following the chain of the source paper (spline -> differentiate -> spline
again -> differentiate), each window of samples y(t_i) is fitted with a cubic
smoothing spline S1, the minimiser of

    sum_i (y_i - S1(t_i))^2 + lam * integral S1''(t)^2 dt,

position and velocity are S1 and S1', then a second smoothing spline S2 with
the same lam is fitted to the velocities S1'(t_i) and acceleration is S2'.
Differentiating S1 twice would give a useless acceleration at the newest
sample, since a smoothing spline's second derivative is zero at both ends.

The smoothing parameter is set by a cutoff frequency: on uniform samples the
spline is a linear filter whose gain is exactly 1/2 at ``cutoff_hz``
(see :func:`smoothing_lambda`).  lam has units of s^3 for any channel unit.

Everything is linear in y, so on uniform samples the estimate at a fixed
position in the window is a fixed weight vector: it is precomputed once and
each frame costs one (3 x W) @ (W x n) product over a ring buffer.  Windows
with irregular timestamps (dropped frames, jitter) and the warm-up windows get
an exact fit on the actual times: the weights for that one window, O(W) by a
banded Cholesky factorisation, then the same product.  A window on the nominal
grid but for one gap (a loop that skipped a deadline: an interval of a whole
number of periods) is fitted on the grid once per gap size and place and the
weights kept (up to `GRID_WEIGHTS_BYTES`): as the window slides past the next
gap alike, the same windows come back, where an exact fit costs about 70 us a
frame at 200 samples.  Windows with more gaps are fitted each time (their
patterns seldom repeat), from band terms kept per interval as samples arrive
(each interval's terms depend on it and its two neighbours only, so a sliding
window's are a slice of a ring): a fit then forms none of them again.
"""

from __future__ import annotations

import math
import struct
from collections import OrderedDict, deque

import numpy as np
from scipy.linalg.lapack import dpbtrf, dpbtrs

GRID_WEIGHTS_BYTES = 4 << 20  # kept weights of windows with missing grid samples, at most (bytes)
MAX_GAP_PERIODS = 1000  # a longer gap is fitted on its actual times
_ENTRY_OVERHEAD = 300  # bytes a kept weight array costs beyond its numbers (array object, key, dict slot)
# the band terms kept per interval (SlidingSplineDifferentiator._keep_terms)
_TERMS = ("h", "inv", "mid", "diagonal", "sub", "subsub")
_TERMS_ROW = struct.Struct(f"={len(_TERMS)}d")  # one row of them, as the ring's native doubles


def smoothing_lambda(dt: float, cutoff_hz: float) -> float:
    """Smoothing parameter lam (s^3) whose spline has gain 1/2 at ``cutoff_hz`` on samples ``dt`` s apart.

    On an infinite uniform grid the cubic smoothing spline is the filter
    H(w) = 1 / (1 + (lam / dt^3) (2 - 2 cos w dt)^2 * 3 / (2 + cos w dt)), w in rad/s,
    which tends to 1 / (1 + lam dt w^4) at low frequency.  ``cutoff_hz`` must
    lie below the Nyquist frequency 1 / (2 dt).
    """
    if not 0.0 < cutoff_hz * dt < 0.5:
        raise ValueError(f"cutoff {cutoff_hz} Hz must lie in (0, {0.5 / dt:g}) Hz for samples {dt:g} s apart")
    theta = 2.0 * math.pi * cutoff_hz * dt
    return dt**3 * (2.0 + math.cos(theta)) / (3.0 * (2.0 - 2.0 * math.cos(theta)) ** 2)


def _slopes_adjoint(u: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Transpose of the knot-slope map of a natural cubic spline, applied to ``u``: a row (k,) or rows (r, k).

    The slopes at the knots are v = Dg g + Dc c for knot values g and second
    derivatives c (both (k,)); this returns (u Dg, u Dc), each shaped as ``u``.
    """
    # Each knot takes its two intervals' terms: the middle knots' by one subtraction each, the ends' alone; the
    # same values, op for op, as zeroes with the terms added in (two in-place updates each), in fewer calls.
    rate = u[..., :-1] / h
    zg = np.empty(u.shape)
    zg[..., 0] = 0.0 - rate[..., 0]
    np.subtract(rate[..., :-1], rate[..., 1:], out=zg[..., 1:-1])
    zg[..., -1] = rate[..., -1] + 0.0
    end_rate = u[..., -1] / h[-1]  # the last slope uses the last interval from the left
    zg[..., -2] -= end_rate
    zg[..., -1] += end_rate
    arm = u[..., :-1] * h / 6.0
    twice = -2.0 * arm
    zc = np.empty(u.shape)
    zc[..., 0] = twice[..., 0] + 0.0
    np.subtract(twice[..., 1:], arm[..., :-1], out=zc[..., 1:-1])
    zc[..., -1] = 0.0 - arm[..., -1]
    end_arm = u[..., -1] * h[-1] / 6.0
    zc[..., -2] += end_arm
    zc[..., -1] += 2.0 * end_arm
    return zg, zc


def window_weights(t: np.ndarray, lam: float, index: int) -> np.ndarray:
    """(3, k) weights giving [position, velocity, acceleration] at sample ``index`` of one window.

    ``t``: (k,) strictly increasing times, s; ``lam``: smoothing parameter, s^3.
    For samples Y (k, n) of any unit the estimate is ``weights @ Y``: S1(t_index),
    S1'(t_index) (unit/s) and S2'(t_index) (unit/s^2).  One sample gives zero
    derivatives, two give the line through them.

    Smoothing by the Reinsch algorithm (Green & Silverman 1994, ch. 2):
    S1 has knot values g = y - lam Q A^-1 Q^T y and second derivatives
    A^-1 Q^T y, A = R + lam Q^T Q pentadiagonal.  Only one row of each linear
    map is wanted, so it is found through the transposed maps: two banded
    solves with one or two right-hand sides, O(k), whatever the channel count.
    The maps act on rows (one weight vector a row, contiguous): numpy's
    per-call cost, not the O(k) arithmetic, is most of a fit's time.
    """
    k = t.shape[0]
    if k == 1:
        return np.array([[1.0], [0.0], [0.0]])
    h = t[1:] - t[:-1]  # np.diff's arithmetic without its call overhead
    if k == 2:
        unit = np.zeros((1, k))
        unit[0, index] = 1.0
        vel, _ = _slopes_adjoint(unit, h)
        acc, _ = _slopes_adjoint(vel, h)
        return np.vstack([unit, vel, acc])
    # Columns of the k x (k-2) second-difference matrix Q: entries at rows a, a+1, a+2.
    inv = 1.0 / h
    lo = inv[:-1]
    hi = inv[1:]
    mid = -lo - hi
    # Lower banded form of A = R + lam Q^T Q (symmetric positive definite); LAPACK's
    # unblocked band Cholesky costs half as much in lower as in upper storage.
    ab = np.zeros((k - 2, 3)).T  # column-major, as LAPACK takes it: no copy
    square = inv**2
    ab[0] = (h[:-1] + h[1:]) / 3.0 + lam * (square[:-1] + mid**2 + square[1:])  # lo**2 + mid**2 + hi**2
    ab[1, :-1] = h[1:-1] / 6.0 + lam * (mid[:-1] * lo[1:] + hi[:-1] * mid[1:])
    ab[2, :-2] = lam * (hi[:-2] * lo[2:])
    return banded_weights(h, inv, mid, ab, lam, index)


def banded_weights(h: np.ndarray, inv: np.ndarray, mid: np.ndarray, ab: np.ndarray, lam: float,
                   index: int) -> np.ndarray:
    """`window_weights` of a window of k >= 3 samples from its intervals' terms: ``h`` (k-1,) s, ``inv`` = 1 / h,
    ``mid`` (k-2,) = -inv[:-1] - inv[1:] (Q's middle entries) and ``ab`` (3, k-2), column-major, A in LAPACK's
    lower band storage (its entries past the matrix zero), which the factorisation overwrites. The terms
    depend only on the intervals, so a sliding window can keep them per interval (`SlidingSplineDifferentiator`)
    rather than form them for every fit."""
    k = h.shape[0] + 1
    lo = inv[:-1]
    hi = inv[1:]
    # LAPACK directly: the scipy.linalg wrappers cost more than the O(k) work here.
    factor, info = dpbtrf(ab, lower=1, overwrite_ab=1)
    if info != 0:
        raise ValueError(f"smoothing system not positive definite (info {info}): times must increase")

    def hat_t(base: np.ndarray, extra: np.ndarray) -> np.ndarray:
        # base + (Q A^-1 (extra[1:-1] - lam Q^T base))^T along the last axis, in place, for one row (k,) or
        # rows (r, k): the transposed smoothing map.  With extra = 0 it is a row of the hat matrix; with
        # (base, extra) = (u Dg, u Dc) it is u V for the knot-velocity map V = Dg H + Dc A^-1 Q^T.
        rhs = extra[..., 1:-1] - lam * (lo * base[..., :-2] + mid * base[..., 1:-1] + hi * base[..., 2:])
        # rows in, rows out: LAPACK's column-major right-hand sides are the rows transposed, no copy
        inner = dpbtrs(factor, rhs.T, lower=1, overwrite_b=1)[0].T
        base[..., :-2] += lo * inner
        base[..., 1:-1] += mid * inner
        base[..., 2:] += hi * inner
        return base

    # Row 0 of ``out``: the unit vector at ``index``; row 1: (Dg, Dc) of it, which touch the two knots of
    # the interval its slope is taken on (_slopes_adjoint, written out for one nonzero); row 2 from row 1.
    out = np.zeros((3, k))
    extra = np.zeros((2, k))
    out[0, index] = 1.0
    a = min(index, k - 2)
    arm = h[a] / 6.0
    out[1, a], out[1, a + 1] = -1.0 / h[a], 1.0 / h[a]
    extra[1, a], extra[1, a + 1] = (-2.0 * arm, -arm) if index < k - 1 else (arm, 2.0 * arm)
    hat_t(out[:2], extra)  # in place: out's first two rows are views
    out[2] = hat_t(*_slopes_adjoint(out[1], h))  # one row: numpy's 1-D calls cost less
    return out


def uniform_weights(window: int, lag: int, dt: float, lam: float) -> np.ndarray:
    """(3, window) weights giving [position, velocity, acceleration] at ``lag`` samples before the newest.

    Valid for ``window`` samples exactly ``dt`` s apart, oldest first: the
    estimate for data Y of shape (window, n) is ``weights @ Y``.
    """
    return window_weights(np.arange(window) * dt, lam, window - 1 - lag)


class SlidingSplineDifferentiator:
    """Ring buffer of the last ``window`` samples and the smoothing-spline estimate inside it.

    ``dt`` is the nominal sample period (s); windows whose intervals all lie
    within ``jitter_tol * dt`` of it use the precomputed weights, any other
    window (and the warm-up, fewer than ``window`` samples) gets an exact fit
    on its actual timestamps, but for a window with one gap of whole periods,
    whose weights are kept (module docstring; at most ``grid_weights_bytes``).
    Memory is bounded at construction.
    """

    def __init__(self, n_channels: int, window: int, lag: int, dt: float, lam: float, jitter_tol: float,
                 grid_weights_bytes: int = GRID_WEIGHTS_BYTES):
        if not 0 <= lag < window:
            raise ValueError(f"lag {lag} must satisfy 0 <= lag < window {window}")
        self.window = window
        self.lag = lag
        self.dt = dt
        self.lam = lam
        self.jitter_tol = jitter_tol
        self.weights = uniform_weights(window, lag, dt, lam)
        # (samples, index, the gap's interval in the window, its periods) -> that window's weights, oldest first
        self._grid: OrderedDict[tuple[int, int, int, int], np.ndarray] = OrderedDict()
        self._grid_kept = grid_weights_bytes // (3 * window * 8 + _ENTRY_OVERHEAD)
        self._gaps: deque[tuple[int, int]] = deque(maxlen=window)
        # Each sample is written twice, W apart, so the window is always one contiguous slice.
        self._y = np.zeros((2 * window, n_channels))
        self._t = np.zeros(2 * window)
        # Per interval m (ending at sample m), in the same ring: the fit's band terms (`banded_weights`) that m
        # completes, so a window's exact fit slices them instead of forming them again (a fifth of its calls).
        self._terms = np.zeros((2 * window, len(_TERMS)))
        self._terms_bytes = memoryview(self._terms).cast("B")
        self.reset()

    def reset(self) -> None:
        """Forget all samples."""
        self._slot = self.window - 1
        self.count = 0
        self._last_irregular = -1  # sample number that ends the most recent off-nominal interval
        self._last_off_grid = -1  # ... the most recent interval that is not a whole number of periods either
        self._previous: tuple[float, float, float, float] | None = None  # interval m-1's h, inv, inv², m-2's mid
        self._gaps.clear()  # (sample number, whole periods) of the intervals longer than one period

    def push(self, t: float, y: np.ndarray) -> None:
        """Append one sample: time ``t`` (s, after the previous one) and values ``y`` (n,)."""
        if self.count:
            h = t - float(self._t[self._slot + self.window])  # s since the previous sample
            self._keep_terms(h)
            if abs(h - self.dt) > self.jitter_tol * self.dt:
                self._off_nominal(h / self.dt)
        s = (self._slot + 1) % self.window
        self._y[s] = y
        self._y[s + self.window] = y
        self._t[s] = t
        self._t[s + self.window] = t
        self._slot = s
        self.count += 1

    def _off_nominal(self, periods: float) -> None:
        """The interval ending at the sample being pushed is ``periods`` nominal periods long (not one)."""
        self._last_irregular = self.count
        whole = round(periods)
        if 1 < whole <= MAX_GAP_PERIODS and abs(periods - whole) <= self.jitter_tol:
            self._gaps.append((self.count, whole))
        else:
            self._last_off_grid = self.count

    def _keep_terms(self, h: float) -> None:
        """Interval m = ``count`` (``h`` s) into the ring of band terms (``_TERMS``): its own h and 1 / h, the
        middle entry of Q and the diagonal of A at the knot it closes (column m-1), the sub-diagonals of column
        m-2. Plain floats in numpy's order of operations (`window_weights`), so the terms are its bit for bit."""
        lam = self.lam
        inv = 1.0 / h if h else math.inf  # numpy's 1 / 0: equal times, which the fit then refuses
        square = inv * inv  # numpy's inv**2
        mid = diagonal = sub = subsub = 0.0  # a stream's first intervals: their columns are never read
        if self._previous is not None:
            h1, inv1, square1, mid0 = self._previous
            mid = -inv1 - inv
            diagonal = (h1 + h) / 3.0 + lam * (square1 + mid * mid + square)
            if self.count > 2:
                sub = h1 / 6.0 + lam * (mid0 * inv1 + inv1 * mid)
                subsub = lam * (inv1 * inv)
        self._previous = (h, inv, square, mid)
        # both copies packed as raw doubles: a tuple's conversion by numpy costs twice as much
        pack, place = _TERMS_ROW.pack_into, self._terms_bytes
        start = self.count % self.window * _TERMS_ROW.size
        pack(place, start, h, inv, mid, diagonal, sub, subsub)
        pack(place, start + self.window * _TERMS_ROW.size, h, inv, mid, diagonal, sub, subsub)

    def _fit(self, k: int, index: int) -> np.ndarray:
        """`window_weights` of the newest ``k`` samples' times at ``index``, from the kept band terms."""
        if k < 3:
            end = self._slot + self.window + 1
            return window_weights(self._t[end - k : end], self.lam, index)
        s = (self.count - k + 1) % self.window  # the slot of the window's first interval
        terms = self._terms[s : s + k - 1]
        ab = np.zeros((k - 2, 3))  # row-major here: LAPACK's column-major (3, k - 2) transposed
        ab[:, 0] = terms[1:, 3]
        ab[:-1, 1:] = terms[2:, 4:]
        ab[-2:, 2] = 0.0  # the last two columns' second sub-diagonal lies past the matrix: zero, as window_weights
        return banded_weights(terms[:, 0], terms[:, 1], terms[1:, 2], ab.T, self.lam, index)

    def backfill(self, channels: np.ndarray, values: np.ndarray) -> None:
        """Overwrite the whole history of the masked ``channels`` with their ``values`` (n,).

        Used when a channel is seen for the first time: its earlier samples are
        taken as equal to its first value rather than to a placeholder.
        """
        self._y[:, channels] = values[channels]

    def time_at(self, lag: int) -> float:
        """Timestamp (s) of the sample ``lag`` samples before the newest."""
        return float(self._t[self._slot + self.window - lag])

    def estimate(self, lag: int | None = None) -> np.ndarray:
        """(3, n) position, velocity, acceleration at ``lag`` (default: the configured lag) samples before the newest.

        Needs at least ``lag + 1`` samples held.
        """
        k = min(self.count, self.window)
        end = self._slot + self.window + 1
        samples = self._y[end - k : end]
        if lag is None:
            lag = self.lag
            if k == self.window and self._last_irregular < self.count - self.window + 1:
                return self.weights.dot(samples)  # the same product as @, with less call overhead
        first = self.count - k + 1  # the sample number that ends the window's first interval (never decreases)
        gaps = self._gaps
        while gaps and gaps[0][0] < first:
            gaps.popleft()
        if self._grid_kept < 1 or self._last_off_grid >= first or len(gaps) != 1:  # more: seldom seen again
            return self._fit(k, k - 1 - lag) @ samples
        ends, periods = gaps[0]
        return self._grid_weights((k, k - 1 - lag, ends - first, periods)) @ samples

    def _grid_weights(self, key: tuple[int, int, int, int]) -> np.ndarray:
        """The weights of a window of ``k`` samples at ``index`` on the nominal grid but for interval ``at``,
        ``periods`` long (``key``: k, index, at, periods): fitted once, kept for the next window alike."""
        weights = self._grid.get(key)
        if weights is None:
            k, index, at, periods = key
            steps = np.ones(k - 1)
            steps[at] = periods
            weights = window_weights(np.concatenate(([0.0], np.cumsum(steps))) * self.dt, self.lam, index)
            if len(self._grid) >= self._grid_kept:
                self._grid.popitem(last=False)
            self._grid[key] = weights
        return weights
