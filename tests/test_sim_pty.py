"""PtyPort: a real pty, a stable symlinked path, timed replies, unplug/replug, clean shutdown."""

from __future__ import annotations

import math
import os
import termios
import time

import pytest
import serial
from sim_support import short_gil_switch, wait_until  # noqa: F401 - short_gil_switch is a fixture

from sim_devices.pty_port import _SPEEDS, MAX_PENDING_OUTPUT, PortServer, PtyPort

pytestmark = pytest.mark.usefixtures("short_gil_switch")


class Echo:
    """Answers each chunk upper-cased after ``delay`` s; optional one-off timed message."""

    def __init__(self, delay: float = 0.0, message_at: float = math.inf, burst: int = 0) -> None:
        self.delay = delay
        self.message_at = message_at
        self.burst = burst
        self.polls: list[float] = []
        self.received: list[bytes] = []

    def on_bytes(self, data: bytes, now: float):
        self.received.append(data)
        if self.burst:
            return [(now, bytes(65536))] * self.burst
        return [(now + self.delay, data.upper())]

    def poll(self, now: float):
        self.polls.append(now)
        self.message_at = math.inf
        return [(now, b"tick")]

    def next_deadline(self) -> float:
        return self.message_at


class Broken(Echo):
    def on_bytes(self, data: bytes, now: float):
        raise ZeroDivisionError("device bug")


def test_path_is_a_stable_symlink_to_a_real_pty():
    with PtyPort(Echo(), name="ttyTEST") as port:
        assert os.path.islink(port.path) and os.path.basename(port.path) == "ttyTEST"
        assert os.readlink(port.path).startswith("/dev/pts/")
        with serial.Serial(port.path, 115200, timeout=1.0) as client:
            client.write(b"hello")
            assert client.read(5) == b"HELLO"


def test_replies_are_written_in_due_order_at_their_due_time():
    device = Echo(delay=0.03)
    with PtyPort(device) as port, serial.Serial(port.path, 115200, timeout=1.0) as client:
        start = time.perf_counter()
        client.write(b"a")
        assert wait_until(lambda: device.received)  # "a" is in before "b" is written: due first
        client.write(b"b")
        assert client.read(1) == b"A"
        assert time.perf_counter() - start >= 0.03
        assert client.read(1) == b"B"


def test_poll_runs_at_the_device_deadline():
    device = Echo()
    with PtyPort(device) as port, serial.Serial(port.path, 115200, timeout=1.0) as client:
        start = time.monotonic()
        device.message_at = start + 0.05
        client.write(b"x")  # wakes the port so it sees the new deadline
        assert client.read(5) == b"Xtick"
        assert device.polls and device.polls[0] >= start + 0.05


def test_vanish_gives_client_errors_and_restore_allows_reopening_the_same_path():
    with PtyPort(Echo()) as port:
        client = serial.Serial(port.path, 115200, timeout=0.5)
        port.vanish()
        assert not port.present and not os.path.exists(port.path)
        with pytest.raises(serial.SerialException):
            client.write(b"x")
        with pytest.raises(serial.SerialException):
            client.read(1)
        client.close()
        with pytest.raises(serial.SerialException):
            serial.Serial(port.path, 115200)
        port.restore()
        assert port.present and os.path.exists(port.path)
        with serial.Serial(port.path, 115200, timeout=1.0) as again:
            again.write(b"back")
            assert again.read(4) == b"BACK"


def test_line_speed_is_the_clients_setting():
    with PtyPort(Echo()) as port:
        with serial.Serial(port.path, 57600):
            assert port.line_speed() == 57600
        with serial.Serial(port.path, 1_000_000):
            assert port.line_speed() == 1_000_000
        port.vanish()
        assert port.line_speed() is None


def test_line_speed_reads_every_rate_as_the_termios_module_does():
    """The kept-buffer ioctl gives each speed (and an unknown one) as `termios.tcgetattr`'s output speed."""
    with PtyPort(Echo()) as port:
        client = os.open(port.path, os.O_RDWR | os.O_NOCTTY)
        try:
            for code in [*_SPEEDS, termios.B50, termios.B0]:
                attrs = termios.tcgetattr(client)
                attrs[4] = attrs[5] = code
                termios.tcsetattr(client, termios.TCSANOW, attrs)
                assert port.line_speed() == _SPEEDS.get(termios.tcgetattr(client)[5])
        finally:
            os.close(client)


