"""A simulated serial device served on a real pseudo-terminal.

`PtyPort` opens a pty pair (``os.openpty``, slave side in raw mode) and serves the
master side from a `PortServer`'s background thread (its own, or one shared by the ports of
one robot's buses). Unmodified clients (pyserial,
dynamixel-sdk, python-can's slcan) open :attr:`PtyPort.path`, a symlink in a
private temporary directory that points at the current ``/dev/pts/N``. The
symlink is the stable name: :meth:`PtyPort.vanish` closes the pty and removes the
link (clients get I/O errors, as when a USB adapter is unplugged) and
:meth:`PtyPort.restore` opens a fresh pty and re-points the link, so a client can
reopen the same path.

The device behind the port is any object with the `ByteDevice` methods. All of
its methods are called from the port thread, with ``now`` from
``time.monotonic()`` in seconds. Replies are ``(due, bytes)`` pairs: the port
writes each payload once ``due`` has passed, in due order, so devices can model
response delays without sleeping. With ``spin=True`` (a device whose timing is a bus
model, e.g. the Dynamixel chain) it spins through the last `SPIN_BEFORE_DUE_S` before a
reply is due, so the reply leaves on time rather than when a late select() wake-up allows
(the simulated bus's timing is the model's, not the host's); spinning holds the GIL, so
devices that send many small replies (CAN frames, board streams) do not.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import heapq
import itertools
import math
import os
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty
import weakref
from collections.abc import Iterable
from typing import Protocol

Reply = tuple[float, bytes]

# A reply due this soon is waited for by spinning rather than in select(), whose wake-up comes
# tens of microseconds late (more on a busy machine): the simulated bus delivers on time.
SPIN_BEFORE_DUE_S = 1e-4

# Bytes waiting for a client that does not read are dropped beyond this bound,
# as a real adapter's FIFO would overflow; it keeps memory bounded.
MAX_PENDING_OUTPUT = 64 * 1024

# the line speed's code (`c_cflag & CBAUD`, as glibc's cfgetospeed gives it) -> baud
_SPEEDS = {
    getattr(termios, f"B{rate}"): rate
    for rate in (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600,
                 1000000, 1152000, 1500000, 2000000, 2500000, 3000000, 3500000, 4000000)
    if hasattr(termios, f"B{rate}")
}
# The slave's termios as the kernel's TCGETS fills it (its c_cflag the third 32-bit word on every Linux
# architecture); 64 bytes is more than any architecture's struct termios.
_TERMIOS_BYTES = 64
_CFLAG = struct.Struct("=8xI")


class ByteDevice(Protocol):
    """What a `PtyPort` serves: a byte-stream device driven by the port thread."""

    def on_bytes(self, data: bytes, now: float) -> Iterable[Reply]:
        """Consume bytes written by the client at monotonic time ``now`` (s)."""

    def poll(self, now: float) -> Iterable[Reply]:
        """Do timed work that is due at ``now`` (s); called once ``now >= next_deadline()``."""

    def next_deadline(self) -> float:
        """Monotonic time (s) at which `poll` must next run, or ``math.inf``."""


class PtyPort:
    """Serve ``device`` on a pty reachable at the stable path :attr:`path`.

    Serving starts at construction and stops on :meth:`close` (also the context-manager exit), from
    ``server``'s thread (shared with other ports) or, without one, from a `PortServer` of its own. An
    exception raised by the device is kept and re-raised by :meth:`close`, so device bugs surface in the
    caller.
    """

    def __init__(self, device: ByteDevice, name: str = "ttySIM", spin: bool = False,
                 server: PortServer | None = None) -> None:
        self._device = device
        self._spin_s = SPIN_BEFORE_DUE_S if spin else 0.0
        self._dir = tempfile.mkdtemp(prefix="livezmp-pty-")
        # Remove the directory at exit even if close() is never called.
        self._cleanup = weakref.finalize(self, shutil.rmtree, self._dir, ignore_errors=True)
        self.path = os.path.join(self._dir, name)
        self._lock = threading.RLock()
        self._master = -1
        self._slave = -1
        self._termios = bytearray(_TERMIOS_BYTES)  # the slave's termios, read into this at each line_speed()
        self._pending: list[tuple[float, int, bytes]] = []
        self._seq = itertools.count()
        self._out = bytearray()
        self._unplug_requests: list[threading.Event] = []
        self._closed = False
        self.error: Exception | None = None
        self.dropped_output_bytes = 0
        self._selected = -1  # the master the last select watched
        self._deadline = -math.inf  # the device's next_deadline() as asked before that select (monotonic s)
        self._open_pty()
        # a port of its own is served as a server's only port: one serving loop for both
        self._server = server if server is not None else PortServer(f"pty-{name}")
        self._server.add(self)

    # -- public API -------------------------------------------------------------------------------

    @property
    def present(self) -> bool:
        """True while the pty exists and :attr:`path` resolves to it."""
        return self._master >= 0

    def vanish(self) -> None:
        """Unplug: close the pty, drop queued output and remove the symlink; returns when done."""
        if not self._served_elsewhere():
            self._unplug()
            return
        # The serving thread may be blocked in select() on the pty: let it close the descriptors.
        done = threading.Event()
        with self._lock:
            self._unplug_requests.append(done)
        self._server.wake()
        done.wait(timeout=5.0)

    def _served_elsewhere(self) -> bool:
        """Whether another thread than this one serves the port (and so must be asked to unplug it)."""
        return self._server.serves(self) and threading.current_thread() is not self._server.thread

    def restore(self) -> None:
        """Plug back in: open a new pty and point :attr:`path` at it."""
        with self._lock:
            if self._master < 0 and not self._closed:
                self._open_pty()
        self._server.wake()

    def line_speed(self) -> int | None:
        """The client's configured line speed in baud, or None if unknown or absent.

        Read from the slave's termios at every call (one ioctl into a kept buffer): the client may have
        changed it since, and only the kernel knows (see docs/live_loop.md, session 22)."""
        with self._lock:
            if self._slave < 0:
                return None
            try:
                fcntl.ioctl(self._slave, termios.TCGETS, self._termios)
            except OSError:
                return None
            return _SPEEDS.get(_CFLAG.unpack_from(self._termios)[0] & termios.CBAUD)

    def close(self) -> None:
        """Stop serving, close the pty and remove the temporary directory."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._server.remove(self)
        self.vanish()
        self._cleanup()
        if self.error is not None:
            raise RuntimeError(f"simulated device on {self.path} failed: {self.error!r}") from self.error

    def __enter__(self) -> PtyPort:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals: the serving thread's steps, each under the port's lock -------------------------

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        link = self.path + ".new"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(link)
        os.symlink(os.ttyname(slave), link)
        os.replace(link, self.path)
        self._master, self._slave = master, slave

    def _unplug(self) -> None:
        with self._lock:
            if self._master < 0:
                return
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.path)
            os.close(self._master)
            os.close(self._slave)
            self._master = self._slave = -1
            self._pending.clear()
            self._out.clear()

    def _waits(self) -> tuple[int, bool, float] | None:
        """What the next select waits on: (the master to read, -1 for none; whether to wait to write to it;
        when to wake at the latest, monotonic s); None once closed."""
        with self._lock:
            if self._closed:
                return None
            if self._unplug_requests:
                self._unplug()
                for done in self._unplug_requests:
                    done.set()
                self._unplug_requests.clear()
            master = self._selected = self._master
            self._deadline = self._device.next_deadline()
            if self._pending:
                return master, bool(self._out) and master >= 0, min(self._deadline,
                                                                     self._pending[0][0] - self._spin_s)
            return master, bool(self._out) and master >= 0, self._deadline

    def _serve_selected(self, readable: list[int], now: float) -> float:
        """After the select: the client's bytes to the device, its timed work; when the next reply is due."""
        device = self._device
        with self._lock:
            # The pty may have vanished or been replaced while we waited: only read the one we
            # selected on if it is still current.
            master = self._selected
            if master >= 0 and master == self._master and master in readable:
                data = self._read(master)
                if data:
                    self._queue(device.on_bytes(data, now))
            # the deadline asked before the select: bytes taken in since only move it later (the packet's
            # time restarts the bus watchdogs, which on_bytes expired first), and polling early does nothing
            if now >= self._deadline:
                self._queue(device.poll(now))
            return self._pending[0][0] if self._pending else math.inf

    def _flush_due(self, now: float) -> float:
        """The replies due by ``now`` (monotonic s) written; when the next one is due (inf: none, or no pty)."""
        with self._lock:
            if self._master < 0:
                return math.inf
            self._flush(self._master, now)
            return self._pending[0][0] if self._pending else math.inf

    def _read(self, master: int) -> bytes:
        try:
            return os.read(master, 65536)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:  # no client end open: nothing to read
                return b""
            raise

    def _queue(self, replies: Iterable[Reply]) -> None:
        for due, payload in replies:
            heapq.heappush(self._pending, (due, next(self._seq), payload))

    def _flush(self, master: int, now: float) -> None:
        pending = self._pending
        while pending and pending[0][0] <= now:
            self._out += heapq.heappop(pending)[2]
        if len(self._out) > MAX_PENDING_OUTPUT:
            excess = len(self._out) - MAX_PENDING_OUTPUT
            del self._out[:excess]
            self.dropped_output_bytes += excess
        if not self._out:
            return
        try:
            written = os.write(master, self._out)
        except BlockingIOError:
            return
        del self._out[:written]


