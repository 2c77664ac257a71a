"""Scenarios: a humanoid's goal joint angles as functions of time, and the disturbances that go with them.

A scenario is the robot's base command, what it is asked to do; a live loop's balance
corrector adds its offsets to the leg joints on top. Scenarios work for any humanoid,
whatever its joint names, order and the signs of its URDF axes: the joints they move are
found from the kinematic tree (`joint_roles`: each leg is the chain from the trunk to a
foot, its hip, knee and ankle the first, middle and last joints turning about the
lateral axis (a hip pitch up to 46° off it, above the other two, Unitree H2's: that leg
then bends by the legs' IK, `Poser._bent_feet`), its hip and ankle roll the first and last about the forward axis; each
arm the chain to a hand that no other limb shares, its shoulder the first joints turning
about the lateral axis and about the axis that turns the upper arm out to the side
(`_abduction`), its elbow the next that bends the arm), and
postures are rotations about world axes in the zero posture, turned into joint angles
through each joint's own axis as the model gives it. Role names follow OP3's
({l,r}_{hip_pitch, knee, ank_pitch, hip_roll, ank_roll, sho_pitch, sho_roll, el}).

Standing posture: knees bent, hip −θ, knee +2θ, ankle −θ about the lateral axis (y,
left), which keeps each sole parallel to the pelvis (flat on the ground) and the legs
away from their straight-knee singularity; a knee whose limits let it bend only the other way (its shank forward)
bends so, hip +θ, knee −2θ, ankle +θ (`Poser._knee_bend`) (soles not level and on one plane in the zero
posture, as Wolfgang-OP's cleats, are first turned level at the ankles and the legs
re-solved to put both on the floor: `Poser.on_feet`); arms hang down, turned out a little by the
shoulder roll (OP3's zero posture holds them out sideways). θ is 0.3 rad, or the first of `FLEXIONS` at which the
scenario's leg goals keep within their limits (the stance's ankle and the lean's share one range), then 0, legs
straight, where a knee's limits let it bend neither way.

Angles in rad, times in s, world frame z up, x forward, y left. ``livezmp run --scenario``
sends them to a robot; ``livezmp sim``/``demo`` also play them on the simulated humanoid,
which applies their pushes (:class:`sim_devices.scenario_player.ScenarioPlayer`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.optimize import brentq

from livezmp.balance.support import clamp_to_polygon, support_polygon
from livezmp.balance.zmp import compute_zmp
from livezmp.correct.limits import CorrectionLimits
from livezmp.correct.online import hips_height, size_scaled_margin, uses_legs
from livezmp.correct.root_motion import RootMover
from livezmp.errors import InputError
from livezmp.live.config import SafetyConfig
from livezmp.model.base_placement import BasePlacer
from livezmp.model.body import BodyModel, foot_soles
from livezmp.model.mimic import follow
from livezmp.model.trajectory_csv import read_joint_csv
from livezmp.model.urdf_body import ALIGNED, TILTED, leg_joints


class BeyondLimits(InputError):
    """A scenario's stance or goals take a leg joint beyond its limits (`Poser.standing`, `_check_limits`)."""


SIDES = ("l", "r")
G = 9.81  # m/s^2
X, Y, Z = 0, 1, 2


@dataclass(frozen=True)
class Push:
    """A horizontal force ``force`` (N, world x and y) at ``height`` (m above the ground),
    applied from ``start`` (s) for ``duration`` (s); it grows from zero over its first
    ``rise_s`` (s) and dies away over its last ``rise_s`` (half a cosine each; 0: a step),
    as a hand leaning on the robot does."""

    force: tuple[float, float]
    height: float
    start: float
    duration: float
    rise_s: float = 0.0

    def __post_init__(self) -> None:
        values = (*self.force, self.height, self.start, self.duration, self.rise_s)
        if len(self.force) != 2 or not all(math.isfinite(v) for v in values):
            raise InputError(f"push: force must be two finite numbers (N) and height, start, duration, rise_s "
                             f"finite, got force={self.force!r} height={self.height!r} start={self.start!r} "
                             f"duration={self.duration!r} rise_s={self.rise_s!r}")
        if self.height < 0 or self.duration <= 0 or not 0 <= 2 * self.rise_s <= self.duration:
            raise InputError(f"push: height must be >= 0 m, duration > 0 s and rise_s within [0, duration / 2], "
                             f"got {self.height} m, {self.duration} s, {self.rise_s} s")

    def share(self, t: float) -> float:
        """The fraction (0-1) of ``force`` acting at time ``t`` (s)."""
        if not self.start <= t < self.start + self.duration:
            return 0.0
        if self.rise_s <= 0:
            return 1.0
        return float(min(smooth_step((t - self.start) / self.rise_s),
                         smooth_step((self.start + self.duration - t) / self.rise_s)))


@dataclass(frozen=True)
class Scenario:
    """``goals(t)``: joint goal angles (rad, ``body.joint_names`` order) at scenario time
    t (s); ``duration`` (s); ``pushes`` in scenario time; ``slope`` (rad): the ground it is
    played on rises ahead of the robot by this angle (a simulator's ground; on a robot,
    where to stand it); ``edge``: (side, fraction) when that foot stands rolled over a step's
    edge, borne by the part of its sole that ``fraction`` of its width spans from its low edge,
    the other foot flat (a simulator's ground)."""

    name: str
    goals: Callable[[float], np.ndarray]
    duration: float
    pushes: tuple[Push, ...] = ()
    slope: float = 0.0
    edge: tuple[str, float] | None = None




