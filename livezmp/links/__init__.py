"""Servo links: `open_link` picks and opens the backend a URL names (URL forms: :mod:`livezmp.links.base`).

    dynamixel:PATH[+PATH2...][?baud=1000000&fast=auto&read=position&return_delay=0&watchdog=0.1&timeout=S]
    can:INTERFACE:CHANNEL[?bitrate=1000000&rate=30&watchdog=0.2&timeout=0.1&OPTION=VALUE...]
    can:INTERFACE:CHANNEL[+CHANNEL2...]?protocol=mit[&kp=20&kd=0.5&bitrate=1000000&timeout=0.1&OPTION=VALUE...]
    fw:URL[?baud=1000000&rate=500&watchdog=0.2&timeout=0.1]
    mock:                       (registered by sim_devices: an in-process simulated robot)

Backends are :class:`Backend` entries: the three above are built in; more are registered
through the ``livezmp.links`` entry-point group (``name = "module:BACKEND"`` in a
package's metadata), as python-can finds its interfaces, so a package such as
``sim_devices`` adds ``mock:`` without livezmp importing it.

``dynamixel:PATH1+PATH2`` is one robot on several buses, read in parallel
(:mod:`livezmp.links.multi_bus`). Options follow the last ``?`` (a pyserial URL with
options of its own keeps them before it: ``fw:socket://host:5000?logging=debug?rate=200``).
Times in seconds, rates in Hz. A bad URL or option is an `InputError` naming it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from importlib.metadata import entry_points

from livezmp.errors import InputError
from livezmp.links.base import FootSensors, Link, LinkError, LinkFrame, LinkReadError, LinkStats, LinkUnusable
from livezmp.model.robot_config import RobotConfig, ServoConfig

__all__ = ["Backend", "FootSensors", "Link", "LinkError", "LinkFrame", "LinkReadError", "LinkStats", "LinkUnusable",
           "make_link", "open_link", "parse_link_url"]

ENTRY_POINT_GROUP = "livezmp.links"
Builder = Callable[[str, str, list[str], RobotConfig, dict, dict], Link]


@dataclass(frozen=True)
class Backend:
    """One link scheme: ``build(url, target, joint_names, robot_config, options, extra)`` makes the
    (unopened) link; ``options`` name -> (kind, default), kind one of "rate", "time", "positive",
    "flag", "auto_flag", "read", "return_delay"; ``target``: whether the URL names a device after the scheme;
    ``extra_options``: unknown options are passed on (``extra``) rather than refused."""

    build: Builder
    options: dict[str, tuple[str, object]] = field(default_factory=dict)
    target: bool = True
    extra_options: bool = False


def parse_link_url(url: str) -> tuple[str, str, dict[str, str]]:
    """(scheme, target, raw options) of a link URL; InputError if malformed."""
    scheme, colon, rest = url.partition(":")
    backend = _backend(scheme) if colon else None
    if backend is None:
        raise InputError(f"link URL '{url}': expected {_forms()}")
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
    if not backend.target and target:
        raise InputError(f"link URL '{url}': {scheme}: takes no device")
    if backend.target and not target:
        raise InputError(f"link URL '{url}': {scheme}: needs a device (expected {_forms()})")
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
        if kind == "read":
            if text not in ("position", "state"):
                raise ValueError
            return text
        value = int(text) if kind in ("rate", "return_delay") else float(text)
    except ValueError:
        value = None
    ok = value is not None and {"rate": lambda v: v > 0, "time": lambda v: 0 <= v < 1e4,
                                "positive": lambda v: 0 < v < 1e4,
                                "return_delay": lambda v: 0 <= v <= 508 and v % 2 == 0}[kind](value)
    if not ok:
        want = {"rate": "a positive integer", "time": "seconds >= 0", "positive": "seconds > 0",
                "flag": "0 or 1", "auto_flag": "0, 1 or auto", "read": "position or state",
                "return_delay": "an even number of microseconds, 0-508"}[kind]
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
    backend = _backend(scheme)
    known = backend.options
    extra = {k: v for k, v in raw.items() if k not in known}
    if extra and not backend.extra_options:
        name = next(iter(extra))
        listed = ", ".join(known) or "none"
        raise InputError(f"link URL '{url}': unknown option '{name}' for {scheme}: (options: {listed})")
    opts = {name: (_value(url, name, kind, raw[name]) if name in raw else default)
            for name, (kind, default) in known.items()}
    return backend.build(url, target, list(joint_names), robot_config, opts, extra)


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
    options = {k: opts[k] for k in ("baud", "fast", "read", "return_delay", "watchdog", "timeout")}
    servos = _servos("dynamixel", names, config)
    if "+" in target:  # several buses, one robot
        from livezmp.links.multi_bus import MultiBusLink

        paths = target.split("+")
        if len(set(paths)) != len(paths) or not all(paths):
            raise InputError(f"link URL '{url}': dynamixel:PATH1+PATH2... needs distinct, non-empty ports")
        return MultiBusLink(paths, names, servos, **options)  # an [imu] is read on one bus only (so far)
    return DynamixelLink(target, names, servos, imu=config.imu, **options)


def _can(url: str, target: str, names: list[str], config: RobotConfig, opts: dict, extra: dict) -> Link:
    from livezmp.links.can import CanBoards
    from livezmp.links.firmware import FirmwareLink

    protocol = extra.pop("protocol", "firmware")
    if protocol == "mit":
        return _can_mit(url, target, names, config, opts, extra)
    if protocol != "firmware":
        raise InputError(f"link URL '{url}': option 'protocol' must be firmware or mit, got '{protocol}'")
    if "+" in target:
        raise InputError(f"link URL '{url}': several CAN buses (CHANNEL1+CHANNEL2) need protocol=mit")
    _check_watchdog(url, opts["watchdog"], 65.535)
    nodes = sorted({s.id for s in _servos("can", names, config)})
    bad = [n for n in nodes if not 1 <= n <= 127]
    if bad:
        raise InputError(f"{config.source}: servo id {bad[0]} cannot be a CAN node id (1..127)")
    interface, _, channel = target.partition(":")
    _check_bus_options(url, interface, extra)
    bus_options = {k: _bus_option(v) for k, v in extra.items()}
    if opts["bitrate"] is not None:
        bus_options["bitrate"] = opts["bitrate"]
    tids: dict[tuple[int, int], int] = {}  # kept from one connection to the next (see CanBoards)

    def connect() -> CanBoards:
        return CanBoards(interface, channel, nodes, tids, **bus_options)

    return FirmwareLink(url, names, connect, rate=opts["rate"], watchdog=opts["watchdog"], timeout=opts["timeout"])


def _can_mit(url: str, target: str, names: list[str], config: RobotConfig, opts: dict, extra: dict) -> Link:
    import can

    from livezmp.links.can import open_can_bus
    from livezmp.links.can_mit import MitCanLink
    from livezmp.links.mit_protocol import MINI_CHEETAH

    servos = _servos("can", names, config)
    bad = [s.id for s in servos if not 1 <= s.id <= 255]
    if bad:
        raise InputError(f"{config.source}: servo id {bad[0]} cannot be an MIT-mode motor's CAN id (1..255)")
    gains = {}
    for name, top in (("kp", MINI_CHEETAH.kp), ("kd", MINI_CHEETAH.kd)):
        value = _bus_option(extra.pop(name, "20" if name == "kp" else "0.5"))
        if isinstance(value, str) or not 0 <= value <= top:
            raise InputError(f"link URL '{url}': option '{name}' must be a number in 0..{top:g}, got '{value}'")
        gains[name] = float(value)
    interface, _, channels = target.partition(":")
    buses = channels.split("+")
    if len(set(buses)) != len(buses) or not all(buses):
        raise InputError(f"link URL '{url}': can:INTERFACE:CHANNEL1+CHANNEL2... needs distinct, non-empty channels")
    bitrate = opts["bitrate"] or 1_000_000
    _check_bus_options(url, interface, extra)
    bus_options = {k: _bus_option(v) for k, v in extra.items()}

    def open_bus(channel: str) -> can.BusABC:
        return open_can_bus(interface, channel, bitrate=bitrate, **bus_options)

    return MitCanLink(url, names, servos, buses, open_bus, bitrate=bitrate, timeout=opts["timeout"], **gains)


# python-can interfaces whose bus needs options beyond the channel (their constructors' required arguments)
REQUIRED_BUS_OPTIONS = {"socketcand": ("host", "port")}


def _check_bus_options(url: str, interface: str, extra: dict) -> None:
    """A python-can interface's required options named in one line (python-can itself says only that a
    constructor misses positional arguments), with the URL form that gives them."""
    missing = [name for name in REQUIRED_BUS_OPTIONS.get(interface, ()) if name not in extra]
    if missing:
        form = "&".join(f"{name}={name.upper()}" for name in REQUIRED_BUS_OPTIONS[interface])
        raise InputError(f"link URL '{url}': {interface} needs option(s) {', '.join(missing)}: "
                         f"can:{interface}:CHANNEL?{form} (CHANNEL: the daemon's CAN interface, e.g. can0)")


_BUILT_IN = {
    "dynamixel": Backend(_dynamixel, {"baud": ("rate", 1_000_000), "fast": ("auto_flag", None),
                                      "read": ("read", "position"), "return_delay": ("return_delay", 0),
                                      "watchdog": ("time", 0.1), "timeout": ("positive", None)}),
    "can": Backend(_can, {"bitrate": ("rate", None), "rate": ("rate", 30), "watchdog": ("time", 0.2),
                          "timeout": ("positive", 0.1)}, extra_options=True),  # the rest go to python-can's Bus
    "fw": Backend(_fw, {"baud": ("rate", 1_000_000), "rate": ("rate", 500), "watchdog": ("time", 0.2),
                        "timeout": ("positive", 0.1)}),
}
_FORMS = {"dynamixel": "dynamixel:PATH", "can": "can:INTERFACE:CHANNEL", "fw": "fw:URL"}


def _registered() -> dict[str, object]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name not in _BUILT_IN}


def _backend(scheme: str) -> Backend | None:
    """The built-in or registered backend of ``scheme``; None if there is none."""
    if scheme in _BUILT_IN:
        return _BUILT_IN[scheme]
    ep = _registered().get(scheme)
    if ep is None:
        return None
    backend = ep.load()
    if not isinstance(backend, Backend):
        raise InputError(f"link backend {scheme}: ({ep.value}) is not a livezmp.links.Backend")
    return backend


def _forms() -> str:
    forms = [*_FORMS.values(), *(f"{name}:" for name in sorted(_registered()))]
    return ", ".join(forms[:-1]) + " or " + forms[-1]


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
