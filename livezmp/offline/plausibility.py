"""Is a take's motion physically plausible? Its centre-of-mass accelerations and ZMP–CoM distances
against what force plates measured on real walks.

The references are the largest 99th percentiles over the 17 tuning trials with force plates (the two shared
walks and fifteen c3d.org and lab samples, docs/validation.md "Plausibility references"; ``python
benchmarks/bench_forceplates.py DIR`` prints each trial's), per axis the larger of the plates' (ground reaction ÷
mass − g, complete frames) and livezmp's own estimate from the markers over the whole take (which is what a take is
judged by: it also sees heel strikes the complete frames leave out, and is noisier), rounded up to 0.1 m/s². Walking
speeds only: a take of running, jumping or dancing will exceed them without being wrong, and the verdict says "for
walking".

Fore-aft and lateral are the path's, not the lab's: along the path's heading (the velocity's moving mean over a
stride, twice) the horizontal acceleration is split into its slow part (the same means: below the stride frequency;
turns, starting, stopping; on a circle the centripetal v²/r) and the within-step rest, the oscillation the
references describe, which is judged. The slow part is reported (``path_acc_p99_mps2``, over the frames whose means
are whole: a stride or more from the take's ends), not judged against the straight-walk references: a turn is
balanced by the ZMP moving to its inside (a_c·h/g), which the ZMP–CoM distance check bounds. Within a stride of the
take's ends the means are cut short and keep part of the oscillation (1 % on a 2 Hz swing over 10 s).
"""

from __future__ import annotations

import tempfile

import numpy as np

from livezmp.offline.upper_quantile import UpperQuantile
from livezmp.offline.validation import walking_axes

# m/s², fore-aft, lateral, vertical (see the module docstring): the markers' 3.06 (sample14), 1.23 (newwalk) and
# 5.18 (TYPE-3) rounded up; two shared walks' (3.4, 1.2, 3.4) before, which called 5 of 46 real plate walks
# implausible (vertical 1.5-1.6x: heel strikes the two did not have)
WALK_COM_ACC_P99 = (3.1, 1.3, 5.2)
# m, horizontal CoP-to-CoM distance, same frames: above every tuning and held-out walk's (at most 0.235 m)
WALK_ZMP_COM_P99_M = 0.30
PLAUSIBLE_RATIO = 1.5
# In flight nothing holds the body up and its CoM falls at g: a take whose "flight" frames (no foot on the ground the
# tool found) are a tenth of it or more while their CoM falls at less than g/2 on average has its feet off that ground
# for another reason (a floor that is not level, a root pinned in the air). Real flights (CMU 01_01's hops, Xia's
# jumps) average -6.9 to -7.5 m/s² under the estimator's smoothing; such takes 0 to +0.2 (docs/validation.md).
FLIGHT_SHARE = 0.1
FLIGHT_FALL_MPS2 = -9.81 / 2
# s: the moving mean's length (taken twice): a stride. A walk's lateral sway repeats at the stride frequency (0.75-1.1
# Hz), its fore-aft swing at twice it: the two means keep 9 % of a sway at 0.75 Hz, 5 % at 0.8, under 1 % at 0.95-1.1,
# under 4 % of a swing at 1.6-2.2 Hz, and a turn's acceleration (seconds long) nearly whole
STRIDE_S = 1.0
PATH_MIN_SPEED = 0.2  # m/s: slower (standing, stepping in place), the take's net travel gives the axes, not its path
BLOCK_FRAMES = 1 << 16  # horizontal velocities and accelerations read back 65536 frames at a time (and a margin)


def com_accelerations(com: np.ndarray, dt: float) -> np.ndarray:
    """(N, 3) m/s²: the estimated CoM trajectory (smooth: it comes from the estimator's positions)
    differentiated twice by central differences."""
    if len(com) < 3:
        return np.zeros_like(com)
    return np.gradient(np.gradient(com, dt, axis=0), dt, axis=0)


def plausibility(com: np.ndarray, zmp: np.ndarray, has_zmp: np.ndarray, dt: float,
                 flight: np.ndarray | None = None) -> dict:
    """CoM acceleration p99 (fore-aft, lateral, vertical; m/s²) and ZMP–CoM distance p99 (m) of a take
    (internal frame), their ratios to a real walk's, the CoM's mean vertical acceleration over the ``flight``
    frames (no foot on the ground), and a one-line verdict."""
    stats = PlausibilityStats(len(com), dt)
    stats.add(com, zmp, has_zmp, flight)
    return stats.result()