def joint_axes(body: BodyModel) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(world axis, world origin) of each actuated joint in the zero posture."""
    model = body.model
    data = model.createData()
    pin.computeJointJacobians(model, data, np.zeros(model.nq))
    axis, origin = {}, {}
    for name in body.joint_names:
        j = model.getJointId(name)
        axis[name] = data.J[3:, model.joints[j].idx_v].copy()
        origin[name] = data.oMi[j].translation.copy()
    return axis, origin


def _limb(model: pin.Model, frame: int, names: set[str]) -> list[str]:
    """Actuated joints from the trunk down to ``frame``, top first."""
    out = []
    j = model.frames[frame].parentJoint
    while j > 0:
        if model.names[j] in names:
            out.append(model.names[j])
        j = model.parents[j]
    return out[::-1]


def leg_chains(body: BodyModel) -> dict[str, list[str]]:
    """Foot side -> the actuated joints from the trunk down to that foot that the other foot's chain does not
    share (a waist above both legs is the trunk's), top first."""
    names = set(body.joint_names)
    legs = leg_joints(body.model, {side: foot.frame_id for side, foot in body.feet.items()})
    return {side: [body.model.names[j] for j in chain if body.model.names[j] in names] for side, chain in legs.items()}


def joint_roles(body: BodyModel) -> dict[str, str]:
    """Role (``l_hip_pitch``, ``r_knee``, ``l_sho_roll``...) -> joint name, from the kinematic tree
    (module docstring). Roles not found are left out (`Poser.index` names what is missing)."""
    return _roles_and_arms(body)[0]


ANKLE_SHARE = 0.25  # an ankle pitch lies in this lowest share of its leg, hip to sole (Bolt's knee, at 0.5, is none)
SHOULDER_ALIGNED = 0.85  # |cos|: a shoulder's pitch or roll may be turned up to 32° off the world axis (H1: 25°)


def _about(axis: dict[str, np.ndarray], joint: str, k: int, aligned: float = ALIGNED) -> bool:
    """Whether ``joint`` turns about world axis ``k`` (zero posture) within ``aligned`` (|cos|); False for a
    joint not in ``axis``."""
    return joint in axis and abs(float(axis[joint][k])) >= aligned


def _roles_and_arms(body: BodyModel) -> tuple[dict[str, str], dict[str, Arm]]:
    """`joint_roles` and the arms (`_arms`) they came from, from one pass over the tree."""
    axis, origin = joint_axes(body)
    roles: dict[str, str] = {}
    chains = leg_chains(body)
    followers = {body.joint_names[m.joint] for m in body.mimics}  # never moved on their own: no role
    for side, full in chains.items():
        chain = [n for n in full if n not in followers]
        pitch = [n for n in chain if _about(axis, n, Y)]
        if len(pitch) == 2:  # a hip pitch turned off the lateral axis above the knee and ankle (H2's, 30°)
            hip = next((n for n in chain[:chain.index(pitch[0])] if _about(axis, n, Y, TILTED)), None)
            pitch = [hip, *pitch] if hip else pitch
        if len(pitch) >= 3:
            hip, ankle = pitch[0], pitch[-1]
            middle = 0.5 * (origin[hip][Z] + origin[ankle][Z])
            knee = min(pitch[1:-1], key=lambda n: abs(origin[n][Z] - middle))
            roles.update({f"{side[0]}_hip_pitch": hip, f"{side[0]}_knee": knee, f"{side[0]}_ank_pitch": ankle})
        roll = [n for n in chain if _about(axis, n, X)]
        if len(roll) >= 2:
            roles.update({f"{side[0]}_hip_roll": roll[0], f"{side[0]}_ank_roll": roll[-1]})
    found = _arms(body, set().union(*chains.values()), {n: a for n, a in axis.items() if n not in followers},
                  origin)
    for s, arm in found.items():
        roles.update({f"{s}_{role}": joint for role, joint in
                      (("sho_pitch", arm.pitch), ("sho_roll", arm.roll), ("el", arm.elbow)) if joint})
    return roles, found


@dataclass(frozen=True)
class Arm:
    """An arm found in the tree: its shoulder pitch and roll joints and its elbow (None where it has none), and
    ``upper``: the world point (zero posture, m) the upper arm reaches from the shoulder (the elbow, else the
    centre of mass of the arm's last link), ``upper_at``: that point as (Pinocchio joint id, m in its frame)."""

    pitch: str | None
    roll: str | None
    elbow: str | None
    upper: np.ndarray
    upper_at: tuple[int, np.ndarray]


def _arms(body: BodyModel, legs: set[str], axis: dict[str, np.ndarray],
          origin: dict[str, np.ndarray]) -> dict[str, Arm]:
    """Side ("l", "r") -> its `Arm`: the chain from the trunk to a leaf link on that side that no leg and no
    other side shares, with a joint about the lateral (pitch) or forward (roll) axis (within `SHOULDER_ALIGNED`:
    Unitree's H1 and G1 mount the shoulder pitch 25° and 16° off the lateral axis); its elbow the first joint
    after the shoulder's whose origin lies a fifth of the way or more from the shoulder to the hand. ``axis``,
    ``origin``: `joint_axes` (a joint left out of ``axis``, a mimic joint, plays no role)."""
    model, names = body.model, set(body.joint_names)
    children = np.zeros(model.njoints, dtype=int)
    for j in range(1, model.njoints):
        children[model.parents[j]] += 1
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(model.nq))
    side_of: dict[str, set[int]] = {}  # joint -> the sides (-1 right, 0 middle, +1 left) of the leaves below it
    chains = []
    for f in range(model.nframes):
        if model.frames[f].type != pin.FrameType.BODY or children[model.frames[f].parentJoint]:
            continue
        chain = _limb(model, f, names)
        if not chain or set(chain) & legs:
            continue
        y = float(data.oMf[f].translation[Y])
        sign = 0 if abs(y) < 0.01 else int(np.sign(y))
        j = model.frames[f].parentJoint
        chains.append((sign, chain, j))
        for n in chain:
            side_of.setdefault(n, set()).add(sign)
    found: dict[str, Arm] = {}
    for sign, chain, j in chains:
        hand = data.oMi[j].act(model.inertias[j].lever)
        side = {1: "l", -1: "r"}.get(sign)
        own = [n for n in chain if side_of[n] == {sign}]  # below the trunk, on one side only
        if side is None or side in found or not own:
            continue
        pitch = next((n for n in own if _about(axis, n, Y, SHOULDER_ALIGNED)), None)
        shoulder_at = origin[own[0]]
        bend = next((origin[n] for n in own if np.linalg.norm(origin[n] - shoulder_at)
                     >= 0.4 * np.linalg.norm(hand - shoulder_at)), hand)  # the upper arm's end: at the elbow
        out = _abduction(bend - shoulder_at)
        roll = next((n for n in own if n in axis and abs(float(axis[n] @ out)) >= SHOULDER_ALIGNED), None)
        if pitch is None and roll is None:
            continue
        shoulder = [n for n in (pitch, roll) if n]
        start = origin[shoulder[-1] if roll is None else roll]
        reach = float(np.linalg.norm(hand - start))
        after = own[max(own.index(n) for n in shoulder) + 1:]
        # the elbow bends the arm: a twist about the upper arm (NAO's elbow yaw, at its elbow) is not it
        elbow = next((n for n in after if n in axis and np.linalg.norm(origin[n] - start) >= 0.2 * reach
                      and abs(float(axis[n] @ (origin[n] - start))) < SHOULDER_ALIGNED * np.linalg.norm(
                          origin[n] - start)), None)
        at = (model.getJointId(elbow), np.zeros(3)) if elbow else (j, model.inertias[j].lever.copy())
        found[side] = Arm(pitch, roll, elbow, origin[elbow] if elbow else hand, at)
    return found


def _abduction(arm: np.ndarray) -> np.ndarray:
    """World axis (unit, zero posture) about which a shoulder roll turns an arm pointing along ``arm`` (world
    vector) out to the side: perpendicular to the lateral axis and to the arm's course in the sagittal plane
    (forward, x, for an arm hanging down; vertical, z, for an arm held forward, NAO's zero posture, whose elbow
    yaw turns about x as a twist of the forearm), forward for an arm held out sideways (OP3's zero posture)."""
    sagittal = np.array([arm[X], 0.0, arm[Z]])
    if np.linalg.norm(sagittal) < 0.3 * np.linalg.norm(arm):
        return np.array([1.0, 0.0, 0.0])
    out = np.cross([0.0, 1.0, 0.0], sagittal)
    return out / np.linalg.norm(out)


FLAT = 1e-6  # rad, m: soles turned or at heights this far apart in the zero posture are not flat on one plane


def soles_flat(body: BodyModel) -> bool:
    """Whether, in the zero posture, every sole frame is level (z up, within `FLAT` rad) and every sole's lowest
    corner is at the same height (within `FLAT` m): the knees-bent stance, which keeps each sole parallel to the
    pelvis, then stands both flat on the floor with the trunk upright."""
    model, data = body.model, body.model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(model.nq))
    tilts = [math.acos(min(1.0, float(data.oMf[f.frame_id].rotation[Z, Z]))) for f in body.feet.values()]
    heights = [float(sole[:, Z].min()) for sole in foot_soles(body, data).values()]
    return max(tilts) <= FLAT and max(heights) - min(heights) <= FLAT


def _levelled(body: BodyModel, targets: dict[str, list[pin.SE3]]) -> dict[str, list[pin.SE3]]:
    """Foot frame placements ``targets`` (`RootMover.feet_of`) turned level about their origins, their headings
    kept, and moved up or down so that every sole's bottom is at their mean height."""
    out, bottoms = {}, {}
    for side, (pose, *rest) in targets.items():
        level = pin.rpy.rpyToMatrix(0.0, 0.0, math.atan2(pose.rotation[Y, X], pose.rotation[X, X]))
        out[side] = [pin.SE3(level, pose.translation.copy()), *rest]
        bottoms[side] = pose.translation[Z] + float(body.feet[side].sole_local[:, Z].min())
    mean = float(np.mean(list(bottoms.values())))
    for side, (pose, *_) in out.items():
        pose.translation[Z] += mean - bottoms[side]
    return out


