"""One robot whose Dynamixel servos are split over several buses, read and written in parallel.

    dynamixel:PATH1+PATH2[+PATH3...][?options]

A bus carries a limited number of bytes a second (:mod:`.bus_timing`); competition
humanoids put their legs on two buses and their arms on a third to go faster. Which servo
is on which bus is found at `open` (each bus is asked for every servo's ID register, so
the robot config needs no change); a servo heard on no bus, or on two, is a LinkError
naming it. Every bus gets the same options (baud, fast, read, ...) and is a
`DynamixelLink` of its own; to the loop this is one link with the robot's joints.

Each cycle every bus's read instruction is out before any reply is waited for (sent ahead
with the goals by a pipelined loop, see `DynamixelLink.write_ticks`, or at the start of
`read`), so the buses carry their transactions at the same time and a cycle costs the
slowest bus's transaction, not their sum. The replies are then taken in one bus after the
other in the calling thread: they wait in each port's buffer meanwhile, and no thread
hand-off (a wake-up and the GIL) sits in the cycle. A frame is returned only when every
bus read verified (else LinkReadError, or the first bus's LinkError). Goals are checked
against every servo's limits before any bus is sent its share, so a refused goal sends
nothing anywhere.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from livezmp.links.base import LinkError, LinkFrame, LinkReadError, LinkStats, joints_per_bus
from livezmp.links.bus_timing import Adapter, BusCeiling
from livezmp.links.dynamixel import DynamixelLink, find_servos
from livezmp.model.robot_config import ServoConfig


class MultiBusLink:
    """Servos ``servos[i]`` drive joints ``joint_names[i]``, on the buses at ``paths`` (see module
    docstring); ``options`` are `DynamixelLink`'s, the same for every bus. No I/O until `open`."""

    def __init__(self, paths: Sequence[str], joint_names: Sequence[str], servos: Sequence[ServoConfig],
                 **options) -> None:
        if len(paths) < 2 or len(set(paths)) != len(paths):
            raise ValueError(f"MultiBusLink: needs two or more distinct ports, got {list(paths)}")
        self.paths = list(paths)
        self.joint_names = list(joint_names)
        self._servos = list(servos)
        self._options = options
        self.buses: list[DynamixelLink] = []
        self._joints: list[np.ndarray] = []  # per bus: the robot joint index of each of its servos
        self._order = np.zeros(0, dtype=int)  # see `open`
        self._scale = np.zeros((4, len(self.joint_names)))  # see `open`
        self._reads = self._writes = 0
        self._prepared = False  # every bus has goals prepared
        self._reconnects = 0

    # -- Link -----------------------------------------------------------------------------------

    def open(self) -> None:
        """Find each servo's bus, then open every bus (checked, torque on, holding)."""
        self._release()
        found = self._assign()
        self.buses = []
        try:
            for path, joints in zip(self.paths, found, strict=True):
                bus = DynamixelLink(path, [self.joint_names[i] for i in joints], [self._servos[i] for i in joints],
                                    **self._options)
                bus.open()  # a bus idle while the next ones open re-arms its watchdog before its first goals
                self.buses.append(bus)
        except LinkError:
            self._release()
            raise
        self._joints = [np.asarray(j, dtype=int) for j in found]
        # the buses' frames end to end, taken in this order, are in the robot's joint order
        self._order = np.argsort(np.concatenate(self._joints))
        # every bus's tick scale and goal limits in the robot's joint order: one conversion a cycle for the robot
        self._scale = np.empty((4, len(self.joint_names)))
        for bus, joints in zip(self.buses, self._joints, strict=True):
            self._scale[:, joints] = bus.tick_scale

    @property
    def pty_ports(self) -> int:
        """How many of the buses' ports are pseudo-terminals (see `DynamixelLink.pty_ports`)."""
        return sum(bus.pty_ports for bus in self.buses)

    def request(self) -> None:
        """Every bus's next read instruction sent now (see `DynamixelLink.request`)."""
        for bus in self.buses:
            bus.request()

    def read(self) -> LinkFrame:
        """Every bus read at once (all instructions out, then the replies); one frame in the robot's joint order."""
        if not self.buses:
            raise LinkError(f"{'+'.join(self.paths)}: link is not open")
        self._reads += 1
        for bus in self.buses:  # those not yet asked (`request`), so that all transactions travel together
            try:
                bus.request()
            except LinkError:
                pass  # its read below finds the port failed and says so
        outcomes: list[LinkFrame | LinkError] = []
        for bus in self.buses:
            try:
                outcomes.append(bus.read())
            except LinkError as e:
                outcomes.append(e)
        errors = [o for o in outcomes if isinstance(o, LinkError)]
        hard = [e for e in errors if not isinstance(e, LinkReadError)]
        if hard:
            raise hard[0]
        if errors:
            raise LinkReadError("; ".join(str(e) for e in errors))
        return self._merge(outcomes)

    def write_goals(self, positions: np.ndarray, request: bool = False) -> None:
        """Goal positions (n,) rad in ``joint_names`` order: each bus its share, after all were checked
        (with ``request``: and each bus's next read instruction, see `DynamixelLink.write_ticks`)."""
        ticks = self._goal_ticks(self._checked(positions))
        self._writes += 1
        for bus, t in zip(self.buses, ticks, strict=True):
            bus.write_ticks(t, request)

    def prepare_goals(self, positions: np.ndarray) -> None:
        """Each bus's share of ``positions`` (rad) and its next read instruction built now (see
        `DynamixelLink.prepare_goals`; a LinkError leaves nothing that `send_prepared` may send)."""
        ticks = self._goal_ticks(self._checked(positions))
        self._prepared = False
        for bus, t in zip(self.buses, ticks, strict=True):
            bus.prepare_ticks(t)
        self._prepared = True

    def send_prepared(self) -> None:
        """Every bus sends what `prepare_goals` built."""
        if not self._prepared:
            raise LinkError(f"{'+'.join(self.paths)}: no goals prepared")
        self._prepared = False
        self._writes += 1
        for bus in self.buses:
            bus.send_prepared()

    def hold(self) -> None:
        for bus in self.buses:
            bus.hold()

    def safe_stop(self, drop_torque: bool = False) -> None:
        for bus in self.buses:
            bus.safe_stop(drop_torque)

    def reconnect(self) -> bool:
        """Reopen every bus (finding the servos again); True when all are back."""
        try:
            self.open()
        except LinkError:
            return False
        self._reconnects += 1
        return True

    def close(self) -> None:
        self.safe_stop()
        self._release()

    # -- reports --------------------------------------------------------------------------------

    @property
    def stats(self) -> LinkStats:
        """Reads and writes of the robot; errors summed over the buses."""
        total = LinkStats(reads=self._reads, writes=self._writes, reconnects=self._reconnects)
        for bus in self.buses:
            total.read_errors += bus.stats.read_errors
            total.write_errors += bus.stats.write_errors
            for kind, n in bus.stats.errors_by_kind.items():
                total.errors_by_kind[kind] = total.errors_by_kind.get(kind, 0) + n
        return total

    @property
    def read_label(self) -> str:
        return self.buses[0].read_label if self.buses else ""

    def bus_ceilings(self, adapter: Adapter) -> list[BusCeiling]:
        return [c for bus in self.buses for c in bus.bus_ceilings(adapter)]

    # -- helpers --------------------------------------------------------------------------------

    def _assign(self) -> list[list[int]]:
        """Robot joint indices on each bus, from which servos answer where."""
        ids = [s.id for s in self._servos]
        baud = self._options.get("baud", 1_000_000)
        heard = [find_servos(path, ids, baud) for path in self.paths]
        return joints_per_bus(ids, self.joint_names, heard, self.paths, "servo", "check power, ids and baud rate")

    def _checked(self, positions: np.ndarray) -> np.ndarray:
        goals = np.asarray(positions, dtype=float)
        if goals.shape != (len(self.joint_names),):
            raise LinkError(f"write_goals needs {len(self.joint_names)} positions, got shape {goals.shape}")
        return goals

    def _goal_ticks(self, goals: np.ndarray) -> list[np.ndarray]:
        """Each bus's goal ticks (int32, its servos' order) for ``goals`` (rad, robot order), converted and
        checked as `DynamixelLink.goal_ticks` does, for the whole robot at once (a bus's call costs the same
        for 10 servos as for 20). A goal beyond its servo's range: that bus refuses it, in its own words."""
        zero, ticks_per_rad, lowest, highest = self._scale
        ticks = np.rint(zero + goals * ticks_per_rad)
        if not ((ticks >= lowest) & (ticks <= highest)).all():  # also catches NaN
            return [bus.goal_ticks(goals[joints]) for bus, joints in zip(self.buses, self._joints, strict=True)]
        return [ticks[joints].astype("<i4") for joints in self._joints]

    def _merge(self, frames: list[LinkFrame]) -> LinkFrame:
        order = self._order

        def gather(name: str) -> np.ndarray | None:
            parts = [getattr(f, name) for f in frames]
            return None if any(p is None for p in parts) else np.concatenate(parts)[order]

        errors = {joint: bits for f in frames for joint, bits in f.hardware_errors.items()}
        return LinkFrame(t=max(f.t for f in frames), positions=gather("positions"), velocities=gather("velocities"),
                         currents=gather("currents"), hardware_errors=errors)

    def _release(self) -> None:
        for bus in self.buses:
            bus._release()
        self.buses = []