def _spin_to(reply_due: float, now: float, spin_s: float) -> None:
    """Return at ``reply_due`` if it is within ``spin_s`` of ``now`` (s), at once otherwise."""
    while time.monotonic() < reply_due <= now + spin_s:
        pass  # a reply due within the spin time: written when due, not after select's late wake-up


class PortServer:
    """One thread serving `PtyPort`s (``PtyPort(..., server=...)``): the buses of one simulated robot, or a
    port of its own. Their replies due at the same time leave together, and no port's spin before its reply
    holds the GIL against another port's thread (with a thread each, the second bus's reply waited for the
    first's spin). A pass of the thread: each port's waits asked once (its device's next deadline among
    them), one select on every port's pty and the server's wake-up pipe, each port's bytes taken in and its
    timed work done, then the replies due written (spinning up to its spin time to each). A device's
    exception stops its port only (kept in its ``error``). The thread runs while there are ports to serve."""

    def __init__(self, name: str = "pty-server") -> None:
        self._name = name
        self._ports: list[PtyPort] = []
        self._serving: tuple[PtyPort, ...] = ()  # the ports as the thread's next pass takes them
        self._changed = threading.Condition()
        self._wake_w = -1  # the running thread's wake-up pipe (write end; -1: no thread)
        self.thread: threading.Thread | None = None

    def add(self, port: PtyPort) -> None:
        """Serve ``port`` from now on (the thread's next pass: woken for it)."""
        with self._changed:
            self._ports.append(port)
            self._serving = tuple(self._ports)
            if self.thread is None:
                wake_r, self._wake_w = os.pipe()
                os.set_blocking(wake_r, False)
                self.thread = threading.Thread(target=self._run, args=(wake_r,), name=self._name, daemon=True)
                self.thread.start()
            else:
                self._wake_locked()

    def serves(self, port: PtyPort) -> bool:
        with self._changed:
            return port in self._ports

    def wake(self) -> None:
        """End the thread's wait now: a port was closed, unplugged or plugged back in."""
        with self._changed:
            self._wake_locked()

    def _wake_locked(self) -> None:
        if self._wake_w >= 0:  # the pipe is closed only under this lock, as the thread ends
            with contextlib.suppress(OSError):
                os.write(self._wake_w, b"x")

    def remove(self, port: PtyPort) -> None:
        """Wait (up to 5 s) until the thread has dropped ``port`` (closed: its next pass sees it)."""
        if threading.current_thread() is self.thread:
            self._drop(port)
            return
        with self._changed:
            self._wake_locked()
            self._changed.wait_for(lambda: port not in self._ports, timeout=5.0)

    def _drop(self, port: PtyPort) -> None:
        with self._changed:
            if port in self._ports:
                self._ports.remove(port)
                self._serving = tuple(self._ports)
            self._changed.notify_all()

    def _fail(self, port: PtyPort, exc: Exception) -> None:
        """A device's exception: kept in its port's ``error`` (re-raised by its close), the port dropped."""
        port.error = exc
        self._drop(port)

    def _run(self, wake_r: int) -> None:
        try:
            self._serve(wake_r)
        except Exception as exc:  # the server's own (a select that failed): every port it serves stops with it
            with self._changed:
                for port in self._ports:
                    port.error = port.error or exc
                self._ports.clear()
                self._serving = ()
                self._end(wake_r)

    def _end(self, wake_r: int) -> None:
        """The thread ends (under the lock, no port left): the next add starts another."""
        self.thread = None
        os.close(wake_r)
        os.close(self._wake_w)
        self._wake_w = -1
        self._changed.notify_all()

    def _serve(self, wake_r: int) -> None:
        """Passes until no port is left to serve."""
        while True:
            ports = self._serving
            if not ports:
                with self._changed:
                    if not self._ports:
                        self._end(wake_r)
                        return
                continue
            served, readers, writers, wake_at = self._waits(ports)
            if not served:
                continue
            readers.append(wake_r)
            timeout = None if wake_at == math.inf else max(0.0, wake_at - time.monotonic())
            readable, _, _ = select.select(readers, writers, [], timeout)
            now = time.monotonic()
            if readable and readable[-1] == wake_r:
                with contextlib.suppress(BlockingIOError):
                    os.read(wake_r, 4096)
            due, spin_s = self._take_in(served, readable, now)
            # each reply due within the spin time leaves when due, in this pass: a second bus's reply due just
            # after the first's does not cost another round of select and device calls
            while True:
                _spin_to(due, now, spin_s)
                now = time.monotonic()
                due = self._write_due(served, now)
                if not spin_s or due > now + spin_s:
                    break

    def _waits(self, ports: tuple[PtyPort, ...]) -> tuple[list[PtyPort], list[int], list[int], float]:
        """A pass's start: the ports still served, the ptys to wait to read and to write, when to wake at the
        latest (monotonic s); a closed port dropped."""
        served, readers, writers, wake_at = [], [], [], math.inf
        for port in ports:
            try:
                waits = port._waits()
            except Exception as exc:
                self._fail(port, exc)
                continue
            if waits is None:  # closed
                self._drop(port)
                continue
            served.append(port)
            master, writing, at = waits
            if master >= 0:
                readers.append(master)
                if writing:
                    writers.append(master)
            wake_at = min(wake_at, at)
        return served, readers, writers, wake_at

    def _take_in(self, served: list[PtyPort], readable: list[int], now: float) -> tuple[float, float]:
        """After the select: each port's bytes to its device and its timed work, at ``now`` (monotonic s); when the
        next reply is due and the longest spin before one."""
        due, spin_s = math.inf, 0.0
        for port in served:
            try:
                due = min(due, port._serve_selected(readable, now))
            except Exception as exc:
                self._fail(port, exc)
                continue
            spin_s = max(spin_s, port._spin_s)
        return due, spin_s

    def _write_due(self, served: list[PtyPort], now: float) -> float:
        """Every reply due by ``now`` (monotonic s) written; when the next is due."""
        due = math.inf
        for port in served:
            if port.error is None:
                try:
                    due = min(due, port._flush_due(now))
                except Exception as exc:
                    self._fail(port, exc)
        return due


class PtyDevice:
    """The shared front of a simulated device served on a `PtyPort`: its path, its port,
    what its fault injector injected, ``close`` and the context manager. Subclasses set
    ``_port`` (a `PtyPort`) and ``_faults`` (an injector with ``counters``)."""

    _port: PtyPort

    @property
    def path(self) -> str:
        """Device path to open with the client (stable across vanish/return)."""
        return self._port.path

    @property
    def port(self) -> PtyPort:
        """The pty port, e.g. to `PtyPort.vanish` / `PtyPort.restore` by hand."""
        return self._port

    @property
    def fault_counters(self):
        """What the (current) fault injector injected so far (a `FaultCounters`)."""
        return self._faults.counters

    def close(self) -> None:
        """Stop serving and remove the device path."""
        self._port.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