def _gradient(f: np.ndarray, first: int, total: int, dt: float, lo: int, hi: int) -> np.ndarray:
    """:func:`numpy.gradient` (spacing ``dt``, first-order edges) of a series of ``total`` samples, at
    samples [lo, hi), from its samples ``f`` of [first, first + len(f)): the same arithmetic."""
    out = np.empty((hi - lo, *f.shape[1:]))
    i = np.arange(max(lo, 1), min(hi, total - 1)) - first
    out[max(lo, 1) - lo:min(hi, total - 1) - lo] = (f[i + 1] - f[i - 1]) / (2.0 * dt)
    if lo == 0:
        out[0] = (f[1 - first] - f[-first]) / dt
    if hi == total:
        out[-1] = (f[total - 1 - first] - f[total - 2 - first]) / dt
    return out


class PlausibilityStats:
    """:func:`plausibility` of a take of ``total`` frames ``dt`` s apart, its results added chunk by
    chunk in bounded memory: the CoM accelerations (:func:`com_accelerations`, two frames of CoM
    carried between chunks) and ZMP–CoM distances go into exact upper percentiles
    (:class:`UpperQuantile`); the horizontal accelerations, whose fore-aft and lateral parts depend on
    the take's net travel (known at the end), wait in a temporary file (16 bytes a frame)."""

    def __init__(self, total: int, dt: float):
        self.total, self.dt = total, dt
        self.vertical, self.distance = UpperQuantile(total), UpperQuantile(total)
        self.spill = tempfile.TemporaryFile()  # noqa: SIM115 (closed by close)
        self.com = np.empty((0, 3))  # CoM of frames [self.first, self.received)
        self.flight = np.empty(0, dtype=bool)  # flight frames among them
        self.flight_count, self.flight_acc = 0, 0.0  # flight frames out, sum of their vertical accelerations
        self.first = self.received = self.done = 0  # self.done: frames whose acceleration is out
        self.start: np.ndarray | None = None  # the first frame's CoM

    def add(self, com: np.ndarray, zmp: np.ndarray, has_zmp: np.ndarray, flight: np.ndarray | None = None) -> None:
        """The next chunk's CoM, ZMP (C, 3), where there is a ZMP (C,) and its flight frames (C,; None: none)."""
        if self.start is None:
            self.start = com[0].copy()
        self.com = np.concatenate([self.com, com])
        self.flight = np.concatenate([self.flight, np.zeros(len(com), bool) if flight is None else flight])
        self.received += len(com)
        self.distance.add(np.linalg.norm(zmp[has_zmp, :2] - com[has_zmp, :2], axis=1))
        done = self.received - 2 if self.received < self.total else self.total  # frame i needs CoM to i + 2
        if done <= self.done:
            return
        if self.total < 3:  # as com_accelerations: too short to differentiate
            acc = np.zeros((done - self.done, 3))
        else:
            v_lo, v_hi = max(self.done - 1, 0), min(done + 1, self.total)
            vel = _gradient(self.com, self.first, self.total, self.dt, v_lo, v_hi)
            acc = _gradient(vel, v_lo, self.total, self.dt, self.done, done)
        self.vertical.add(np.abs(acc[:, 2]))
        flying = self.flight[self.done - self.first:done - self.first]
        self.flight_count += int(flying.sum())
        self.flight_acc += float(acc[flying, 2].sum())
        vel_out = vel[self.done - v_lo:done - v_lo, :2] if self.total >= 3 else np.zeros((done - self.done, 2))
        self.spill.write(np.ascontiguousarray(np.hstack([vel_out, acc[:, :2]])).tobytes())
        self.done = done
        drop = max(done - 2, 0) - self.first
        self.com, self.flight, self.first = self.com[drop:], self.flight[drop:], self.first + drop

    def close(self) -> None:
        """Close the spill file (:meth:`result` does; a stats object dropped before its result must)."""
        self.spill.close()

    def result(self) -> dict:
        fwd, _ = walking_axes(np.stack([self.start, self.com[-1]]))
        parts = tuple(UpperQuantile(self.total) for _ in range(3))  # fore-aft, lateral within steps; path
        half = max(int(round(STRIDE_S / 2 / self.dt)), 1)
        reach = 2 * half  # of the two means
        margin = 2 * reach  # the heading's means, then the means of the acceleration along it
        for lo in range(0, self.done, BLOCK_FRAMES):
            hi = min(lo + BLOCK_FRAMES, self.done)
            first, last = max(lo - margin, 0), min(hi + margin, self.done)
            self.spill.seek(32 * first)
            block = np.frombuffer(self.spill.read(32 * (last - first))).reshape(-1, 4)
            *steps, path = _path_split(block, half, fwd[:2])
            for part, value in zip(parts[:2], steps, strict=True):
                part.add(value[lo - first:hi - first])
            whole = np.arange(lo, hi)  # the slow part is reported where its two means are whole
            whole = whole[(whole >= reach) & (whole < self.done - reach)]
            parts[2].add(path[whole - first])
        self.close()
        fall = self.flight_acc / self.flight_count if self.flight_count else None
        share = self.flight_count / self.total if self.total else 0.0
        return _verdict([parts[0].value(), parts[1].value(), self.vertical.value()], self.distance.value() or 0.0,
                        fall, share, self.total, parts[2].value() if self.done > 2 * reach else None)


