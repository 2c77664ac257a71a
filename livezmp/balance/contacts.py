"""Foot contacts and ground height, estimated frame by frame from the feet.

Frame: world, z up; heights in metres, speeds in m/s. Per frame each foot gives its sole corner
points in world coordinates ((k, 3), e.g. the 4 corners of a heel-to-toe rectangle) and their
velocities ((k, 3), one per corner), or a single velocity for the whole foot.

A foot is in contact when its lowest sole point is near the ground and barely moves
horizontally. The speed that matters is that of the lowest sole point: it stays put while the foot
rolls over the heel after heel strike and over the toes at push-off, whereas the ankle then moves
at 0.5-1.8 m/s. On the Bandai-Namco walks (30 Hz) an ankle speed misses most double-support
frames and reports flight between steps; per-corner velocities give the walking pattern.

Two mechanisms stop the state from chattering when noisy signals hover at a threshold:
hysteresis (a foot touches down at or below ``height_on`` and ``speed_on`` but lifts off only above
``height_off`` or ``speed_off``), and debouncing (a change must be seen on ``min_frames``
consecutive frames, which delays each change by ``min_frames - 1`` frames).

The ground height is a low percentile of the lowest sole point (lower of the two feet) over the
first ``warmup_frames`` frames, then tracked with a constant-memory quantile update that moves at
most ``track_step`` per frame, so it follows slow drift but not a jump or a fall. With noisy sole
points it sits low by about 2.5 noise standard deviations (the low percentile of the lowest of
several noisy corners). It is the height
the sole points rest at: if they are markers above the real sole, that is above the floor. It can
be fixed instead with ``GroundConfig.override``. Contacts can also come from outside (foot force
sensors): pass ``contacts=(left, right)`` to :meth:`ContactDetector.update`.

Memory and per-frame cost are constant: the only buffer is the warm-up window.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from livezmp.balance.support import SUPPORT_LABELS
from livezmp.errors import InputError


class ContactError(InputError):
    """Bad contact input: a malformed sole or velocity on some frame, or an invalid configuration."""


def _check_number(cfg, name: str, low: float = 0.0, high: float = math.inf) -> None:
    v = getattr(cfg, name)
    if isinstance(v, bool) or not isinstance(v, int | float) or not (math.isfinite(v) and low <= v <= high):
        raise ContactError(f"{type(cfg).__name__}.{name}: must be a number in [{low}, {high}], got {v!r}")


def _check_count(cfg, name: str) -> None:
    v = getattr(cfg, name)
    if isinstance(v, bool) or not isinstance(v, int) or v < 1:
        raise ContactError(f"{type(cfg).__name__}.{name}: must be an integer >= 1, got {v!r}")


@dataclass(frozen=True)
class ContactConfig:
    """Contact thresholds. The defaults suit human motion capture at 30-120 Hz; see :meth:`small_robot`.

    Heights are of the lowest sole point above the ground, speeds are its horizontal speed. A human
    foot in stance rests within 2-3 cm of the ground estimate (marker and skeleton offsets) and its
    lowest point moves below 0.3 m/s (raw 100 Hz markers: up to 0.4 m/s as the heel lands), while a
    swinging foot moves at 1-5 m/s. Speed is what separates them: the toes pass only 1-2 cm above
    the floor in mid-swing. With these defaults, raw Plug-in Gait heel and toe markers at 100 Hz
    give every force-plate foot strike and foot off to within 2 frames.
    """

    height_on: float = 0.03
    """m above the ground: the lowest sole point must be at or below this to touch down."""
    height_off: float = 0.05
    """m above the ground: a foot in contact lifts off once its lowest sole point is above this."""
    speed_on: float = 0.40
    """m/s: the horizontal speed must be at or below this to touch down."""
    speed_off: float = 1.00
    """m/s: a foot in contact lifts off once its horizontal speed is above this."""
    min_frames: int = 2
    """Consecutive frames a change must be seen before the state changes (1 = at once)."""

    def __post_init__(self) -> None:
        _check_number(self, "height_on")
        _check_number(self, "height_off", low=self.height_on)
        _check_number(self, "speed_on")
        _check_number(self, "speed_off", low=self.speed_on)
        _check_count(self, "min_frames")

    @classmethod
    def small_robot(cls) -> ContactConfig:
        """Thresholds for a small servo humanoid such as the ROBOTIS OP3 (feet about 0.12 m long).

        Its feet come from exact kinematics (no marker noise) but lift only 3-5 cm and swing at
        0.1-0.4 m/s, or not at all when stepping in place, so height carries the decision: touch
        down within 1 cm, lift off above 2 cm.
        """
        return cls(height_on=0.01, height_off=0.02, speed_on=0.05, speed_off=0.10, min_frames=2)


@dataclass(frozen=True)
class GroundConfig:
    """Ground-height estimation from the feet (z of the ground plane, metres, world frame)."""

    warmup_frames: int = 60
    """Frames whose lowest sole points form the initial estimate (0.5-2 s at 120-30 Hz)."""
    percentile: float = 5.0
    """Percentile (0-100) of the lowest sole point taken as the ground: low, to ignore swing and
    flight frames, but not the minimum, to ignore outliers."""
    track_step: float = 0.001
    """m per frame, after warm-up: a frame below the estimate lowers it by (1 - p) * track_step, one
    above raises it by p * track_step (p = percentile / 100), which converges to that percentile:
    the default follows a floor dropping at up to 0.95 mm per frame or rising at 0.05 mm per frame
    (6 mm/s at 120 Hz, 1.5 mm/s at 30 Hz)."""
    override: float | None = None
    """Fixed ground height in metres; when set, nothing is estimated."""

    def __post_init__(self) -> None:
        _check_count(self, "warmup_frames")
        _check_number(self, "percentile", high=100.0)
        _check_number(self, "track_step")
        if self.override is not None:
            _check_number(self, "override", low=-math.inf)


def percentile_of_sorted(values: list[float], percentile: float) -> float:
    """The ``percentile`` (0-100) of the ascending, non-empty, finite ``values``, interpolated linearly
    between the closest ranks: numpy.percentile's default method with the same arithmetic (equal results),
    without its per-call cost (some 30 µs, paid on every warm-up frame)."""
    index = (len(values) - 1) * (percentile / 100)
    if index >= len(values) - 1:
        return values[-1]
    low = math.floor(index)
    a, b = values[low], values[low + 1]
    gamma = index - low
    diff = b - a
    # numpy interpolates from the nearer end
    return b - diff * (1 - gamma) if gamma >= 0.5 else a + diff * gamma


class GroundEstimator:
    """Streaming ground height (z of the ground plane, metres, world frame) from the feet's lowest points."""

    def __init__(self, config: GroundConfig | None = None) -> None:
        self.config = config or GroundConfig()
        self._sorted: list[float] = []  # the warm-up frames' lowest points, ascending
        self._count = 0
        self._height = self.config.override

    @property
    def height(self) -> float | None:
        """Current ground height in metres, or None before the first frame (unless overridden)."""
        return self._height

    def update(self, lowest_z: float) -> float:
        """Feed one frame's lowest sole point z (metres, lower of both feet); return the ground height."""
        cfg = self.config
        if cfg.override is not None:
            return cfg.override
        if not math.isfinite(lowest_z):
            raise ContactError(f"ground: lowest sole point z must be finite, got {lowest_z}")
        if self._count < cfg.warmup_frames:
            bisect.insort(self._sorted, lowest_z)
            self._count += 1
            self._height = percentile_of_sorted(self._sorted, cfg.percentile)
            if self._count == cfg.warmup_frames:
                self._sorted = []  # not needed any more
        else:
            p = cfg.percentile / 100.0
            self._height += cfg.track_step * (p - 1.0 if lowest_z < self._height else p)
        return self._height


