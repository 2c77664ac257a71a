"""The servo-link interface: one set of calls, many backends, chosen by a URL.

    dynamixel:/dev/ttyUSB0?baud=1000000     Dynamixel Protocol 2.0 bus (dynamixel-sdk)
    can:slcan:/dev/ttyACM0?bitrate=1000000  CAN servos (python-can, any interface)
    fw:/dev/ttyACM0                         a firmware board (firmware_protocol over pyserial)
    mock:                                   an in-process simulated robot, no bus (registered by sim_devices)

A link reads the robot's joint state (and, where the device has them, foot sensors and
IMU) and writes goal positions, in radians, in the robot's joint-name order. Ticks,
zero offsets and directions are the backend's business (from the robot config).

Safety contract every backend keeps: ``read`` never returns a frame it could not
verify (bad CRC, short reply, timeout, hardware error on a joint it then reports): it
raises :class:`LinkReadError` and counts it; ``write_goals`` sends nothing when given a
non-finite value; ``safe_stop`` is idempotent and is the first thing called on any
exit path.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np


class LinkError(RuntimeError):
    """A device or bus fault (port gone, no answer, refused handshake)."""


class LinkReadError(LinkError):
    """One read failed verification; the frame is dropped, the link may still be up."""


class LinkUnusable(LinkError):
    """The bus works but too badly to control a robot with (e.g. it loses too many replies): stop."""


@dataclass
class FootSensors:
    """Per-foot vertical forces (N) at the sole corners and the board's centre of
    pressure (m, in the foot frame, or None)."""

    forces: dict[str, np.ndarray]
    cop: dict[str, np.ndarray | None]


@dataclass
class LinkFrame:
    """One verified read. ``t``: host monotonic time of the read (s); ``positions``
    (n,) rad; ``velocities`` (n,) rad/s or None; ``currents`` (n,) A or None;
    ``hardware_errors``: joint name → device error bits (only joints with errors);
    ``device_time``: the device's own timestamp (s) if it has one."""

    t: float
    positions: np.ndarray
    velocities: np.ndarray | None = None
    currents: np.ndarray | None = None
    hardware_errors: dict[str, int] = field(default_factory=dict)
    feet: FootSensors | None = None
    imu: dict[str, np.ndarray] | None = None
    device_time: float | None = None


@dataclass
class LinkStats:
    """Counters since open: reads/writes attempted and failed, by kind."""

    reads: int = 0
    read_errors: int = 0
    writes: int = 0
    write_errors: int = 0
    reconnects: int = 0
    errors_by_kind: dict[str, int] = field(default_factory=dict)

    def count(self, kind: str) -> None:
        self.errors_by_kind[kind] = self.errors_by_kind.get(kind, 0) + 1


class Link(Protocol):
    """What the live loop needs from a servo bus or board."""

    joint_names: list[str]
    stats: LinkStats

    def open(self) -> None:
        """Connect, check the devices, enable torque. Raises LinkError."""

    def read(self) -> LinkFrame:
        """One verified joint-state read. Raises LinkReadError or LinkError."""

    def write_goals(self, positions: np.ndarray) -> None:
        """Goal positions (n,) rad in ``joint_names`` order. Raises LinkError. A link that also has
        ``request()`` (its next read's instruction sent ahead) takes ``request=True`` here: the
        goals and that instruction in one transfer."""

    def hold(self) -> None:
        """Hold the present posture (goals = present positions)."""

    def safe_stop(self, drop_torque: bool = False) -> None:
        """Stop commanding: hold (or drop torque); idempotent; never raises."""

    def reconnect(self) -> bool:
        """Try once to reopen a vanished port; True when the link is back."""

    def close(self) -> None:
        """safe_stop, then release the port."""


class PortLink:
    """What the port-backed links share: ``reconnect`` redoes ``open`` on a fresh port,
    ``close`` stops then releases. Subclasses provide ``open``, ``safe_stop``,
    ``_release`` (drop the port, never raises) and ``stats``."""

    stats: LinkStats

    def reconnect(self) -> bool:
        """Reopen the port and redo `open`'s configuration (re-arming the device's
        watchdog); True when the link is back."""
        self._release()
        try:
            self.open()
        except LinkError:
            return False
        self.stats.reconnects += 1
        return True

    def close(self) -> None:
        """Hold, then release the port (the device's watchdog then holds)."""
        self.safe_stop()
        self._release()


def joints_per_bus(ids: Sequence[int], joint_names: Sequence[str], heard: Sequence[set[int]],
                   buses: Sequence[str], device: str, hint: str) -> list[list[int]]:
    """The robot's joint indices on each of ``buses`` (their names), from the device ids ``heard``
    answering on each; ``ids[j]`` is joint ``j``'s device. Raises LinkError naming the joint whose
    ``device`` answered on no bus (with ``hint``) or on two, or a bus where none answered."""
    found: list[list[int]] = [[] for _ in buses]
    for j, ident in enumerate(ids):
        where = [k for k, h in enumerate(heard) if int(ident) in h]
        who = f"{device} {ident} ({joint_names[j]})"
        if not where:
            raise LinkError(f"{who} answered on none of {', '.join(buses)}: {hint}")
        if len(where) > 1:
            raise LinkError(f"{who} answered on {' and '.join(buses[k] for k in where)}: two {device}s share its id")
        found[where[0]].append(j)
    empty = [buses[k] for k, joints in enumerate(found) if not joints]
    if empty:
        raise LinkError(f"{empty[0]}: none of the robot's {device}s answered on this bus")
    return found
