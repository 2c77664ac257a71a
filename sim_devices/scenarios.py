"""Scenarios for the simulated humanoid: goal joint angles as functions of time.

A scenario is the robot's base command, what it is asked to do; a live loop's balance
corrector adds its offsets to the leg joints on top. Scenarios work for any body with
the usual humanoid joint names (head_pan, head_tilt, {l,r}_{sho_pitch, sho_roll, el,
hip_yaw, hip_roll, hip_pitch, knee, ank_pitch, ank_roll}), e.g. ROBOTIS OP3 and
livezmp_mini, whatever the signs of their URDF axes: postures are rotations about
world axes in the zero posture, turned into joint angles through each joint's own axis
as the model gives it.

Standing posture: knees bent, hip −θ, knee +2θ, ankle −θ about the lateral axis (y,
left), which keeps each sole parallel to the pelvis (flat on the ground) and the legs
away from their straight-knee singularity; arms hang down, turned out a little by the
shoulder roll (OP3's zero posture holds them out sideways).

Angles in rad, times in s, world frame z up, x forward, y left.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.optimize import brentq

from livezmp.balance.support import clamp_to_polygon, support_polygon
from livezmp.errors import InputError
from livezmp.model.base_placement import BasePlacer
from livezmp.model.body import BodyModel, foot_soles
from livezmp.model.trajectory_csv import read_joint_csv
from sim_devices.humanoid import Push, SimHumanoid

SIDES = ("l", "r")
X, Y, Z = 0, 1, 2


@dataclass(frozen=True)
class Scenario:
    """``goals(t)``: joint goal angles (rad, ``body.joint_names`` order) at scenario time
    t (s); ``duration`` (s); ``pushes`` in scenario time."""

    name: str
    goals: Callable[[float], np.ndarray]
    duration: float
    pushes: tuple[Push, ...] = ()


class Poser:
    """Joint-angle vectors from rotations about world axes, for one body."""

    def __init__(self, body: BodyModel):
        self.body = body
        self.names = list(body.joint_names)
        model = body.model
        data = model.createData()
        q0 = np.zeros(model.nq)
        pin.computeJointJacobians(model, data, q0)
        self.axis: dict[str, np.ndarray] = {}
        self.origin: dict[str, np.ndarray] = {}
        for name in self.names:
            j = model.getJointId(name)
            self.axis[name] = data.J[3:, model.joints[j].idx_v].copy()  # world axis in the zero posture
            self.origin[name] = data.oMi[j].translation.copy()

    def index(self, name: str) -> int:
        if name not in self.names:
            raise InputError(f"{self.body.model.name}: no joint {name!r}; scenarios need the usual humanoid "
                             "joint names (e.g. l_knee, r_sho_pitch)")
        return self.names.index(name)

    def unit(self, name: str, world_axis: int) -> np.ndarray:
        """Joint vector that turns ``name`` by +1 rad about the world axis (0 x, 1 y, 2 z)."""
        i = self.index(name)
        along = float(self.axis[name][world_axis])
        if abs(along) < 0.99:
            raise InputError(f"{self.body.model.name}: joint {name!r} turns about {np.round(self.axis[name], 3)}, "
                             f"not the world {'xyz'[world_axis]} axis this scenario needs")
        out = np.zeros(len(self.names))
        out[i] = 1.0 / along
        return out

    def legs_flexed(self, angle: float, sides: tuple[str, ...] = SIDES) -> np.ndarray:
        """Legs ("l", "r") bent by ``angle``: hip −θ, knee +2θ, ankle −θ about y (each sole
        stays parallel to the pelvis)."""
        out = np.zeros(len(self.names))
        for s in sides:
            out += angle * (-self.unit(f"{s}_hip_pitch", Y) + 2 * self.unit(f"{s}_knee", Y)
                            - self.unit(f"{s}_ank_pitch", Y))
        return out

    def ankles_lean(self, angle: float) -> np.ndarray:
        """Both ankles turned so that, feet flat, the body leans forward by ``angle`` (rad)."""
        return -angle * (self.unit("l_ank_pitch", Y) + self.unit("r_ank_pitch", Y))

    def arms_down(self, out_angle: float) -> np.ndarray:
        """Shoulder rolls that make each upper arm hang down, ``out_angle`` rad away from the body."""
        out = np.zeros(len(self.names))
        for s, lateral in (("l", 1.0), ("r", -1.0)):
            roll, elbow = f"{s}_sho_roll", f"{s}_el"
            i = self.index(roll)
            self.index(elbow)
            a = self.axis[roll]
            d = self.origin[elbow] - self.origin[roll]  # upper arm in the zero posture
            target = np.array([0.0, lateral * np.sin(out_angle), -np.cos(out_angle)])
            d, target = d - (d @ a) * a, target - (target @ a) * a
            out[i] = np.arctan2(a @ np.cross(d, target), d @ target)
        return out

    def standing(self, flexion: float = 0.3, arm_out: float = 0.1) -> np.ndarray:
        """The standing posture (see module docstring)."""
        return self.legs_flexed(flexion) + self.arms_down(arm_out)


def smooth_step(x: np.ndarray | float) -> np.ndarray | float:
    """0 → 1 over x in [0, 1] with zero slope at both ends (half a cosine)."""
    return 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))


def stand(body: BodyModel, duration: float = 3.0, flexion: float = 0.3) -> Scenario:
    """Stand still in the standing posture."""
    q = Poser(body).standing(flexion)
    return Scenario("stand", lambda t: q.copy(), duration)


def static_margin(body: BodyModel, joints: np.ndarray) -> float:
    """Signed distance (m, + inside) of the CoM's ground projection to the support
    polygon of both soles, for the robot standing still on both feet in ``joints``."""
    placer = BasePlacer(body)
    q = np.concatenate([placer.update(joints), joints])
    data = body.model.createData()
    pin.centerOfMass(body.model, data, q)
    pin.framesForwardKinematics(body.model, data, q)
    soles = foot_soles(body, data)
    poly = support_polygon(soles["left"], soles["right"], "double")
    return clamp_to_polygon(data.com[0][:2], poly).margin


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


def lean(body: BodyModel, beyond: float = 0.004, settle_s: float = 0.5, ramp_s: float = 2.0, hold_s: float = 3.0,
         flexion: float = 0.3) -> Scenario:
    """Lean forward at the ankles, slowly (over ``ramp_s``), until the static CoM is
    ``beyond`` (m) past the toes; hold it ``hold_s``; lean back. Uncorrected, the robot
    falls during the hold; a few degrees of root rotation keep the ZMP inside."""
    poser = Poser(body)
    q0 = poser.standing(flexion)
    dq = poser.ankles_lean(lean_angle(body, beyond, flexion))
    up_end = settle_s + ramp_s + hold_s

    def goals(t: float) -> np.ndarray:
        s = smooth_step((t - settle_s) / ramp_s) - smooth_step((t - up_end) / ramp_s)
        return q0 + s * dq

    return Scenario("lean", goals, up_end + ramp_s + settle_s)


def arm_swing(body: BodyModel, amplitude: float = 0.3, frequency: float = 2.5, duration: float = 4.0,
              toe_margin: float | None = 0.008, flexion: float = 0.3) -> Scenario:
    """Lean forward at the ankles until the static CoM is ``toe_margin`` (m) inside the
    toes (None: stay upright), then swing both arms forward and back together at the
    shoulders, ``amplitude`` rad at ``frequency`` Hz (the defaults peak at 4.7 rad/s,
    near the XM430's 4.8), the swing growing over its first half second. The static
    CoM stays inside the feet; the ZMP swings with the arms' acceleration, past the toes
    on every swing."""
    poser = Poser(body)
    q0 = poser.standing(flexion)
    if toe_margin is not None:
        q0 = q0 + poser.ankles_lean(lean_angle(body, -toe_margin, flexion))
    dq = poser.unit("l_sho_pitch", Y) + poser.unit("r_sho_pitch", Y)
    w = 2 * np.pi * frequency

    def goals(t: float) -> np.ndarray:
        return q0 + amplitude * smooth_step(t / 0.5) * np.sin(w * max(t, 0.0)) * dq

    return Scenario("arm_swing", goals, duration)


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


def push(body: BodyModel, force: tuple[float, float] = (5.0, 0.0), at: float = 1.0, duration: float = 0.1,
         height: float | None = None, total: float = 3.0, flexion: float = 0.3) -> Scenario:
    """Stand, and get pushed: a horizontal ``force`` (N, world x, y) for ``duration`` from
    ``at``, at ``height`` (m above the ground; default the base link's height)."""
    q0 = Poser(body).standing(flexion)
    if height is None:
        height = float(BasePlacer(body).update(q0)[2])
    return Scenario("push", lambda t: q0.copy(), total, (Push(tuple(force), height, at, duration),))


class ScenarioPlayer:
    """Feeds a scenario's goals to a humanoid ``rate_hz`` times a second of simulated
    time, without any servo bus: switches every joint's torque on, schedules the
    scenario's pushes, and steps the humanoid between goal updates. ``correct(t,
    goals) -> goals`` (optional) may change each goal vector before it is sent, as a
    live loop's corrector does. Scenario time 0 is the humanoid's time at creation."""

    def __init__(self, humanoid: SimHumanoid, scenario: Scenario, rate_hz: float = 125.0,
                 correct: Callable[[float, np.ndarray], np.ndarray] | None = None):
        self.humanoid = humanoid
        self.scenario = scenario
        self.period = 1.0 / rate_hz
        self.correct = correct
        self.start = humanoid.t
        self.ticks = 0
        for i in range(len(humanoid.position)):
            humanoid.set_torque(i, True)
        for p in scenario.pushes:
            humanoid.push(Push(p.force, p.height, self.start + p.start, p.duration))

    @property
    def t(self) -> float:
        """Scenario time of the next goal update (s)."""
        return self.ticks * self.period

    def tick(self) -> None:
        """Send the goals for the current time and simulate one goal period."""
        t = self.t
        goals = self.scenario.goals(t)
        if self.correct is not None:
            goals = self.correct(t, goals)
        self.humanoid.set_goals(goals)
        self.ticks += 1
        self.humanoid.advance_to(self.start + self.ticks * self.period)

    def run(self, duration: float | None = None) -> None:
        """Play ``duration`` seconds (default: the rest of the scenario)."""
        end = self.scenario.duration if duration is None else self.t + duration
        while self.t < end - 1e-9:
            self.tick()
