"""Per-frame balance correction for the live loop: causal, constant cost per frame.

Each frame, the ZMP's shortfall from ``margin_m`` inside the support polygon (`MARGIN_M`,
15 mm, by default; the live loop scales it with the robot's size: :func:`size_scaled_margin`;
wider than offline, so the correction starts early and gently) is turned
into a change of the root rotation δ through the quasi-static sensitivity of the ZMP
to δ: rotating the upper body by δ about the pivot P moves the CoM by
(m_upper / m) · δ × (c_upper − P). A damped least-squares step (yaw damped hardest:
it barely moves the ZMP) is taken with gain ``gain_per_s`` × dt — the loop integrates,
so model error only slows it; keep 1/gain well above the estimator's lag — then
limited in acceleration (the trunk's own angular acceleration pushes the ZMP the
other way at first), rate and size. When the ZMP is comfortably inside, δ relaxes
back toward zero over ``relax_s``, but only while the ZMP keeps three margins
(hysteresis, so relaxing and correcting do not chase each other). The output is joint
offsets: the root and thigh channels of a skeleton, the leg joints of a robot (its
base is not actuated).

A robot's trunk may be too light, or its CoM too near its hips, for any turn within the limits to move its CoM
as far as the ZMP needs (a legs-only robot: Alexbotmini's 15° move it 1.8 mm). What the trunk's turn would
have had to give beyond its range is then given by the legs (the hip-and-ankle strategy of a person who cannot
bend at the waist far enough): the pelvis is carried horizontally over the feet, both legs re-solved so the
feet stay, by ``shift`` (m, world x and y), through the CoM's own answer to it (`legs_response`), within the
range, rate and acceleration of the legs leaning about the ankles (`hips_height` above them) as far and as fast as
the trunk may turn about the hips. Only a robot whose trunk is too short a lever does so (`uses_legs`: its largest
turn moves its CoM less than half the corrector's margin); the others are corrected by the trunk alone.

The ZMP estimated from the joints cannot see an external force (a push, a hand leaning
on the robot): the servos hold the posture, and only the ground's reaction changes.
Where the feet have force sensors, their measured centre of pressure (CoP) does see it,
but it never leaves the feet. So the corrector acts on the estimate moved by what the
sensors disagree with: p = ZMP + (CoP − ZMP clamped to the support polygon). Without an
external force the CoP is the clamped ZMP and p is the estimate, whose depth outside the
feet the CoP cannot show; under a push p follows the CoP to the edge the push presses
it against, and the integrating step moves the trunk until the CoP is back
``margin_m`` inside.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from livezmp.balance.pipeline import FrameResult
from livezmp.balance.plates import G
from livezmp.balance.support import clamp_to_polygon
from livezmp.balance.zmp import compute_zmp
from livezmp.correct.limits import CorrectionLimits, clip, zmp_target
from livezmp.correct.root_motion import RootMover, hip_axes
from livezmp.model.base_placement import BasePlacer
from livezmp.model.body import BodyModel, foot_soles


@dataclass
class OnlineCorrection:
    """``delta`` (3,) rad root rotation; ``offsets`` (nq,) SI offsets to add to the
    commanded channels (zero outside the corrector's own channels); ``limited`` when a
    limit cut the step this frame."""

    delta: np.ndarray
    offsets: np.ndarray
    limited: bool


# 1/s: the ZMP's shortfall is closed at this rate; faster overshoots. Robots x scenarios of
# benchmarks/bench_any_humanoid.py where the uncorrected run falls and the corrected one stands, by gain:
# 1.3: 92 of 96, 1.6: 91, 1.8: 90, 2.0 and 2.5: 87 (tall robots fall corrected in lean and push), 4: the
# livezmp_mini falls corrected in lean; with the trunk acceleration limit scaled as 1 / h (size_scaled_accel), 1.3
# passes 95 of 96 (the 96th: an armless robot refused arm_swing). (Asked 4/s, the loop ran at ~1.6/s while S took
# the legs' subtree CoMs in their joints' own frames, 2.5x too large.)
GAIN_PER_S = 1.3
TRUNK_SIZE_M = 0.3  # CoM height up to which the trunk acceleration limit and the margin hold as given (mini 0.28 m)
# m: how far inside the support polygon the corrector aims the ZMP, for a robot up to TRUNK_SIZE_M (see
# size_scaled_margin). The corrected ZMP overshoots its aim by up to 12-16 mm on the 0.3 m robots of
# benchmarks/bench_any_humanoid.py (the estimator's lag and the trunk's limited acceleration), which 15 mm covers.
MARGIN_M = 0.015


def com_height(body: BodyModel, q: np.ndarray) -> float:
    """m: the height of ``body``'s CoM above its soles' lowest point in the configuration ``q`` (base and joints)."""
    model, data = body.model, body.model.createData()
    pin.centerOfMass(model, data, q)
    pin.framesForwardKinematics(model, data, q)
    ground = min(float(sole[:, 2].min()) for sole in foot_soles(body, data).values())
    return float(data.com[0][2]) - ground


def size_factor(body: BodyModel) -> float:
    """max(1, h / `TRUNK_SIZE_M`), h (m) the height of ``body``'s CoM above its soles in the zero posture: how much
    larger than the robots the corrector's limits were set on ``body`` is."""
    height = com_height(body, np.zeros(body.model.nq))
    return max(1.0, height / TRUNK_SIZE_M) if height > 0 else 1.0


def size_scaled_accel(body: BodyModel, accel_deg_s2: float) -> float:
    """The root rotation's angular acceleration limit (deg/s^2) for ``body``: ``accel_deg_s2`` for a robot whose
    CoM stands at most `TRUNK_SIZE_M` above its soles (zero posture), × `TRUNK_SIZE_M` / h for a taller one.
    Dynamically similar robots (Froude scaling: lengths × L, times × sqrt(L / g), the robot's own time constant
    sqrt(h / g)) turn their trunks alike at angular accelerations × 1 / L; the ZMP swing a trunk acceleration
    α causes, I α / (m g), then grows as L, the same share of the feet. (Scaled by (0.3 m / h)^2 instead,
    which kept that swing the same in mm, a 1.8 m, 60 kg humanoid turned its trunk at 9 deg/s^2: 1.8° in its
    last 0.6 s while its lean brought the ZMP at 35 mm/s to its toes, and it fell corrected in ``lean`` and
    ``push``; at 30 deg/s^2 it stands, benchmarks/bench_any_humanoid.py.)"""
    return accel_deg_s2 / size_factor(body)


def size_scaled_margin(body: BodyModel, margin_m: float = MARGIN_M) -> float:
    """The corrector's ZMP margin (m) for ``body``: ``margin_m`` for a robot whose CoM stands at most
    `TRUNK_SIZE_M` above its soles, × h / `TRUNK_SIZE_M` for a taller one. The margin has to cover how far the
    corrected ZMP overshoots its aim, and that overshoot is a length of the robot's own dynamics: the ZMP's
    travel during the estimator's lag and the corrector's response, and the swing of the trunk's acceleration
    (`size_scaled_accel`), all grow as L between dynamically similar robots; so do the soles, so the margin stays
    the same share of the feet (15 mm of the 0.3 m robots' 120 mm soles; 50 mm of the 1.8 m robot's 430 mm).
    With 15 mm whatever its size, the 1.8 m, 60 kg humanoid's true ZMP left its feet corrected (−4.6 mm in
    ``lean``, −5.7 mm in ``push``; benchmarks/bench_any_humanoid.py)."""
    return margin_m * size_factor(body)


# The trunk's response time sqrt(K / S) (K: the ZMP's answer to its pitch acceleration, m per rad/s^2,
# `reaction_per_accel`; S: its static lever, m/rad, `OnlineCorrector.sensitivity`) in units of the robot's own
# sqrt(h / g) (h its CoM's height), up to which `size_scaled_margin` holds: 1.13-1.44 for the 51 robots of
# /work/extra_robots and the OP3 that the scenarios stand (knees-bent stance of ``lean``), 2.74 for THORMANG3,
# whose file gives 38 of its links a placeholder 1 kg m^2 inertia: turning its trunk back pushed its ZMP forward
# 82 mm per rad/s^2 (X1's 16 mm), more than its 40 mm margin at the trunk's acceleration limit, and the corrected
# lean fell earlier (3.91 s) than the uncorrected (4.79 s).
RESPONSE_RATIO = 1.5


def slow_trunk_factor(reaction_m: float, lever_m: float, height_m: float) -> float:
    """How many times wider than `size_scaled_margin` the corrector's margin must be for a trunk that answers
    slower than a humanoid's (`RESPONSE_RATIO`): max(1, sqrt(``reaction_m`` / ``lever_m``) / sqrt(``height_m`` /
    g) / `RESPONSE_RATIO`), ``reaction_m`` (m per rad/s^2) the ZMP's answer to the trunk's pitch acceleration,
    ``lever_m`` (m/rad) the CoM's static move per rad of it, ``height_m`` (m) the CoM's height. The ZMP runs on
    while the trunk builds up its turn, and first the other way (its reaction), for a time that grows as that
    response time; the margin has to cover the run. 1 where any of them is not positive."""
    if min(reaction_m, lever_m, height_m) <= 0:
        return 1.0
    return max(1.0, float(np.sqrt(reaction_m / lever_m) / np.sqrt(height_m / G) / RESPONSE_RATIO))


# share of the static CoM's distance inside the feet that the ZMP's answer to the trunk's acceleration may take up
REACTION_SHARE = 0.5
ROLL, PITCH = 0, 1  # δ's components about the forward and lateral axes (hip axes: `hip_axes`)


def reaction_per_accel(body: BodyModel, mover: RootMover, joints: np.ndarray) -> np.ndarray:
    """K (2, 3), m per rad/s^2: how far the ZMP moves (world x, y) when the root rotation δ (hip axes, as
    `RootMover` turns it) accelerates by 1 rad/s^2 from rest, the feet held: the robot's whole-body dynamics
    standing in ``joints`` (rad; not straight-kneed: a roll about the hips then asks the knees to bend at their
    singularity), its base placed by its feet. Turning the trunk back first pushes the ground's reaction forward:
    at the corrector's largest acceleration (`size_scaled_accel`) Atlas v5's ZMP moves 24.8 mm in its push's
    stance, livezmp_mini's 5.3. The roll's and pitch's columns (the forward and lateral axes: the corrector's turns
    for a lean sideways or forward) are filled; the yaw's, which barely moves the ZMP, is left zero. Both postures
    are placed by one `BasePlacer`, so on the same stance foot: placed each by a fresh one, a roll's lowered one
    foot by micrometres, the first posture stood on the other and the base jumped by the feet's distance apart
    (the OP3's roll column came out at 20 m per rad/s^2 for 2.5 mm). Zeros for a skeleton (its root is no robot's
    base)."""
    k = np.zeros((2, 3))
    if body.kind != "urdf":
        return k
    # rad: small enough for the motion's first order, large enough for the legs' IK tolerance
    _, _, k[:, [ROLL, PITCH]] = _first_order(body, mover, joints, [(np.eye(3)[a], None) for a in (ROLL, PITCH)], 1e-4)
    return k


def _first_order(body: BodyModel, mover: RootMover, joints: np.ndarray, moves: list, eps: float
                 ) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """The robot ``body`` standing in ``joints`` (rad), its base placed by its feet: its configuration q (base and
    joints), and for each move (δ (3,) rad, shift (3,) m or None: `RootMover.apply`'s, the feet held) of ``moves``
    the configuration moved by ``eps`` of it and the ZMP's answer (m, world x, y; zero where there is no ZMP) to
    accelerating by one unit of it per s^2 from rest. One `BasePlacer` places every configuration, so all stand on
    the same foot (`reaction_per_accel`)."""
    model, data, base, placer = body.model, body.model.createData(), len(body.base_channels), BasePlacer(body)
    q = np.concatenate([placer.update(joints), joints])
    rest = np.zeros(model.nv)
    at_rest = compute_zmp(model, data, q, rest, rest).zmp
    moved_qs, answers = [], np.zeros((2, len(moves)))
    for i, (delta, shift) in enumerate(moves):
        moved = mover.apply(q, eps * delta, 0.5, shift=None if shift is None else eps * shift)[base:]
        moved_qs.append(np.concatenate([placer.update(moved), moved]))
        zmp = compute_zmp(model, data, q, rest, (moved_qs[-1] - q) / eps).zmp
        if at_rest is not None and zmp is not None:
            answers[:, i] = zmp[:2] - at_rest[:2]
    return q, moved_qs, answers


# A trunk whose largest turn moves the static CoM less than this share of the corrector's margin is too short a
# lever, and the legs carry the pelvis (module docstring). Of the real robots of the held-out rounds that the
# scenarios stand (benchmarks/bench_any_humanoid.py), in the knees-bent stance, Alexbotmini's 15° move its CoM 0.08 of
# its 23 mm margin, Cassie's 0.21; every other's at least 0.60 (NimbRo-OP2X), and those stand corrected on the trunk
# alone. The legs' shift moves most of
# the robot's mass, and its acceleration pushes the ZMP back the more (legs_response's K: 25-40 mm per m/s^2 against
# the trunk's 2-25 mm per rad/s^2): taken up by every robot whose trunk ran out of range in a transient (an arm
# swing's), it cut iCub's corrected margins by up to 8.8 mm.
LEGS_BELOW = 0.5


def trunk_reach(body: BodyModel, mover: RootMover, q: np.ndarray, turn: float) -> float:
    """m: how far the static CoM's ground point moves when the root of ``body`` standing in ``q`` (base and joints,
    the base placed by the feet) is turned by ``turn`` (rad) about the hips' line, the farther of the two ways, the
    feet held (`RootMover`)."""
    model, data = body.model, body.model.createData()
    com = pin.centerOfMass(model, data, q)[:2].copy()
    return max(float(np.linalg.norm(pin.centerOfMass(model, data, mover.apply(q, np.array([0.0, sign * turn, 0.0]),
                                                                               0.5))[:2] - com))
               for sign in (1.0, -1.0))


def uses_legs(body: BodyModel, mover: RootMover, q: np.ndarray, turn: float, margin_m: float) -> bool:
    """Whether the corrector (margin ``margin_m``, m; largest pitch ``turn``, rad) carries the pelvis of ``body``
    standing in ``q`` (base and joints) with its legs: a robot whose trunk's largest turn moves its CoM less than
    `LEGS_BELOW` of the margin (`trunk_reach`)."""
    return body.kind == "urdf" and trunk_reach(body, mover, q, turn) < LEGS_BELOW * margin_m


def legs_response(body: BodyModel, mover: RootMover, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(S, K), each (2, 2): the static CoM's move (m per m) and the ZMP's answer (m per m/s^2, as
    `reaction_per_accel`) when the pelvis is carried horizontally (world x, y) over the feet by the legs
    (`RootMover.apply`'s ``shift``), the robot standing in ``joints`` (rad), its base placed by its feet: S is
    the legs' lever, the share of the robot's mass the shift carries (legs-only Alexbotmini: ~0.5); zeros for a
    skeleton (its legs turn at the thigh alone, they cannot carry its root)."""
    s = np.zeros((2, 2))
    if body.kind != "urdf":
        return s, np.zeros((2, 2))
    eps = 1e-5  # m: the motion's first order, well above the legs' IK tolerance
    q, moved, k = _first_order(body, mover, joints, [(np.zeros(3), np.eye(3)[axis]) for axis in range(2)], eps)
    model, data = body.model, body.model.createData()
    com = pin.centerOfMass(model, data, q)[:2].copy()
    for axis, q_moved in enumerate(moved):
        s[:, axis] = (pin.centerOfMass(model, data, q_moved)[:2] - com) / eps
    return s, k


def hips_height(body: BodyModel, q: np.ndarray) -> float:
    """m: the mean height of the hips (``correction.hips``) above the soles' lowest point, in the configuration
    ``q``: the lever of the legs leaning about the ankles (`OnlineCorrector`'s legs strategy turns the trunk's
    angular limits into the pelvis' by it)."""
    model, data = body.model, body.model.createData()
    pin.framesForwardKinematics(model, data, q)
    ground = min(float(sole[:, 2].min()) for sole in foot_soles(body, data).values())
    return max(float(np.mean([data.oMf[f].translation[2] for f in body.correction.hips.values()])) - ground, 0.0)


def _leg_root(body: BodyModel, side: str) -> int:
    """The top joint of a leg (Pinocchio id), whose subtree is the leg: from the hip's joint up the joints the
    leg's correction channels turn (a robot's hip pitch may hang below its hip yaw and roll)."""
    model = body.model
    legs = set(body.correction.legs[side])
    j = model.frames[body.correction.hips[side]].parentJoint
    while model.parents[j] > 0 and model.joints[model.parents[j]].idx_q in legs:
        j = model.parents[j]
    return j


class OnlineCorrector:
    """Causal corrector; call :meth:`step` once per analysed frame. ``margin_m`` (m): how far inside the support
    polygon it aims the ZMP (the live loop gives a robot its `size_scaled_margin`). Its state: the trunk's turn
    ``delta`` (rad, hip axes) and the pelvis' ``shift`` (m, world x, y; the legs strategy, module docstring),
    limited alike as one vector ``u`` = (delta, shift)."""

    def __init__(self, body: BodyModel, dt: float, limits: CorrectionLimits | None = None,
                 gain_per_s: float = GAIN_PER_S, relax_s: float = 2.0, max_accel_deg_s2: float = 500.0,
                 pivot_tau_s: float = 0.05, margin_m: float = MARGIN_M):
        self.body = body
        self.limits = replace(limits or CorrectionLimits(), margin_m=margin_m)
        self.dt = dt
        self.gain = min(1.0, gain_per_s * dt)
        self.relax = min(1.0, dt / relax_s)
        # the trunk's limits (rad); the pelvis' (m) follow in the standing posture (`prepare`)
        self.max_step = np.concatenate([np.full(3, np.radians(self.limits.max_rate_deg_s) * dt), np.zeros(2)])
        self.max_accel_step = np.concatenate([np.full(3, np.radians(max_accel_deg_s2) * dt * dt), np.zeros(2)])
        self.max_rot = np.concatenate([np.radians(np.asarray(self.limits.max_rotation_deg, dtype=float)),
                                       np.zeros(2)])
        self.pivot_alpha = min(1.0, dt / pivot_tau_s)
        self._damp = np.diag([1e-6, 1e-6, 1e-4])  # the gain's damping (m², per δ axis), made once
        self.mover = RootMover(body)
        self.reaction: np.ndarray | None = None  # (2, 5) `reaction_per_accel`, `legs_response`: `prepare`
        self._hips_h = 0.0  # m: `hips_height` in the standing posture (`prepare`)
        self.legs = np.zeros((2, 2))  # `legs_response`'s S: the CoM's move per m of the pelvis' shift
        self.data = body.model.createData()
        corr = body.correction
        self.leg_roots = [_leg_root(body, s) for s in ("left", "right")]
        actuated = set(corr.root_channels) if body.kind == "bvh" else set()
        actuated |= {c for cols in corr.legs.values() for c in cols}
        actuated -= {len(body.base_channels) + m.joint for m in body.mimics}  # they follow their parents' goals
        self.channels = np.array(sorted(actuated))
        self.reset()

    def reset(self) -> None:
        self.u = np.zeros(5)
        self.prev_step = np.zeros(5)
        self.w_left = 0.5
        self._pivot_rate = 0.0  # the pivot weight's last change (per frame)
        self._room = -np.inf  # m: the static CoM's distance inside the feet at the last frame
        self._last_offsets = np.zeros(self.body.nq)  # the IK's warm start

    @property
    def delta(self) -> np.ndarray:
        """(3,) rad: the trunk's turn (hip axes), a view of ``u``."""
        return self.u[:3]

    @property
    def shift(self) -> np.ndarray:
        """(2,) m: the pelvis' shift over the feet (world x, y), a view of ``u``."""
        return self.u[3:]

    def prepare(self, q: np.ndarray) -> None:
        """Measure the robot's own dynamics in the posture ``q`` (base and joints), once: the ZMP's answer to the
        trunk's acceleration (`reaction_per_accel`), the margin widened for a trunk slow to answer
        (`slow_trunk_factor`); for a robot whose trunk is too short a lever (`uses_legs`), the legs' lever and the
        ZMP's answer to the pelvis' acceleration (`legs_response`) and the pelvis' limits (the trunk's angular ones
        × `hips_height`). 4.5-10 ms of CPU for livezmp_mini, more than a 200 Hz cycle: the live loop calls it with the
        posture read at start-up, before its clock starts; not called, :meth:`update` calls it with its first
        frame's posture. :meth:`reset` keeps it."""
        joints = q[len(self.body.base_channels):]
        self.reaction = np.hstack([reaction_per_accel(self.body, self.mover, joints), np.zeros((2, 2))])
        pin.framesForwardKinematics(self.body.model, self.data, q)
        wider = slow_trunk_factor(float(np.linalg.norm(self.reaction[:, PITCH])),
                                  float(np.linalg.norm(self.sensitivity(q)[:, PITCH])), com_height(self.body, q))
        # the legs' strategy is for a trunk too short a lever, not a slow one: judged by the margin as given
        self._hips_h = h = hips_height(self.body, q)
        if uses_legs(self.body, self.mover, q, self.max_rot[PITCH], self.limits.margin_m):
            self.legs, self.reaction[:, 3:] = legs_response(self.body, self.mover, joints)
            self.max_rot[3:] = h * np.sin(self.max_rot[[PITCH, ROLL]])
            self.max_step[3:] = h * self.max_step[0]
            self.max_accel_step[3:] = h * self.max_accel_step[0]
        self.limits = replace(self.limits, margin_m=wider * self.limits.margin_m)

    def sensitivity(self, q: np.ndarray) -> np.ndarray:
        """S (2, 3): quasi-static ZMP (= CoM) shift per radian of δ, m/rad; ``data`` must
        hold the frame placements of ``q``."""
        model, data = self.body.model, self.data
        pin.centerOfMass(model, data, q)
        m = data.mass[0]
        legs_m = sum(data.mass[j] for j in self.leg_roots)
        # a subtree's CoM, data.com[j] (j > 0), is in its joint's own frame (Pinocchio 3-4): to the world's
        legs_mc = sum(data.mass[j] * data.oMi[j].act(data.com[j]) for j in self.leg_roots)
        m_up = m - legs_m
        c_up = (m * data.com[0] - legs_mc) / m_up
        corr = self.body.correction
        h_left, h_right = data.oMf[corr.hips["left"]].translation, data.oMf[corr.hips["right"]].translation
        pivot = self.w_left * h_left + (1 - self.w_left) * h_right
        r = c_up - pivot
        # δ is in hip axes (see RootMover): world rotation = H δ; CoM shift = ω × r = −skew(r) ω
        return -(m_up / m) * (pin.skew(r) @ hip_axes(h_left, h_right))[:2]

    def step(self, result: FrameResult, q_command: np.ndarray, cop: np.ndarray | None = None) -> OnlineCorrection:
        """Update δ from an analysed frame and return offsets for ``q_command`` (SI, the
        posture about to be sent, before correction). ``cop``: the feet's measured centre of
        pressure (m, the result's frame) of the same sample, where the link has foot sensors.
        :meth:`update` then :meth:`offsets`, which a caller short of time may run apart."""
        limited = self.update(result, cop)
        return OnlineCorrection(self.delta.copy(), self.offsets(q_command), limited)

    def update(self, result: FrameResult, cop: np.ndarray | None = None) -> bool:
        """The first part of :meth:`step`: δ (``delta``) and the pelvis' ``shift`` from an analysed frame (``cop``
        as there); whether a limit cut their step."""
        if self.reaction is None:
            self.prepare(result.q)
        pin.framesForwardKinematics(self.body.model, self.data, result.q)
        self.w_left += self._pivot_step({"left": 1.0, "right": 0.0}.get(result.support, 0.5))
        s = np.hstack([self.sensitivity(result.q), self.legs])
        com, polygon = result.com, result.polygon  # the robot's own: before the feet's CoP moves the result
        result = with_measured_cop(result, cop)
        target = zmp_target(result, self.limits.margin_m)
        if target is not None:
            err = target - result.zmp[:2]
            full = np.linalg.solve(s[:, :3].T @ s[:, :3] + self._damp, s[:, :3].T @ err)  # the turn that closes it
            want = self.u.copy()
            want[:3] += self.gain * full
            want[3:] += self.gain * self._legs_take(s[:, :3], full)
        else:
            want = self.u * (1 - self.relax)
            if result.zmp is not None and result.margin is not None and len(result.polygon) > 2:
                # relax only as far as the predicted ZMP keeps three margins: the hysteresis
                # stops a relax-correct limit cycle
                pred = result.zmp[:2] + s @ (want - self.u)
                if clamp_to_polygon(pred, result.polygon).margin < 3 * self.limits.margin_m:
                    want = self.u.copy()
        step = want - self.u
        lo, hi = self.prev_step - self.max_accel_step, self.prev_step + self.max_accel_step
        clipped = braked(clip(self._reaction_kept(clip(step, lo, hi), com, polygon), -self.max_step, self.max_step),
                         self.u, self.max_rot, self.max_accel_step)
        new = clip(self.u + clipped, -self.max_rot, self.max_rot)
        limited = bool((np.abs(new - want) > 1e-12).any())
        self.prev_step = new - self.u
        self.u = new
        return limited

    def _pivot_step(self, target: float) -> float:
        """The pivot weight's change this frame toward ``target`` (1 the left hip, 0 the right; `pivot_tau_s`'s
        first-order step), cut so that the root's move it makes stays within the pelvis' rate and acceleration (the
        trunk's × the hips' height, as the legs' shift's): the root turned by δ about another pivot stands
        elsewhere, (I − R(δ)) (h_left − h_right) per unit of weight, and the legs carry it there. AgiBot X1 on its
        foot meshes, its trunk turned 0.25 rad back and 0.11 rad rolled in ``lean``, was read as on its right foot
        alone (its left sole 0.9 mm into the floor): the pivot slid from between its hips to its right hip within
        50 ms, the root dropped 9 mm, its legs' goals turned at up to 60 rad/s^2, and its true ZMP left its feet by
        562 mm for 31 ms. ``data`` must hold the frame's placements."""
        step = self.pivot_alpha * (target - self.w_left)
        corr = self.body.correction
        h_left, h_right = self.data.oMf[corr.hips["left"]].translation, self.data.oMf[corr.hips["right"]].translation
        lever = float(np.linalg.norm((h_left - h_right) - pin.exp3(hip_axes(h_left, h_right) @ self.delta)
                                     @ (h_left - h_right)))  # m of the root's move per unit of weight
        if lever > 0.0:
            accel, rate = self._hips_h * np.array([self.max_accel_step[PITCH], self.max_step[PITCH]]) / lever
            step = float(clip(clip(step, self._pivot_rate - accel, self._pivot_rate + accel), -rate, rate))
        step = float(clip(self.w_left + step, 0.0, 1.0)) - self.w_left
        self._pivot_rate = step
        return step

    def _legs_take(self, s_trunk: np.ndarray, full: np.ndarray) -> np.ndarray:
        """(2,) m: the pelvis' shift that moves the CoM as far as the part of the trunk's turn ``full`` (rad, the
        change of δ that would close the ZMP's shortfall) beyond its range would have (``s_trunk`` (2, 3): the
        trunk's lever, m/rad); zeros while the trunk's range holds it, or where the legs carry no CoM (a
        skeleton)."""
        beyond = full - (clip(self.delta + full, -self.max_rot[:3], self.max_rot[:3]) - self.delta)
        if not beyond.any() or not self.legs.any():
            return np.zeros(2)
        return np.linalg.lstsq(self.legs, s_trunk @ beyond, rcond=None)[0]

    def _reaction_kept(self, step: np.ndarray, com: np.ndarray, polygon: np.ndarray) -> np.ndarray:
        """``step`` (``u``'s change this frame: rad, m) with its change from the last step, the trunk's and the
        pelvis' acceleration, cut so that the ZMP's answer to it (``reaction``: `reaction_per_accel`,
        `legs_response`) takes up at most `REACTION_SHARE` of the static CoM's distance inside the support
        polygon (m, ``com`` (3,) and ``polygon`` (k, 2) of the frame). A robot standing nearer its toes than the
        corrector's aim (a big robot's aim is wide: `size_scaled_margin`) is otherwise turned back at the full
        acceleration limit, whose answer can be wider than its distance to them: Atlas v5 in ``push`` stood 20 mm
        inside, its ZMP moved 24.8 mm forward and stayed past its toes for the 0.2 s the trunk took to
        accelerate, and it fell before it was pushed. Where the CoM is outside, nothing is cut."""
        if len(polygon) < 3:
            return step
        room = clamp_to_polygon(com[:2], polygon).margin
        nearing, self._room = room < self._room, room
        accel = step - self.prev_step
        moved = self.reaction @ accel / (self.dt * self.dt)
        if nearing or room <= 0 or clamp_to_polygon(com[:2] + moved, polygon).margin >= (1 - REACTION_SHARE) * room:
            return step
        lo, hi = 0.0, 1.0  # the margin is concave along the segment: bisect for the largest share that keeps it
        for _ in range(20):
            mid = 0.5 * (lo + hi)
            if clamp_to_polygon(com[:2] + mid * moved, polygon).margin >= (1 - REACTION_SHARE) * room:
                lo = mid
            else:
                hi = mid
        return self.prev_step + lo * accel

    def offsets(self, q_command: np.ndarray) -> np.ndarray:
        """The second part of :meth:`step`, the costlier (the legs' IK): offsets (nq,) of the corrector's channels
        for ``q_command`` (SI, the posture about to be sent, before correction) that turn the root by the present
        δ about the present pivot and carry it by the present shift, the feet kept in place."""
        offsets = np.zeros(self.body.nq)
        if self.u.any():  # the method, not np.any: its wrapper costs more than the test
            shift = np.array([*self.u[3:], 0.0]) if self.u[3:].any() else None
            q_new = self.mover.apply(q_command, self.u[:3], self.w_left, self._last_offsets, shift)
            offsets[self.channels] = q_new[self.channels] - q_command[self.channels]
        self._last_offsets = offsets
        return offsets


def braked(step: np.ndarray, u: np.ndarray, bound: np.ndarray, accel_step: np.ndarray) -> np.ndarray:
    """``step`` (per frame, rad or m: ``u``'s change) no faster than stops ``u`` at its ``bound`` (±, same units)
    within the acceleration limit ``accel_step`` (change of step per frame): |step| <= sqrt(2 a d), d the way left
    to the bound it moves toward. Clipped at its range without braking, the trunk stopped within one frame: THORMANG3
    (82 mm of ZMP per rad/s^2) reaching its 15° at speed put its true ZMP 440 mm behind its heels for 30 ms."""
    toward = np.sign(step)
    left = np.maximum(bound - toward * u, 0.0)
    return toward * np.minimum(np.abs(step), np.sqrt(2.0 * accel_step * left))


def with_measured_cop(result: FrameResult, cop: np.ndarray | None) -> FrameResult:
    """``result`` with its ZMP moved by the measured CoP's disagreement with it (module
    docstring): ZMP + (CoP − clamped ZMP), clamped and judged again; ``result`` itself
    without a CoP, a ZMP or a support polygon."""
    if cop is None or result.zmp is None or result.clamped is None or len(result.polygon) < 3:
        return result
    zmp = result.zmp.copy()
    zmp[:2] += cop[:2] - result.clamped[:2]
    c = clamp_to_polygon(zmp[:2], result.polygon)
    clamped = np.array((*c.point, result.zmp[2]))
    return replace(result, zmp=zmp, clamped=clamped, margin=c.margin, inside=c.inside)
