"""A simulated servo humanoid: the whole URDF robot that simulated servos move.

`SimHumanoid` is a `JointPlant` (see :mod:`sim_devices.servo_plant`), so a simulated
servo bus can drive it in place of a bare `ServoPlant`. Model, per fixed internal step
``h`` (default 1 ms):

* joints: a `ServoPlant` (first-order goal tracking with velocity and acceleration
  limits; torque off makes a joint passive). Its goal is the commanded goal averaged
  over the last ``goal_window_s`` (8 ms), then lagged with time constant ``goal_lag_s``
  (10 ms): the motor and its load cannot change speed at once. Fed directly, the plant's
  velocity jumps on every goal update (by Δgoal / tau in one step), so goals arriving
  at 125 Hz make its acceleration a train of spikes up to its acceleration limit,
  which throws the whole-body ZMP about by tens of centimetres; the average turns a
  staircase of goals sent every ``goal_window_s`` (or an integer fraction of it) into
  their linear interpolation, and the lag keeps the acceleration finite on any jump.
  With torque off both follow the joint, so switching torque on holds it where it is;
* base: the stance foot is flat on the ground, the base follows from the leg
  (:class:`livezmp.model.base_placement.BasePlacer`): the servos prescribe the whole motion
  and the feet neither slip nor tip;
* ground: a plane, level or sloped by ``slope`` (rad, rising ahead along the starting
  stance foot's x axis). The simulation works in the ground's frame (its plane z = 0, x
  uphill), where gravity is tilted: (−g sin slope, 0, −g cos slope). Everything below —
  states, ZMP, soles, polygon, pushes (along the ground) — is in that frame; only the
  IMU, as a real one, reads the world (gravity straight down). With ``edge=(side, fraction)``
  the ground is level but foot ``side`` stands rolled over a step's edge (the scenario's
  ankle roll): the other foot is the flat one the base is placed from, for the whole run,
  and only the strip of the rolled sole from its low edge across ``fraction`` of its width
  (up to the step's edge under it) bears weight, so that strip, not the whole sole, joins the
  support polygon; the rolled foot counts as in contact when its low edge is within
  ``contact_tolerance`` of the floor or below it (a floor a few mm lower under it: its ankle's
  roll lowers the edge);
* true ZMP: exact rigid-body dynamics of the whole body
  (:func:`livezmp.balance.zmp.compute_zmp`) in the state (q, v, a), under the ground
  frame's gravity: the centre of pressure on the ground plane. v and a are second-order
  central differences of the last three whole-body configurations (base coordinates
  from the placer, joint angles from the plant), evaluated at the middle one: for the
  joints this is exactly the plant's own velocity (the mean of its two step
  velocities) and its change per step; for the base the same stencil keeps the stance
  foot's velocity from (q, v) at zero to O(h²). The dynamic state is therefore one
  step behind the plant (``HumanoidState.t``). When the stance changes, the two older
  configurations are re-placed from the new stance foot, so no difference straddles
  the jump of the anchor;
* contacts: a foot is in contact when its lowest sole corner is within
  ``contact_tolerance`` (1 mm) of the ground; the support polygon is the hull of the
  soles in contact (:mod:`livezmp.balance.support`);
* push: a horizontal force F (N, world x, y) applied at height h (m) above the ground
  is an external force, so the ground's share of the wrench loses it: contact force
  = dḣ − m g − F, contact moment about the CoM c = τ − (r − c) × F with r at height
  h above the CoM's ground point. The contact ZMP moves by +h F / F_z (towards the
  push; −h F / F_z with F the ground's reaction to the push). The body's motion does
  not change: the servos hold it, the ground has to deliver the difference;
* fall: when the contact ZMP stays outside the support polygon (or the contact force
  is below 5 % of the weight) for longer than ``fall_after_s``, the robot has fallen:
  :attr:`SimHumanoid.fallen` records when and why, and from then on it holds (joints
  frozen, no further motion of the model). Only its IMU sees the fall, as a robot's own
  IMU would: from then on it reads the body toppling over the support edge the ZMP left
  by, as a rigid inverted pendulum of the CoM's height pivoting on that edge (linearised:
  tilt = 0.05 rad x cosh(t sqrt(g / h)), until it lies at 90 degrees), so a host that
  watches the IMU can tell the fall, as on hardware.

Sensors, computed on request from the latest dynamic state: four foot force cells per
foot (:meth:`SimHumanoid.foot_forces`) and an IMU on the base link
(:meth:`SimHumanoid.imu`). Frame: the ground's (z up, ground z = 0; on a level ground the
world), metres, SI units.

Stepping: :meth:`advance_to` runs whole internal steps up to a time; :meth:`step`
(the `JointPlant` call) advances by ``dt``, or, when the humanoid has a ``clock``, to
the clock's time whatever ``dt`` says, so a servo bus and a :class:`RealtimeThread`
may both call it without counting time twice. One lock guards everything, so a servo
simulator thread may set goals while another thread steps.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from livezmp.balance.contacts import support_label
from livezmp.balance.support import clamp_to_vertices, convex_hull, support_vertices
from livezmp.balance.zmp import compute_zmp, zmp_from_wrench
from livezmp.errors import InputError
from livezmp.live.scenarios import Push
from livezmp.model.base_placement import BasePlacer, base_coordinates
from livezmp.model.body import BodyModel, foot_soles
from sim_devices.servo_plant import Array, ServoPlant

FLIGHT_FRACTION = 0.05  # contact force below this share of the weight: nothing holds the robot up


_NO_PUSH = np.zeros(3)  # the push force and moment of a step without pushes, shared: read-only
_NO_PUSH.flags.writeable = False

TOPPLE_START_RAD = 0.05  # tilt the toppling starts from: a lean already past the edge
TOPPLED_RAD = math.pi / 2  # lying on the ground


@dataclass(frozen=True)
class FallEvent:
    """The robot fell at ``t`` (s); the ZMP had been unsupported since ``since`` (s)."""

    t: float
    since: float
    reason: str


class HumanoidState(NamedTuple):
    """The dynamic state at time ``t`` (s), made every physics step (a named tuple: a frozen dataclass's
    ``__init__`` cost 3 times as much). ``q``, ``v``, ``a``: whole body (base x, y, z
    in m, yaw, pitch, roll in rad, then the joints in URDF order; their rates).
    ``zmp`` (3,) is the contact ZMP on the ground (None when the contact force is below
    5 % of the weight), ``com`` (3,) the centre of mass, ``force`` (3,) the contact force
    (N), ``push`` (2,) the push force acting (N). ``clamped`` (2,) is the ZMP's nearest
    point of ``polygon`` (its hull of the soles in contact, (m, 2)); ``margin`` (m) is
    its signed distance to the polygon edge, + inside; ``soles`` maps side to its (4, 3)
    corners."""

    t: float
    q: Array
    v: Array
    a: Array
    zmp: Array | None
    com: Array
    force: Array
    push: Array
    stance: str
    support: str
    polygon: Array
    soles: dict[str, Array]
    clamped: Array | None
    margin: float | None

    @property
    def supported(self) -> bool:
        """Whether the ground can deliver this state: a ZMP inside the support polygon."""
        return self.margin is not None and self.margin >= 0.0


@dataclass(frozen=True)
class FootForces:
    """Vertical forces (N) of the force cells under each sole, one per sole corner (four
    for a box sole) in the order of ``body.feet[side].sole_local``; ``cop`` (2,) their
    centre of pressure (m, world), ``total`` their sum (N)."""

    left: Array
    right: Array
    cop: Array | None
    total: float


@dataclass(frozen=True)
class ImuReading:
    """An IMU at the base link's origin, axes along the base link. ``quaternion`` (x, y,
    z, w) rotates base-link vectors into the world (z up, gravity down, whatever the
    ground's slope); ``angular_velocity`` (rad/s) and ``specific_force`` (m/s², acceleration
    minus gravity: +9.81 up at rest) are in the base-link axes."""

    t: float
    quaternion: Array
    angular_velocity: Array
    specific_force: Array


@dataclass
class BalanceCounters:
    """Running counts over the dynamic steps: ``steps``, ``unsupported_steps`` (ZMP outside
    the polygon or no contact force), ``worst_margin`` (m, most negative margin seen) and
    ``longest_unsupported_s`` (s, the longest run of consecutive unsupported steps)."""

    steps: int = 0
    unsupported_steps: int = 0
    worst_margin: float = math.inf
    longest_unsupported_s: float = 0.0


def _continued(angles: list[float], previous: list[float]) -> list[float]:
    """``angles`` (rad) shifted by whole turns to lie within π of ``previous``, so that
    differences across ±π stay small."""
    # plain floats: the base's three angles every physics step, where numpy's per-call cost is most of the work;
    # Python's float % is numpy's remainder (the same result bit for bit)
    return [p + (a - p + math.pi) % (2 * math.pi) - math.pi for a, p in zip(angles, previous, strict=True)]


SAME_CORNER = 1e-5  # corners this share of their span apart are one point: the legs' IK holds the feet to 1e-7 m


def cop_weights(corners: Array, point: Array) -> Array:
    """Non-negative weights (k,) summing to 1 whose weighted mean of ``corners`` (k, 2)
    is ``point`` (2,), which must lie in their hull (m, world plane).

    The hull is fanned into triangles from the corners' mean g; in the triangle (g, v_i,
    v_i+1) that holds the point, its barycentric weight on g is spread evenly over all
    corners and the other two go to v_i and v_i+1: the point at g loads every corner
    equally, and the load moves towards the edge the point approaches. A hull vertex where
    several corners meet (two soles touching at the mid-line between the feet, as default soles
    trimmed to it do) shares its weight evenly among them: given to the first alone, the load
    jumped to one foot whenever rounding made that meeting point a vertex, the other foot read as
    lifted, and the corrector rolled the trunk over the one (Cassie's, Z-Bot2's)."""
    k = len(corners)
    hull = convex_hull(corners)
    # convex_hull returns the input coordinates (subnormal ones as 0): the corners at a vertex are those
    same = SAME_CORNER * float(np.ptp(corners, axis=0).max())
    at = [np.flatnonzero(np.abs(corners - v).sum(axis=1) <= same) for v in hull]
    g = corners.mean(axis=0)
    a, b = hull - g, np.roll(hull, -1, axis=0) - g
    p = point - g
    det = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    la = (p[0] * b[:, 1] - p[1] * b[:, 0]) / det
    lb = (a[:, 0] * p[1] - a[:, 1] * p[0]) / det
    bary = np.column_stack([1.0 - la - lb, la, lb])
    i = int(np.argmax(bary.min(axis=1)))  # the triangle holding the point (the most inside one)
    lg, li, lj = np.maximum(bary[i], 0.0) / np.maximum(bary[i], 0.0).sum()
    w = np.full(k, lg / k)
    w[at[i]] += li / len(at[i])
    w[at[(i + 1) % len(hull)]] += lj / len(at[(i + 1) % len(hull)])
    return w


def edge_strip(sole: Array, fraction: float) -> Array:
    """The corners (4, 3) of the strip of a rectangular ``sole`` (corners (4, 3), world) rolled over an
    edge: from its two lowest corners across ``fraction`` of the way to the two others."""
    order = np.argsort(sole[:, 2])
    low, high = sole[order[:2]], sole[order[2:]]
    # pair each high corner with the low corner across the sole's width (the nearer one)
    if np.linalg.norm(high[0] - low[0]) > np.linalg.norm(high[0] - low[1]):
        low = low[::-1]
    return np.vstack([low, low + fraction * (high - low)])


class _GoalShaper:
    """Commanded goals → a servo plant's goal: their mean over the last ``window`` steps,
    then a first-order lag (``gain`` per step); joints with torque off reset both to
    their position. ``lagged``: the array the shaped goal is kept in and updated in place (the
    plant's goal: no copy a step), its values the start. Memory: ``window`` goal vectors."""

    def __init__(self, lagged: Array, window: int, gain: float):
        self.recent = np.tile(lagged, (window, 1))
        self.next = 0
        self.gain = gain
        self.lagged = lagged

    def update(self, goal: Array, position: Array, torque_on: Array) -> Array:
        self.recent[self.next] = goal
        self.next = (self.next + 1) % len(self.recent)
        # np.mean's own sum and division, without its Python wrapper (the shaper runs every physics step)
        self.lagged += (np.add.reduce(self.recent, axis=0) / len(self.recent) - self.lagged) * self.gain
        if b"\x00" in torque_on.tobytes():  # not all on (a bool array's bytes are 0 or 1): cheaper than a reduction
            off = ~torque_on
            self.recent[:, off] = position[off]
            self.lagged[off] = position[off]
        return self.lagged


class SimHumanoid:
    """A whole servo humanoid (see module docstring); a `JointPlant` over ``body.joint_names``.

    ``posture``: initial joint angles (rad, URDF order); or ``servo``: the joint plant
    to use, at its own position (default: a `ServoPlant` at ``posture`` with the URDF's
    joint limits); ``dt``: the internal step (s); ``goal_window_s``, ``goal_lag_s``: the
    goal shaping (s, 0 = none; see the module docstring); ``clock``: a time source (s)
    for wall-clock stepping, e.g. ``time.monotonic``; ``torque_on``: initial torque of
    every joint; ``device_steps``: whether :meth:`step`, the call a simulated device
    makes at every packet, advances the simulation (False when a :class:`RealtimeThread`
    alone keeps a clocked humanoid current, so a device's reply never waits for physics
    steps: the reply reports the state of the last step, at most one thread period old,
    as a real servo samples its encoder on its own clock). The cost of a call is
    proportional to the simulated time it covers (about 0.1 ms per step, see
    benchmarks/bench_sim_humanoid.py), so a clocked humanoid is best kept up to date by a
    :class:`RealtimeThread`."""

    def __init__(self, body: BodyModel, posture: Array | None = None, *, servo: ServoPlant | None = None,
                 dt: float = 1e-3, goal_window_s: float = 0.008, goal_lag_s: float = 0.01,
                 fall_after_s: float = 0.2, contact_tolerance: float = 1e-3, clock: Callable[[], float] | None = None,
                 torque_on: bool = False, device_steps: bool = True, slope: float = 0.0,
                 edge: tuple[str, float] | None = None) -> None:
        if body.kind != "urdf" or len(body.base_channels) != 6:
            raise InputError("SimHumanoid: needs a URDF robot body with a floating base (body_from_urdf)")
        if not (math.isfinite(slope) and abs(slope) < math.radians(45)):
            raise InputError(f"SimHumanoid: slope must be a finite angle under 45 degrees (rad), got {slope!r}")
        if edge is not None and (edge[0] not in ("left", "right") or not 0.0 < edge[1] <= 1.0):
            raise InputError(f"SimHumanoid: edge must be (left or right, a fraction in (0, 1]), got {edge!r}")
        if not (dt > 0 and min(goal_window_s, goal_lag_s, fall_after_s, contact_tolerance) >= 0):
            raise InputError(f"SimHumanoid: need dt > 0 and goal_window_s, goal_lag_s, fall_after_s, contact_tolerance "
                             f">= 0; got {dt}, {goal_window_s}, {goal_lag_s}, {fall_after_s}, {contact_tolerance}")
        self.body = body
        self.model = body.model
        self.slope = slope
        g = float(np.linalg.norm(body.model.gravity.linear))
        #: gravity in the ground's frame (m/s²), and the world's orientation of that frame
        self.gravity = np.array([-g * math.sin(slope), 0.0, -g * math.cos(slope)])
        self._ground_in_world = pin.AngleAxis(-slope, np.array([0.0, 1.0, 0.0])).toRotationMatrix()
        n = len(body.joint_names)
        if servo is not None and posture is not None:
            raise InputError("SimHumanoid: give a posture or a servo plant (at its own position), not both")
        if servo is None:
            start = np.zeros(n) if posture is None else np.asarray(posture, dtype=float)
            if start.shape != (n,) or not np.all(np.isfinite(start)):
                raise InputError(f"SimHumanoid: posture must be {n} finite joint angles (rad), got shape "
                                 f"{start.shape}")
            servo = ServoPlant(n, position=start, lower=self.model.lowerPositionLimit[6:],
                               upper=self.model.upperPositionLimit[6:])
        elif servo.n != n:
            raise InputError(f"SimHumanoid: servo plant has {servo.n} joints, the body {n}")
        servo.torque_on[:] = torque_on
        self.servo = servo
        self.goal = servo.position.copy()  #: commanded goals (rad); the plant's own goal is their shaped copy
        servo.goal[:] = servo.position
        self._shaper = _GoalShaper(servo.goal, max(1, round(goal_window_s / dt)),
                                   -math.expm1(-dt / goal_lag_s) if goal_lag_s > 0 else 1.0)
        # The JointPlant arrays: the servo plant's own, updated in place.
        self.position, self.velocity, self.current = servo.position, servo.velocity, servo.current
        self.dt = dt
        self.fall_after_s = fall_after_s
        self.contact_tolerance = contact_tolerance
        self.clock = clock
        self.device_steps = device_steps
        self._clock_zero = clock() if clock is not None else 0.0
        self.fallen: FallEvent | None = None
        self._topple: tuple[float, Array, float] | None = None  # see _topple_axis
        self.counters = BalanceCounters()
        self._lock = threading.Lock()
        self._data = self.model.createData()  # dynamics, per step
        self._place_data = self.model.createData()  # re-placement on a stance switch
        self._sensor_data = self.model.createData()  # sensors, on request
        self._imu_frame = body.correction.root_frame_id
        self.edge = edge
        # on a step's edge the flat foot carries the base all along: no stance switch
        self._placer = BasePlacer(body) if edge is None else \
            BasePlacer(body, switch_depth=math.inf, stance="right" if edge[0] == "left" else "left")
        self._steps = 0
        self._requested = 0.0
        self._unsupported_since: float | None = None
        self._pushes: list[Push] = []
        self._polygon_cache: tuple[str, list[float], Array, list] | None = None
        q = np.concatenate([self._placer.update(servo.position), servo.position])
        self._history = [q, q, q]  # configurations at steps k-2, k-1, k
        self._state = self._evaluate(0.0)

    # -- JointPlant ---------------------------------------------------------------------------

    def set_goal(self, idx: int, position: float) -> None:
        """Set joint ``idx``'s goal (rad); a fallen robot keeps it but does not move."""
        if not math.isfinite(position):
            raise InputError(f"SimHumanoid.set_goal: joint {idx} ({self.body.joint_names[idx]}): goal {position!r} "
                             "is not a finite angle")
        with self._lock:
            self.goal[idx] = position

    def set_goals(self, positions: Array) -> None:
        """Set every joint's goal at once (rad, URDF order), atomically."""
        goals = np.asarray(positions, dtype=float)
        # the joints' floats checked one by one: a ufunc and its reduction cost several times that (every step)
        if goals.shape != self.goal.shape or not all(map(math.isfinite, goals.tolist())):
            bad = "shape " + str(goals.shape) if goals.shape != self.goal.shape else \
                "joint " + self.body.joint_names[int(np.flatnonzero(~np.isfinite(goals))[0])] + " not finite"
            raise InputError(f"SimHumanoid.set_goals: need {len(self.goal)} finite angles (rad), got {bad}")
        with self._lock:
            self.goal[:] = goals

    def set_torque(self, idx: int, on: bool) -> None:
        """Switch joint ``idx``'s torque; off makes it passive."""
        with self._lock:
            self.servo.set_torque(idx, on)

    def step(self, dt: float) -> None:
        """Advance by ``dt`` seconds of simulated time, or, with a ``clock``, to the clock's time;
        nothing when the humanoid is not ``device_steps`` (its thread steps it)."""
        if self.device_steps:
            self._step(dt)

    def _step(self, dt: float) -> None:
        with self._lock:
            if self.clock is not None:
                self._advance(self.clock() - self._clock_zero)
            else:
                self._requested = max(self._requested, self._steps * self.dt) + max(dt, 0.0)
                self._advance(self._requested)

    # -- stepping -----------------------------------------------------------------------------

    @property
    def t(self) -> float:
        """Simulated time of the plant's joint state (s)."""
        return self._steps * self.dt

    def advance_to(self, t: float) -> None:
        """Run whole internal steps until the plant's time reaches ``t`` (s); earlier t does nothing."""
        with self._lock:
            self._advance(t)

    def sync(self) -> None:
        """Advance to the clock's time (needs a ``clock``)."""
        if self.clock is None:
            raise InputError("SimHumanoid.sync: this humanoid has no clock; use advance_to(t)")
        self._step(0.0)

    def push(self, push: Push) -> None:
        """Schedule a push (its ``start`` is simulated time, s)."""
        with self._lock:
            self._pushes.append(push)

    def _advance(self, t: float) -> None:
        # a tolerance of 1e-6 step, so t = k * dt reaches step k despite rounding
        for _ in range(math.floor(t / self.dt + 1e-6) - self._steps):
            self._steps += 1
            if self.fallen is None:
                self._step_once()

    def _step_once(self) -> None:
        stance = self._placer.stance
        servo = self.servo
        self._shaper.update(self.goal, servo.position, servo.torque_on)  # into servo.goal
        servo.step(self.dt)
        q = self._whole_body(self.servo.position)
        q0, q1 = self._history[1], self._history[2]
        if self._placer.stance != stance:
            q0, q1 = self._replaced(q0), self._replaced(q1)
        self._history = [q0, q1, q]
        self._state = self._evaluate(self.t - self.dt)
        self._check_fall(self._state)

    def _whole_body(self, joints: Array) -> Array:
        # the base's coordinates as floats, its angles continued, then one array: fewer numpy calls, the same values
        base = self._placer.update(joints).tolist()
        base[3:] = _continued(base[3:], self._history[2][3:6].tolist())
        return np.concatenate((base, joints))

    def _replaced(self, q: Array) -> Array:
        """``q`` with its base re-placed from the (new) stance foot's anchor."""
        model, data = self.model, self._place_data
        local = q.copy()
        local[:6] = 0.0
        pin.forwardKinematics(model, data, local)
        foot = self.body.feet[self._placer.stance].frame_id
        out = q.copy()
        coords = base_coordinates(self._placer.anchor * pin.updateFramePlacement(model, data, foot).inverse())
        out[:3] = coords[:3]
        out[3:6] = _continued(coords[3:6].tolist(), q[3:6].tolist())
        return out

    def _push_wrench(self, t: float, com: Array) -> tuple[Array, Array]:
        """Total push force (3,) and its moment about ``com`` (3,) at time t (the arrays of no push, read-only,
        when none is scheduled: most steps)."""
        if not self._pushes:
            return _NO_PUSH, _NO_PUSH
        self._pushes = [p for p in self._pushes if p.start + p.duration > t]
        force, moment = np.zeros(3), np.zeros(3)
        for p in self._pushes:
            share = p.share(t)
            if share > 0:
                f = share * np.array([p.force[0], p.force[1], 0.0])
                force += f
                moment += np.cross(np.array([0.0, 0.0, p.height - com[2]]), f)
        return force, moment

    def _evaluate(self, t: float) -> HumanoidState:
        q0, q1, q2 = self._history
        h = self.dt
        v = (q2 - q0) / (2 * h)
        a = (q2 - 2 * q1 + q0) / (h * h)
        model, data = self.model, self._data
        res = compute_zmp(model, data, q1, v, a, 0.0, FLIGHT_FRACTION, self.gravity)
        push, push_moment = self._push_wrench(t, res.com)
        force, zmp = res.force, res.zmp
        if push is not _NO_PUSH and np.logical_or.reduce(push):  # any(), unwrapped, only while pushes are scheduled
            force = res.force - push
            # the flight threshold only when pushed: the model's gravity is a copy made each time it is read
            min_fz = FLIGHT_FRACTION * self.body.total_mass * float(-model.gravity.linear[2])
            zmp = zmp_from_wrench(res.com, force, data.dhg.angular - push_moment, 0.0, min_fz)
        soles = foot_soles(self.body, data, place=True)
        # the lowest corner as floats (a numpy reduction costs more than the four floats; the soles are finite, made
        # from finite goals, so min() finds what np.min would)
        touching = [min(soles[s][:, 2].tolist()) <= self.contact_tolerance for s in ("left", "right")]
        support = support_label(*touching)
        polygon, vertices = self._polygon(soles, support)
        clamped, margin = None, None
        if zmp is not None:
            c = clamp_to_vertices(zmp[:2], vertices)
            clamped, margin = c.point, c.margin
        return HumanoidState(t, q1, v, a, zmp, res.com, force, push[:2], self._placer.stance, support, polygon,
                             soles, clamped, margin)

    def _polygon(self, soles: dict[str, Array], support: str) -> tuple[Array, list[tuple[float, float]]]:
        """The support polygon (m, 2) and its vertices as float pairs (checked once, when built: the ZMP is
        clamped to them every step); reused while the soles in contact stay within 1 nm of where it was built
        (feet on the ground do not move), as building a hull costs more than a step."""
        # the held soles' corners as floats, compared one by one: cheaper than numpy's concatenation, difference and
        # reduction on two dozen numbers (every step)
        key = [x for s in ("left", "right") if support in (s, "double") for x in soles[s].ravel().tolist()]
        cached = self._polygon_cache
        if cached is not None and cached[0] == support and \
                all(abs(x - y) <= 1e-9 for x, y in zip(cached[1], key, strict=True)):
            return cached[2], cached[3]
        bearing = dict(soles)
        if self.edge is not None:
            bearing[self.edge[0]] = edge_strip(soles[self.edge[0]], self.edge[1])
        vertices = support_vertices(bearing["left"], bearing["right"], support)
        polygon = np.array(vertices, dtype=float).reshape(-1, 2)  # as support_polygon makes it
        self._polygon_cache = (support, key, polygon, vertices)
        return polygon, vertices

    def _check_fall(self, s: HumanoidState) -> None:
        c = self.counters
        c.steps += 1
        if s.margin is not None:
            c.worst_margin = min(c.worst_margin, s.margin)
        if s.supported:
            self._unsupported_since = None
            return
        c.unsupported_steps += 1
        if self._unsupported_since is None:
            self._unsupported_since = s.t
        c.longest_unsupported_s = max(c.longest_unsupported_s, s.t - self._unsupported_since + self.dt)
        # "for longer than": strictly more than fall_after_s of consecutive unsupported steps
        if s.t - self._unsupported_since + self.dt > self.fall_after_s + 1e-9 * self.dt:
            what = ("the contact force fell below 5 % of the weight" if s.margin is None
                    else f"the ZMP was {-s.margin * 1e3:.1f} mm outside the support polygon")
            self.fallen = FallEvent(s.t, self._unsupported_since,
                                    f"fell at t = {s.t:.3f} s: {what}, unsupported for more than "
                                    f"{self.fall_after_s} s (since t = {self._unsupported_since:.3f} s)")
            self._topple = self._topple_axis(s)
            self.servo.velocity[:] = 0.0
            self.servo.current[:] = 0.0
            # it holds: from now on a static state
            self._history = [self._history[2]] * 3
            self._state = self._evaluate(self.t)

    def _topple_axis(self, s: HumanoidState) -> tuple[float, Array, float]:
        """(fall time, world axis the body topples about, pendulum rate sqrt(g / CoM height))."""
        out = np.array([1.0, 0.0]) if s.zmp is None or s.clamped is None else s.zmp[:2] - s.clamped
        norm = float(np.linalg.norm(out))
        out = out / norm if norm > 1e-9 else np.array([1.0, 0.0])
        axis = np.array([-out[1], out[0], 0.0])  # z x out: the top moves towards ``out``
        return s.t, axis, math.sqrt(9.81 / max(float(s.com[2]), 0.05))

    def _toppled(self, t: float) -> tuple[Array, Array]:
        """World rotation added by toppling and the world angular velocity (rad/s), ``t`` s after the fall."""
        t_fall, axis, rate = self._topple
        x = min(max(t - t_fall, 0.0) * rate, math.acosh(TOPPLED_RAD / TOPPLE_START_RAD))
        tilt = TOPPLE_START_RAD * (math.cosh(x) - 1.0)
        speed = TOPPLE_START_RAD * rate * math.sinh(x) if tilt < TOPPLED_RAD - TOPPLE_START_RAD else 0.0
        return pin.AngleAxis(tilt, axis).toRotationMatrix(), axis * speed

    # -- readings -----------------------------------------------------------------------------

    def state(self) -> HumanoidState:
        """The latest dynamic state (immutable snapshot)."""
        with self._lock:
            return self._state

    def foot_forces(self) -> FootForces:
        """Force-cell readings of the latest state: the cells of the feet in contact carry
        the contact force's vertical part, with their centre of pressure at the ZMP
        clipped to the support polygon (:func:`cop_weights` splits it); zero when the
        contact force is below 5 % of the weight."""
        s = self.state()
        cells = {side: np.zeros(len(sole)) for side, sole in s.soles.items()}
        if s.clamped is None:
            return FootForces(cells["left"], cells["right"], None, 0.0)
        sides = [side for side in ("left", "right") if s.support in (side, "double")]
        corners = np.vstack([s.soles[side][:, :2] for side in sides])
        w = cop_weights(corners, s.clamped) * float(s.force[2])
        start = 0
        for side in sides:
            cells[side] = w[start:start + len(s.soles[side])]
            start += len(s.soles[side])
        return FootForces(cells["left"], cells["right"], w @ corners / w.sum(), float(w.sum()))

    def imu(self) -> ImuReading:
        """IMU reading of the latest state (see :class:`ImuReading`)."""
        with self._lock:
            s = self._state
            model, data, f = self.model, self._sensor_data, self._imu_frame
            pin.forwardKinematics(model, data, s.q, s.v, s.a)
            rotation = pin.updateFramePlacement(model, data, f).rotation
            omega = pin.getFrameVelocity(model, data, f, pin.LOCAL).angular
            acc = pin.getFrameClassicalAcceleration(model, data, f, pin.LOCAL).linear
            if self._topple is not None:
                tipped, spin = self._toppled(self.t)
                rotation = tipped @ rotation
                omega = omega + rotation.T @ spin
            specific = acc - rotation.T @ self.gravity
            world = self._ground_in_world @ rotation
            return ImuReading(s.t, pin.Quaternion(world).coeffs().copy(), omega.copy(), specific)


class RealtimeThread:
    """Steps a clocked `SimHumanoid` to its clock every ``period`` seconds, in a thread;
    a context manager (stops and joins on exit). An exception in the thread stops it and
    is raised again by :meth:`stop`."""

    def __init__(self, humanoid: SimHumanoid, period: float = 0.002) -> None:
        if humanoid.clock is None:
            raise InputError("RealtimeThread: the humanoid needs a clock (SimHumanoid(..., clock=time.monotonic))")
        self.humanoid = humanoid
        self.period = period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim-humanoid", daemon=True)
        self.error: BaseException | None = None

    def _run(self) -> None:
        try:
            while not self._stop.wait(self.period):
                self.humanoid.sync()
        except BaseException as e:  # handed to the thread that calls stop()
            self.error = e

    def start(self) -> RealtimeThread:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()
        if self.error is not None:
            raise self.error

    def __enter__(self) -> RealtimeThread:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
