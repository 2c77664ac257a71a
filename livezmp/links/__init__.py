"""Servo links: `open_link` picks and opens the backend a URL names (URL forms: :mod:`livezmp.links.base`).

    dynamixel:PATH[?baud=1000000&fast=auto&watchdog=0.1&timeout=S]
    can:INTERFACE:CHANNEL[?bitrate=1000000&rate=30&watchdog=0.2&timeout=0.1&OPTION=VALUE...]
    fw:URL[?baud=1000000&rate=500&watchdog=0.2&timeout=0.1]
    mock:

Options follow the last ``?`` (a pyserial URL with options of its own keeps them before
it: ``fw:socket://host:5000?logging=debug?rate=200``). Times in seconds, rates in Hz.
A bad URL or option is an `InputError` naming it.
"""

from __future__ import annotations

from collections.abc import Sequence

from livezmp.errors import InputError
from livezmp.links.base import FootSensors, Link, LinkError, LinkFrame, LinkReadError, LinkStats
from livezmp.model.robot_config import RobotConfig, ServoConfig

__all__ = ["FootSensors", "Link", "LinkError", "LinkFrame", "LinkReadError", "LinkStats", "make_link", "open_link",
           "parse_link_url"]

FORMS = "dynamixel:PATH, can:INTERFACE:CHANNEL, fw:URL or mock:"
_OPTIONS = {  # scheme -> option -> (parser, default)
    "dynamixel": {"baud": ("rate", 1_000_000), "fast": ("auto_flag", None), "watchdog": ("time", 0.1),
                  "timeout": ("positive", None)},
    "can": {"bitrate": ("rate", None), "rate": ("rate", 30), "watchdog": ("time", 0.2),
            "timeout": ("positive", 0.1)},
    "fw": {"baud": ("rate", 1_000_000), "rate": ("rate", 500), "watchdog": ("time", 0.2),
           "timeout": ("positive", 0.1)},
    "mock": {},
}


def parse_link_url(url: str) -> tuple[str, str, dict[str, str]]:
    """(scheme, target, raw options) of a link URL; InputError if malformed."""
    scheme, colon, rest = url.partition(":")
    if not colon or scheme not in _OPTIONS:
        raise InputError(f"link URL '{url}': expected {FORMS}")
    target, _, query = rest.rpartition("?") if "?" in rest else (rest, "", "")
    options: dict[str, str] = {}
    for item in query.split("&"):
        if not item:
            continue
        name, eq, value = item.partition("=")
        if not eq or not name or not value:
            raise InputError(f"link URL '{url}': option '{item}' is not NAME=VALUE")
        if name in options:
            raise InputError(f"link URL '{url}': option '{name}' given twice")
        options[name] = value
    if scheme == "mock" and target:
        raise InputError(f"link URL '{url}': mock: takes no device")
    if scheme != "mock" and not target:
        raise InputError(f"link URL '{url}': {scheme}: needs a device (expected {FORMS})")
    if scheme == "can" and not all(target.partition(":")[::2]):
        raise InputError(f"link URL '{url}': expected can:INTERFACE:CHANNEL, e.g. can:slcan:/dev/ttyACM0")
    return scheme, target, options


def _value(url: str, name: str, kind: str, text: str):
    try:
        if kind in ("flag", "auto_flag"):
            if text == "auto" and kind == "auto_flag":
                return None
            if text not in ("0", "1", "true", "false"):
                raise ValueError
            return text in ("1", "true")
        value = int(text) if kind == "rate" else float(text)
    except ValueError:
        value = None
    ok = value is not None and {"rate": lambda v: v > 0, "time": lambda v: 0 <= v < 1e4,
                                "positive": lambda v: 0 < v < 1e4}[kind](value)
    if not ok:
        want = {"rate": "a positive integer", "time": "seconds >= 0", "positive": "seconds > 0",
                "flag": "0 or 1", "auto_flag": "0, 1 or auto"}[kind]
        raise InputError(f"link URL '{url}': option '{name}' must be {want}, got '{text}'")
    return value


