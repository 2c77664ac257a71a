"""HostSession <-> BoardEngine over real clients: pyserial on a pty pair, pyserial socket://, python-can.

The board runs in a thread stepping its engine; every wait has a deadline.
The in-memory backend is an ideal servo: the measured position is the goal.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import threading
import time
import tty

import can
import pytest
import serial
from sim_support import wait_until

import firmware_protocol as fp
from firmware_protocol import BoardState, FaultCode, JointError, NackCode, WatchdogAction

JOINTS = (11, 12, 13)
NAMES = ("l_hip", "l_knee", "l_ankle")


class MemoryBackend:
    """Trivial board hardware: ideal servos, optional IMU and foot sensors, a log of what was asked."""

    def __init__(self, imu: bool = True, joints: tuple[int, ...] = JOINTS):
        self.joints = joints
        self.goal = dict.fromkeys(joints, 0.0)
        self.torque = dict.fromkeys(joints, False)
        self.holds = 0
        self.drops = 0
        self.has_imu = imu

    def joint_state(self, t_us):
        js = self.joints
        err = tuple(0 if self.torque[j] else int(JointError.TORQUE_OFF) for j in js)
        return fp.JointState(t_us, js, tuple(self.goal[j] for j in js), (0.0,) * len(js),
                             tuple(0.5 if self.torque[j] else 0.0 for j in js), err)

    def foot_sensors(self, t_us):
        return fp.FootSensors(t_us, (0, 1), ((10.0, 10.0, 10.0, 10.0),) * 2, (0.0, 0.0), (0.0, 0.0))

    def imu(self, t_us):
        return fp.Imu(t_us, (1.0, 0.0, 0.0, 0.0), (0.0,) * 3, (0.0, 0.0, 9.75)) if self.has_imu else None

    def supply_voltage(self):
        return 12.0

    def set_goals(self, ids, positions):
        self.goal.update(zip(ids, positions, strict=True))

    def set_torque(self, ids, enable):
        self.torque.update(zip(ids, enable, strict=True))

    def hold(self):
        self.holds += 1

    def drop_torque(self):
        self.drops += 1
        self.torque = dict.fromkeys(self.joints, False)


@contextlib.contextmanager
def running(engine: fp.BoardEngine):
    """Step the board engine in a thread until the block ends."""
    stop = threading.Event()
    failure = []

    def loop():
        try:
            while not stop.is_set():
                engine.step(timeout=0.002)
        except Exception as err:  # surfaced in the test below
            failure.append(err)

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    try:
        yield engine
    finally:
        stop.set()
        thread.join(timeout=5)
        assert not thread.is_alive()
        if failure:
            raise failure[0]


def wait_for(host: fp.HostSession, predicate, timeout: float = 2.0) -> list:
    """Poll the host until predicate(messages so far) holds; fail at the deadline."""
    seen = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        seen += host.poll(timeout=0.005)
        if predicate(seen):
            return seen
    raise AssertionError(f"condition not met within {timeout} s; got {[type(m).__name__ for m in seen][-10:]}")


@contextlib.contextmanager
def pty_null_modem():
    """Two ptys whose masters are cross-connected: a serial cable between two real tty paths."""
    pairs = [os.openpty(), os.openpty()]
    for _, slave in pairs:
        tty.setraw(slave)  # a real UART does not echo, even before the program on it opens it
    stop_r, stop_w = os.pipe()
    masters = [pairs[0][0], pairs[1][0]]

    def bridge():
        while True:
            ready, _, _ = select.select([*masters, stop_r], [], [], 1.0)
            if stop_r in ready:
                return
            for i, fd in enumerate(masters):
                if fd in ready:
                    try:
                        data = os.read(fd, 65536)
                    except OSError:
                        continue
                    os.write(masters[1 - i], data)

    thread = threading.Thread(target=bridge, daemon=True)
    thread.start()
    try:
        yield os.ttyname(pairs[0][1]), os.ttyname(pairs[1][1])
    finally:
        os.write(stop_w, b"x")
        thread.join(timeout=5)
        for fd in (*masters, pairs[0][1], pairs[1][1], stop_r, stop_w):
            os.close(fd)


@contextlib.contextmanager
def tcp_relay():
    """A 127.0.0.1 listener that accepts two connections and relays bytes between them."""
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    stop = threading.Event()

    def relay():
        server.settimeout(5)
        a, _ = server.accept()
        b, _ = server.accept()
        with a, b:
            while not stop.is_set():
                ready, _, _ = select.select([a, b], [], [], 0.1)
                for s in ready:
                    data = s.recv(65536)
                    if not data:
                        return
                    (b if s is a else a).sendall(data)

    thread = threading.Thread(target=relay, daemon=True)
    thread.start()
    try:
        yield f"socket://127.0.0.1:{port}"
    finally:
        stop.set()
        thread.join(timeout=5)
        server.close()


@contextlib.contextmanager
def link(kind: str):
    """(host transport, board transport) over a pty pair, a TCP relay or a virtual CAN bus."""
    if kind == "pty":
        with pty_null_modem() as (a, b):
            host, board = fp.SerialTransport(a), fp.SerialTransport(b, role="board")
            try:
                yield host, board
            finally:
                host.close()
                board.close()
    elif kind == "socket":
        with tcp_relay() as url:
            host = fp.SerialTransport(url)
            board = fp.SerialTransport(url, role="board")
            try:
                yield host, board
            finally:
                host.close()
                board.close()
    else:
        channel = f"fw-{time.monotonic_ns()}"
        with can.Bus(interface="virtual", channel=channel) as hb, can.Bus(interface="virtual", channel=channel) as bb:
            yield fp.CanTransport(hb, 5), fp.CanTransport(bb, 5, role="board")


def make_board(transport, backend, **kw) -> fp.BoardEngine:
    return fp.BoardEngine(transport, backend, joint_ids=JOINTS, joint_names=NAMES, **kw)


@pytest.mark.parametrize("kind", ["pty", "socket", "can"])
def test_session_commands_reach_the_servos_and_state_comes_back(kind):
    backend = MemoryBackend()
    with link(kind) as (host_t, board_t), running(make_board(board_t, backend)):
        host = fp.HostSession(host_t)
        ack = host.connect(timeout=2.0)
        assert (ack.joint_ids, ack.joint_names, ack.schema_hash) == (JOINTS, NAMES, fp.SCHEMA_HASH)
        host.set_torque(JOINTS, True)
        assert all(backend.torque.values())
        host.set_rates(joint_state_hz=200, foot_sensors_hz=50, imu_hz=50, heartbeat_hz=20)
        seq = host.send_goals((11, 13), (0.25, -0.5))
        seen = wait_for(host, lambda ms: any(isinstance(m, fp.JointState) and m.position == (0.25, 0.0, -0.5)
                                             for m in ms)
                        and any(isinstance(m, fp.Imu) for m in ms) and any(isinstance(m, fp.FootSensors) for m in ms))
        assert backend.goal == {11: 0.25, 12: 0.0, 13: -0.5}
        js = [m for m in seen if isinstance(m, fp.JointState)][-1]
        assert js.current == (0.5, 0.5, 0.5) and js.error == (0, 0, 0)
        wait_for(host, lambda _: host.health.status is not None and host.health.status.last_cmd_seq == seq)
        status = host.health.status
        assert (status.state, status.torque_mask, status.watchdog_timeout_ms) == (BoardState.ACTIVE, 0b111, 200)
        assert host.health.alive(time.monotonic(), 0.3)
        assert not any(host.errors.values())
        assert not any(v for k, v in board_t.errors.items() if k != "seq_gap")


@pytest.mark.parametrize("action", [WatchdogAction.HOLD, WatchdogAction.DROP_TORQUE])
def test_watchdog_trips_when_the_host_goes_quiet_and_recovers(action):
    backend = MemoryBackend()
    with link("pty") as (host_t, board_t), running(make_board(board_t, backend)) as board:
        host = fp.HostSession(host_t, watchdog_timeout=0.2, watchdog_action=action)
        host.connect()
        host.set_torque(JOINTS, True)
        host.send_goals(JOINTS, (0.1, 0.2, 0.3))
        t0 = time.monotonic()
        while time.monotonic() - t0 < 0.3:  # a healthy control loop: polls (and so heartbeats) keep it alive
            host.poll(timeout=0.01)
        assert board.state == BoardState.ACTIVE and backend.holds == backend.drops == 0
        # the control loop stalls: no poll, no heartbeat; the board's 0.2 s watchdog acts
        assert wait_until(lambda: board.state != BoardState.ACTIVE, timeout=3.0)
        seen = wait_for(host, lambda ms: any(isinstance(m, fp.Fault) for m in ms))
        fault = next(m for m in seen if isinstance(m, fp.Fault))
        assert fault.code == FaultCode.WATCHDOG_EXPIRED and fault.value >= 0.2
        if action == WatchdogAction.HOLD:
            assert board.state == BoardState.HOLDING and backend.holds == 1 and all(backend.torque.values())
            host.send_goals(JOINTS, (0.0, 0.0, 0.0))
        else:
            assert board.state == BoardState.LIMP and backend.drops == 1 and not any(backend.torque.values())
            host.set_torque(JOINTS, True)
        wait_for(host, lambda _: host.health.board_state == BoardState.ACTIVE)


def test_without_the_watchdog_a_stalled_host_leaves_the_robot_moving():
    """The failure the watchdog exists for: with it disabled, nothing stops the servos."""
    backend = MemoryBackend()
    with link("pty") as (host_t, board_t), running(make_board(board_t, backend)) as board:
        host = fp.HostSession(host_t, watchdog_timeout=0.0)
        host.connect()
        host.set_torque(JOINTS, True)
        # 0.4 s without a heartbeat, twice a watchdog's 0.2 s: nothing stops the servos
        assert not wait_until(lambda: board.state != BoardState.ACTIVE or backend.holds or backend.drops, timeout=0.4)
        assert board.state == BoardState.ACTIVE and backend.holds == backend.drops == 0


def test_estop_latches_and_refuses_motion_until_released():
    backend = MemoryBackend()
    with link("can") as (host_t, board_t), running(make_board(board_t, backend)) as board:
        host = fp.HostSession(host_t)
        host.connect()
        host.set_torque(JOINTS, True)
        host.estop()
        assert board.state == BoardState.ESTOP and backend.drops == 1 and not any(backend.torque.values())
        host.send_goals(JOINTS, (1.0, 1.0, 1.0))
        wait_for(host, lambda _: host.health.nacks.get(NackCode.ESTOPPED) == 1)
        assert backend.goal == dict.fromkeys(JOINTS, 0.0)
        with pytest.raises(fp.CommandRefused, match="ESTOPPED"):
            host.set_torque(JOINTS, True)
        host.release_estop()
        assert board.state == BoardState.ACTIVE and not any(backend.torque.values())  # torque stays off
        host.set_torque(JOINTS, True)
        assert all(backend.torque.values())


def test_refused_commands_name_the_reason():
    with link("can") as (host_t, board_t), running(make_board(board_t, MemoryBackend(imu=False),
                                                              capabilities=fp.Capability.JOINT_CURRENT)):
        host = fp.HostSession(host_t)
        host.connect()
        with pytest.raises(fp.CommandRefused, match="UNKNOWN_JOINT") as err:
            host.set_torque((11, 99), True)
        assert err.value.code == NackCode.UNKNOWN_JOINT
        with pytest.raises(fp.CommandRefused, match="UNSUPPORTED"):
            host.set_rates(100, 0, 100, 10)  # this board has no IMU
        with pytest.raises(fp.CommandRefused, match="BAD_VALUE"):
            host.set_rates(5000, 0, 0, 10)


def test_mismatched_firmware_is_refused_and_stays_disconnected():
    backend = MemoryBackend()
    old = fp.SCHEMA_HASH ^ 0xFF
    with link("pty") as (host_t, board_t), running(make_board(board_t, backend, schema_hash=old)) as board:
        host = fp.HostSession(host_t)
        with pytest.raises(fp.HandshakeError) as err:
            host.connect()
        assert f"{old:#018x}" in str(err.value) and f"{fp.SCHEMA_HASH:#018x}" in str(err.value)
        assert board.state == BoardState.DISCONNECTED
        host_t.send(fp.Torque(JOINTS, (True,) * 3))  # a host that ignores the refusal gets nowhere
        wait_for(host, lambda ms: any(isinstance(m, fp.Nack) and m.code == NackCode.NOT_CONNECTED for m in ms))
        assert not any(backend.torque.values())


def test_no_board_is_a_handshake_timeout():
    with link("can") as (host_t, _board_t):
        host = fp.HostSession(host_t, ack_timeout=0.05)
        t0 = time.monotonic()
        with pytest.raises(fp.HandshakeError, match="no HELLO_ACK within 0.2 s"):
            host.connect(timeout=0.2)
        assert time.monotonic() - t0 < 1.0
        with pytest.raises(fp.ProtocolError, match="not connected"):
            host.send_goals((11,), (0.0,))


def test_loop_url_echo_is_counted_not_delivered():
    port = fp.SerialTransport("loop://")
    port.send(fp.Estop())
    assert port.receive(timeout=0.1) == []
    assert port.errors["wrong_direction"] == 1


def test_unopenable_port_is_a_link_error():
    with pytest.raises(fp.LinkError, match="/nonexistent/ttyX: cannot open serial port"):
        fp.SerialTransport("/nonexistent/ttyX")


def test_broadcast_estop_stops_every_node_and_nobody_answers():
    channel = f"fw-{time.monotonic_ns()}"
    with (can.Bus(interface="virtual", channel=channel) as hb, can.Bus(interface="virtual", channel=channel) as b3,
          can.Bus(interface="virtual", channel=channel) as b4, can.Bus(interface="virtual", channel=channel) as spy):
        backends = [MemoryBackend(), MemoryBackend()]
        quiet = fp.StreamRates(0, 0, 0, 0)
        boards = [make_board(fp.CanTransport(bus, node, role="board"), be, rates=quiet, status_period=60)
                  for bus, node, be in ((b3, 3, backends[0]), (b4, 4, backends[1]))]
        for board in boards:
            board.step()  # initial STATUS
        while spy.recv(0) is not None:
            pass
        fp.CanTransport(hb, 3).send(fp.Estop(True), broadcast=True)
        deadline = time.monotonic() + 2
        while time.monotonic() < deadline and not all(b.state == BoardState.ESTOP for b in boards):
            for board in boards:
                board.step(timeout=0.005)
        assert all(b.state == BoardState.ESTOP for b in boards) and all(be.drops == 1 for be in backends)
        frames = []
        while (frame := spy.recv(0.05)) is not None:
            frames.append(frame)
        (estop,) = [f for f in frames if f.arbitration_id >> 21 == 0x01]
        assert estop.arbitration_id >> 13 & 0x7F == 0  # node 0: broadcast
        assert not [f for f in frames if f.arbitration_id >> 21 in (0x18, 0x19)]  # no ACK / NACK storm


def test_broadcast_goals_reach_each_node_for_the_joints_it_owns():
    """Sync write on CAN: one transfer to node 0, each servo node takes its own joint."""
    channel = f"fw-{time.monotonic_ns()}"
    buses = [can.Bus(interface="virtual", channel=channel) for _ in range(4)]
    try:
        left, right = MemoryBackend(joints=(11,)), MemoryBackend(joints=(21,))
        boards = [fp.BoardEngine(fp.CanTransport(buses[0], 3, role="board"), left, joint_ids=(11,),
                                 joint_names=("l_hip",)),
                  fp.BoardEngine(fp.CanTransport(buses[1], 4, role="board"), right, joint_ids=(21,),
                                 joint_names=("r_hip",))]
        with running(boards[0]), running(boards[1]):
            hosts = [fp.HostSession(fp.CanTransport(buses[2], 3)), fp.HostSession(fp.CanTransport(buses[3], 4))]
            for host in hosts:
                host.connect()
            hosts[0].transport.send(fp.SetGoals(0, (11, 21), (0.5, -0.5)), broadcast=True)
            deadline = time.monotonic() + 2
            while time.monotonic() < deadline and (left.goal[11], right.goal[21]) != (0.5, -0.5):
                for host in hosts:
                    host.poll(timeout=0.005)
            assert (left.goal, right.goal) == ({11: 0.5}, {21: -0.5})
            assert not hosts[0].health.nacks and not hosts[1].health.nacks
    finally:
        for bus in buses:
            bus.shutdown()


class FlakyBus:
    """A real virtual bus whose transmit side can be failed, as python-can reports bus-off (CanOperationError)."""

    def __init__(self, bus):
        self.bus = bus
        self.down = False
        self.channel_info = "flaky"

    def send(self, msg, timeout=None):
        if self.down:
            raise can.CanOperationError("Transmit buffer full (bus-off)")
        self.bus.send(msg, timeout)

    def recv(self, timeout=None):
        return self.bus.recv(timeout)


def test_bus_off_is_ridden_out_and_reported_on_recovery():
    clock = [0.0]
    channel = f"fw-{time.monotonic_ns()}"
    with can.Bus(interface="virtual", channel=channel) as hb, can.Bus(interface="virtual", channel=channel) as bb:
        flaky = FlakyBus(bb)
        board = make_board(fp.CanTransport(flaky, 2, role="board"), MemoryBackend(), clock=lambda: clock[0])
        host_t = fp.CanTransport(hb, 2)
        flaky.down = True
        for _ in range(50):  # 0.5 s of bus-off: the engine keeps stepping without raising
            clock[0] += 0.01
            board.step()
        assert board.transport.tx_failed > 0
        flaky.down = False
        clock[0] += 0.01
        board.step()
        got = []
        while (rx := host_t.receive(timeout=0.05)) or not got:
            got += [r.message for r in rx]
            if not rx:
                break
        (fault,) = [m for m in got if isinstance(m, fp.Fault)]
        assert fault.code == FaultCode.LINK_RECOVERED and 0.45 <= fault.value <= 0.55
        host_t.bus = FlakyBus(hb)
        host_t.bus.down = True
        with pytest.raises(fp.LinkError, match="bus-off"):
            host_t.send(fp.Estop())
        assert host_t.errors["tx_failed"] == 1


def test_stream_rates_follow_the_board_clock_exactly():
    clock = [0.0]
    channel = f"fw-{time.monotonic_ns()}"
    with can.Bus(interface="virtual", channel=channel) as hb, can.Bus(interface="virtual", channel=channel) as bb:
        board = make_board(fp.CanTransport(bb, 1, role="board"), MemoryBackend(), clock=lambda: clock[0],
                           rates=fp.StreamRates(250, 50, 100, 10), status_period=0.5)
        host_t = fp.CanTransport(hb, 1)
        for _ in range(1000):  # one simulated second in 1 ms steps
            board.step()
            clock[0] += 0.001
        got = []
        while rx := host_t.receive(timeout=0.05):
            got += [r.message for r in rx]
        counts = {name: sum(type(m).__name__ == name for m in got)
                  for name in ("JointState", "FootSensors", "Imu", "Heartbeat", "Status")}
        assert counts == {"JointState": 250, "FootSensors": 50, "Imu": 100, "Heartbeat": 10, "Status": 2}
        times = [m.board_time_us for m in got if isinstance(m, fp.JointState)]
        assert all(b - a == 4000 for a, b in zip(times, times[1:], strict=False))


def test_port_read_failure_is_a_link_error():
    port = serial.serial_for_url("loop://", timeout=0)
    transport = fp.SerialTransport(port, role="board")
    port.close()
    with pytest.raises(fp.LinkError, match="read failed"):
        transport.receive()


class SlowBoard:
    """A host-side transport to a board that acknowledges every command ``latency`` s after it was sent (None:
    never), on a simulated clock that a receive advances by its timeout."""

    is_board = False
    name = "slow board"

    def __init__(self, latency: float | None) -> None:
        self.latency, self.now, self.seq, self.sent = latency, 0.0, 0, 0
        self.replies: list[tuple[float, fp.Ack]] = []
        self.errors: dict[str, int] = {}

    def clock(self) -> float:
        return self.now

    def send(self, msg) -> int:
        self.seq += 1
        self.sent += 1
        if self.latency is not None:
            self.replies.append((self.now + self.latency, fp.Ack(msg.spec.msg_id, self.seq)))
        return self.seq

    def receive(self, timeout: float = 0.0) -> list:
        self.now += max(timeout, 1e-3)
        due = [fp.Received(ack, 0) for t, ack in self.replies if t <= self.now]
        self.replies = [(t, ack) for t, ack in self.replies if t > self.now]
        return due


def own_ack_only(session: fp.HostSession, msg) -> None:
    """The policy before: three tries of ``ack_timeout``, each waiting for its own ACK only."""
    for _ in range(3):
        key = (msg.spec.msg_id, session.transport.send(msg))
        session._wait(lambda _m, key=key: key in session._replies, session.ack_timeout)
        if session._replies.pop(key, None) is not None:
            return
    raise fp.LinkError(f"{session.transport.name}: no ACK for {msg.spec.name} after 3 tries")


@pytest.mark.parametrize("latency", [0.6, 1.5])
def test_a_late_ack_to_any_try_counts_until_the_deadline(latency):
    # a loaded host read the first try's ACK late, while its third try waited for its own ACK: "no ACK for TORQUE
    # after 3 tries" (can: 0.25 s a try); any try's ACK now counts, and tries go on until the deadline
    board = SlowBoard(latency)
    fp.HostSession(board, ack_timeout=0.25, retries=2, ack_deadline=2.0, clock=board.clock).estop()
    assert board.now == pytest.approx(latency, abs=0.01)  # answered when the first try's ACK came
    before = SlowBoard(latency)
    session = fp.HostSession(before, ack_timeout=0.25, retries=2, clock=before.clock)
    with pytest.raises(fp.LinkError, match="no ACK for ESTOP after 3 tries"):
        own_ack_only(session, fp.Estop(True))


def test_a_board_that_never_acknowledges_is_one_line_after_the_deadline():
    board = SlowBoard(None)
    with pytest.raises(fp.LinkError) as err:
        fp.HostSession(board, ack_timeout=0.25, retries=2, ack_deadline=2.0, clock=board.clock).estop()
    assert str(err.value) == "slow board: no ACK for ESTOP after 8 tries in 2 s"
    assert board.sent == 8 and board.now == pytest.approx(2.0, abs=0.01)
