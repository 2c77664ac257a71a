"""The live loop's safety rules: which frames may drive a command, what may be sent,
and when to stop commanding.

* Frames (:class:`FrameGuard`). A link only returns frames it verified (CRC, lengths);
  the guard adds the rules a link cannot know. *Stale*: the frame is older than
  ``max_frame_age_s`` (by its host time stamp) when a command would be computed from
  it, or it is not newer than the previous one (its host time, or the device's own
  timestamp, did not advance: a repeated frame). *Corrupted*: a non-finite or
  wrong-sized position vector, a joint beyond its URDF limits by more than
  ``position_tolerance_rad``, or a joint that moved faster than ``speed_factor`` times
  its URDF velocity limit since the last good frame (plus ``position_tolerance_rad``
  of encoder noise). A rejected frame never drives a command.
* Goals (:class:`GoalLimiter`). Correction offsets are clipped to
  ``max_correction_rad`` per joint and may change by at most
  ``max_correction_rate_rad_s`` (rad/s); the goals (command + offsets) are clipped to the
  URDF joint limits less ``limit_margin_rad``; then each may move from the goal sent before
  it by at most its joint's URDF velocity limit times the loop time between them
  (``default_joint_speed_rad_s`` where the URDF gives none), so a motion that steps is sent
  as a ramp the servo can follow, not as one jump it slams through (and a posture read just
  beyond a limit comes back inside at that speed).
* Watchdog (:class:`Watchdog`): no valid frame for ``watchdog_s`` (at least three loop
  periods) → the loop stops
  commanding and either holds the present posture or drops torque
  (``drop_torque``); while the port is gone it tries to reconnect every
  ``reconnect_every_s``.
* A servo that reports a hardware error (overload, overheating, ...) latches a safe
  stop when ``stop_on_hardware_error`` (the default): the loop keeps monitoring but no
  longer commands.

Units: rad, rad/s, s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from livezmp.correct.limits import clip
from livezmp.links.base import LinkFrame
from livezmp.live.config import SafetyConfig
from livezmp.model.body import BodyModel
from livezmp.model.mimic import Mimic, follow


@dataclass(frozen=True)
class JointLimits:
    """Per joint, in link order: ``lower``/``upper`` positions (rad, ±inf when the URDF
    gives none) and ``velocity`` (rad/s, inf when none)."""

    names: list[str]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray


def joint_limits(body: BodyModel) -> JointLimits:
    """The URDF limits of a robot body's actuated joints (``body.joint_names`` order)."""
    nb = len(body.base_channels)
    model = body.model

    def finite(a: np.ndarray, fill: float) -> np.ndarray:
        # Pinocchio marks "no limit" with ±max float (and velocity 0 for a missing tag)
        a = np.asarray(a[nb:], dtype=float).copy()
        a[np.abs(a) >= 1e300] = fill
        return a

    vel = finite(model.velocityLimit, math.inf)
    vel[vel <= 0] = math.inf
    return JointLimits(list(body.joint_names), finite(model.lowerPositionLimit, -math.inf),
                       finite(model.upperPositionLimit, math.inf), vel)


@dataclass(frozen=True)
class Verdict:
    """Why a frame was rejected: ``kind`` "stale" or "corrupted", and a one-line ``reason``."""

    kind: str
    reason: str


class FrameGuard:
    """Applies the stale and corrupted rules to each frame; remembers the last good one."""

    def __init__(self, limits: JointLimits, config: SafetyConfig):
        self.limits = limits
        self.config = config
        # the bounds every frame is checked against, made once (the loop checks a frame every cycle)
        tol = config.position_tolerance_rad
        self._lowest, self._highest = limits.lower - tol, limits.upper + tol
        self._max_speed = config.speed_factor * limits.velocity
        self.reset()

    def reset(self) -> None:
        """Forget the last good frame (after a gap, the speed rule starts afresh)."""
        self._last_q: np.ndarray | None = None
        self._last_t = -math.inf
        self._last_device_t = -math.inf

    def check(self, frame: LinkFrame, now: float) -> Verdict | None:
        """None when ``frame`` may drive a command, else why not; ``now``: the present time
        (s, the clock of the frames' host time stamps)."""
        cfg, lim = self.config, self.limits
        q = np.asarray(frame.positions, dtype=float)
        if q.shape != lim.lower.shape:
            return Verdict("corrupted", f"{q.size} positions for {lim.lower.size} joints")
        finite = np.isfinite(q)
        # all() and any() as their ufuncs' reductions, without the methods' Python wrappers (every cycle)
        if not np.logical_and.reduce(finite):
            return Verdict("corrupted", f"joint {lim.names[int(np.argmin(finite))]}: non-finite position")
        tol = cfg.position_tolerance_rad
        out = (q < self._lowest) | (q > self._highest)
        if np.logical_or.reduce(out):
            j = int(np.argmax(out))
            return Verdict("corrupted", f"joint {lim.names[j]}: {q[j]:.3f} rad is beyond its limits "
                                        f"[{lim.lower[j]:.3f}, {lim.upper[j]:.3f}]")
        if now - frame.t > cfg.max_frame_age_s:
            return Verdict("stale", f"frame is {1e3 * (now - frame.t):.1f} ms old "
                                    f"(> {1e3 * cfg.max_frame_age_s:.1f} ms)")
        if frame.t <= self._last_t or (frame.device_time is not None and frame.device_time <= self._last_device_t):
            return Verdict("stale", "frame is not newer than the previous one")
        if self._last_q is not None:
            step = np.abs(q - self._last_q)
            allowed = self._max_speed * (frame.t - self._last_t) + tol
            fast = step > allowed
            if np.logical_or.reduce(fast):
                j = int(np.argmax(fast))
                return Verdict("corrupted", f"joint {lim.names[j]}: jumped {step[j]:.3f} rad since the last frame")
        self._last_q, self._last_t = q.copy(), frame.t
        if frame.device_time is not None:
            self._last_device_t = frame.device_time
        return None