def _bus_option(text: str) -> int | float | str:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def make_link(url: str, joint_names: Sequence[str], robot_config: RobotConfig) -> Link:
    """The link a URL names for ``joint_names`` (no I/O yet: call ``open()``). InputError on a bad URL,
    option, or a joint the robot config has no servo for (dynamixel:, can:)."""
    scheme, target, raw = parse_link_url(url)
    known = _OPTIONS[scheme]
    extra = {k: v for k, v in raw.items() if k not in known}
    if extra and scheme != "can":
        name = next(iter(extra))
        listed = ", ".join(known) or "none"
        raise InputError(f"link URL '{url}': unknown option '{name}' for {scheme}: (options: {listed})")
    opts = {name: (_value(url, name, kind, raw[name]) if name in raw else default)
            for name, (kind, default) in known.items()}
    return _BUILDERS[scheme](url, target, list(joint_names), robot_config, opts, extra)


def _mock(url: str, target: str, names: list[str], config: RobotConfig, opts: dict, extra: dict) -> Link:
    from livezmp.links.mock import MockLink
    from sim_devices.servo_plant import ServoPlant

    return MockLink(ServoPlant(len(names)), names)


def _fw(url: str, target: str, names: list[str], config: RobotConfig, opts: dict, extra: dict) -> Link:
    from livezmp.links.firmware import FirmwareLink, SerialBoard

    _check_watchdog(url, opts["watchdog"], 65.535)
    return FirmwareLink(url, names, lambda: SerialBoard(target, opts["baud"]), rate=opts["rate"],
                        watchdog=opts["watchdog"], timeout=opts["timeout"])


def _dynamixel(url: str, target: str, names: list[str], config: RobotConfig, opts: dict, extra: dict) -> Link:
    from livezmp.links.dynamixel import WATCHDOG_MAX, WATCHDOG_UNIT, DynamixelLink

    if opts["watchdog"] and not WATCHDOG_UNIT <= opts["watchdog"] <= WATCHDOG_MAX:
        raise InputError(f"link URL '{url}': option 'watchdog' must be 0 (off) or {WATCHDOG_UNIT}.."
                         f"{WATCHDOG_MAX:.2f} s, got {opts['watchdog']:g}")
    return DynamixelLink(target, names, _servos("dynamixel", names, config), baud=opts["baud"], fast=opts["fast"],
                         watchdog=opts["watchdog"], timeout=opts["timeout"])


def _can(url: str, target: str, names: list[str], config: RobotConfig, opts: dict, extra: dict) -> Link:
    from livezmp.links.can import CanBoards
    from livezmp.links.firmware import FirmwareLink

    _check_watchdog(url, opts["watchdog"], 65.535)
    nodes = sorted({s.id for s in _servos("can", names, config)})
    bad = [n for n in nodes if not 1 <= n <= 127]
    if bad:
        raise InputError(f"{config.source}: servo id {bad[0]} cannot be a CAN node id (1..127)")
    interface, _, channel = target.partition(":")
    bus_options = {k: _bus_option(v) for k, v in extra.items()}
    if opts["bitrate"] is not None:
        bus_options["bitrate"] = opts["bitrate"]
    tids: dict[tuple[int, int], int] = {}  # kept from one connection to the next (see CanBoards)

    def connect() -> CanBoards:
        return CanBoards(interface, channel, nodes, tids, **bus_options)

    return FirmwareLink(url, names, connect, rate=opts["rate"], watchdog=opts["watchdog"], timeout=opts["timeout"])


_BUILDERS = {"mock": _mock, "fw": _fw, "dynamixel": _dynamixel, "can": _can}


def _servos(scheme: str, names: list[str], config: RobotConfig) -> list[ServoConfig]:
    """The robot config's servo of each joint; InputError naming the first joint without one."""
    missing = [joint for joint in names if joint not in config.servos]
    if missing:
        raise InputError(f"{config.source}: no [servos.{missing[0]}] entry: the {scheme}: link needs a servo for "
                         "every joint")
    return [config.servos[joint] for joint in names]


def open_link(url: str, joint_names: Sequence[str], robot_config: RobotConfig) -> Link:
    """`make_link`, then ``open()``: connected, checked, torque on, holding. LinkError if the device fails."""
    link = make_link(url, joint_names, robot_config)
    link.open()
    return link


def _check_watchdog(url: str, value: float, limit: float) -> None:
    if value > limit:
        raise InputError(f"link URL '{url}': option 'watchdog' must be at most {limit} s, got {value}")
