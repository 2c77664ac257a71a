"""Firmware-board link: firmware_protocol host sessions behind the Link interface.

    fw:URL[?baud=1000000&rate=500&watchdog=0.2&timeout=0.1]

``URL`` is anything pyserial's ``serial_for_url`` opens (a device path, ``socket://``...).
The same `FirmwareLink` serves the CAN link (one session per servo node, see
:mod:`livezmp.links.can`): only how the sessions are opened and polled differs (`Boards`).

`open`: HELLO handshake with every board (schema checked), stream rates set (JOINT_STATE
at ``rate`` Hz, FOOT_SENSORS and IMU at the same rate when the board has them, HEARTBEAT
10 Hz), the link's joints mapped by name from HELLO_ACK, watchdog configured (``watchdog``
s, HOLD; 0 disables it), goals set to the present positions, torque enabled and checked.

`read` returns when every board has sent a JOINT_STATE since the previous read (the host
heartbeat goes out from the same polling, so a stalled loop trips the board's watchdog);
positions (rad), velocities (rad/s), currents (A) as the board sends them, the latest foot
sensors and IMU, and ``hardware_errors``: the JointError bits of joints with any bit but
TORQUE_OFF. A joint flagged COMMS, STALE or ENCODER makes the read raise LinkReadError, as
does no fresh state within ``timeout`` s, or a state that reached us ``timeout`` s later
than the board's usual delay (measured on its clock: the host fell behind the stream and
reads a backlog). ``stats.read_errors`` counts board messages lost or rejected, from the
gaps in their sequence numbers (a rejected frame leaves a gap), plus the reads that timed
out or were late; ``errors_by_kind`` breaks them down (seq_gap, bad_crc, timeout, stale...).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

import firmware_protocol as fp
from livezmp.links.base import FootSensors, LinkError, LinkFrame, LinkReadError, LinkStats, PortLink

HEARTBEAT_HZ = 10
POLL_WAIT = 0.005  # s: the one serial read timeout used (changing it reconfigures the port)
CONNECT_TIMEOUT = 1.0  # s per board
# Watchdog while the boards are set up one after the other (the ones done first get no heartbeat meanwhile);
# the link's own goes on once they all are.
OPEN_WATCHDOG = 1.0
UNTRUSTED = fp.JointError.COMMS | fp.JointError.STALE | fp.JointError.ENCODER
CLOCK_DRIFT = 1e-3  # s/s: how fast a board clock may drift from ours (crystals: < 1e-4)
FOOT_SIDES = ("left", "right")  # FOOT_SENSORS foot_id 0 and 1


class Boards(Protocol):
    """The open transport of a link: one HostSession per board (or CAN servo node)."""

    name: str
    sessions: list[fp.HostSession]

    def poll(self) -> list[tuple[int, fp.Message]]:
        """(session index, message) for everything received now, waiting up to POLL_WAIT s for the first."""

    def pending(self) -> bool:
        """True when more input is already waiting (a poll would not wait)."""

    def errors(self) -> dict[str, int]:
        """Receive errors by kind (firmware_protocol decoder counters)."""

    def close(self) -> None:
        """Release the port or bus; never raises."""


class SerialBoard:
    """One board on a pyserial URL."""

    def __init__(self, url: str, baud: int) -> None:
        self.name = url
        try:
            transport = fp.SerialTransport(url, baudrate=baud)
            transport.port.reset_input_buffer()  # what the board sent before we opened is stale
        except fp.ProtocolError as err:
            raise LinkError(str(err)) from None
        self.sessions = [fp.HostSession(transport, watchdog_timeout=OPEN_WATCHDOG)]

    def poll(self) -> list[tuple[int, fp.Message]]:
        return [(0, msg) for msg in self.sessions[0].poll(POLL_WAIT)]

    def pending(self) -> bool:
        try:
            return self.sessions[0].transport.port.in_waiting > 0
        except OSError as err:
            raise fp.LinkError(f"{self.name}: {err}") from None

    def errors(self) -> dict[str, int]:
        return self.sessions[0].transport.decoder.errors

    def close(self) -> None:
        try:
            self.sessions[0].transport.close()
        except OSError:
            pass


class _Board:
    """What the link knows of one board: which of its joint ids are the link's joints, and where they go."""

    def __init__(self, session: fp.HostSession, hello: fp.HelloAck, index_of: dict[str, int]) -> None:
        self.session = session
        self.capabilities = fp.Capability(hello.capabilities)
        pairs = [(jid, index_of[name]) for jid, name in zip(hello.joint_ids, hello.joint_names, strict=True)
                 if name in index_of]
        self.ids = tuple(jid for jid, _ in pairs)
        self.slots = [slot for _, slot in pairs]
        self.slot_of = dict(pairs)
        self._routes: dict[tuple[int, ...], list[tuple[int, int]] | None] = {}
        self.fresh = False
        self.time: float | None = None  # board clock of its last JOINT_STATE, unwrapped (s)
        self.age = 0.0  # how much later than usual that JOINT_STATE reached us (s)
        self._raw_us: int | None = None
        self._wraps = 0
        self._floor: float | None = None  # smallest (our clock - its clock) seen, allowed to drift up
        self._floor_at = 0.0

    def clock(self, board_time_us: int, now: float) -> None:
        """Note a sample's board time (32-bit us, wrapping) received at our ``now`` (s): unwrap it and measure its
        age, the delay beyond the best one seen, which grows when we fall behind the board's stream."""
        if self._raw_us is not None and board_time_us < self._raw_us - (1 << 31):
            self._wraps += 1
        self._raw_us = board_time_us
        self.time = (board_time_us + (self._wraps << 32)) * 1e-6
        lag = now - self.time
        if self._floor is None or lag < self._floor + CLOCK_DRIFT * (now - self._floor_at):
            self._floor = lag
        else:
            self._floor += CLOCK_DRIFT * (now - self._floor_at)
        self._floor_at = now
        self.age = lag - self._floor

    def route(self, ids: tuple[int, ...]) -> list[tuple[int, int]] | None:
        """(message index, link slot) of this board's joints in a JOINT_STATE with ``ids``; None if some is absent."""
        route = self._routes.get(ids, False)
        if route is False:
            route = [(k, self.slot_of[jid]) for k, jid in enumerate(ids) if jid in self.slot_of]
            route = route if len(route) == len(self.slot_of) else None
            if len(self._routes) < 16:  # boards send one layout; bound the cache anyway
                self._routes[ids] = route
        return route


