"""The per-frame pipeline: estimate → ZMP → contacts → support polygon → clamp.

The same :class:`Pipeline` serves live streams (``step`` per frame) and files
(``run`` over a whole motion, or :func:`livezmp.offline.batch.run_batch`, its vectorised
twin), so live and offline results agree. Results come out
``lag`` frames behind the input (the estimator's fixed lag); ``flush`` delivers the
last ones at the end of a file.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from livezmp.balance.contacts import ContactConfig, ContactDetector, GroundConfig
from livezmp.balance.support import support_and_clamp
from livezmp.balance.zmp import compute_zmp, zmp_on_plane
from livezmp.errors import InputError
from livezmp.estimate.estimator import Estimate, EstimatorConfig, StreamingEstimator, default_estimator
from livezmp.model.body import BodyModel, foot_soles, lowest_sole_points

MODES = ("full", "seed")
PROGRESS_EVERY = 500  # frames between progress reports of the per-frame path


@dataclass(frozen=True)
class PipelineConfig:
    """``mode``: "full" (rigid bodies) or "seed" (point masses). ``ground_z`` fixes the
    ground height (internal frame, m) instead of detecting it from the feet. ``belt``: the (left, right)
    horizontal velocities (vx, vy) m/s, internal frame, of the surface under each foot (an instrumented
    treadmill's belts, :mod:`livezmp.offline.treadmill`): a foot's contact is judged by its speed relative
    to it; None: a floor at rest."""

    mode: str = "full"
    estimator: EstimatorConfig = field(default_factory=EstimatorConfig)
    contacts: ContactConfig = field(default_factory=ContactConfig)
    ground_z: float | None = None
    ground_warmup_frames: int = 60
    flight_fraction: float = 0.05
    belt: tuple[tuple[float, float], tuple[float, float]] | None = None


@dataclass
class FrameResult:
    """One analysed frame, internal frame (z up, metres).

    ``zmp``/``clamped``/``margin``/``inside`` are None in flight (no ZMP) or when there is
    no support; ``margin`` is the signed distance to the polygon edge (+ inside);
    ``load`` is the vertical ground force over body weight."""

    index: int
    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    zmp: np.ndarray | None
    com: np.ndarray
    support: str
    polygon: np.ndarray
    soles: dict[str, np.ndarray]
    ground_z: float
    inside: bool | None = None
    clamped: np.ndarray | None = None
    margin: float | None = None
    load: float = 0.0  # vertical ground force over body weight (1 standing still, 0 in flight)


def default_config(body: BodyModel, fps: float, mode: str = "full", ground_z: float | None = None,
                   cutoff_hz: float | None = None) -> PipelineConfig:
    """The configuration ``livezmp analyze`` uses: human or small-robot contact thresholds
    by body kind, contacts debounced over about 1/60 s whatever the frame rate (one frame
    at 30 Hz, two at 120 Hz); ``ground_z`` in the internal frame (m), None = detected; the
    estimator's defaults for ``fps`` (:func:`livezmp.estimate.estimator.default_estimator`),
    with ``cutoff_hz`` (Hz) if given."""
    contacts = ContactConfig.small_robot() if body.kind == "urdf" else ContactConfig()
    contacts = replace(contacts, min_frames=max(1, round(fps / 60)))
    return PipelineConfig(mode=mode, estimator=default_estimator(fps, cutoff_hz), contacts=contacts,
                          ground_z=ground_z)


class Pipeline:
    """Streaming balance analysis of one body. ``step`` costs the same at every frame."""

    def __init__(self, body: BodyModel, config: PipelineConfig | None = None, nominal_dt: float | None = None):
        """``nominal_dt``: the input's frame period (s); it sets the estimator's rate."""
        self.body = body
        self.config = config or PipelineConfig()
        if self.config.mode not in MODES:
            raise InputError(f"unknown ZMP mode {self.config.mode!r} (full or seed)")
        self.model = body.model if self.config.mode == "full" else body.point_model
        self.data = self.model.createData()
        est_cfg = self.config.estimator
        if nominal_dt is not None:
            est_cfg = replace(est_cfg, rate_hz=1.0 / nominal_dt)
        self.estimator = StreamingEstimator(body.nq, body.angle_mask, est_cfg)
        self._count = 0
        self._index0 = 0  # number of the current stream's first frame (see restart)
        ground = GroundConfig(warmup_frames=self.config.ground_warmup_frames, override=self.config.ground_z)
        self.contacts = ContactDetector(self.config.contacts, ground)
        self._outside_contacts: dict[int, tuple[bool, bool]] = {}
        self._gravity: dict[int, np.ndarray] = {}  # frame -> gravity in the ground's frame (an IMU's, see step)

    @property
    def lag(self) -> int:
        """Frames a result comes after its input frame (the estimator's smoothing lag)."""
        return self.estimator.lag

    def step(self, t: float, channels: np.ndarray, contacts: tuple[bool, bool] | None = None,
             gravity: np.ndarray | None = None) -> FrameResult | None:
        """Feed one input frame (raw channels in file units, time in s); return the result
        for the frame ``lag`` frames back, or None while the estimator fills.

        ``contacts`` (left, right) from foot sensors replaces contact detection for this frame.
        ``gravity`` (3,) m/s²: gravity in the internal frame for this frame, when the ground
        is not level (e.g. from an IMU, :mod:`livezmp.estimate.ground_tilt`); the ZMP is then
        the centre of pressure on the ground plane, whatever its tilt."""
        # the estimator first: a frame it refuses (EstimatorError) leaves no contacts or gravity behind to be
        # read as a later frame's
        est = self.estimator.step(t, self.body.channels_to_q(np.asarray(channels, dtype=float)))
        if contacts is not None:
            self._outside_contacts[self._count] = contacts
        if gravity is not None:
            self._gravity[self._count] = gravity
        self._count += 1
        return None if est is None else self._analyse(est)

    def flush(self) -> list[FrameResult]:
        """Results for the last ``lag`` frames (end of a file or stream); then a new stream starts."""
        out = [self._analyse(e) for e in self.estimator.flush()]
        self._count = self._index0 = 0
        self._outside_contacts.clear()
        self._gravity.clear()
        return out

    def restart(self) -> list[FrameResult]:
        """Results for the pending frames, then the estimator starts over (the source's
        timeline jumped: a looped file wrapped, a stream resynchronised); frame numbers go on."""
        first = self._index0 + self._count
        out = self.flush()
        self._index0 = first
        return out

    @property
    def frames_in(self) -> int:
        """Frames stepped into the current stream (0: a fresh stream)."""
        return self._count

    def run(self, times: np.ndarray, frames: np.ndarray, contacts: list[tuple[bool, bool]] | None = None,
            progress: Callable[[int], None] | None = None) -> list[FrameResult]:
        """Step every frame of a whole motion (``times`` (N,) s, ``frames`` (N, nq) raw channels)
        and flush: one result per input frame, in order. ``contacts`` (left, right) per frame
        replaces contact detection; ``progress(frames_done)`` is called every 500 frames.

        Always frame by frame; the faster whole-take path, equal to rounding, is
        :func:`livezmp.offline.batch.run_batch`."""
        out = []
        for k in range(len(frames)):
            r = self.step(float(times[k]), frames[k], None if contacts is None else contacts[k])
            if r is not None:
                out.append(r)
            if progress is not None and k % PROGRESS_EVERY == 0:
                progress(k)
        return out + self.flush()

    def _analyse(self, est: Estimate) -> FrameResult:
        model, data = self.model, self.data
        gravity = self._gravity.pop(est.index, None) if self._gravity else None
        z = compute_zmp(model, data, est.q, est.qd, est.qdd, 0.0, self.config.flight_fraction, gravity)
        pin.updateFramePlacements(model, data)
        soles = foot_soles(self.body, data)
        low = lowest_sole_points(self.body, model, data, soles, self.config.belt)
        outside = self._outside_contacts.pop(est.index, None) if self._outside_contacts else None
        support = self.contacts.update_lowest(*low["left"], *low["right"], outside)
        left, right = soles["left"], soles["right"]
        ground = self.contacts.ground_height
        zmp = None
        if z.zmp is not None:
            # the ZMP was computed on z = 0; move it onto the detected ground plane
            zmp = zmp_on_plane(z.zmp, z.force, ground)
        # the polygon lies on the ground: the soles' z column is ignored
        poly, c = support_and_clamp(left, right, support, None if zmp is None else zmp[:2])
        fz = float(z.force[2])
        res = FrameResult(est.index + self._index0, est.t, est.q, est.qd, est.qdd, zmp, z.com, support, poly, soles,
                          ground, load=fz / (data.mass[0] * -float(model.gravity.linear[2])))
        if c is not None:
            res.inside, res.margin = c.inside, c.margin
            x, y = c.point.tolist()
            res.clamped = np.array((x, y, ground))
        return res
