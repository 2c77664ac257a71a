"""Instrumented treadmills: a whole take whose body stays in place while its feet cycle, and its belts' velocity.

On a treadmill the stance foot rides the belt backwards at the belt's speed (0.5-2 m/s), while contact detection
(:mod:`livezmp.balance.contacts`) takes a foot that moves faster than 1 m/s for a swinging one: rtosim's treadmill
walk had a tenth of its frames judged as flight. A foot's contact, the support polygon it makes and the walk's
speed are judged in the belt's frame instead: the sole's speed relative to the belt under it.

A belt running at a constant speed is an inertial frame: the ZMP and the plates' CoP at an instant are the same
point whether taken in the lab's frame or the belt's, and the ground reaction equals the body's m (g + a) in both,
so nothing else changes. A belt that speeds up or slows down (a perturbation treadmill) is not: the belt is taken
as running at one velocity over the whole take, and the contacts around its change of speed are misjudged.

Found from the feet (a whole take; frames internal, z up, metres, m/s): the frames where a foot's lowest sole corner
lies within :data:`LOW_M` of the ground (the low percentile of the lowest corners) give its horizontal velocities;
their mode (:func:`stance_velocity`) is the foot's stance velocity, the belt under it. A take is a treadmill walk when
each foot's stance velocity is at least :data:`MIN_BELT_MPS`, both point the same way, most of each foot's low frames
move at it (:data:`MIN_STANCE_SHARE`: the feet cycle on a moving surface, not a foot sliding once), and the body's
net horizontal speed over the take is under :data:`BODY_STILL_MPS` and under half the belt's. An overground walk's
stance feet stand still (its belts' speed 0), a standing take's too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from livezmp.balance.contacts import ContactConfig
from livezmp.errors import InputError

SIDES = ("left", "right")
LOW_M = ContactConfig().height_on  # m above the ground: a sole corner this low may be in stance (contact's touch-down)
GROUND_PERCENTILE = 5.0  # the ground: this percentile of the lowest sole corners (contacts' GroundConfig)
# m/s: a stance foot's lowest corner moves less than 0.1 m/s overground (the tuning trials' median under 0.05); the
# slowest treadmill protocols run at 0.3 m/s and more
MIN_BELT_MPS = 0.2
# m/s: the body's net horizontal speed (net travel over the take's duration) on a treadmill: it may drift on the belt
# by a few tenths of a metre over a take; an overground walk travels at 0.5 m/s and more
BODY_STILL_MPS = 0.25
MODE_HALF_WIDTH_MPS = 0.25  # m/s: the stance samples counted at a velocity (a heel rolling on a belt: ±0.1 m/s)
MIN_STANCE_SHARE = 0.4  # of a foot's low frames move at its stance velocity (a walk's stance: 60 % of the cycle)
SAME_WAY_COS = float(np.cos(np.radians(30.0)))  # the two feet's stance velocities at most 30 deg apart
# the feet's stance speeds differ by more than this part of the faster: two belts (split-belt); else one speed for
# both, their mean (tied belts: the two estimates differ by a few hundredths of a m/s by the marker noise)
SPLIT_FRACTION = 0.15
MODE_ITERATIONS = 5


@dataclass(frozen=True)
class Treadmill:
    """The belts under the feet: ``velocity`` {side: (2,)} m/s, horizontal, internal frame (the belt's surface; the
    stance foot moves with it); ``source`` "estimated" (from the feet) or "given" (``--treadmill``); ``feet`` {side:
    (2,)} m/s, each foot's own stance velocity and ``stance_share`` {side: fraction of its low frames moving at it}
    (estimated only); ``body_mps`` the body's net horizontal speed over the take."""

    velocity: dict[str, np.ndarray]
    source: str
    body_mps: float
    feet: dict[str, np.ndarray] | None = None
    stance_share: dict[str, float] | None = None

    @property
    def belt(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """(left, right) belt velocities (m/s, internal frame) as :class:`PipelineConfig`'s ``belt`` takes them."""
        return tuple(tuple(float(v) for v in self.velocity[s]) for s in SIDES)

    @property
    def mean_velocity(self) -> np.ndarray:
        """(2,) m/s: the frame the body's walk is judged in (split belts: between the two)."""
        return (self.velocity["left"] + self.velocity["right"]) / 2

    def summary(self, to_input: np.ndarray) -> dict:
        """The summary's ``treadmill``: the belts' speeds (m/s) and velocities in the file's frame (``to_input``
        (3, 3) rotating internal-frame vectors into it), how they were found."""
        def vec(v: np.ndarray) -> list[float]:
            return [round(float(c), 4) for c in np.array([v[0], v[1], 0.0]) @ to_input]

        out = {"belt_mps": [round(float(np.hypot(*self.velocity[s])), 4) for s in SIDES],
               "belt_velocity_mps": {s: vec(self.velocity[s]) for s in SIDES}, "source": self.source,
               "body_mps": round(self.body_mps, 4)}
        if self.feet is not None:
            out["feet_stance_mps"] = [round(float(np.hypot(*self.feet[s])), 4) for s in SIDES]
            out["stance_share"] = [round(self.stance_share[s], 3) for s in SIDES]
        return out


def lowest_corners(sole: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Height z (F,) m of each frame's lowest sole corner (``sole`` (F, k, 3) m) and its horizontal velocity (F, 2)
    m/s (central differences of each corner's path, ``dt`` s apart)."""
    rows = np.arange(len(sole))
    low = np.argmin(sole[:, :, 2], axis=1)
    vel = np.gradient(sole[:, :, :2], dt, axis=0)
    return sole[rows, low, 2], vel[rows, low]


def stance_velocity(vel: np.ndarray) -> tuple[np.ndarray, float]:
    """The mode (2,) m/s of horizontal velocities ``vel`` (n, 2) (a foot's low frames: stance, and the toes passing
    low in swing) and the share of them within :data:`MODE_HALF_WIDTH_MPS` of it: from the median, the median of
    the samples near it, a few times (the swing's fast samples drop out)."""
    if not len(vel):
        return np.zeros(2), 0.0
    centre = np.median(vel, axis=0)
    near = np.ones(len(vel), dtype=bool)
    for _ in range(MODE_ITERATIONS):
        near = np.hypot(*(vel - centre).T) <= MODE_HALF_WIDTH_MPS
        if not near.any():
            break
        centre = np.median(vel[near], axis=0)
    return centre, float(near.mean())


def body_speed(path: np.ndarray, dt: float) -> float:
    """The body's net horizontal speed (m/s): its point ``path`` (F, 3) m (the CoM, the pelvis) from the first frame
    to the last, over the take's duration (``dt`` s a frame)."""
    duration = dt * (len(path) - 1)
    return float(np.hypot(*(path[-1, :2] - path[0, :2])) / duration) if duration > 0 else 0.0


def find_treadmill(soles: dict[str, np.ndarray], path: np.ndarray, dt: float) -> Treadmill | None:
    """The treadmill a take walks on (see the module docstring), or None (overground, standing, too short).

    ``soles`` {"left", "right"}: sole corners (F, k, 3) m, internal frame; ``path`` (F, 3) m the body's point (CoM
    or pelvis); ``dt`` s between frames."""
    if len(path) < 3:
        return None
    low = {s: lowest_corners(soles[s], dt) for s in SIDES}
    lowest = np.minimum(low["left"][0], low["right"][0])
    if not np.isfinite(lowest).any():
        return None
    ground = np.percentile(lowest[np.isfinite(lowest)], GROUND_PERCENTILE)
    feet, share = {}, {}
    for s in SIDES:
        z, vel = low[s]
        # a frame whose sole is not finite (a gap the marker body could not fill) is no sample
        feet[s], share[s] = stance_velocity(vel[(z - ground <= LOW_M) & np.isfinite(vel).all(axis=1)])
    speeds = {s: float(np.hypot(*feet[s])) for s in SIDES}
    body = body_speed(path, dt)
    slowest = min(speeds.values())
    if slowest < MIN_BELT_MPS or min(share.values()) < MIN_STANCE_SHARE:
        return None
    if float(feet["left"] @ feet["right"]) < SAME_WAY_COS * speeds["left"] * speeds["right"]:
        return None
    if not body < min(BODY_STILL_MPS, slowest / 2):  # (a body path ending in a gap is no evidence either)
        return None
    if abs(speeds["left"] - speeds["right"]) > SPLIT_FRACTION * max(speeds.values()):
        velocity = dict(feet)
    else:
        tied = (feet["left"] + feet["right"]) / 2
        velocity = {s: tied for s in SIDES}
    return Treadmill(velocity, "estimated", body, feet, share)


def given_treadmill(speeds: tuple[float, float], facing: np.ndarray, path: np.ndarray, dt: float) -> Treadmill:
    """The belts at the given (left, right) ``speeds`` (m/s), running against the way the subject faces
    (``facing`` (2,), internal frame); ``path`` (F, 3) m the body's point, ``dt`` s between frames."""
    back = -np.asarray(facing, dtype=float)[:2]
    if not np.hypot(*back) > 1e-6:  # the pelvis' headings average out (it turns all round): no way to run the belt
        raise InputError("--treadmill SPEED: the subject faces no one way over the take (the pelvis turns all "
                         "round); give --treadmill auto")
    back = back / np.hypot(*back)
    return Treadmill({s: v * back for s, v in zip(SIDES, speeds, strict=True)}, "given", body_speed(path, dt))


def parse_treadmill(text: str) -> str | tuple[float, float]:
    """``--treadmill``: "auto", "off", a belt speed SPEED (m/s, both belts) or LEFT,RIGHT (split belts); one
    line naming the option when it is none of these."""
    if text in ("auto", "off"):
        return text
    parts = text.split(",")
    try:
        speeds = [float(p) for p in parts]
    except ValueError:
        speeds = []
    if len(speeds) not in (1, 2) or not all(np.isfinite(v) and 0.0 <= v <= 10.0 for v in speeds):
        raise InputError(f"--treadmill: expected auto, off, a belt speed in m/s (0-10) or LEFT,RIGHT speeds, "
                         f"got {text!r}")
    return (speeds[0], speeds[-1])
