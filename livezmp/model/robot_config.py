"""Robot config files (TOML) that sit next to a URDF: feet, soles, correction joints, servos.

Looked up as ``ROBOT.toml`` beside ``ROBOT.urdf``, else a built-in config named after
the URDF's ``<robot name>`` (``livezmp/data/robots/NAME.toml``); everything is optional.

    [feet.left]
    link = "l_ank_roll_link"
    sole = [[x, y, z], ...]          # corners in the link frame, metres
    # or: box = { length = 0.127, width = 0.072, center = [x, y, z] }

    [correction.legs]                 # joints a leg re-solve may move; default: the
                                      # chain from the base to each foot
    left = ["l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ank_pitch", "l_ank_roll"]

    [servos.l_hip_pitch]              # for servo links
    id = 11
    zero = 2048                       # ticks at 0 rad
    direction = 1                     # +1 or -1
    ticks_per_rev = 4096
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from livezmp.errors import InputError
from livezmp.tomlfile import read_toml


@dataclass
class ServoConfig:
    """Servo ``id`` of a joint and the tick ↔ radian conversion."""

    joint: str
    id: int
    zero: int = 2048
    direction: int = 1
    ticks_per_rev: int = 4096

    def to_ticks(self, rad: float) -> int:
        return int(round(self.zero + self.direction * rad * self.ticks_per_rev / (2 * np.pi)))

    def to_rad(self, ticks: float) -> float:
        return self.direction * (ticks - self.zero) * 2 * np.pi / self.ticks_per_rev


@dataclass
class RobotConfig:
    feet: dict[str, dict] = field(default_factory=dict)
    legs: dict[str, list[str]] = field(default_factory=dict)
    servos: dict[str, ServoConfig] = field(default_factory=dict)
    source: str = "<defaults>"


def _parse(data: dict, source: str) -> RobotConfig:
    cfg = RobotConfig(source=source)
    for side, f in (data.get("feet") or {}).items():
        if side not in ("left", "right"):
            raise InputError(f"{source}: [feet.{side}]: side must be left or right")
        if "link" not in f:
            raise InputError(f"{source}: [feet.{side}]: missing 'link'")
        if "sole" in f:
            sole = np.asarray(f["sole"], dtype=float)
            if sole.ndim != 2 or sole.shape[1] != 3 or len(sole) < 3:
                raise InputError(f"{source}: [feet.{side}] sole: need at least 3 points [x, y, z]")
            f = {**f, "sole": sole}
        cfg.feet[side] = f
    corr = data.get("correction") or {}
    cfg.legs = {k: list(v) for k, v in (corr.get("legs") or {}).items()}
    for joint, s in (data.get("servos") or {}).items():
        if "id" not in s:
            raise InputError(f"{source}: [servos.{joint}]: missing 'id'")
        d = int(s.get("direction", 1))
        if d not in (1, -1):
            raise InputError(f"{source}: [servos.{joint}] direction: must be 1 or -1")
        cfg.servos[joint] = ServoConfig(joint, int(s["id"]), int(s.get("zero", 2048)), d,
                                        int(s.get("ticks_per_rev", 4096)))
    return cfg


def load_robot_config(path: str | Path) -> RobotConfig:
    p = Path(path)
    return _parse(read_toml(p, "robot config"), str(p))


def find_robot_config(urdf: str | Path, robot_name: str) -> RobotConfig:
    """The config beside the URDF, else the built-in one for ``robot_name``, else defaults."""
    beside = Path(urdf).with_suffix(".toml")
    if beside.is_file():
        return load_robot_config(beside)
    builtin = resources.files("livezmp") / "data" / "robots" / f"{robot_name}.toml"
    if builtin.is_file():
        return _parse(tomllib.loads(builtin.read_text(encoding="utf-8")), f"livezmp:{robot_name}.toml")
    return RobotConfig()