@dataclass(frozen=True)
class FootContact:
    """Contact state of one foot."""

    in_contact: bool | None = None
    """True in contact, False in the air, None before the first frame."""
    pending: int = 0
    """Consecutive frames so far that call for a change of state."""


def step_foot(state: FootContact, height: float, speed: float, cfg: ContactConfig) -> FootContact:
    """Next contact state of one foot.

    height: lowest sole point above the ground, metres. speed: horizontal speed, m/s.
    The first frame decides at once: in contact unless the lift-off thresholds are exceeded (a
    foot that starts near the ground and barely moving is standing on it).
    """
    if not (math.isfinite(height) and math.isfinite(speed)):
        raise ContactError(f"foot: height {height} m and speed {speed} m/s must be finite")
    lifts = height > cfg.height_off or speed > cfg.speed_off
    if state.in_contact is None:
        return FootContact(not lifts)
    change = lifts if state.in_contact else (height <= cfg.height_on and speed <= cfg.speed_on)
    if not change:
        return state if state.pending == 0 else FootContact(state.in_contact)
    if state.pending + 1 >= cfg.min_frames:
        return FootContact(not state.in_contact)
    return FootContact(state.in_contact, state.pending + 1)


def support_label(left: bool, right: bool) -> str:
    """Support label from the two feet's contacts: "left", "right", "double" or "none" (flight)."""
    return SUPPORT_LABELS[(3, 1, 0, 2)[2 * bool(left) + bool(right)]]