class FirmwareLink(PortLink):
    """Joints ``joint_names`` on the boards ``connect()`` opens (see module docstring)."""

    def __init__(self, name: str, joint_names: Sequence[str], connect: Callable[[], Boards], *, rate: int = 500,
                 watchdog: float = 0.2, timeout: float = 0.1) -> None:
        self.name = name
        self.joint_names = list(joint_names)
        self.rate = rate
        self.watchdog = watchdog
        self.timeout = timeout
        self.stats = LinkStats()
        self._connect = connect
        self._boards: Boards | None = None
        self._list: list[_Board] = []
        n = len(self.joint_names)
        self._position = np.zeros(n)
        self._velocity = np.zeros(n)
        self._current = np.zeros(n)
        self._error = np.zeros(n, dtype=np.int64)
        self._feet: FootSensors | None = None
        self._imu: dict[str, np.ndarray] | None = None
        self._carried: dict[str, int] = {}  # decoder counts of transports closed by reconnect
        self._own: dict[str, int] = {}  # the link's own error kinds (timeout, partial_state, untrusted)

    # -- Link -----------------------------------------------------------------------------------

    def open(self) -> None:
        """Handshake, configure and enable every board (see module docstring). LinkError on failure."""
        self._boards = self._connect()  # LinkError if the port or bus cannot be opened
        try:
            self._configure()
        except LinkError:
            self._release()
            raise
        except fp.ProtocolError as err:  # names the port or node already
            self._release()
            raise LinkError(str(err)) from None

    def read(self) -> LinkFrame:
        """The joint state every board sent since the previous read (see module docstring)."""
        boards = self._require()
        self.stats.reads += 1
        deadline = time.monotonic() + self.timeout
        try:
            while True:
                for k, msg in boards.poll():
                    self._take(self._list[k], msg)
                if all(b.fresh for b in self._list):
                    if not boards.pending() or time.monotonic() > deadline:
                        break  # the newest state: a stalled caller gets today's, not the backlog's first
                    continue
                if time.monotonic() > deadline:
                    late = [b.session.transport.name for b in self._list if not b.fresh]
                    self._own["timeout"] = self._own.get("timeout", 0) + 1
                    self._account()
                    raise LinkReadError(f"{self.name}: no joint state within {self.timeout} s from "
                                        f"{', '.join(late[:4])}{' ...' if len(late) > 4 else ''}")
        except fp.ProtocolError as err:
            raise LinkError(str(err)) from None
        t = time.monotonic()
        self._account()
        for b in self._list:
            b.fresh = False
        late = max(self._list, key=lambda b: b.age)
        if late.age > self.timeout:
            self._own["stale"] = self._own.get("stale", 0) + 1
            self._account()
            raise LinkReadError(f"{self.name}: the joint state of {late.session.transport.name} is "
                                f"{late.age * 1e3:.0f} ms late: this host is not keeping up with its stream (lower "
                                "the rate)")
        untrusted = np.flatnonzero(self._error & UNTRUSTED)
        if untrusted.size:
            self._own["untrusted"] = self._own.get("untrusted", 0) + 1
            self._account()
            i = int(untrusted[0])
            raise LinkReadError(f"{self.name}: joint '{self.joint_names[i]}' reported "
                                f"{fp.JointError(int(self._error[i]) & UNTRUSTED)!r}: its state is not usable")
        faults = np.flatnonzero(self._error & ~fp.JointError.TORQUE_OFF)
        return LinkFrame(
            t=t, positions=self._position.copy(), velocities=self._velocity.copy(), currents=self._current.copy(),
            hardware_errors={self.joint_names[i]: int(self._error[i]) for i in faults},
            feet=self._feet, imu=self._imu, device_time=self._list[0].time if len(self._list) == 1 else None,
        )

    def write_goals(self, positions: np.ndarray) -> None:
        """Goal positions (n,) rad in ``joint_names`` order: one SET_GOALS per board."""
        goals = np.asarray(positions, dtype=float)
        if goals.shape != self._position.shape:
            raise LinkError(f"{self.name}: write_goals needs {len(self._position)} positions, got shape "
                            f"{goals.shape}")
        finite = np.isfinite(goals) & (np.abs(goals) < 3.0e38)  # must fit a float32
        if not finite.all():
            i = int(np.argmin(finite))
            raise LinkError(f"{self.name}: goal for joint '{self.joint_names[i]}' is not finite: {goals[i]!r}; "
                            "nothing sent")
        self._require()
        values = goals.tolist()
        self.stats.writes += 1
        try:
            for b in self._list:
                b.session.send_goals(b.ids, [values[slot] for slot in b.slots])
        except fp.ProtocolError as err:
            self.stats.write_errors += 1
            raise LinkError(str(err)) from None

    def hold(self) -> None:
        """Goals = the present positions, from a fresh read."""
        self.write_goals(self.read().positions)

    def safe_stop(self, drop_torque: bool = False) -> None:
        """Hold (or switch torque off); never raises: the boards' watchdogs cover a dead link."""
        if self._boards is None:
            return
        if not drop_torque:
            try:
                self.hold()
            except (LinkError, fp.ProtocolError):
                pass  # nothing more can be sent; the boards' watchdogs hold
            return
        for b in self._list:  # every board, even when one does not answer
            try:
                b.session.set_torque(b.ids, False)
            except (LinkError, fp.ProtocolError):
                self.stats.write_errors += 1

    # -- internals ------------------------------------------------------------------------------

    def _configure(self) -> None:
        boards = self._boards
        index_of = {name: i for i, name in enumerate(self.joint_names)}
        self._list = []
        for session in boards.sessions:
            hello = session.connect(CONNECT_TIMEOUT)
            board = _Board(session, hello, index_of)
            feet = self.rate if fp.Capability.FOOT_SENSORS in board.capabilities else 0
            imu = self.rate if fp.Capability.IMU in board.capabilities else 0
            session.set_rates(self.rate, feet, imu, HEARTBEAT_HZ)
            self._list.append(board)
        owners: dict[int, int] = {}
        for b in self._list:
            for slot in b.slots:
                owners[slot] = owners.get(slot, 0) + 1
        missing = [name for i, name in enumerate(self.joint_names) if i not in owners]
        if missing:
            raise LinkError(f"{self.name}: no board has joint(s) {', '.join(missing)}")
        twice = [name for i, name in enumerate(self.joint_names) if owners[i] > 1]
        if twice:
            raise LinkError(f"{self.name}: joint(s) {', '.join(twice)} are on more than one board")
        for b in self._list:
            b.session.configure_watchdog(self.watchdog, fp.WatchdogAction.HOLD)
        self._forget()  # only state sent after the handshake counts
        self.hold()  # before torque: a board that enables torque at its old goal would jump
        for b in self._list:
            b.session.set_torque(b.ids, True)
        self._forget()
        frame = self.read()
        off = [f"{name} ({fp.JointError(int(self._error[i]))!r})" for i, name in enumerate(self.joint_names)
               if self._error[i] & fp.JointError.TORQUE_OFF]
        if off:
            raise LinkError(f"{self.name}: torque did not come on for joint(s) {', '.join(off)}")
        self.write_goals(frame.positions)

    def _forget(self) -> None:
        """Drop the state received so far: each board sent it before what it acknowledged last, so the
        next JOINT_STATE of every board is newer than our last command."""
        for k, msg in self._boards.poll():
            self._take(self._list[k], msg)
        for b in self._list:
            b.fresh = False

    def _take(self, board: _Board, msg: fp.Message) -> None:
        if isinstance(msg, fp.JointState):
            route = board.route(msg.ids)
            if route is None:
                self._own["partial_state"] = self._own.get("partial_state", 0) + 1
                return
            for k, slot in route:
                self._position[slot] = msg.position[k]
                self._velocity[slot] = msg.velocity[k]
                self._current[slot] = msg.current[k]
                self._error[slot] = msg.error[k]
            board.fresh = True
            board.clock(msg.board_time_us, time.monotonic())
        elif isinstance(msg, fp.FootSensors):
            forces = {FOOT_SIDES[f]: np.array(force) for f, force in zip(msg.foot_ids, msg.force, strict=True)
                      if f < len(FOOT_SIDES)}
            cop = {FOOT_SIDES[f]: (np.array([x, y]) if sum(force) > 0 else None)
                   for f, force, x, y in zip(msg.foot_ids, msg.force, msg.cop_x, msg.cop_y, strict=True)
                   if f < len(FOOT_SIDES)}
            self._feet = FootSensors(forces, cop)
        elif isinstance(msg, fp.Imu):
            self._imu = {"orientation": np.array(msg.orientation), "angular_velocity": np.array(msg.angular_velocity),
                         "acceleration": np.array(msg.acceleration)}

    def _account(self) -> None:
        """Refresh the error counters from the decoder(s) and the link's own counts."""
        counts = dict(self._carried)
        for kind, n in self._boards.errors().items():
            if n and kind != "seq_restart":  # a restart is a rebooted board, not a lost message
                counts[kind] = counts.get(kind, 0) + n
        lost = counts.get("seq_gap", 0)
        counts.update(self._own)
        self.stats.errors_by_kind = counts
        self.stats.read_errors = lost + self._own.get("timeout", 0) + self._own.get("stale", 0)

    def _require(self) -> Boards:
        if self._boards is None:
            raise LinkError(f"{self.name}: link is not open")
        return self._boards

    def _release(self) -> None:
        boards, self._boards = self._boards, None
        if boards is not None:
            for kind, n in boards.errors().items():
                if n and kind != "seq_restart":
                    self._carried[kind] = self._carried.get(kind, 0) + n
            boards.close()
