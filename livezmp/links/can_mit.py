"""A robot of "MIT mode" CAN motors (`mit_protocol`) on one or more CAN buses, through python-can.

    can:INTERFACE:CHANNEL[+CHANNEL2...]?protocol=mit[&kp=20&kd=0.5&bitrate=1000000&timeout=S&OPTION=VALUE...]

e.g. ``can:socketcan:can0+can1+can2+can3?protocol=mit`` (one bus per limb, as the MIT Mini
Cheetah runs one per leg), or ``can:socketcand:can0+can1?protocol=mit&host=10.0.0.2&port=29536``.
Each motor answers each command frame with one state frame, so a cycle costs two frames a
motor on its bus (about 230 bit times at 1 Mbit/s: `can_timing`), where the firmware
protocol's JOINT_STATE stream and SET_GOALS cost four. Buses carry their frames at the
same time: every bus is sent its commands before any reply is waited for, so a cycle
costs the busiest bus's wire time. Which motor is on which bus is found at `open` (each
bus is sent "enter motor mode" for every motor; a motor heard on no bus or on two is a
LinkError naming it). The robot config's servo id is the motor's CAN id; its
angle is ``zero * 2 pi / ticks_per_rev + direction * joint angle``. A state reply names its motor in
one byte: ids 1..255.

A command is also the read request: `write_goals` sends the goals and the motors answer
with their state, which the next `read` takes (the loop's pipelined cycle: the state is
measured when the goals arrive); `read` without goals written since sends the held goals
again. The goals are held with the gains ``kp`` (N·m/rad) and ``kd`` (N·m·s/rad).
Velocities come back; the motors' torque is not a current, so ``currents`` is None.
Limits: no watchdog is armed (the firmware's CAN timeout is set on the motor itself); a
classic frame carries 8 bytes, and python-can's socketcand interface carries classic
frames only (no CAN FD).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import can
import numpy as np

from livezmp.links import mit_protocol as mit
from livezmp.links.base import LinkError, LinkFrame, LinkReadError, LinkStats, PortLink, joints_per_bus
from livezmp.links.bus_timing import Adapter
from livezmp.links.can_timing import CanBusCeiling, frame_bits
from livezmp.model.robot_config import ServoConfig

OPEN_TIMEOUT = 0.2  # s to wait for every motor's answer to "enter motor mode"


class MitCanLink(PortLink):
    """Motors ``servos[i]`` drive joints ``joint_names[i]`` on the buses ``channels``, each opened by
    ``open_bus(channel)`` (see module docstring). No I/O until `open`."""

    def __init__(self, name: str, joint_names: Sequence[str], servos: Sequence[ServoConfig], channels: Sequence[str],
                 open_bus: Callable[[str], can.BusABC], *, bitrate: int = 1_000_000, kp: float = 20.0,
                 kd: float = 0.5, timeout: float = 0.02, clock: Callable[[], float] = time.monotonic) -> None:
        self.name = name
        self.joint_names = list(joint_names)
        self.channels = list(channels)
        self.stats = LinkStats()
        self.bitrate = bitrate
        self.kp, self.kd, self.timeout = kp, kd, timeout
        self._open_bus = open_bus
        self._clock = clock
        self._ids = np.array([s.id for s in servos])
        self._offset = np.array([s.zero * 2.0 * math.pi / s.ticks_per_rev for s in servos])
        self._direction = np.array([s.direction for s in servos], dtype=float)
        self.buses: list[can.BusABC] = []
        self._on_bus: list[np.ndarray] = []  # per bus: the joint indices of its motors
        self._index = {int(i): k for k, i in enumerate(self._ids)}
        self._goals = np.zeros(len(servos))  # motor rad
        self._positions = np.full(len(servos), np.nan)  # motor rad, last heard
        self._velocities = np.zeros(len(servos))
        self._rounds = 0  # command rounds sent whose replies are not read yet
        self._last_command = mit.pack_command(0.0, 0.0, kp, kd, 0.0)
        self._last_reply = mit.pack_reply(1, 0.0, 0.0, 0.0)

    # -- Link -----------------------------------------------------------------------------------

    def open(self) -> None:
        """Open every bus, find each motor's bus (entering motor mode), then hold the present posture."""
        self._release()
        self._on_bus = []
        try:
            for channel in self.channels:
                self.buses.append(self._open_bus(channel))
        except (can.CanError, ValueError, TypeError, OSError, ImportError) as err:
            self._release()
            raise LinkError(f"{self.name}: cannot open CAN bus {channel}: {err}") from None
        try:
            self._assign()
        except LinkError:
            self.safe_stop(drop_torque=True)
            self._release()
            raise
        self._goals = self._positions.copy()
        self._send(self._goals)

    def request(self) -> None:
        """The held goals sent again, as a read request, unless a request is already out."""
        if self._rounds == 0:
            self._send(self._goals)

    def read(self) -> LinkFrame:
        """Every motor's state after the latest commands (sending them first if none is out)."""
        self._require()
        self.stats.reads += 1
        self.request()
        rounds, self._rounds = self._rounds, 0
        heard = np.zeros(len(self._ids), dtype=int)
        deadline = self._clock() + self.timeout
        for bus, joints in zip(self.buses, self._on_bus, strict=True):
            want = rounds * len(joints)
            got = 0
            while got < want:
                msg = self._recv(bus, deadline - self._clock())
                if msg is None:
                    break
                got += self._take(msg, heard)
        missing = [self.joint_names[k] for k in np.flatnonzero(heard < rounds)]
        if missing:
            self.stats.read_errors += 1
            self.stats.count("timeout")
            raise LinkReadError(f"{self.name}: no state from {len(missing)} motor(s) ({', '.join(missing[:4])}) "
                                f"within {1e3 * self.timeout:g} ms")
        return LinkFrame(t=self._clock(), positions=self._direction * (self._positions - self._offset),
                         velocities=self._direction * self._velocities)

    def write_goals(self, positions: np.ndarray, request: bool = False) -> None:
        """Goal positions (n,) rad in ``joint_names`` order, one command frame a motor (each also the next
        read's request, whatever ``request`` says). Nothing is sent if any goal is non-finite or out of
        the motors' position range."""
        self._require()
        goals = np.asarray(positions, dtype=float)
        if goals.shape != self._ids.shape or not np.all(np.isfinite(goals)):
            self.stats.write_errors += 1
            raise LinkError(f"{self.name}: write_goals needs {len(self._ids)} finite positions")
        motor = self._offset + self._direction * goals
        if np.any(np.abs(motor) > mit.MINI_CHEETAH.p):
            self.stats.write_errors += 1
            raise LinkError(f"{self.name}: a goal is beyond the motors' +-{mit.MINI_CHEETAH.p} rad")
        self.stats.writes += 1
        self._goals = motor
        self._send(motor)

    def hold(self) -> None:
        if np.all(np.isfinite(self._positions)):
            self._goals = self._positions.copy()
        self._send(self._goals)

    def safe_stop(self, drop_torque: bool = False) -> None:
        """Hold the last posture heard (or exit motor mode: no torque); never raises."""
        try:
            if drop_torque:
                self._special(mit.EXIT_MOTOR_MODE)
            elif self.buses and self._on_bus:
                self.hold()
        except LinkError:
            pass

    # -- reports --------------------------------------------------------------------------------

    read_label = "state"

    def bus_ceilings(self, adapter: Adapter) -> list[CanBusCeiling]:
        """Each bus's ceiling: one command and one reply a motor, with the stuff bits of the last frames
        sent and heard (`can_timing`), plus ``adapter``'s round trip."""
        command = frame_bits(int(self._ids[0]), self._last_command)
        reply = frame_bits(mit.MASTER_ID, self._last_reply)
        return [CanBusCeiling(self.bitrate, len(joints) * (mit.COMMAND_BYTES + mit.REPLY_BYTES), 0.0, adapter,
                              bits_per_cycle=len(joints) * (command + reply), frames_per_cycle=2 * len(joints))
                for joints in self._on_bus]

    # -- helpers --------------------------------------------------------------------------------

    def _assign(self) -> None:
        """Which motors answer on which bus (each is sent "enter motor mode" on every bus)."""
        heard_on: list[set[int]] = [set() for _ in self.buses]
        for bus in self.buses:
            self._drain(bus)
            for ident in self._ids:
                self._transmit(bus, int(ident), mit.ENTER_MOTOR_MODE)
        deadline = self._clock() + OPEN_TIMEOUT
        heard = np.zeros(len(self._ids), dtype=int)
        for k, bus in enumerate(self.buses):  # until the deadline: a motor may answer on a later bus too
            while (msg := self._recv(bus, deadline - self._clock())) is not None:
                if self._take(msg, heard):
                    heard_on[k].add(int(msg.data[0]))
        try:
            on_bus = joints_per_bus(self._ids, self.joint_names, heard_on, self.channels, "motor",
                                    "check power, CAN ids and bitrate")
        except LinkError as e:
            raise LinkError(f"{self.name}: {e}") from None
        self._on_bus = [np.asarray(j, dtype=int) for j in on_bus]

    def _send(self, motor_goals: np.ndarray) -> None:
        """One command a motor, every bus before any reply is waited for."""
        self._require()
        kp, kd = self.kp, self.kd
        for bus, joints in zip(self.buses, self._on_bus, strict=True):
            if self._rounds == 0:
                self._drain(bus)  # late replies of a failed read would pass for this round's
            for j in joints:
                data = mit.pack_command(float(motor_goals[j]), 0.0, kp, kd, 0.0)
                self._transmit(bus, int(self._ids[j]), data)
        self._last_command = data
        self._rounds += 1

    def _special(self, data: bytes) -> None:
        """``data`` to every motor id on every bus (also before `open` found which is where)."""
        for bus in self.buses:
            for ident in self._ids:
                self._transmit(bus, int(ident), data)

    def _transmit(self, bus: can.BusABC, ident: int, data: bytes) -> None:
        try:
            bus.send(can.Message(arbitration_id=ident, data=data, is_extended_id=False))
        except (can.CanError, OSError, ValueError) as err:
            self.stats.write_errors += 1
            self.stats.count("port")
            raise LinkError(f"{self.name}: CAN send failed: {err}") from None

    def _recv(self, bus: can.BusABC, timeout: float) -> can.Message | None:
        try:
            return bus.recv(max(timeout, 0.0))
        except (can.CanError, OSError, ValueError) as err:
            self.stats.count("port")
            raise LinkError(f"{self.name}: CAN receive failed: {err}") from None

    def _drain(self, bus: can.BusABC) -> None:
        while self._recv(bus, 0.0) is not None:
            pass

    def _take(self, msg: can.Message, heard: np.ndarray) -> int:
        """1 if ``msg`` is a motor's state reply (kept), else 0."""
        if msg.arbitration_id != mit.MASTER_ID or msg.is_extended_id or msg.is_error_frame \
                or len(msg.data) != mit.REPLY_BYTES:
            return 0
        j = self._index.get(msg.data[0])
        if j is None:
            return 0
        data = bytes(msg.data)
        _, p, v, _ = mit.unpack_reply(data)
        self._positions[j], self._velocities[j] = p, v
        heard[j] += 1
        self._last_reply = data
        return 1

    def _require(self) -> None:
        if not self.buses:
            raise LinkError(f"{self.name}: link is not open")

    def _release(self) -> None:
        for bus in self.buses:
            try:
                bus.shutdown()
            except (can.CanError, OSError, ValueError):
                pass  # the adapter is gone already
        self.buses = []
        self._rounds = 0
