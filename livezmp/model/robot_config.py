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
    model = 1020                      # optional: its Dynamixel model number (1020: XM430-W350); a
                                      # servo answering with another is refused at open

    [imu]                             # an IMU sub-controller on the Dynamixel bus (the OP3's OpenCR)
    id = 200
    axes = [-1, -1, 1]                # sign of each board axis in the base link's axes
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from livezmp.errors import InputError
from livezmp.tomlfile import read_toml


@dataclass
class ServoConfig:
    """Servo ``id`` of a joint and the tick ↔ radian conversion; ``model``: the servo's Dynamixel model number
    (its Model Number register), None where the config does not say."""

    joint: str
    id: int
    zero: int = 2048
    direction: int = 1
    ticks_per_rev: int = 4096
    model: int | None = None

    def to_rad(self, ticks: float) -> float:
        """The joint angle (rad) of a servo position in ticks."""
        return self.direction * (ticks - self.zero) * 2 * np.pi / self.ticks_per_rev


SERVO_KEYS = ("direction", "id", "model", "ticks_per_rev", "zero")


def _known_keys(table: dict, keys: tuple[str, ...], where: str) -> None:
    """Refuse a key of ``table`` not among ``keys``: misspelt, it would be ignored (a servo's direction or zero
    would then drive its joint wrongly)."""
    unknown = set(table) - set(keys)
    if unknown:
        raise InputError(f"{where}: unknown key {sorted(unknown)[0]!r} ({', '.join(keys)})")


@dataclass(frozen=True)
class ImuConfig:
    """An IMU sub-controller at bus ``id``; ``axes``: the sign of each of its axes in the
    base link's (see :mod:`livezmp.links.dynamixel_imu`)."""

    id: int
    axes: tuple[int, int, int] = (1, 1, 1)


@dataclass
class RobotConfig:
    feet: dict[str, dict] = field(default_factory=dict)
    legs: dict[str, list[str]] = field(default_factory=dict)
    servos: dict[str, ServoConfig] = field(default_factory=dict)
    source: str = "<defaults>"
    imu: ImuConfig | None = None


MAX_SOLE_M = 1.0  # a sole dimension or corner offset beyond a metre is not a foot
NAME_RE = re.compile(r"[A-Za-z0-9_.-]+")


def _table(value: object, where: str) -> dict:
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise InputError(f"{where}: need a table, got {type(value).__name__}")
    return value


def _int(value: object, where: str, lo: int, hi: int) -> int:
    if type(value) is not int or not lo <= value <= hi:
        raise InputError(f"{where}: need an integer {lo} .. {hi}, got {value!r}"[:200])
    return value


def _length(value: object, where: str, positive: bool) -> float:
    ok = type(value) in (int, float) and math.isfinite(value) and abs(value) <= MAX_SOLE_M
    if not ok or (positive and value <= 0):
        need = f"a length in (0, {MAX_SOLE_M:g}] m" if positive else f"a length within ±{MAX_SOLE_M:g} m"
        raise InputError(f"{where}: need {need}, got {value!r}"[:200])
    return float(value)


def _point(value: object, where: str) -> list[float]:
    if not isinstance(value, list) or len(value) != 3:
        raise InputError(f"{where}: need [x, y, z] in metres")
    return [_length(v, f"{where}[{i}]", False) for i, v in enumerate(value)]


