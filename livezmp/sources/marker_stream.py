"""A live capture stream's labelled markers through the C3D marker body: the :class:`Source` the
monitor reads for ``lsl://``, ``qtm://`` and ``natnet://``.

The body (segments, masses, soles, the subject's pelvis width and depth and stature) is calibrated
once, before the first frame is analysed: on a C3D trial of the same subject (``calibration``, e.g.
the lab's static trial, labels as the stream's), else on the stream's own first ``calibration_s``
seconds (the subject standing in view; those frames build the body and are not analysed). Every
frame is then turned into the body's channels by the same per-frame geometry as a C3D take
(:func:`livezmp.model.markers.marker_channels`), so a stream of a trial gives the channels of the
trial. Labels lose their prefixes (``Subject:LASI``, NatNet's ``SET:LASI``); the stream's axes (its
up axis) and length units are the stream's own (:class:`~livezmp.sources.mocap_frame.MocapFrame`).

Marker gaps, causally (no look-ahead, no added latency): a marker missing from a frame is carried
on at its last velocity (from its last two seen positions; its last position when seen once) for
at most ``max_gap_s`` (0.1 s, the longest gap a C3D take fills); a longer gap leaves the marker
out (NaN): the segments that need it get no measurement and the estimator predicts them, and the
gap is reported (``marker_gap``) and counted in :meth:`MarkerStreamSource.details`.

Segment poses: a stream that carries the body's segments solved by the capture system (rigid
bodies or skeleton bones named as the marker body's segments: ``pelvis``, ``thigh_l``, ``shank_l``,
``foot_l``, ..., ``hat`` or the upper-body ones; NatNet skeletons) drives the body directly from
them, frame by frame when all are tracked (the markers are then not needed); otherwise the markers.

A marker (or a solved segment) at infinity or beyond 1000 m of the origin (``MAX_COORDINATE_M``, the
bound a C3D file is refused at) is a broken measurement, not a position: it is left out as an occluded
one (the gap rule above), the frame's other markers kept, and the frame counted (``bad_markers``)
and reported.

Force plates: the plates' combined centre of pressure (each plate's CoP weighted by its vertical
force; none below 20 N) goes with the frame, in the stream's axes.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import replace

import numpy as np

from livezmp.balance.plates import plates_floor
from livezmp.checks import MAX_COORDINATE_M
from livezmp.errors import InputError
from livezmp.model.body import world_from_up_axis
from livezmp.model.body_spec import marker_body, stream_marker_body
from livezmp.model.c3d import C3dTrial, strip_prefix
from livezmp.model.markers import MarkerBodyOptions, marker_channels, marker_roles, segment_channels
from livezmp.sources.interface import SourceFrame
from livezmp.sources.mocap_frame import MocapFrame, MocapSource

CALIBRATION_S = 2.0  # s of stream that calibrate the body when no calibration trial is given
MAX_GAP_S = 0.1  # s: longest marker gap carried on (the C3D take's fill limit)
BATCH = 32  # frames already waiting that are converted together


def _beyond(points: np.ndarray) -> np.ndarray:
    """(n,) which of ``points`` (n, 3) m have a coordinate infinite or beyond MAX_COORDINATE_M (NaN: occluded,
    not beyond)."""
    return (np.abs(points) > MAX_COORDINATE_M).any(axis=1)


class MarkerStreamSource:
    """``mocap`` (a connected capture stream) as marker-body frames; see the module docstring.
    ``calibration`` a C3D trial of the subject (None: the stream's first ``calibration_s``);
    ``options`` the marker body's (mass, HAT). ``ground_z`` (m, internal frame): the floor, the
    calibration trial's plates' surface when it has plates (as ``livezmp analyze`` takes it), else None.
    ``batch``: at most this many frames already waiting are converted in one call (1: one by one)."""

    def __init__(self, mocap: MocapSource, calibration: C3dTrial | None = None,
                 options: MarkerBodyOptions | None = None, calibration_s: float = CALIBRATION_S,
                 max_gap_s: float = MAX_GAP_S, timeout: float = 10.0, batch: int = BATCH):
        self.mocap, self.name = mocap, mocap.name
        self.batch = batch
        self.stats, self.errors = mocap.stats, mocap.errors
        self.max_gap_s = max_gap_s
        self.up = mocap.up
        self.rotation = world_from_up_axis(self.up)
        opts = options or MarkerBodyOptions()
        self.calibration = {"source": "trial", "trial": calibration.source} if calibration else None
        if calibration is None:
            calibration = self._calibrate_on_stream(calibration_s, timeout)
        self.ground_z = plates_floor(calibration)  # internal frame; None: detected by the pipeline
        take, spec = marker_body(calibration, replace(opts, floor_z=self.ground_z))
        if not take.roles:  # a cluster set (a map's, or a file's Plug-in Gait segment outputs): not streamed
            marker_roles(calibration, opts.marker_map)  # refused as a standard set is, naming what it lacks
            raise InputError(f"{calibration.source}: a cluster set is not streamed: the live body reads a Plug-in "
                             f"Gait / Helen Hayes set's markers")
        self.take = take
        self.body, self.body_spec = stream_marker_body(take, spec, self.up)
        self.roles = [r for r, label in take.roles.items() if label is not None]
        self._role_labels = [take.roles[r] for r in self.roles]
        self._labels: tuple[str, ...] | None = None
        self._index = np.zeros(len(self.roles), int)
        self._means: tuple[np.ndarray, np.ndarray] | None = None  # rows that average a second label, its index
        n = len(self.roles)
        self._last = np.full((n, 3), np.nan)
        self._prev = np.full((n, 3), np.nan)
        self._t_last = np.full(n, -np.inf)
        self._t_prev = np.full(n, -np.inf)
        self._long = np.zeros(n, bool)
        self._angles = self.body.angle_mask
        self._channels: np.ndarray | None = None
        self.filled = self.long_gaps = self.frames_with_long_gap = 0
        self._pending: deque[MocapFrame] = deque()
        self._ready: deque[SourceFrame] = deque()
        self.segments = [n[: -len(".x")] for n in self.body.channel_names[::6]]  # the body's, in channel order
        self._segment_names: tuple[str, ...] = ()
        self._segment_index: np.ndarray | None = None
        self.from_segments = 0
        self._wait_for_rate(timeout)

    # -- calibration ----------------------------------------------------------

    def _calibrate_on_stream(self, seconds: float, timeout: float) -> C3dTrial:
        """A C3D trial (internal frame, no plates) of the stream's first ``seconds``."""
        frames: list[MocapFrame] = []
        deadline = time.monotonic() + seconds + timeout
        while time.monotonic() < deadline:
            f = self._read(0.1)
            if f is None:
                continue
            if frames and f.labels != frames[0].labels:
                frames.clear()  # the marker set changed: start over
            frames.append(f)
            if f.t - frames[0].t >= seconds:
                break
        if len(frames) < 4:
            raise InputError(f"{self.name}: {len(frames)} frames in {seconds + timeout:g} s: too few to calibrate "
                             "the marker body (is the stream running?)")
        points = np.stack([f.markers for f in frames]) @ self.rotation.T
        rate = 1.0 / self.mocap.nominal_dt
        self.calibration = {"source": "stream", "frames": len(frames), "seconds": round(frames[-1].t - frames[0].t, 3)}
        return C3dTrial(self.name, [strip_prefix(x) for x in frames[0].labels], points, rate, rate, 0.0, [])

    def _wait_for_rate(self, timeout: float) -> None:
        """A stream that does not state its rate (NatNet) has it measured from its first frames: they
        are kept and delivered first."""
        deadline = time.monotonic() + timeout
        while self.mocap.nominal_dt is None:
            if time.monotonic() > deadline:
                raise InputError(f"{self.name}: no frames within {timeout:g} s to measure the stream's rate")
            f = self._read(0.1)
            if f is not None:
                self._pending.append(f)

    # -- per frame ------------------------------------------------------------

    @property
    def nominal_dt(self) -> float | None:
        return self.mocap.nominal_dt

    @property
    def finished(self) -> bool:
        return self.mocap.finished

    def _map_labels(self, labels: tuple[str, ...]) -> None:
        """Where each marker role is in frames with ``labels``; a role the stream lacks stays missing."""
        stripped = [strip_prefix(x) for x in labels]
        where = {}
        for i, x in enumerate(stripped):
            where.setdefault(x, i)
        # a role the body reads as the mean of two labels (the toe's metatarsal stand-in) looks up both
        parts = [self.take.mean_of.get(x, (x,)) for x in self._role_labels]
        missing = [x for labs in parts for x in labs if x not in where]
        if missing:
            self.errors.report("marker_gap", f"{self.name}: the stream has no marker {', '.join(missing)}")
        self._index = np.array([where.get(labs[0], len(labels)) for labs in parts], int)
        rows = [i for i, labs in enumerate(parts) if len(labs) == 2]
        self._means = (np.array(rows, int), np.array([where.get(parts[i][1], len(labels)) for i in rows], int)) \
            if rows else None
        self._labels = labels

    def _markers(self, f: MocapFrame) -> np.ndarray:
        """(n roles, 3) m internal frame, short gaps carried on (see the module docstring)."""
        if f.labels != self._labels:
            self._map_labels(f.labels)
        if f.restart:  # a new timeline: no marker is carried on from the old one
            self._last[:], self._prev[:], self._t_last[:], self._t_prev[:] = np.nan, np.nan, -np.inf, -np.inf
            self._long[:] = False
        padded = np.vstack([f.markers, np.full((1, 3), np.nan)])
        p = padded[self._index]
        if self._means is not None:
            rows, second = self._means
            p[rows] = (p[rows] + padded[second]) / 2
        p = p @ self.rotation.T
        seen = np.isfinite(p).all(axis=1)
        age = f.t - self._t_last
        carry = ~seen & (age <= self.max_gap_s + 1e-9) & np.isfinite(self._last[:, 0])
        if carry.any():
            dt = self._t_last - self._t_prev
            v = np.where((np.isfinite(self._prev[:, 0]) & np.isfinite(dt) & (dt > 0))[:, None],
                         (self._last - self._prev) / np.where(dt > 0, dt, 1.0)[:, None], 0.0)
            p[carry] = self._last[carry] + v[carry] * age[carry, None]
            self.filled += int(carry.sum())
        long = ~seen & ~carry
        if long.any():
            self.frames_with_long_gap += 1
            new = long & ~self._long
            if new.any():
                self.long_gaps += int(new.sum())
                names = ", ".join(self._role_labels[i] for i in np.flatnonzero(new))
                self.errors.report("marker_gap", f"{self.name}: {names} missing for more than "
                                                 f"{1000 * self.max_gap_s:.0f} ms at t = {f.t:.3f} s")
        self._long = long
        self._prev[seen], self._t_prev[seen] = self._last[seen], self._t_last[seen]
        self._last[seen], self._t_last[seen] = p[seen], f.t
        return p

    def _poses(self, f: MocapFrame) -> np.ndarray | None:
        """Indices into ``f.segments`` of the body's segments when the frame has all of them tracked."""
        names = f.segments.names
        if not names:
            return None
        if names != self._segment_names:
            where = {n: i for i, n in enumerate(names)}
            self._segment_index = (np.array([where[n] for n in self.segments])
                                   if all(n in where for n in self.segments) else None)
            self._segment_names = names
        i = self._segment_index
        return i if i is not None and f.segments.tracked[i].all() else None

    def _to_channels(self, batch: list[MocapFrame]) -> np.ndarray:
        """(B, nq) channels of a batch of frames, angles continuing from the previous frame's: from the
        body's segment poses when the stream solved them all, else from the markers."""
        out = np.empty((len(batch), self.body.nq))
        poses = [self._poses(f) for f in batch]
        by_pose = [k for k, i in enumerate(poses) if i is not None]
        by_markers = [k for k, i in enumerate(poses) if i is None]
        if by_pose:
            r = self.rotation
            seg = {n: (np.stack([batch[k].segments.position[poses[k][j]] for k in by_pose]) @ r.T,
                       r @ np.stack([batch[k].segments.rotation[poses[k][j]] for k in by_pose]))
                   for j, n in enumerate(self.segments)}
            out[by_pose] = segment_channels(seg, unwrap=False)
            self.from_segments += len(by_pose)
        if by_markers:
            p = np.stack([self._markers(batch[k]) for k in by_markers])
            out[by_markers] = marker_channels(self.take, {r: p[:, i] for i, r in enumerate(self.roles)})
        for ch in out:
            last = self._channels
            if last is not None:  # no jump of 2 pi from one frame to the next
                turn = self._angles & np.isfinite(ch) & np.isfinite(last)
                ch[turn] -= 2 * np.pi * np.round((ch[turn] - last[turn]) / (2 * np.pi))
                self._channels = np.where(np.isfinite(ch), ch, last)
            else:
                self._channels = ch.copy()
        return out

    def _next(self, timeout: float) -> MocapFrame | None:
        return self._pending.popleft() if self._pending else self._read(timeout)

    def _read(self, timeout: float) -> MocapFrame | None:
        """The capture stream's next frame, its markers and segments beyond MAX_COORDINATE_M (or infinite)
        left out: such a frame is counted (``bad_markers``) and reported."""
        f = self.mocap.read(timeout)
        if f is None:
            return None
        far = _beyond(f.markers)
        far_segments = _beyond(f.segments.position) & f.segments.tracked
        if not (far.any() or far_segments.any()):
            return f
        self.stats.bad_markers += 1
        names = [f.labels[i] for i in np.flatnonzero(far)] + [f.segments.names[i] for i in np.flatnonzero(far_segments)]
        self.errors.report("bad_markers", f"{self.name}: frame {f.frame}: {', '.join(names[:5])} at infinity or beyond "
                                          f"{MAX_COORDINATE_M:g} m of the origin: left out")
        markers = np.where(far[:, None], np.nan, f.markers)
        segments = replace(f.segments, tracked=f.segments.tracked & ~far_segments) if far_segments.any() else f.segments
        return replace(f, markers=markers, segments=segments)

    def read(self, timeout: float) -> SourceFrame | None:
        """The next frame. Frames that are already waiting are converted together (the geometry is
        vectorised over frames): a reader that fell behind catches up at a fraction of the cost."""
        if not self._ready:
            f = self._next(timeout)
            if f is None:
                return None
            batch = [f]
            while len(batch) < self.batch and (f := self._next(0.0)) is not None:
                batch.append(f)
            channels = self._to_channels(batch)
            for f, ch in zip(batch, channels, strict=True):
                cop = f.plates.combined_cop(self.rotation[2]) if len(f.plates) else None
                self._ready.append(SourceFrame(f.t, ch, None, f.received, f.latency, cop, restart=f.restart))
        return self._ready.popleft()

    def details(self) -> dict:
        """For the summary: how the body was calibrated and what the gap rule did."""
        return {"calibration": self.calibration, "up_axis": self.up,
                "markers": {"roles": len(self.roles), "max_gap_ms": 1000 * self.max_gap_s,
                            "filled_samples": self.filled, "long_gaps": self.long_gaps,
                            "frames_with_long_gap": self.frames_with_long_gap},
                "frames_from_segment_poses": self.from_segments}

    def close(self) -> None:
        self.mocap.close()
