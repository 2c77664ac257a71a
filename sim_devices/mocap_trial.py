"""What the simulated capture servers play: a C3D trial or generated marker motion,
with the impairments of a real capture (noise, occlusion gaps, dropped and late frames).

A :class:`MocapTrial` holds labelled markers (F, n, 3) m and force plates (F, p, 3) in
the lab axes of its source (C3D: as the file says, usually z up), one plate sample per
marker frame (the analog sample at the frame's instant). :class:`TrialPlayer` hands the
frames out at the trial's rate × speed and decides, seeded, which to drop and which to
hold back; every server (LSL, QTM RT, NatNet) sends what it is given in its own format.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace

import numpy as np

from livezmp.errors import InputError
from livezmp.sources.file_replay import Pacer
from sim_devices.impairments import Impairments

UNIT_SCALE = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
MOMENT_SCALE = {"Nmm": 1e-3, "Nm": 1.0, "N.mm": 1e-3, "N.m": 1.0}


@dataclass(frozen=True)
class MocapTrial:
    """``labels`` (n,); ``markers`` (F, n, 3) m, NaN where occluded; ``rate`` Hz; ``up``
    the lab's up axis ("+z"); plates: ``plate_names`` (p,), ``force`` (F, p, 3) N,
    ``moment`` (F, p, 3) N·m about the plate origin, ``cop`` (F, p, 3) m (NaN unloaded),
    ``corners`` (p, 4, 3) m; ``source`` where it came from."""

    labels: tuple[str, ...]
    markers: np.ndarray
    rate: float
    up: str
    plate_names: tuple[str, ...]
    force: np.ndarray
    moment: np.ndarray
    cop: np.ndarray
    corners: np.ndarray
    source: str
    segment_names: tuple[str, ...] = ()  # rigid segments a capture system solves (skeleton bones)
    segment_pos: np.ndarray | None = None  # (F, s, 3) m, lab axes
    segment_rot: np.ndarray | None = None  # (F, s, 3, 3), columns the segment's axes in the lab's

    @property
    def n_frames(self) -> int:
        return self.markers.shape[0]


def _c3d_up(params: dict) -> str:
    screen = params.get("POINT", {}).get("Y_SCREEN", {}).get("value", ["+Z"])
    text = (screen[0] if screen else "+Z").strip().lower()
    return text if text in ("+x", "-x", "+y", "-y", "+z", "-z") else "+z"


def load_c3d_trial(path: str) -> MocapTrial:
    """Markers and force plates of a C3D file (ezc3d), in metres, newtons, N·m."""
    import ezc3d

    try:
        c = ezc3d.c3d(str(path), extract_forceplat_data=True)
    except Exception as e:  # ezc3d raises bare RuntimeError/ValueError on bad files
        raise InputError(f"{path}: not a readable C3D file ({e})") from None
    params = c["parameters"]
    unit = params["POINT"]["UNITS"]["value"][0].strip()
    if unit not in UNIT_SCALE:
        raise InputError(f"{path}: POINT:UNITS {unit!r} is not one of {', '.join(UNIT_SCALE)}")
    pts = c["data"]["points"][:3].transpose(2, 1, 0) * UNIT_SCALE[unit]  # (F, n, 3)
    labels = tuple(s.strip() for s in params["POINT"]["LABELS"]["value"])
    rate = float(params["POINT"]["RATE"]["value"][0])
    plates = c["data"]["platform"]
    n = pts.shape[0]
    force = np.zeros((n, len(plates), 3))
    moment, cop = np.zeros_like(force), np.full_like(force, np.nan)
    corners = np.zeros((len(plates), 4, 3))
    for i, p in enumerate(plates):
        ratio = p["force"].shape[1] // max(n, 1)
        idx = np.arange(n) * ratio  # the analog sample at each marker frame's instant
        pos = UNIT_SCALE.get(p["unit_position"], 1e-3)
        force[:, i] = p["force"][:, idx].T
        moment[:, i] = p["moment"][:, idx].T * MOMENT_SCALE.get(p["unit_moment"], 1e-3)
        cop[:, i] = p["center_of_pressure"][:, idx].T * pos
        corners[i] = p["corners"].T * pos
    names = tuple(f"plate{i + 1}" for i in range(len(plates)))
    return MocapTrial(labels[: pts.shape[1]], pts, rate, _c3d_up(params), names, force, moment, cop, corners,
                      str(path))


def with_segments(trial: MocapTrial, path: str) -> MocapTrial:
    """``trial`` (of the C3D file ``path``) with the segment poses of livezmp's marker body of that file
    (pelvis, thighs, shanks, feet, the HAT or the upper-body segments), as a capture system's skeleton
    solver would stream them: the truth a skeleton stream of this trial carries. A placed HAT moves with the
    mid-hip (a live solver has no whole-take trend for it to sway about)."""
    from scipy.spatial.transform import Rotation

    from livezmp.model.c3d import read_c3d
    from livezmp.model.markers import MarkerBodyOptions, body_from_markers

    take = body_from_markers(read_c3d(path), MarkerBodyOptions(hat_sway_gain=None))
    if take.first_frame != 0 or len(take.frames) != trial.n_frames:
        raise InputError(f"{path}: the marker body does not cover every frame; no segment poses")
    r_in = take.body.world_from_input
    q = take.frames.reshape(trial.n_frames, -1, 6)
    rot = Rotation.from_euler("ZYX", q[:, :, 3:].reshape(-1, 3)).as_matrix().reshape(q.shape[:2] + (3, 3))
    names = tuple(n[: -len(".x")] for n in take.body.channel_names[::6])
    return replace(trial, segment_names=names, segment_pos=q[:, :, :3] @ r_in,
                   segment_rot=np.einsum("ji,fsjk->fsik", r_in, rot))


def generated_trial(rate: float, seconds: float, n_markers: int = 20, n_plates: int = 2) -> MocapTrial:
    """A synthetic trial at ``rate`` Hz: markers on a body swaying 2 cm at 0.5 Hz (z up,
    metres), each plate carrying half of a 700 N body with its CoP following the sway."""
    n = max(int(round(rate * seconds)), 1)
    t = np.arange(n) / rate
    sway = 0.02 * np.sin(2 * np.pi * 0.5 * t)
    k = np.arange(n_markers)
    base = np.stack([0.1 * np.cos(k), 0.1 * np.sin(k), 0.05 + 1.6 * k / max(n_markers - 1, 1)], axis=1)
    markers = base[None] + (sway[:, None, None] * np.array([1.0, 0.0, 0.0]))
    y0 = (np.arange(n_plates) - (n_plates - 1) / 2) * 0.2
    cop = np.zeros((n, n_plates, 3))
    cop[:, :, 0] = sway[:, None]
    cop[:, :, 1] = y0
    force = np.zeros((n, n_plates, 3))
    force[:, :, 2] = 700.0 / n_plates
    moment = np.cross(cop, force)  # about the plate origin at the lab origin, no free moment
    corners = np.array([[[0.25, y + 0.1, 0], [-0.25, y + 0.1, 0], [-0.25, y - 0.1, 0], [0.25, y - 0.1, 0]]
                        for y in y0]).reshape(n_plates, 4, 3)
    return MocapTrial(tuple(f"M{i:02d}" for i in range(n_markers)), markers, rate, "+z",
                      tuple(f"plate{i + 1}" for i in range(n_plates)), force, moment, cop, corners,
                      f"generated {rate:g} Hz")


def resampled(trial: MocapTrial, rate: float) -> MocapTrial:
    """``trial`` at ``rate`` Hz over the same span: markers and plates interpolated by a cubic spline
    through the recorded frames (a marker missing at either neighbouring frame stays missing), e.g.
    a 100 Hz gait trial played as a 1000 Hz camera would see it."""
    from scipy.interpolate import CubicSpline

    t = np.arange(trial.n_frames) / trial.rate
    new = np.arange(int(np.floor(t[-1] * rate)) + 1) / rate

    def spline(x: np.ndarray) -> np.ndarray:
        seen = np.isfinite(x).all(axis=tuple(range(2, x.ndim)))  # (F, n) samples with every coordinate
        out = CubicSpline(t, np.nan_to_num(x), axis=0)(new)
        nearest = np.clip(np.searchsorted(t, new), 1, len(t) - 1)
        ok = seen[nearest - 1] & seen[nearest]
        return np.where(ok.reshape(ok.shape + (1,) * (x.ndim - 2)), out, np.nan)

    return replace(trial, markers=spline(trial.markers), rate=rate, force=spline(trial.force),
                   moment=spline(trial.moment), cop=spline(trial.cop), source=f"{trial.source} at {rate:g} Hz",
                   segment_names=(), segment_pos=None, segment_rot=None)  # poses are not interpolated


@dataclass
class PlayCounters:
    """What the player did: frames ``sent``, ``dropped``, ``delayed`` (held back),
    ``out_of_order`` (sent after a later frame: what a receiver must call late), ``gaps``
    (marker samples made missing in the frames sent in order), ``first``/``last`` frame
    numbers sent in order."""

    sent: int = 0
    dropped: int = 0
    delayed: int = 0
    out_of_order: int = 0
    gaps: int = 0
    first: int = -1
    last: int = -1

    def receiver_view(self) -> dict[str, int]:
        """What an exact receiver counts: frames delivered in order, ``late`` ones and
        ``lost`` numbers (skipped between the first and last delivered)."""
        delivered = self.sent - self.out_of_order
        return {"delivered": delivered, "late": self.out_of_order,
                "lost": (self.last - self.first + 1) - delivered if delivered else 0}


@dataclass(frozen=True)
class TrialFrame:
    """One frame as a server sends it: ``number`` (0-based), ``t`` s from the first
    frame, ``markers`` (n, 3) m (NaN missing), plates ``force``/``moment``/``cop`` (p, 3),
    ``gaps`` markers made missing in this frame; ``segment_pos`` (s, 3) / ``segment_rot`` (s, 3, 3)
    the segment poses when the trial has them."""

    number: int
    t: float
    markers: np.ndarray
    force: np.ndarray
    moment: np.ndarray
    cop: np.ndarray
    gaps: int = 0
    segment_pos: np.ndarray | None = None
    segment_rot: np.ndarray | None = None


class TrialPlayer:
    """Plays ``trial`` at its rate × ``speed`` (0 = as fast as sent), looping if asked, for
    at most ``max_frames``; :meth:`play` calls ``send(frame)`` for each frame due."""

    def __init__(self, trial: MocapTrial, impairments: Impairments | None = None, speed: float = 1.0,
                 loop: bool = False, max_frames: int | None = None):
        self.trial, self.imp = trial, impairments or Impairments()
        self.speed, self.loop, self.max_frames = speed, loop, max_frames
        self.counters = PlayCounters()
        self.stop = threading.Event()
        self._thread: threading.Thread | None = None

    def frames(self) -> Iterator[TrialFrame]:
        """Frames when due, noisy and with gaps, before the drop/late decision."""
        tr, imp = self.trial, self.imp
        rng = np.random.default_rng(imp.seed)
        pacer = Pacer(self.speed, tr.source)
        n, k = tr.n_frames, 0
        while not self.stop.is_set() and (self.max_frames is None or k < self.max_frames) and (self.loop or k < n):
            t = k / tr.rate
            if pacer.due(t, 0.1) is None:
                continue
            i = k % n
            m, gaps = tr.markers[i], 0
            if imp.noise_pos:
                m = m + rng.normal(0.0, imp.noise_pos, m.shape)
            if imp.gap:
                hide = rng.random(len(m)) < imp.gap
                gaps = int(np.count_nonzero(hide & ~np.isnan(m[:, 0])))
                m = np.where(hide[:, None], np.nan, m)
            poses = (None, None) if tr.segment_pos is None else (tr.segment_pos[i], tr.segment_rot[i])
            yield TrialFrame(k, t, m, tr.force[i], tr.moment[i], tr.cop[i], gaps, *poses)
            k += 1

    def start(self, send: Callable[[TrialFrame], None], name: str) -> None:
        """:meth:`play` in a thread of its own (the capture system's camera)."""
        self._thread = threading.Thread(target=self.play, args=(send,), name=name, daemon=True)
        self._thread.start()

    def join(self) -> None:
        """Wait until the trial has been played (forever with loop; Ctrl-C interrupts)."""
        while self._thread is not None and self._thread.is_alive():
            self._thread.join(0.5)

    def close(self) -> None:
        """Stop playing and wait for the thread."""
        self.stop.set()
        if self._thread is not None:
            self._thread.join(5.0)

    def play(self, send: Callable[[TrialFrame], None]) -> PlayCounters:
        rng = np.random.default_rng(self.imp.seed + 1)
        held: list[tuple[int, TrialFrame]] = []
        for f in self.frames():
            for item in [h for h in held if h[0] <= f.number]:
                held.remove(item)
                self._send(send, item[1])
            u = rng.random(2)
            if u[0] < self.imp.drop:
                self.counters.dropped += 1
                continue
            if u[1] < self.imp.late:
                held.append((f.number + self.imp.late_by, f))
                self.counters.delayed += 1
                continue
            self._send(send, f)
        for _, f in held:
            self._send(send, f)
        return self.counters

    def _send(self, send: Callable[[TrialFrame], None], f: TrialFrame) -> None:
        send(f)
        c = self.counters
        c.sent += 1
        if f.number < c.last:
            c.out_of_order += 1
            return
        c.first = f.number if c.first < 0 else c.first
        c.last = f.number
        c.gaps += f.gaps