def _polygon_area(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _foot(side: str, f: object, source: str) -> dict:
    where = f"{source}: [feet.{side}]"
    f = _table(f, where)
    _known_keys(f, ("link", "sole", "box"), where)
    if not isinstance(f.get("link"), str):
        raise InputError(f"{where} link: need the link's name (a string)")
    out: dict = {"link": f["link"]}
    if "sole" in f:
        if not isinstance(f["sole"], list) or len(f["sole"]) < 3:
            raise InputError(f"{where} sole: need at least 3 points [x, y, z]")
        sole = np.array([_point(c, f"{where} sole[{i}]") for i, c in enumerate(f["sole"])])
        if _polygon_area(sole) <= 1e-6:  # m^2: a sole smaller than 1 mm x 1 mm cannot carry a body
            raise InputError(f"{where} sole: the corners enclose no area")
        out["sole"] = sole
    if "box" in f:
        box = _table(f["box"], f"{where} box")
        _known_keys(box, ("length", "width", "center"), f"{where} box")
        out["box"] = {k: _length(box[k], f"{where} box.{k}", True) for k in ("length", "width") if k in box}
        if "center" in box:
            out["box"]["center"] = _point(box["center"], f"{where} box.center")
    return out


def _parse(data: dict, source: str) -> RobotConfig:
    """A config from parsed TOML; every field's type and range is checked (one line per field)."""
    cfg = RobotConfig(source=source)
    for side, f in _table(data.get("feet"), f"{source}: [feet]").items():
        if side not in ("left", "right"):
            raise InputError(f"{source}: [feet.{side}]: side must be left or right")
        cfg.feet[side] = _foot(side, f, source)
    corr = _table(data.get("correction"), f"{source}: [correction]")
    for side, joints in _table(corr.get("legs"), f"{source}: [correction.legs]").items():
        if side not in ("left", "right"):
            raise InputError(f"{source}: [correction.legs] {side}: side must be left or right")
        if not isinstance(joints, list) or not all(isinstance(j, str) for j in joints):
            raise InputError(f"{source}: [correction.legs] {side}: need a list of joint names")
        cfg.legs[side] = list(joints)
    for joint, s in _table(data.get("servos"), f"{source}: [servos]").items():
        where = f"{source}: [servos.{joint}]"
        s = _table(s, where)
        _known_keys(s, SERVO_KEYS, where)
        if "id" not in s:
            raise InputError(f"{where}: missing 'id'")
        d = s.get("direction", 1)
        if type(d) is not int or d not in (1, -1):
            raise InputError(f"{where} direction: must be 1 or -1")
        ticks = _int(s.get("ticks_per_rev", 4096), f"{where} ticks_per_rev", 1, 1 << 24)
        servo_id = _int(s["id"], f"{where} id", 0, 252)
        same = next((o.joint for o in cfg.servos.values() if o.id == servo_id), None)
        if same is not None:  # one servo would take both joints' goals (and the links find a servo by its id)
            raise InputError(f"{where} id: {servo_id} is already the id of {same}")
        model = _int(s["model"], f"{where} model", 0, 0xFFFF) if "model" in s else None
        cfg.servos[joint] = ServoConfig(joint, servo_id,
                                        _int(s.get("zero", 2048), f"{where} zero", -(1 << 31), (1 << 31) - 1),
                                        d, ticks, model)
    if "imu" in data:
        cfg.imu = _imu(_table(data["imu"], f"{source}: [imu]"), f"{source}: [imu]", cfg)
    return cfg


def _imu(t: dict, where: str, cfg: RobotConfig) -> ImuConfig:
    _known_keys(t, ("id", "axes"), where)
    if "id" not in t:
        raise InputError(f"{where}: missing 'id'")
    dxl_id = _int(t["id"], f"{where} id", 0, 252)
    if any(s.id == dxl_id for s in cfg.servos.values()):
        raise InputError(f"{where} id: {dxl_id} is a servo's id")
    axes = t.get("axes", [1, 1, 1])
    if not isinstance(axes, list) or len(axes) != 3 or not all(type(a) is int and a in (1, -1) for a in axes):
        raise InputError(f"{where} axes: need three signs, e.g. [-1, -1, 1]")
    return ImuConfig(dxl_id, tuple(axes))


def load_robot_config(path: str | Path) -> RobotConfig:
    """The robot config TOML at ``path``; InputError naming the file and key when it is not valid."""
    p = Path(path)
    return _parse(read_toml(p, "robot config"), str(p))


def find_robot_config(urdf: str | Path, robot_name: str) -> RobotConfig:
    """The config beside the URDF, else the built-in one for ``robot_name``, else defaults.

    A robot name that is not a plain file name (letters, digits, ``_ . -``; e.g. one with
    a space, ``/`` or ``..``) names no built-in config: it is not looked up (defaults)."""
    beside = Path(urdf).with_suffix(".toml")
    if beside.is_file():
        return load_robot_config(beside)
    if not NAME_RE.fullmatch(robot_name) or robot_name.startswith("."):
        return RobotConfig()
    builtin = resources.files("livezmp") / "data" / "robots" / f"{robot_name}.toml"
    if builtin.is_file():
        return _parse(tomllib.loads(builtin.read_text(encoding="utf-8")), f"livezmp:{robot_name}.toml")
    return RobotConfig()