class Watchdog:
    """Expires when no valid frame was fed for ``timeout_s`` (s, the loop's clock)."""

    def __init__(self, timeout_s: float, now: float):
        self.timeout_s = timeout_s
        self.last = now

    def feed(self, now: float) -> None:
        self.last = now

    def expired(self, now: float) -> bool:
        return now - self.last > self.timeout_s


@dataclass(frozen=True)
class Slowed:
    """Goals the joint speed limit cut in one command: ``mask`` (n,) which joints; for the first of them,
    ``joint`` its index, ``asked`` the change the command wanted from the goal before (rad), ``allowed``
    the change the time since allowed (rad) at the joint's ``speed`` (rad/s)."""

    mask: np.ndarray
    joint: int
    asked: float
    allowed: float
    speed: float


class GoalLimiter:
    """command + correction offsets → goals inside the correction limits, the joints' speed limits
    and the joint limits; ``dt``: seconds between calls (the loop period)."""

    def __init__(self, limits: JointLimits, config: SafetyConfig, dt: float, mimics: tuple[Mimic, ...] = ()):
        self.mimics = mimics  # a mimic joint's goal is its parent's goal times the multiplier plus the offset
        self.lower = limits.lower + config.limit_margin_rad
        self.upper = limits.upper - config.limit_margin_rad
        self.max_offset = config.max_correction_rad
        self.max_step = config.max_correction_rate_rad_s * dt
        self.speed = np.where(np.isfinite(limits.velocity), limits.velocity, config.default_joint_speed_rad_s)
        self.max_goal_step = self.speed * dt  # a goal's change a period (rad)
        self.reset()

    def reset(self) -> None:
        """Offsets start again from zero (after a stop); the next goals are not speed-limited until
        :meth:`start_from` says where the servos stand."""
        self.offsets = np.zeros_like(self.lower)
        self.goals: np.ndarray | None = None  # the goals sent last (rad): where the next may move from

    def start_from(self, q: np.ndarray) -> None:
        """Commanding (re)starts with the servos at ``q`` (n,) rad: the first goals move from there."""
        self.goals = follow(np.asarray(q, dtype=float).copy(), self.mimics)

    def apply(self, command: np.ndarray, offsets: np.ndarray, periods: float = 1.0) -> tuple[np.ndarray, bool,
                                                                                              Slowed | None]:
        """Goals (n,) rad for ``command`` (n,) rad plus ``offsets`` (n,) rad, ``periods`` loop periods after
        the goals before, whether a limit cut anything, and what the speed limit cut (None: nothing).
        Non-finite offsets count as zero. The goals are kept as sent whether their write succeeds or not
        (a failed write may have reached the servos)."""
        goals, limited, sent, slowed = self.propose(command, offsets, periods)
        self.keep(goals, sent)
        return goals, limited, slowed

    def keep(self, goals: np.ndarray, offsets: np.ndarray) -> None:
        """``goals`` and ``offsets`` (rad) from :meth:`propose` were sent. A non-finite goal (the link
        refuses it) leaves that joint's last goal as it was. Before :meth:`start_from` the goals are not
        kept (nothing says where the servos stand)."""
        if self.goals is not None:
            # one reduction says all are finite (a sum is, unless one is not), where isfinite and all() took two calls
            finite = math.isfinite(np.add.reduce(goals))
            self.goals = goals if finite else np.where(np.isfinite(goals), goals, self.goals)
        self.offsets = offsets

    def propose(self, command: np.ndarray, offsets: np.ndarray,
                periods: float = 1.0) -> tuple[np.ndarray, bool, np.ndarray, Slowed | None]:
        """What `apply` would return, and the offsets it would keep (rad), without keeping them:
        for goals built ahead of the cycle that sends them (:meth:`keep` them once they are sent)."""
        want = np.where(np.isfinite(offsets), offsets, 0.0)
        sent = clip(clip(want, -self.max_offset, self.max_offset), self.offsets - self.max_step,
                     self.offsets + self.max_step)
        wanted = follow(command + sent, self.mimics)
        goals = clip(wanted, self.lower, self.upper)
        limited = bool(np.logical_or.reduce(sent != want) or np.logical_or.reduce(goals != wanted))  # any(), unwrapped
        if self.goals is None:
            return goals, limited, sent, None
        # the goals inside the joint limits, then paced: a command held beyond a joint limit is not a fast one (it
        # is not counted), and a posture read just beyond one (the frame guard's tolerance) comes back inside at
        # the joint's speed, not in one jump. Four ufunc calls when nothing is cut (a NaN goal is not: the link
        # refuses it): every cycle pays them
        before = self.goals
        step = self.max_goal_step if periods == 1.0 else periods * self.max_goal_step
        change = goals - before
        cut = np.abs(change) > step
        if not np.logical_or.reduce(cut):  # any(), without its Python wrapper
            return goals, limited, sent, None
        j = int(np.argmax(cut))
        paced = np.where(cut, before + clip(change, -step, step), goals)  # the others exactly as they were
        return paced, True, sent, Slowed(cut, j, float(change[j]), float(step[j]), float(self.speed[j]))