def _sole_bottom(sole, frame: int, name: str) -> tuple[float, int, int]:
    """Lowest z (metres) of a (k, 3) sole, the index of that corner, and k; validated.

    ``frame`` and ``name`` only word the error. The rows are few: plain floats beat numpy's per-call cost."""
    try:
        a = np.asarray(sole, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ContactError(f"frame {frame}: {name}: not an array of numbers ({exc})") from None
    if a.ndim != 2 or a.shape[1] != 3 or a.shape[0] == 0:
        raise ContactError(
            f"frame {frame}: {name}: expected (k, 3) corner points in metres, k >= 1, got shape {a.shape}"
        )
    flat = a.ravel().tolist()
    total = sum(flat)
    # A finite sum means finite coordinates; otherwise look closer (the sum may just have overflowed).
    if total - total != 0.0 and not np.isfinite(a).all():
        raise ContactError(
            f"frame {frame}: {name}: row {int(np.argmin(np.isfinite(a).all(axis=1)))} has a non-finite coordinate"
        )
    heights = flat[2::3]
    low = min(heights)
    return low, heights.index(low), a.shape[0]


def _horizontal_speed(velocity, sole_rows: int, lowest: int, frame: int, name: str) -> float:
    """Horizontal speed (m/s) of the foot: of its lowest sole corner when given per-corner velocities.

    ``frame`` and ``name`` only word the error."""
    try:
        v = np.asarray(velocity, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ContactError(f"frame {frame}: {name}: not a velocity array ({exc})") from None
    if v.shape == (sole_rows, 3):
        v = v[lowest]
    elif v.shape not in ((2,), (3,)):
        raise ContactError(
            f"frame {frame}: {name}: expected (vx, vy[, vz]) or one row per sole corner ({sole_rows}, 3) in m/s, "
            f"got shape {v.shape}"
        )
    components = v.tolist()
    if not all(map(math.isfinite, components)):
        raise ContactError(f"frame {frame}: {name}: non-finite component {components}")
    return math.hypot(components[0], components[1])


class ContactDetector:
    """Streaming two-foot contact detector; one :meth:`update` per frame gives the support label."""

    def __init__(self, config: ContactConfig | None = None, ground: GroundConfig | None = None) -> None:
        self.config = config or ContactConfig()
        self.ground = GroundEstimator(ground)
        self.left = FootContact()
        self.right = FootContact()
        self.frame = 0

    @property
    def ground_height(self) -> float | None:
        """Current ground height in metres (world z), or None before the first frame."""
        return self.ground.height

    def update(
        self,
        left_sole,
        left_velocity,
        right_sole,
        right_velocity,
        contacts: tuple[bool, bool] | None = None,
    ) -> str:
        """Feed one frame; return its support label: "left", "right", "double" or "none" (flight).

        left_sole, right_sole: (k, 3) sole corner points, metres, world frame (z up).
        left_velocity, right_velocity: (k, 3) velocity of each sole corner, m/s, world frame (the
        lowest corner's is used), or one (2,) or (3,) velocity for the whole foot (e.g. the
        ankle's, which moves while the foot rolls on the ground: see the module notes). Only the
        horizontal part counts.
        contacts: (left, right) from outside (e.g. force sensors) to use instead of detection;
        the ground estimate is still updated, and detection resumes from these states.
        Raises ContactError naming the frame and field on malformed input.
        """
        frame = self.frame
        left_z, left_low, left_k = _sole_bottom(left_sole, frame, "left sole")
        right_z, right_low, right_k = _sole_bottom(right_sole, frame, "right sole")
        left_speed = _horizontal_speed(left_velocity, left_k, left_low, frame, "left velocity")
        right_speed = _horizontal_speed(right_velocity, right_k, right_low, frame, "right velocity")
        return self._step(left_z, left_speed, right_z, right_speed, contacts)

    def update_lowest(
        self,
        left_height: float,
        left_speed: float,
        right_height: float,
        right_speed: float,
        contacts: tuple[bool, bool] | None = None,
    ) -> str:
        """:meth:`update` given what it takes from each foot: the height z of its lowest sole point
        (metres, world frame) and that point's horizontal speed (m/s), e.g. from
        :func:`livezmp.model.body.lowest_sole_points`. Raises ContactError if one is not finite."""
        values = (left_height, left_speed, right_height, right_speed)
        try:
            finite = all(map(math.isfinite, values))
        except TypeError:  # not numbers
            finite = False
        if not finite:
            raise ContactError(f"frame {self.frame}: lowest sole point heights and speeds must be finite, got "
                               f"{list(values)}")
        return self._step(*values, contacts)

    def _step(self, left_z: float, left_speed: float, right_z: float, right_speed: float,
              contacts: tuple[bool, bool] | None) -> str:
        frame = self.frame
        ground = self.ground.update(min(left_z, right_z))
        if contacts is None:
            self.left = step_foot(self.left, left_z - ground, left_speed, self.config)
            self.right = step_foot(self.right, right_z - ground, right_speed, self.config)
        else:
            if not isinstance(contacts, tuple | list) or len(contacts) != 2:
                raise ContactError(f"frame {frame}: contacts: expected (left, right) booleans, got {contacts!r}")
            self.left, self.right = FootContact(bool(contacts[0])), FootContact(bool(contacts[1]))
        self.frame += 1
        return support_label(self.left.in_contact, self.right.in_contact)
