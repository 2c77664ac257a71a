"""The built-in demo: livezmp's own small humanoid and a motion that tests balance.

The motion (joint angles only; the base is placed from the stance foot) squats, sways
sideways, leans forward past the toes, recovers, and swings its arms fast, so the ZMP
visits the whole sole and leaves it for a while.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np

from livezmp.model.trajectory_csv import JointTrajectory


def demo_robot_path() -> Path:
    """Path of the demo humanoid's URDF inside the installed package."""
    return Path(str(resources.files("livezmp") / "data" / "robots" / "livezmp_mini.urdf"))


def smooth_ramp(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 before t0, 1 after t1, a smooth (C2) ramp between."""
    s = (t - t0) / (t1 - t0)
    # one time (the live loop's command ramp, every cycle): no numpy scalar round trip
    s = min(max(s, 0.0), 1.0) if isinstance(s, float) else np.clip(s, 0.0, 1.0)
    return s * s * s * (10 - 15 * s + 6 * s * s)


def demo_trajectory(joint_names: list[str], duration: float = 12.0, rate: float = 100.0) -> JointTrajectory:
    """The demo motion for ``livezmp_mini`` (rad, ``joint_names`` order, no base columns)."""
    t = np.arange(int(duration * rate)) / rate
    q = {n: np.zeros_like(t) for n in joint_names}
    squat = 0.5 * (smooth_ramp(t, 0.5, 1.5) - smooth_ramp(t, 2.0, 3.0))
    sway = 0.12 * np.sin(2 * np.pi * 0.5 * (t - 3.0)) * (smooth_ramp(t, 3.0, 3.5) - smooth_ramp(t, 5.5, 6.0))
    lean = 0.35 * (smooth_ramp(t, 6.0, 7.0) - smooth_ramp(t, 8.0, 9.0))
    arms = 1.0 * np.sin(2 * np.pi * 1.5 * (t - 9.0)) * (smooth_ramp(t, 9.0, 9.3) - smooth_ramp(t, 11.5, 11.9))
    for s in ("l", "r"):
        q[f"{s}_hip_pitch"] = -squat
        q[f"{s}_knee"] = 2 * squat
        q[f"{s}_ank_pitch"] = -squat - lean
        q[f"{s}_hip_roll"] = sway
        q[f"{s}_ank_roll"] = -sway
        q[f"{s}_sho_pitch"] = arms if s == "l" else -arms
        q[f"{s}_el"] = -0.3 + 0 * t
    return JointTrajectory(t, np.column_stack([q[n] for n in joint_names]), list(joint_names), None, "<demo>")
