"""Walks made of known sinusoids, for tests, demos and benchmarks.

Every listed channel is ``dc + amp · sin(2π f t + phase)``; the root moves forward at a
constant speed. The BVH skeleton is y up in centimetres, walking along +z, left = +x,
all bones along the axes in the zero pose, so each joint's Xrotation is flexion about
the lateral axis, Yrotation twist about the vertical and Zrotation about the forward
axis.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from livezmp.model.bvh import BvhJoint, BvhMotion
from livezmp.model.trajectory_csv import JointTrajectory

ROT = ["Zrotation", "Xrotation", "Yrotation"]
# name, parent, offset (cm)
SKELETON = [
    ("Hips", -1, (0.0, 0.0, 0.0)),
    ("Spine", 0, (0.0, 10.0, 0.0)),
    ("Neck", 1, (0.0, 40.0, 0.0)),
    ("Head", 2, (0.0, 10.0, 0.0)),
    ("UpperArm_L", 1, (18.0, 35.0, 0.0)),
    ("LowerArm_L", 4, (0.0, -28.0, 0.0)),
    ("UpperArm_R", 1, (-18.0, 35.0, 0.0)),
    ("LowerArm_R", 6, (0.0, -28.0, 0.0)),
    ("UpperLeg_L", 0, (9.0, -5.0, 0.0)),
    ("LowerLeg_L", 8, (0.0, -42.0, 0.0)),
    ("Foot_L", 9, (0.0, -42.0, 0.0)),
    ("Toes_L", 10, (0.0, -6.0, 12.0)),
    ("UpperLeg_R", 0, (-9.0, -5.0, 0.0)),
    ("LowerLeg_R", 12, (0.0, -42.0, 0.0)),
    ("Foot_R", 13, (0.0, -42.0, 0.0)),
    ("Toes_R", 14, (0.0, -6.0, 12.0)),
]
END_SITES = {"Head": (0.0, 15.0, 0.0), "LowerArm_L": (0.0, -25.0, 0.0), "LowerArm_R": (0.0, -25.0, 0.0),
             "Toes_L": (0.0, 0.0, 5.0), "Toes_R": (0.0, 0.0, 5.0)}
HIP_HEIGHT = 92.0  # cm


def sine_skeleton() -> list[BvhJoint]:
    """The joints of :data:`SKELETON` (root with 6 channels, the others 3 rotations)."""
    joints: list[BvhJoint] = []
    first = 0
    for name, parent, off in SKELETON:
        ch = ["Xposition", "Yposition", "Zposition", *ROT] if parent < 0 else list(ROT)
        end = END_SITES.get(name)
        joints.append(BvhJoint(name, parent, np.array(off), ch, None if end is None else np.array(end),
                               first_channel=first))
        if parent >= 0:
            joints[parent].children.append(len(joints) - 1)
        first += len(ch)
    return joints


def waves(t: np.ndarray, spec: dict[str, tuple[float, float, float]], frequency: float) -> dict[str, np.ndarray]:
    """``name -> dc + amp sin(2π f t + phase)`` for every ``name -> (dc, amp, phase)`` of ``spec``."""
    return {k: dc + amp * np.sin(2 * np.pi * frequency * t + ph) for k, (dc, amp, ph) in spec.items()}


def sine_bvh(spec: dict[str, tuple[float, float, float]], frequency: float, speed: float, duration: float,
             fps: float = 30.0, heading: float = 0.0) -> BvhMotion:
    """A BVH walk: ``spec`` maps ``Joint.Channel`` to (dc deg, amplitude deg, phase rad);
    ``frequency`` Hz, root ``speed`` m/s along +z, ``duration`` s at ``fps`` frames/s.
    ``heading`` (deg) turns the whole walk about the vertical (y) axis: 180 walks along −z."""
    joints = sine_skeleton()
    labels = [f"{j.name}.{c}" for j in joints for c in j.channels]
    unknown = sorted(set(spec) - set(labels))
    if unknown:
        raise KeyError(f"no such channel(s): {', '.join(unknown)}")
    t = np.arange(int(round(duration * fps))) / fps
    frames = np.zeros((len(t), len(labels)))
    for k, v in waves(t, spec, frequency).items():
        frames[:, labels.index(k)] = v
    turn = Rotation.from_euler("y", heading, degrees=True)
    frames[:, 0:3] = turn.apply(np.column_stack([np.zeros_like(t), np.full_like(t, HIP_HEIGHT), 100.0 * speed * t]))
    hips = Rotation.from_euler("ZXY", frames[:, 3:6], degrees=True)
    frames[:, 3:6] = (turn * hips).as_euler("ZXY", degrees=True)
    return BvhMotion(joints, 1.0 / fps, frames, "<sine walk>")


def sine_bvh_rates(motion: BvhMotion, spec: dict[str, tuple[float, float, float]], frequency: float,
                   speed: float) -> tuple[np.ndarray, np.ndarray]:
    """The exact first and second time derivatives (F, n) of the channels of ``motion``, a
    :func:`sine_bvh` walk with ``heading`` 0 made from ``spec``, ``frequency`` and ``speed``
    (file units: degrees and cm per s and per s^2): the truth an estimator is measured against."""
    t = np.arange(len(motion.frames)) * motion.frame_time
    labels = motion.channel_labels()
    rate, accel = np.zeros_like(motion.frames), np.zeros_like(motion.frames)
    w = 2 * np.pi * frequency
    for name, (_dc, amp, phase) in spec.items():
        rate[:, labels.index(name)] = amp * w * np.cos(w * t + phase)
        accel[:, labels.index(name)] = -amp * w**2 * np.sin(w * t + phase)
    rate[:, 2] = 100.0 * speed  # the root's z position, cm
    return rate, accel


def sine_trajectory(joint_names: list[str], spec: dict[str, tuple[float, float, float]], frequency: float,
                    speed: float, duration: float, rate: float = 125.0, base_height: float = 0.25) -> JointTrajectory:
    """A robot walk: ``spec`` maps joint names to (dc rad, amplitude rad, phase rad); the
    base moves along +x at ``speed`` m/s at ``base_height`` m (z up), level."""
    t = np.arange(int(round(duration * rate))) / rate
    q = np.zeros((len(t), len(joint_names)))
    for k, v in waves(t, spec, frequency).items():
        q[:, joint_names.index(k)] = v
    base = np.zeros((len(t), 6))
    base[:, 0] = speed * t
    base[:, 2] = base_height
    return JointTrajectory(t, q, list(joint_names), base, "<sine walk>")


def walk_spec(hip_amp: float = 20.0, knee_dc: float = 30.0, knee_amp: float = 25.0, elbow_dc: float = 15.0,
              elbow_amp: float = 12.0, trunk_dc: float = 3.0) -> dict[str, tuple[float, float, float]]:
    """A plausible walk for :func:`sine_bvh` (degrees; phases rad): thighs and knees in
    antiphase left/right, arms swinging against the legs, a little trunk twist and lean."""
    out: dict[str, tuple[float, float, float]] = {"Spine.Xrotation": (trunk_dc, 1.5, 0.4),
                                                  "Spine.Yrotation": (0.0, 4.0, 0.0)}
    for side, ph in (("L", 0.0), ("R", np.pi)):
        out[f"UpperLeg_{side}.Xrotation"] = (-5.0, hip_amp, ph)
        out[f"LowerLeg_{side}.Xrotation"] = (knee_dc, knee_amp, ph + 1.2)
        out[f"UpperArm_{side}.Xrotation"] = (2.0, 10.0, ph + np.pi)
        out[f"LowerArm_{side}.Xrotation"] = (elbow_dc, elbow_amp, ph + np.pi + 0.3)
    return out