def _moving_mean(x: np.ndarray, half: int) -> np.ndarray:
    """(N, k): the mean of ``x`` (N, k) over frames [i − half, i + half], cut at its ends."""
    c = np.concatenate([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    i = np.arange(len(x))
    lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, len(x))
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def _path_split(block: np.ndarray, half: int, fwd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """|fore-aft|, |lateral| within-step acceleration and |slow| horizontal acceleration (m/s²) at each frame of
    ``block`` (N, 4: horizontal velocity m/s, acceleration m/s²). The path's heading is the slow velocity's
    (:func:`_moving_mean` twice over 2·``half`` + 1 frames; ``fwd``, the net travel, where that is slower than
    :data:`PATH_MIN_SPEED`); the acceleration along and left of it is split into its slow part (the same means:
    in this frame a steady turn's centripetal part is constant) and the within-step rest."""
    vel, acc = block[:, :2], block[:, 2:]
    slow_vel = _moving_mean(_moving_mean(vel, half), half)
    speed = np.linalg.norm(slow_vel, axis=1)
    ahead = np.where((speed >= PATH_MIN_SPEED)[:, None], slow_vel / np.maximum(speed, 1e-12)[:, None], fwd)
    along = np.column_stack([np.sum(acc * ahead, axis=1), acc[:, 1] * ahead[:, 0] - acc[:, 0] * ahead[:, 1]])
    slow = _moving_mean(_moving_mean(along, half), half)
    step = np.abs(along - slow)
    return step[:, 0], step[:, 1], np.linalg.norm(slow, axis=1)


def _verdict(p99: list[float], d99: float, fall: float | None = None, share: float = 0.0, frames: int = 3,
             path99: float | None = None) -> dict:
    ratio = [p / r for p, r in zip(p99, WALK_COM_ACC_P99, strict=True)]
    names = ("within-step fore-aft", "within-step lateral", "vertical")
    worst = int(np.argmax(ratio))
    if frames < 3:  # an acceleration needs three positions: com_accelerations gives zeros
        verdict = f"too short to judge: {frames} frame(s), an acceleration needs 3"
    elif fall is not None and share >= FLIGHT_SHARE and fall > FLIGHT_FALL_MPS2:
        verdict = (f"not physically plausible: {100 * share:.0f} % of the frames have no foot on the ground found "
                   f"while the CoM does not fall (mean vertical acceleration {fall:+.1f} m/s², a flight's is -9.8): "
                   "the floor is not level or the root is held in the air")
    elif ratio[worst] > PLAUSIBLE_RATIO:
        verdict = (f"not physically plausible for walking: {names[worst]} CoM acceleration {ratio[worst]:.1f}x "
                   f"a real walk's (force plates)")
    elif d99 / WALK_ZMP_COM_P99_M > PLAUSIBLE_RATIO:
        ratio_d = d99 / WALK_ZMP_COM_P99_M
        verdict = f"not physically plausible for walking: ZMP-CoM distance {ratio_d:.1f}x a real walk's"
    else:
        verdict = "plausible for walking (CoM accelerations within 1.5x a real walk's)"
    return {"com_acc_p99_mps2": [round(p, 3) for p in p99], "walk_reference_mps2": list(WALK_COM_ACC_P99),
            "ratio": [round(r, 2) for r in ratio], "path_acc_p99_mps2": None if path99 is None else round(path99, 3),
            "zmp_com_p99_m": round(d99, 4),
            "walk_reference_zmp_com_m": WALK_ZMP_COM_P99_M,
            "flight_com_acc_mps2": None if fall is None else round(fall, 3), "verdict": verdict}