class Poser:
    """Joint-angle vectors from rotations about world axes, for one body (joints by `joint_roles`)."""

    def __init__(self, body: BodyModel):
        self.body = body
        self.names = list(body.joint_names)
        self.axis, self.origin = joint_axes(body)
        self.roles, self.arms = _roles_and_arms(body)
        self._data = body.model.createData()
        legs = {c for cols in body.correction.legs.values() for c in cols}
        base = len(body.base_channels)
        # the legs' postures are re-solved where a mimic joint is on a leg (so the feet go where they were asked)
        # or the soles do not lie flat on one plane in the zero posture (so they are put there: `on_feet`)
        self.level = not soles_flat(body)
        # legs whose hip pitch turns off the lateral axis (`TILTED`) bend by the legs' IK (`_bent_feet`)
        self.tilted = {s for s in SIDES if f"{s}_hip_pitch" in self.roles
                       and not _about(self.axis, self.roles[f"{s}_hip_pitch"], Y)}
        self.mover = (RootMover(body, ik_iterations=100, ik_tolerance=1e-10)
                      if self.level or self.tilted or any({base + m.joint, base + m.parent} & legs for m in body.mimics)
                      else None)
        self.leg_index = np.array(sorted(legs), dtype=int) - base
        self._last: tuple[np.ndarray, np.ndarray] | None = None  # (asked, solved) configurations of on_feet
        self.bends = {s: self._knee_bend(s) for s in SIDES if f"{s}_knee" in self.roles}

    def _knee_bend(self, side: str) -> float:
        """+1 where the knee of leg ``side`` ("l", "r") may flex by `KNEE_REACH` rad within its limits the way
        that takes its foot back (about the world's left, y), −1 where only the other way (a knee that bends its
        shank forward: Poppy's file gives its left knee the right's range, −0.06..2.34 rad, its axis the same),
        0 where neither (`make_scenario` then stands it straight after the stances of `FLEXIONS`)."""
        knee = self.unit(f"{side}_knee", Y)
        i = int(np.flatnonzero(knee)[0])
        model = self.body.model
        lower, upper = (limits[-len(self.names):][i] for limits in (model.lowerPositionLimit, model.upperPositionLimit))
        for sign in (1.0, -1.0):
            if lower - 1e-9 <= sign * KNEE_REACH * knee[i] <= upper + 1e-9:
                return sign
        return 0.0

    def index(self, role: str) -> int:
        """Index (in ``body.joint_names``) of the joint that plays ``role``; InputError if none does."""
        if role not in self.roles:
            self._check_ankles(role)
            need = ("an arm on each side: a chain from the trunk to a hand with a shoulder joint about the lateral "
                    "axis" if "sho" in role or role.endswith("_el") else "two legs: hip, knee and ankle joints "
                    "about the lateral axis, and hip and ankle joints about the forward axis")
            raise InputError(f"{self.body.model.name}: found no {role} in its kinematic tree (this scenario needs "
                             f"{need}){self._leg_offsets(role)}")
        return self.names.index(self.roles[role])

    def _check_ankles(self, role: str) -> None:
        """InputError (one line) for a leg's pitch role not found where that leg has no joint about the lateral axis
        (within `TILTED`) in its lowest `ANKLE_SHARE` (hip to sole): its foot then turns with its shank and stands on
        a point or an edge (Bolt's: hip abduction, hip and knee flexion, a ball foot), and on two such feet no robot
        stands still, nothing holds it fore-aft: no balance scenario is played on it."""
        side = {"l": "left", "r": "right"}.get(role[0])
        if side not in self.body.feet or role[2:] not in ("hip_pitch", "knee", "ank_pitch"):
            return
        chain = leg_chains(self.body)[side]
        pitch = [n for n in chain if _about(self.axis, n, Y, TILTED)]
        if not pitch:  # no leg that bends fore and aft at all: `index` says what a leg needs
            return
        data = self.body.model.createData()
        pin.framesForwardKinematics(self.body.model, data, np.zeros(self.body.model.nq))
        sole = float(data.oMf[self.body.feet[side].frame_id].translation[Z])
        reach = ANKLE_SHARE * (self.origin[chain[0]][Z] - sole)
        if not any(self.origin[n][Z] - sole <= reach for n in pitch):
            raise InputError(f"{self.body.model.name}: its {side} leg turns about the lateral axis at "
                             f"{len(pitch)} joint{'s' * (len(pitch) != 1)} ({', '.join(pitch)}), none at "
                             "its ankle: its foot turns with its shank and stands on a point or an edge, and on two "
                             "such feet a robot cannot stand still (nothing holds it fore-aft)")

    def _leg_offsets(self, role: str) -> str:
        """For a leg's pitch or roll role not found: how far each of that leg's joints turns off the world axis
        the role needs (GR2's hip pitch, 30° off the lateral axis), as ``; leg joints off the lateral axis:
        NAME 30°, ...``; "" for other roles."""
        side = {"l": "left", "r": "right"}.get(role[0])
        k = {"hip_pitch": Y, "knee": Y, "ank_pitch": Y, "hip_roll": X, "ank_roll": X}.get(role[2:])
        if side is None or k is None or side not in self.body.feet:
            return ""
        chain = [n for n in leg_chains(self.body)[side] if n in self.axis]
        off = ", ".join(f"{n} {np.degrees(np.arccos(min(1.0, abs(float(self.axis[n][k]))))):.0f}°" for n in chain)
        return f"; {side} leg joints off the {'lateral' if k == Y else 'forward'} axis: {off}"

    def unit(self, role: str, world_axis: int) -> np.ndarray:
        """Joint vector that turns the joint of ``role`` by +1 rad about the world axis (0 x, 1 y, 2 z)."""
        i = self.index(role)
        name = self.roles[role]
        along = float(self.axis[name][world_axis])
        if abs(along) < (SHOULDER_ALIGNED if "_sho_" in role else TILTED if role.endswith("hip_pitch") else ALIGNED):
            raise InputError(f"{self.body.model.name}: joint {name!r} turns about {np.round(self.axis[name], 3)}, "
                             f"not the world {'xyz'[world_axis]} axis this scenario needs")
        out = np.zeros(len(self.names))
        out[i] = 1.0 / along
        return out

    def legs_flexed(self, angle: float, sides: tuple[str, ...] = SIDES) -> np.ndarray:
        """Legs ("l", "r") bent by ``angle``: hip −θ, knee +2θ, ankle −θ about y (each sole
        stays parallel to the pelvis), the feet then kept where that puts them (`on_feet`); a leg whose hip
        pitch turns off the lateral axis is solved to put its foot where that bend about y would (`_bent_feet`)."""
        base = self.soles_levelled() if self.level else np.zeros(len(self.names))
        out = base.copy()
        for s in sides:  # a tilted hip's share, turned by 1 / its axis' y: the IK's start near the bent knee
            out += angle * (self.bends.get(s) or 1.0) * (-self.unit(f"{s}_hip_pitch", Y) + 2 * self.unit(f"{s}_knee", Y)
                                                     - self.unit(f"{s}_ank_pitch", Y))
        return self.on_feet(out, self._bent_feet(base, angle, [s for s in sides if s in self.tilted]))

    def _bent_feet(self, joints: np.ndarray, angle: float, sides: list[str]) -> dict[str, list[pin.SE3]]:
        """Foot side -> its frames' placements (`RootMover.feet_of`) for each leg of ``sides`` bent by ``angle``
        about the lateral axis from the posture ``joints`` (rad): the thigh turned −θ about y at the hip pitch's
        origin, the shank +θ, the foot kept parallel to the pelvis, moved as its ankle moves (zero-posture
        origins). The bend the hip, knee and ankle pitch give where all three turn about y; a hip pitch turned
        off it (Unitree H2's, 30° about the forward axis) would also yaw the leg: the legs' IK takes the
        difference up in the hip's other joints."""
        if not sides:
            return {}
        feet = self.mover.feet_of(np.concatenate([np.zeros(len(self.body.base_channels)), joints]))
        thigh, shank = pin.rpy.rpyToMatrix(0.0, -angle, 0.0), pin.rpy.rpyToMatrix(0.0, angle, 0.0)
        out = {}
        for s in sides:
            hip, knee, ankle = (self.origin[self.roles[f"{s}_{r}"]] for r in ("hip_pitch", "knee", "ank_pitch"))
            turns = (thigh, shank) if self.bends.get(s, 1.0) >= 0 else (shank, thigh)  # a knee bent the other way
            bent_knee = hip + turns[0] @ (knee - hip)
            moved = bent_knee + turns[1] @ (ankle - knee) - ankle
            side = next(side for side in feet if side[0] == s)
            out[side] = [pin.SE3(pose.rotation, pose.translation + moved) for pose in feet[side]]
        return out

    def soles_levelled(self) -> np.ndarray:
        """Ankle pitch and roll (rad) that turn each sole level, the trunk upright, from the zero posture: a sole
        whose upward normal is n turns level by a = atan2(−n_x, √(n_y² + n_z²)) about y after b = atan2(n_y, n_z)
        about x (Ry(a) Rx(b) n = z, the ankle pitch above the roll; `on_feet` solves what that leaves)."""
        model, data = self.body.model, self._data
        pin.framesForwardKinematics(model, data, np.zeros(model.nq))
        out = np.zeros(len(self.names))
        for side, foot in self.body.feet.items():
            n = data.oMf[foot.frame_id].rotation[:, Z]
            out += math.atan2(-n[X], math.hypot(n[Y], n[Z])) * self.unit(f"{side[0]}_ank_pitch", Y)
            if f"{side[0]}_ank_roll" in self.roles:
                out += math.atan2(n[Y], n[Z]) * self.unit(f"{side[0]}_ank_roll", X)
        return out

    def on_feet(self, joints: np.ndarray, feet: dict[str, list[pin.SE3]] | None = None) -> np.ndarray:
        """``joints`` (rad) with the legs' joints re-solved so that, with every mimic joint following its
        parent, each foot is where ``joints`` put it relative to the trunk (its joints taken as they are), and,
        where the soles do not lie flat on one plane in the zero posture (`soles_flat`: Wolfgang-OP's cleats
        lie 15° from the pelvis' level, its right foot's 1.3° rolled and 0.9 mm lower), each sole then turned
        level about its frame's origin (its heading kept) and both raised or lowered to their mean height, so
        that with the trunk upright both stand flat on the floor; ``joints`` itself for a robot with neither
        (`RootMover.place_feet`: a follower's Jacobian column folded into its parent's). ``feet``: foot side ->
        its frames' placements, where those feet go instead (`_bent_feet`)."""
        if self.mover is None:
            return joints
        asked = np.concatenate([np.zeros(len(self.body.base_channels)), joints])
        start = asked
        if self._last is not None:  # warm start: the last solution moved as the legs' ask moved (squat: each cycle)
            start = self._last[1] + asked - self._last[0]
        targets = {**self.mover.feet_of(asked), **(feet or {})}
        solved = self.mover.place_feet(start, _levelled(self.body, targets) if self.level else targets)
        self._last = asked, solved
        out = np.array(joints, dtype=float)
        out[self.leg_index] = solved[len(asked) - len(joints):][self.leg_index]
        return out

    def ankles_lean(self, angle: float) -> np.ndarray:
        """Both ankles turned so that, feet flat, the body leans forward by ``angle`` (rad)."""
        return -angle * (self.unit("l_ank_pitch", Y) + self.unit("r_ank_pitch", Y))

    def arms_down(self, out_angle: float) -> np.ndarray:
        """Shoulder rolls that make each upper arm hang down, ``out_angle`` rad away from the body
        (arms without a shoulder roll, and a robot without arms, stay as they are), after the shoulder pitch
        has brought down an upper arm held more than 45° off down in the sagittal plane (`_pitch_down`: NAO's
        zero posture holds the arms forward). A mimic joint that follows
        the roll moves the upper arm with it: the roll is then solved (secant steps) so that the arm hangs
        down with its followers where their parents put them."""
        out = np.zeros(len(self.names))
        for s, lateral in (("l", 1.0), ("r", -1.0)):
            arm = self.arms.get(s)
            if arm is None or arm.roll is None:
                continue
            pitched = self._pitch_down(arm)
            i = self.names.index(arm.roll)
            a = self._axis_at(arm.roll, pitched)
            target = np.array([0.0, lateral * np.sin(out_angle), -np.cos(out_angle)])
            target -= (target @ a) * a

            def miss(roll: float, arm: Arm = arm, i: int = i, a: np.ndarray = a, target: np.ndarray = target,
                     pitched: np.ndarray = pitched) -> float:
                """rad about the roll's axis from the upper arm to the target, rolled by ``roll``."""
                d = self._upper_arm(arm, i, roll, pitched)
                d -= (d @ a) * a
                return float(np.arctan2(a @ np.cross(d, target), d @ target))

            # without a follower miss(θ) = miss(0) − θ: the first step is exact
            x0, e0 = 0.0, miss(0.0)
            x1 = e0
            e1 = miss(x1)
            for _ in range(30):
                if abs(e1) < 1e-12 or e1 == e0:
                    break
                x0, e0, x1 = x1, e1, x1 - e1 * (x1 - x0) / (e1 - e0)
                e1 = miss(x1)
            out += pitched
            out[i] = x1
        return out

    def _pitch_down(self, arm: Arm) -> np.ndarray:
        """Joint vector (zeros but the shoulder pitch) that turns the upper arm, seen in the sagittal plane,
        straight down; zeros if the arm has no pitch, already hangs within 45° of down, or lies mostly across
        the body (an arm held out sideways, OP3's, is brought down by its roll alone)."""
        out = np.zeros(len(self.names))
        if arm.pitch is None:
            return out
        a = self.axis[arm.pitch]
        d = arm.upper - self.origin[arm.pitch]
        flat = d - (d @ a) * a
        down = np.array([0.0, 0.0, -1.0]) - a[Z] * a
        turn = float(np.arctan2(a @ np.cross(flat, down), flat @ down))
        if np.linalg.norm(flat) >= 0.5 * np.linalg.norm(d) and abs(turn) > np.pi / 4:
            out[self.names.index(arm.pitch)] = turn
        return out

    def _axis_at(self, name: str, joints: np.ndarray) -> np.ndarray:
        """World axis of joint ``name`` in the posture ``joints`` (rad, base at the origin)."""
        model = self.body.model
        pin.computeJointJacobians(model, self._data, np.concatenate(
            [np.zeros(model.nq - len(joints)), follow(joints, self.body.mimics)]))
        return self._data.J[3:, model.joints[model.getJointId(name)].idx_v].copy()

    def _upper_arm(self, arm: Arm, i: int, roll: float, joints: np.ndarray) -> np.ndarray:
        """World vector (m) from the shoulder roll's origin to the upper arm's end, in the posture ``joints``
        (rad) with the roll (index ``i``) at ``roll`` rad and the mimic joints following their parents."""
        joints = joints.copy()
        joints[i] = roll
        q = np.concatenate([np.zeros(self.body.model.nq - len(joints)), follow(joints, self.body.mimics)])
        pin.forwardKinematics(self.body.model, self._data, q)
        j, point = arm.upper_at
        return self._data.oMi[j].act(point) - self._data.oMi[self.body.model.getJointId(arm.roll)].translation

    def standing(self, flexion: float = 0.3, arm_out: float = 0.1) -> np.ndarray:
        """The standing posture (see module docstring), within the joints' limits: a leg joint it would put
        beyond them is refused (InputError: the knees-bent stance is what every scenario stands on; a knee
        bends the way its limits let it, `_knee_bend`), any other joint is held at its limit (NAO's elbow roll, whose
        limits leave out its zero)."""
        q = self.legs_flexed(flexion) + self.arms_down(arm_out)
        model = self.body.model
        lower, upper = model.lowerPositionLimit[-len(q):], model.upperPositionLimit[-len(q):]
        for i in self.leg_index:
            if not lower[i] - 1e-9 <= q[i] <= upper[i] + 1e-9:
                raise BeyondLimits(f"{model.name}: standing with {'bent knees' if flexion else 'straight legs'} "
                                   f"needs leg joint {self.names[i]!r} at {q[i]:.2f} rad, outside its limits "
                                   f"[{lower[i]:.2f}, {upper[i]:.2f}] (each knee bent the way its limits let it)")
        return np.clip(q, lower, upper)