def test_output_to_a_client_that_never_reads_is_bounded():
    with PtyPort(Echo(burst=32)) as port, serial.Serial(port.path, 115200) as client:
        client.write(b"go")  # 2 MiB of replies, never read
        assert wait_until(lambda: port.dropped_output_bytes > 0)
        assert len(port._out) <= MAX_PENDING_OUTPUT


def test_close_stops_the_thread_and_removes_the_path():
    port = PtyPort(Echo())
    directory = os.path.dirname(port.path)
    port.close()
    assert wait_until(lambda: port._server.thread is None)
    assert not os.path.exists(directory)
    port.close()  # idempotent


def test_device_errors_surface_on_close():
    port = PtyPort(Broken())
    with serial.Serial(port.path, 115200) as client:
        client.write(b"x")
        assert wait_until(lambda: port.error is not None)
    with pytest.raises(RuntimeError, match="device bug"):
        port.close()


def test_ports_served_by_one_thread_work_as_ports_of_their_own():
    server = PortServer()
    device = Echo(delay=0.02)
    with PtyPort(device, name="ttyA", server=server) as a, PtyPort(Echo(), name="ttyB", server=server) as b:
        broken = PtyPort(Broken(), name="ttyC", server=server)
        assert server.thread is not None and a._served_elsewhere()
        with serial.Serial(a.path, 115200, timeout=1.0) as ca, serial.Serial(b.path, 115200, timeout=1.0) as cb, \
                serial.Serial(broken.path, 115200, timeout=1.0) as cc:
            start = time.perf_counter()
            ca.write(b"a")
            cb.write(b"b")
            cc.write(b"c")  # its device fails: that port stops, the others go on
            assert cb.read(1) == b"B"
            assert ca.read(1) == b"A" and time.perf_counter() - start >= 0.02  # timed as on a port of its own
            assert wait_until(lambda: broken.error is not None)
            ca.write(b"x")
            assert ca.read(1) == b"X"
            b.vanish()  # unplugged through the serving thread
            assert not os.path.exists(b.path)
            b.restore()
        with pytest.raises(RuntimeError, match="device bug"):
            broken.close()
        with serial.Serial(b.path, 115200, timeout=1.0) as again:
            again.write(b"back")
            assert again.read(4) == b"BACK"
    assert wait_until(lambda: server.thread is None)  # no port left: the thread ended


def test_a_port_added_to_an_idle_server_is_served_at_once():
    """The server's thread, waiting with no deadline on its first port, serves a second port added then
    (on main it was watched from the first port's next traffic only)."""
    server = PortServer()
    with PtyPort(Echo(), name="ttyA", server=server), serial.Serial(timeout=1.0) as client:
        time.sleep(0.05)  # the thread waits on ttyA alone, with no timeout
        with PtyPort(Echo(), name="ttyB", server=server) as b:
            client.port = b.path
            client.open()
            client.write(b"b")
            assert client.read(1) == b"B"
            client.close()


class DueAt(Echo):
    """Answers at the absolute time ``due`` (monotonic s), whenever asked."""

    def __init__(self, due: float) -> None:
        super().__init__()
        self.due = due

    def on_bytes(self, data: bytes, now: float):
        return [(self.due, data.upper())]


class LoggedPort(PtyPort):
    """A PtyPort that notes (when, due) for every reply it writes."""

    written: list[tuple[float, float]]

    def _flush(self, master: int, now: float) -> None:
        t = time.monotonic()
        self.written = getattr(self, "written", []) + [(t, due) for due, _, _ in self._pending if due <= now]
        super()._flush(master, now)


def test_replies_due_close_together_on_one_server_each_leave_at_their_time():
    """Two spinning ports of one server with replies due 50 us apart (two buses' replies): each is written
    once due, never before (the server spins from one to the next in one pass)."""
    server = PortServer()
    first, second = DueAt(math.inf), DueAt(math.inf)
    with LoggedPort(first, name="ttyA", spin=True, server=server) as a, \
            LoggedPort(second, name="ttyB", spin=True, server=server) as b, \
            serial.Serial(a.path, 115200, timeout=1.0) as ca, serial.Serial(b.path, 115200, timeout=1.0) as cb:
        first.due = time.monotonic() + 0.02
        second.due = first.due + 5e-5
        ca.write(b"a")
        cb.write(b"b")
        assert ca.read(1) == b"A" and cb.read(1) == b"B"
        for port, device in ((a, first), (b, second)):
            [(when, flushed)] = port.written
            assert flushed == device.due and when >= device.due