def smooth_step(x: np.ndarray | float) -> np.ndarray | float:
    """0 → 1 over x in [0, 1] with zero slope at both ends (half a cosine)."""
    if isinstance(x, float):  # a scenario's goals at one time, every loop cycle: no numpy scalar round trip
        return 0.5 - 0.5 * math.cos(math.pi * min(max(x, 0.0), 1.0))
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))


def stand(body: BodyModel, duration: float = 3.0, flexion: float = 0.3) -> Scenario:
    """Stand still in the standing posture."""
    q = Poser(body).standing(flexion)
    return Scenario("stand", lambda t: q.copy(), duration)


def standing_support(body: BodyModel, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(CoM (3,), support polygon of both soles (k, 2)), m, for the robot standing still on both
    feet in ``joints`` (its base placed by the feet; its mimic joints where their parents put them, as the goals
    sent put them)."""
    joints = follow(joints, body.mimics)
    q = np.concatenate([BasePlacer(body).update(joints), joints])
    data = body.model.createData()
    pin.centerOfMass(body.model, data, q)
    pin.framesForwardKinematics(body.model, data, q)
    soles = foot_soles(body, data)
    return data.com[0].copy(), support_polygon(soles["left"], soles["right"], "double")


def static_margin(body: BodyModel, joints: np.ndarray) -> float:
    """Signed distance (m, + inside) of the CoM's ground projection to the support
    polygon of both soles, for the robot standing still on both feet in ``joints``."""
    com, poly = standing_support(body, joints)
    return clamp_to_polygon(com[:2], poly).margin


def lean_angle(body: BodyModel, beyond: float, flexion: float = 0.3) -> float:
    """The forward lean at the ankles (rad) that puts the static CoM ``beyond`` (m) past
    the toes (negative: that far inside), from the standing posture."""
    poser = Poser(body)
    stood = poser.standing(flexion)

    def excess(angle: float) -> float:
        return static_margin(body, stood + poser.ankles_lean(angle)) + beyond

    if excess(0.0) <= 0 or excess(1.0) >= 0:
        raise InputError(f"{body.model.name}: no forward lean up to 1 rad puts the CoM {beyond * 1e3:.1f} mm past "
                         "the toes from inside the feet")
    return float(brentq(excess, 0.0, 1.0, xtol=1e-9))


def trunk_takes_back(body: BodyModel, joints: np.ndarray) -> float:
    """How far back (m, along -x: the robot faces +x) the static CoM's ground point moves when the robot standing
    in ``joints`` (rad) has its root turned back as far as the corrector may (`CorrectionLimits.max_rotation_deg`
    about the lateral axis, whichever way moves the CoM back) and, a robot whose trunk is too short a lever for the
    live loop's corrector (`uses_legs`, its margin `size_scaled_margin`), its pelvis carried back by its legs as far
    as the corrector may (`hips_height` × the sine of that turn), the feet held where they are (`RootMover`). A
    distance, not a change of the support margin: from a centred stance a move back brings the CoM nearer the
    heels' edge, and the margin falls."""
    joints = follow(joints, body.mimics)
    q = np.concatenate([BasePlacer(body).update(joints), joints])
    mover, turn = RootMover(body, ik_iterations=50), np.radians(CorrectionLimits().max_rotation_deg[Y])
    legs = uses_legs(body, mover, q, turn, size_scaled_margin(body))
    shift = np.array([-hips_height(body, q) * math.sin(turn), 0.0, 0.0]) if legs else None
    base = len(body.base_channels)
    x0 = standing_support(body, joints)[0][X]
    return max(x0 - standing_support(body, mover.apply(q, np.array([0.0, sign * turn, 0.0]), 0.5,
                                                       shift=shift)[base:])[0][X] for sign in (1.0, -1.0))


def _check_trunk_reach(body: BodyModel, name: str, joints: np.ndarray, need: float, why: str) -> None:
    """InputError (one line) where the corrector's largest trunk turn and pelvis shift (`trunk_takes_back`) move the
    static CoM of the posture ``joints`` (rad) back less than ``need`` (m; ``why`` says what for): the robot could
    not stand the scenario ``name`` corrected (a robot whose upper body's CoM lies just above its hips: turned about
    its hip yaws, the corrector's former pivot, NimbRo-OP2X's moved 4 mm back at 15° and it fell corrected; before
    the corrector's legs carried the pelvis, Alexbotmini's trunk alone moved it 1.8 mm where 8 were needed)."""
    back = trunk_takes_back(body, joints)
    if back < need:
        length = float(np.ptp(body.feet["left"].sole_local[:, X]))
        raise InputError(f"{body.model.name}: {name}: its trunk turned back by the corrector's largest "
                         f"{CorrectionLimits().max_rotation_deg[Y]:g}° (and its pelvis carried back by its legs) "
                         f"moves its CoM back only {back * 1e3:.1f} mm, "
                         f"{need * 1e3:.1f} needed ({why}): it could not stand corrected (its soles are "
                         f"{length * 1e3:.0f} mm long; a robot config gives its real ones)")


LEAN_LEAD = 0.0025  # m: the most the lean's own acceleration may move the ZMP ahead of the CoM
LEAN_RAMP_S = 2.0  # s: the shortest lean (livezmp_mini's and the OP3's: their leads are 2.3 and 2.5 mm)


def lean_ramp(body: BodyModel, q0: np.ndarray, dq: np.ndarray) -> float:
    """The time (s) to lean from ``q0`` to ``q0 + dq`` (half a cosine) so that its acceleration moves the ZMP at
    most `LEAN_LEAD` ahead of the CoM: a CoM travel D at height h over T peaks at D pi^2 / (2 T^2) m/s^2, which
    moves the ZMP h / g times that (linear inverted pendulum); at least `LEAN_RAMP_S`. A taller robot's longer
    feet need a longer lean, which a fixed time would make a shove that topples it before its CoM is past its
    toes, corrected or not."""
    c0, c1 = standing_support(body, q0)[0], standing_support(body, q0 + dq)[0]
    travel, height = float(np.linalg.norm(c1[:2] - c0[:2])), float(c0[Z])
    return max(LEAN_RAMP_S, math.pi * math.sqrt(travel * height / (2 * G * LEAN_LEAD)))


def lean(body: BodyModel, beyond: float = 0.004, settle_s: float = 0.5, ramp_s: float | None = None,
         hold_s: float = 3.0, flexion: float = 0.3) -> Scenario:
    """Lean forward at the ankles, slowly (over ``ramp_s``; None: `lean_ramp`), until the static CoM
    is ``beyond`` (m) past the toes; hold it ``hold_s``; lean back. Uncorrected, the robot
    falls during the hold; a few degrees of root rotation keep the ZMP inside."""
    poser = Poser(body)
    q0 = poser.standing(flexion)
    dq = poser.ankles_lean(lean_angle(body, beyond, flexion))
    _check_trunk_reach(body, "lean", q0 + dq, 2 * beyond, f"from {beyond * 1e3:.1f} mm past its toes to as far "
                       "inside")
    if ramp_s is None:
        ramp_s = lean_ramp(body, q0, dq)
    up_end = settle_s + ramp_s + hold_s

    def goals(t: float) -> np.ndarray:
        s = smooth_step((t - settle_s) / ramp_s) - smooth_step((t - up_end) / ramp_s)
        return q0 + s * dq

    return Scenario("lean", goals, up_end + ramp_s + settle_s)


def arm_swing(body: BodyModel, amplitude: float = 0.3, frequency: float | None = 2.5, duration: float = 4.0,
              toe_margin: float | None = 0.008, flexion: float = 0.3, beyond: float = 0.004) -> Scenario:
    """Lean forward at the ankles until the static CoM is ``toe_margin`` (m) inside the
    toes (None: stay upright), then swing both arms forward and back together at the
    shoulders, ``amplitude`` rad at ``frequency`` Hz (the defaults peak at 4.7 rad/s,
    near the XM430's 4.8), the swing growing over its first half second or period
    (`SWING_GROW_S`). The static
    CoM stays inside the feet; the ZMP swings with the arms' acceleration, past the toes
    on every swing. ``frequency=None``: the frequency whose swing puts this robot's ZMP
    ``beyond`` (m) past its toes at the peak (`swing_frequency`: from its masses and
    inertias), so robots of any size are asked the same of their balance. The lean stays back from the toes
    by more than the arms' weight alone moves the CoM at the swing's ends (`ARMS_CLEAR` more): a big
    robot's arms held forward would otherwise put it past its toes at any pace. A robot whose arms are light
    for its feet needs a fast swing to reach ``beyond``, which keeps its ZMP past its toes too briefly to
    topple it: the lean then comes closer to the toes (down to that bound), so that each swing holds the ZMP
    past them for `SWING_PAST_S` (`swing_toe_margin`; a 0.3 m, 0.5 kg humanoid: 3.3 mm, the bound, 1.5 Hz,
    past its toes 0.249 s a swing, where from 8 mm it was 2.1 Hz and 0.15 s). It lasts ``duration`` (s), or
    longer where that would end it before one whole period at full swing."""
    poser = Poser(body)
    q0 = poser.standing(flexion)
    dq = poser.unit("l_sho_pitch", Y) + poser.unit("r_sho_pitch", Y)
    if toe_margin is not None:
        reach = max(front_margin(body, q0) - front_margin(body, q0 + sign * amplitude * dq) for sign in (1, -1))
        toe_margin = max(toe_margin, reach + ARMS_CLEAR)
        if frequency is None:
            toe_margin = swing_toe_margin(body, q0, dq, amplitude, beyond, reach + ARMS_CLEAR, toe_margin, flexion)
        q0 = q0 + poser.ankles_lean(lean_angle(body, -toe_margin, flexion))
    if frequency is None:
        frequency = swing_frequency(body, q0, dq, amplitude, beyond)
    w = 2 * np.pi * frequency
    grow_s = max(SWING_GROW_S, 1.0 / frequency)

    def goals(t: float) -> np.ndarray:
        return q0 + amplitude * smooth_step(t / grow_s) * np.sin(w * max(t, 0.0)) * dq

    # at least one whole period at full swing: JAXON's 0.16 Hz swing grows over 6.3 s, and in 4 s its arms had
    # swung a quarter of the way, its ZMP never past its toes
    return Scenario("arm_swing", goals, max(duration, grow_s + 1.0 / frequency))


# s: the arm swing grows over this long, or over one period of the swing if that is longer: the arms' acceleration
# A (s'' sin wt + 2 s' w cos wt - s w^2 sin wt), s growing as half a cosine, then peaks within 5 % of the swing's own
# A w^2 (over half a period: 1.37 A w^2). Over a fixed 0.5 s, a 1.8 m robot's 0.24 Hz swing started 4x harder than
# it swings: its ZMP went 10 mm past its toes in the first 0.3 s, uncorrected or not.
SWING_GROW_S = 0.5


ARMS_CLEAR = 0.0004  # m: the static CoM at the swing's ends stays this far inside the toes (livezmp_mini: 0.8 mm)


def swing_zmp_beyond_toes(body: BodyModel, q0: np.ndarray, dq: np.ndarray, amplitude: float,
                          frequency: float) -> float:
    """How far (m) past the toes the ZMP goes at the peak of the swing ``q0 + amplitude sin(wt) dq``,
    feet flat, from the whole-body dynamics (base still: only the arms move)."""
    return float(swing_zmp_past_toes(body, q0, dq, amplitude, frequency).max())


def swing_zmp_past_toes(body: BodyModel, q0: np.ndarray, dq: np.ndarray, amplitude: float, frequency: float,
                        samples: int = 64) -> np.ndarray:
    """(samples,) m: how far past the toes the ZMP is (negative: inside) at evenly spaced phases of one cycle of
    the swing ``q0 + amplitude sin(wt) dq``, feet flat, from the whole-body dynamics (base still)."""
    model, data = body.model, body.model.createData()
    # the goals sent: a follower swings with its parent
    q0, dq = follow(q0, body.mimics), follow(dq, body.mimics, offset=False)
    base = BasePlacer(body).update(q0)
    toe = float(standing_support(body, q0)[1][:, X].max())
    w = 2 * np.pi * frequency
    still = np.zeros(len(base))
    past = np.full(samples, -math.inf)
    for k, phase in enumerate(np.linspace(0.0, 2 * np.pi, samples, endpoint=False)):
        q = np.concatenate([base, q0 + amplitude * np.sin(phase) * dq])
        v = np.concatenate([still, amplitude * w * np.cos(phase) * dq])
        a = np.concatenate([still, -amplitude * w * w * np.sin(phase) * dq])
        zmp = compute_zmp(model, data, q, v, a).zmp
        if zmp is not None:
            past[k] = float(zmp[X]) - toe
    return past


# s: each swing holds the ZMP past the toes this long: longer than the 0.2 s a robot's ZMP may stay outside its
# feet before the simulator counts it fallen (a real robot topples in a few sqrt(h / g), 0.13-0.3 s from 0.3 to
# 1.8 m: a fixed time asks a small robot for more, never less)
SWING_PAST_S = 0.25


def swing_toe_margin(body: BodyModel, stood: np.ndarray, dq: np.ndarray, amplitude: float, beyond: float,
                     closest: float, farthest: float, flexion: float) -> float:
    """The lean's distance (m) inside the toes, from ``stood`` (standing posture), for the arm swing that takes
    the ZMP ``beyond`` past them: ``farthest`` when that swing holds the ZMP past the toes for `SWING_PAST_S`
    each cycle, else the largest distance down to ``closest`` that does (a closer lean needs a gentler, slower
    swing to reach ``beyond``, whose ZMP stays past the toes longer); ``closest`` if none does."""
    poser = Poser(body)

    def short(margin: float) -> float:  # s: how much less than SWING_PAST_S each swing holds the ZMP out
        q0 = stood + poser.ankles_lean(lean_angle(body, -margin, flexion))
        frequency = swing_frequency(body, q0, dq, amplitude, beyond)
        past = swing_zmp_past_toes(body, q0, dq, amplitude, frequency, samples=256)
        return SWING_PAST_S - float(np.mean(past > 0)) / frequency

    if short(farthest) <= 0:
        return farthest
    if farthest <= closest or short(closest) > 0:
        return closest
    return float(brentq(short, closest, farthest, xtol=1e-5))


def swing_frequency(body: BodyModel, q0: np.ndarray, dq: np.ndarray, amplitude: float, beyond: float) -> float:
    """The swing frequency (Hz, 0.1-3) that takes the ZMP ``beyond`` (m) past the toes; InputError if none."""
    def excess(f: float) -> float:
        return swing_zmp_beyond_toes(body, q0, dq, amplitude, f) - beyond

    slowest, fastest = excess(0.1), excess(3.0)
    if slowest >= 0 or fastest <= 0:
        # Atlas v5 (160 kg): at 3 Hz, 11 rad/s at the shoulders (its URDF's arm velocity limit is 12), its ZMP stays
        # 2.4 mm inside its toes from 8 mm; a wider swing would need its arms faster still: the refusal says how far
        at, over = ((0.1, slowest) if slowest >= 0 else (3.0, fastest))
        raise InputError(f"{body.model.name}: no arm swing of {amplitude} rad between 0.1 and 3 Hz takes the ZMP "
                         f"{beyond * 1e3:.1f} mm past the toes (at {at:g} Hz, {amplitude * 2 * np.pi * at:.1f} rad/s "
                         f"at the shoulders, its ZMP reaches {abs(over + beyond) * 1e3:.1f} mm "
                         f"{'past' if over + beyond > 0 else 'inside'} them)")
    return float(brentq(excess, 0.1, 3.0, xtol=1e-4))


def squat(body: BodyModel, depth: float = 0.3, period: float = 2.0, cycles: int = 2,
          flexion: float = 0.3) -> Scenario:
    """Squat ``cycles`` times: the leg flexion goes from ``flexion`` to ``flexion + depth``
    and back (half a cosine each way) every ``period``."""
    poser = Poser(body)
    arms = poser.arms_down(0.1)
    duration = cycles * period

    def goals(t: float) -> np.ndarray:
        phase = 2 * np.pi * min(max(t, 0.0), duration) / period
        return arms + poser.legs_flexed(flexion + depth * 0.5 * (1.0 - np.cos(phase)))

    return Scenario("squat", goals, duration)


def walk(body: BodyModel, path: str | Path) -> Scenario:
    """Replay a joint-trajectory CSV (:func:`livezmp.model.trajectory_csv.read_joint_csv`),
    linearly interpolated, holding its first and last frames outside its time span;
    its base columns, if any, are ignored (the humanoid places its own base)."""
    traj = read_joint_csv(path, list(body.joint_names))
    t0, q = traj.t - traj.t[0], traj.q

    def goals(t: float) -> np.ndarray:
        i = int(np.clip(np.searchsorted(t0, t, side="right") - 1, 0, len(t0) - 1))
        if i == len(t0) - 1:
            return q[i].copy()
        f = (t - t0[i]) / (t0[i + 1] - t0[i])
        return q[i] + max(f, 0.0) * (q[i + 1] - q[i])

    return Scenario("walk", goals, float(t0[-1]))


def push(body: BodyModel, force: tuple[float, float] | None = None, at: float = 1.0, duration: float = 0.1,
         height: float | None = None, total: float = 3.0, flexion: float = 0.3, beyond: float = 0.005,
         rise_s: float = 0.0, toe_margin: float | None = None) -> Scenario:
    """Stand (leaning forward at the ankles until the static CoM is ``toe_margin`` (m) inside
    the toes; None: upright), and get pushed: a horizontal ``force`` (N, world x, y) for
    ``duration`` from ``at``, growing over ``rise_s`` (see `Push`), at ``height`` (m above the
    ground; default the hips' height, `hip_height`). ``force=None``: the forward push that moves this
    robot's ZMP ``beyond`` (m) past its toes: a push F at height h moves the ZMP by h F / (m g)
    (m the robot's mass), so F = (toe distance + beyond) m g / h, whatever the robot's size."""
    poser = Poser(body)
    q0 = poser.standing(flexion)
    if toe_margin is not None:
        q0 = q0 + poser.ankles_lean(lean_angle(body, -toe_margin, flexion))
    _check_trunk_reach(body, "push", q0, beyond, "as far as the push takes its ZMP past its toes")
    if height is None:
        height = hip_height(body, q0)
    if force is None:
        force = ((front_margin(body, q0) + beyond) * body.total_mass * G / height, 0.0)
    return Scenario("push", lambda t: q0.copy(), total, (Push(tuple(force), height, at, duration, rise_s),))


def slope(body: BodyModel, degrees: float = 7.0, amplitude: float = 0.4, frequency: float = 0.7,
          duration: float = 4.0, flexion: float = 0.3) -> Scenario:
    """Stand facing up a slope of ``degrees``, upright (leaning forward at the ankles by the
    slope, so the CoM stays over the feet), and swing both arms forward and back together,
    ``amplitude`` rad at ``frequency`` Hz, the swing growing over its first second. A
    flat-foot base estimate sees the body leaning forward by the slope, and its ZMP
    forward by about the CoM height times the slope's tangent; the IMU knows better."""
    poser = Poser(body)
    angle = math.radians(degrees)
    q0 = poser.standing(flexion) + poser.ankles_lean(angle)
    dq = poser.unit("l_sho_pitch", Y) + poser.unit("r_sho_pitch", Y)
    w = 2 * np.pi * frequency

    def goals(t: float) -> np.ndarray:
        return q0 + amplitude * smooth_step(t) * np.sin(w * max(t, 0.0)) * dq

    return Scenario("slope", goals, duration, slope=angle)


def step_edge(body: BodyModel, degrees: float = 8.0, support: float = 0.6, amplitude: float = 0.4,
              frequency: float = 0.7, duration: float = 4.0, flexion: float = 0.3) -> Scenario:
    """Stand with the left foot rolled ``degrees`` outward (its outer side up, resting on the edge
    of a step outside it, its inner edge on the floor: ``support`` of its width bears weight), the
    right foot flat, and swing both arms as in `slope`. A flat-foot base estimate that takes the
    rolled foot as the flat one sees the body rolled by ``degrees`` and its ZMP sideways by about
    the CoM height times their tangent; the IMU knows which way is down."""
    poser = Poser(body)
    q0 = poser.standing(flexion) + math.radians(degrees) * poser.unit("l_ank_roll", X)
    dq = poser.unit("l_sho_pitch", Y) + poser.unit("r_sho_pitch", Y)
    w = 2 * np.pi * frequency

    def goals(t: float) -> np.ndarray:
        return q0 + amplitude * smooth_step(t) * np.sin(w * max(t, 0.0)) * dq

    return Scenario("edge", goals, duration, edge=("left", support))


def hip_height(body: BodyModel, joints: np.ndarray) -> float:
    """Mean height (m above the soles' ground) of the two legs' top joints, standing on both feet in ``joints``:
    where a hand pushes the trunk, wherever the URDF puts its root link's frame."""
    q = np.concatenate([BasePlacer(body).update(joints), joints])
    data = body.model.createData()
    pin.forwardKinematics(body.model, data, q)
    tops = [body.model.getJointId(chain[0]) for chain in leg_chains(body).values()]
    return float(np.mean([data.oMi[j].translation[Z] for j in tops]))


def front_margin(body: BodyModel, joints: np.ndarray) -> float:
    """Distance (m) from the static CoM's ground point forward to the toes' edge, standing on both feet."""
    com, poly = standing_support(body, joints)
    return float(poly[:, X].max() - com[X])


# -- the scenarios by name (livezmp run/sim/demo --scenario) ------------------------------------------

# The demo's arm swing: 0.6 rad, leaning to 8 mm inside the toes, at the frequency that takes the ZMP 4 mm past
# them (livezmp_mini: 0.8 Hz). Uncorrected the ZMP stays past the toes long enough to fall; the loop's corrector
# (estimator lag 30 ms) holds it. (The scenario's own default, 2.5 Hz, is faster than the loop can follow.)
ARM_SWING = {"amplitude": 0.6, "frequency": None, "beyond": 0.004, "toe_margin": 0.008}
# A hand leaning on the robot from behind as it leans 20 mm inside its toes (outside the corrector's 15 mm margin, so
# it does nothing before the push; a robot above 0.3 m has a wider margin, and its corrector starts earlier): the force
# grows over 1 s to what takes the ZMP 5 mm past the toes, holds 1 s and eases off. The joints do not show it; the
# feet's CoP does (OnlineCorrector). Uncorrected, the ZMP is past the toes for longer than the simulator's 0.2 s to
# fall. Faster pushes are not held (0.5 s rise: the trunk, limited to 100 deg/s^2, first pushes the ZMP forward as it
# starts back), nor pushes past what 15 degrees of trunk rotation offsets.
PUSH = {"beyond": 0.005, "toe_margin": 0.02, "duration": 3.0, "rise_s": 1.0, "total": 4.5}
BLEND_S = 1.5  # s, between the parts of a sequence of scenarios (the lean into the arm swing is slow)


def sequence(name: str, parts: list[Scenario], blend_s: float = BLEND_S) -> Scenario:
    """Scenarios one after the other; each part's goals are blended in from where the
    previous one ended over ``blend_s`` seconds (smooth, so no goal jumps)."""
    starts = np.cumsum([0.0] + [p.duration for p in parts])
    ends = [p.goals(p.duration) for p in parts]

    def goals(t: float) -> np.ndarray:
        k = min(max(int(np.searchsorted(starts, t, side="right")) - 1, 0), len(parts) - 1)
        local = t - starts[k]
        q = parts[k].goals(local)
        if k == 0 or local >= blend_s:
            return q
        s = smooth_step(local / blend_s)
        return ends[k - 1] + s * (q - ends[k - 1])

    pushes = tuple(replace(p, start=p.start + starts[k]) for k, part in enumerate(parts) for p in part.pushes)
    return Scenario(name, goals, float(starts[-1]), pushes)


SCENARIOS: dict[str, Callable[[BodyModel], Scenario]] = {
    "stand": stand,
    "lean": lean,
    "arm_swing": lambda body, **kw: arm_swing(body, **{**ARM_SWING, **kw}),
    "squat": squat,
    "slope": slope,
    "edge": step_edge,
    "push": lambda body, **kw: push(body, **{**PUSH, **kw}),
    "demo": lambda body, flexion=0.3, **kw: sequence("demo", [
        lean(body, hold_s=2.0, flexion=flexion), arm_swing(body, duration=3.0, flexion=flexion, **ARM_SWING)], **kw),
}
# rad: the standing posture's leg flexion θ (module docstring), then the straighter stances a scenario is made on,
# in turn, where at the one before it takes a leg joint beyond its limits: the stance's ankle (−θ) and the lean's
# share the ankle's one range (Fourier GR-Mini's ±0.436 rad: from θ = 0.3 its push leaned to −0.53, its lean to
# −0.437, and all three scenarios were refused; from 0.2 they fit). Not below 0.1: the knee's flexion keeps the
# legs' IK, the corrector's, away from the straight knee's singularity; only a robot whose file lets a knee bend
# neither way (`Poser._knee_bend`: 0) stands straight, θ = 0, after them.
FLEXIONS = (0.3, 0.25, 0.2, 0.15, 0.1)
KNEE_REACH = 2 * FLEXIONS[-1]  # rad: a knee bends the way its limits let it bend this far


def make_scenario(name: str, body: BodyModel, **options) -> Scenario:
    """A scenario by name (``SCENARIOS``) for ``body``, with its keyword ``options``;
    InputError naming the choices. Without a ``flexion`` option, on the first stance of `FLEXIONS` that keeps the
    legs within their limits, then, where a knee bends neither way, legs straight; where none does, the refusal is
    the first stance's."""
    if name not in SCENARIOS:
        raise InputError(f"unknown scenario '{name}' (choose from {', '.join(SCENARIOS)})")
    first = None
    flexions = (options["flexion"],) if "flexion" in options else FLEXIONS
    if "flexion" not in options and 0.0 in Poser(body).bends.values():
        flexions = (*FLEXIONS, 0.0)
    for flexion in flexions:
        try:
            return _within_limits(name, body, {**options, "flexion": flexion})
        except BeyondLimits as e:
            first = first or e
    if "flexion" not in options:
        raise BeyondLimits(f"{first} (and from every straighter stance down to {flexions[-1]} rad of flexion)")
    raise first


def _within_limits(name: str, body: BodyModel, options: dict) -> Scenario:
    """The scenario ``name`` for ``body`` with ``options``; BeyondLimits where its stance or goals take a leg joint
    beyond its limits."""
    scenario = SCENARIOS[name](body, **options)
    if body.mimics:  # a mimic joint is not moved on its own: its goal is its parent's times the multiplier + offset
        scenario = replace(scenario, goals=lambda t, goals=scenario.goals: follow(goals(t), body.mimics))
    _check_limits(scenario, body)
    return scenario


LIMIT_CHECK_S = 0.01  # s between the goals a scenario's joint limits are checked at


def _check_limits(scenario: Scenario, body: BodyModel) -> None:
    """InputError (one line) where the scenario's goals take a leg joint beyond its limits: the loop holds its
    goals within them, so the robot would not do what the scenario says (Romeo's default soles, half its hip
    height long, put its toes where leaning to them needs 0.67 rad of ankle, 0.52 allowed: it stood, 88 mm
    inside them). An arm's goals beyond its limits are left to the loop's clip: the swing is one-sided (iCub's
    shoulder pitch stops at 0.09 rad), the robot still swings its arms."""
    model = body.model
    n = len(body.joint_names)
    legs = np.zeros(n, dtype=bool)
    legs[[c - (model.nq - n) for cols in body.correction.legs.values() for c in cols]] = True
    # the loop sends goals within the limits less this (GoalLimiter): a goal between would be cut at t = 0, the
    # stance's ankle jumping (Fourier GR-Mini's push asked -0.4334 rad of an ankle the loop held at -0.426: its true
    # ZMP 516 mm past its toes for 20 ms)
    margin = SafetyConfig().limit_margin_rad - 1e-9
    lower, upper = model.lowerPositionLimit[-n:] + margin, model.upperPositionLimit[-n:] - margin
    for t in np.arange(0.0, scenario.duration, LIMIT_CHECK_S):
        goals = scenario.goals(float(t))
        out = np.flatnonzero(legs & ((goals < lower) | (goals > upper)))
        if out.size:
            i = int(out[0])
            raise BeyondLimits(f"{model.name}: {scenario.name} needs joint {body.joint_names[i]!r} at {goals[i]:.4f} "
                               f"rad (t = {t:.2f} s), beyond its limits [{lower[i] - margin:.4f}, "
                               f"{upper[i] + margin:.4f}] less the loop's {margin:.2f} rad: the robot would not do it "
                               "(soles nearer its real feet, in a robot config, may ask less)")
