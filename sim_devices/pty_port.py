"""A simulated serial device served on a real pseudo-terminal.

`PtyPort` opens a pty pair (``os.openpty``, slave side in raw mode) and serves the
master side from one background thread (or from a `PortServer`'s, shared by the ports of
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
import heapq
import itertools
import math
import os
import select
import shutil
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

_SPEEDS = {
    getattr(termios, f"B{rate}"): rate
    for rate in (9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 576000, 921600,
                 1000000, 1152000, 1500000, 2000000, 2500000, 3000000, 3500000, 4000000)
    if hasattr(termios, f"B{rate}")
}


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

    The serving thread starts at construction and stops on :meth:`close` (also
    the context-manager exit). An exception raised by the device is kept and
    re-raised by :meth:`close`, so device bugs surface in the caller.
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
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        self._master = -1
        self._slave = -1
        self._pending: list[tuple[float, int, bytes]] = []
        self._seq = itertools.count()
        self._out = bytearray()
        self._unplug_requests: list[threading.Event] = []
        self._closed = False
        self.error: Exception | None = None
        self.dropped_output_bytes = 0
        self._selected = -1  # the master the last select watched
        self._open_pty()
        self._server = server
        if server is None:
            self._thread = threading.Thread(target=self._run, name=f"pty-{name}", daemon=True)
            self._thread.start()
        else:
            server.add(self)

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
        self._wake()
        done.wait(timeout=5.0)

    def _served_elsewhere(self) -> bool:
        """Whether another thread than this one serves the port (and so must be asked to unplug it)."""
        if self._server is None:
            return self._thread.is_alive() and threading.current_thread() is not self._thread
        return self._server.serves(self) and threading.current_thread() is not self._server.thread

    def restore(self) -> None:
        """Plug back in: open a new pty and point :attr:`path` at it."""
        with self._lock:
            if self._master < 0 and not self._closed:
                self._open_pty()
        self._wake()

    def line_speed(self) -> int | None:
        """The client's configured line speed in baud, or None if unknown or absent."""
        with self._lock:
            if self._slave < 0:
                return None
            try:
                return _SPEEDS.get(termios.tcgetattr(self._slave)[5])
            except termios.error:
                return None

    def close(self) -> None:
        """Stop the thread, close the pty and remove the temporary directory."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._wake()
        if self._server is None:
            self._thread.join(timeout=5.0)
        else:
            self._server.remove(self)
        self.vanish()
        os.close(self._wake_r)
        os.close(self._wake_w)
        self._cleanup()
        if self.error is not None:
            raise RuntimeError(f"simulated device on {self.path} failed: {self.error!r}") from self.error

    def __enter__(self) -> PtyPort:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- internals --------------------------------------------------------------------------------

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

    def _wake(self) -> None:
        with contextlib.suppress(OSError):
            os.write(self._wake_w, b"x")

    def _run(self) -> None:
        try:
            self._serve()
        except Exception as exc:  # kept and re-raised by close()
            self.error = exc

    def _serve(self) -> None:
        while True:
            waits = self._waits()
            if waits is None:
                return
            readers, writers, due = waits
            timeout = None if due == math.inf else max(0.0, due - time.monotonic())
            readable, _, _ = select.select(readers, writers, [], timeout)
            now = time.monotonic()
            _spin_to(self._serve_selected(readable, now), now, self._spin_s)
            self._flush_due()

    def _waits(self) -> tuple[list[int], list[int], float] | None:
        """What the next select waits on: (readers, writers, when to wake at the latest); None once closed."""
        with self._lock:
            if self._closed:
                return None
            if self._unplug_requests:
                self._unplug()
                for done in self._unplug_requests:
                    done.set()
                self._unplug_requests.clear()
            master = self._selected = self._master
            spin_from = self._pending[0][0] - self._spin_s if self._pending else math.inf
            due = min(self._device.next_deadline(), spin_from)
            writers = [master] if master >= 0 and self._out else []
        return ([self._wake_r] if master < 0 else [self._wake_r, master]), writers, due

    def _serve_selected(self, readable: list[int], now: float) -> float:
        """After the select: the client's bytes to the device, its timed work; when the next reply is due."""
        if self._wake_r in readable:
            with contextlib.suppress(BlockingIOError):
                os.read(self._wake_r, 4096)
        device = self._device
        with self._lock:
            # The pty may have vanished or been replaced while we waited: only read the one we
            # selected on if it is still current.
            master = self._selected
            if master >= 0 and master == self._master and master in readable:
                data = self._read(master)
                if data:
                    self._queue(device.on_bytes(data, now))
            if now >= device.next_deadline():
                self._queue(device.poll(now))
            return self._pending[0][0] if self._pending else math.inf

    def _next_due(self) -> float:
        """When the next queued reply is due (inf: none, or no pty to write it to)."""
        with self._lock:
            return self._pending[0][0] if self._pending and self._master >= 0 else math.inf

    def _flush_due(self) -> None:
        with self._lock:
            if self._master >= 0:
                self._flush(self._master, time.monotonic())

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
    """One thread serving several `PtyPort`s (``PtyPort(..., server=...)``): the buses of one simulated
    robot. Their replies due at the same time leave together, and no port's spin before its reply
    holds the GIL against another port's thread (with a thread each, the second bus's reply waited
    for the first's spin). A device's exception stops its port only (kept in its ``error``). The
    thread runs while there are ports to serve."""

    def __init__(self, name: str = "pty-server") -> None:
        self._name = name
        self._ports: list[PtyPort] = []
        self._changed = threading.Condition()
        self.thread: threading.Thread | None = None

    def add(self, port: PtyPort) -> None:
        """Serve ``port`` from now on."""
        with self._changed:
            self._ports.append(port)
            if self.thread is None:
                self.thread = threading.Thread(target=self._run, name=self._name, daemon=True)
                self.thread.start()

    def serves(self, port: PtyPort) -> bool:
        with self._changed:
            return port in self._ports

    def remove(self, port: PtyPort) -> None:
        """Wait (up to 5 s) until the thread has dropped ``port`` (closed: its next select sees it)."""
        if threading.current_thread() is self.thread:
            self._drop(port)
            return
        with self._changed:
            self._changed.wait_for(lambda: port not in self._ports, timeout=5.0)

    def _drop(self, port: PtyPort) -> None:
        with self._changed:
            if port in self._ports:
                self._ports.remove(port)
            self._changed.notify_all()

    def _run(self) -> None:
        while True:
            with self._changed:
                ports = list(self._ports)
                if not ports:
                    self.thread = None  # the next add starts another
                    return
            waits = {}
            for port in ports:
                w = self._step(port, port._waits)
                if w is None:
                    self._drop(port)
                else:
                    waits[port] = w
            if not waits:
                continue
            due = min(w[2] for w in waits.values())
            timeout = None if due == math.inf else max(0.0, due - time.monotonic())
            readable, _, _ = select.select([fd for w in waits.values() for fd in w[0]],
                                           [fd for w in waits.values() for fd in w[1]], [], timeout)
            now = time.monotonic()
            replies = [self._step(port, port._serve_selected, readable, now) for port in waits]
            spin_s = max(port._spin_s for port in waits)
            due = min((r for r in replies if r is not None), default=math.inf)
            # each reply due within the spin time leaves when due, in this pass: a second bus's reply due just
            # after the first's does not cost another round of select and device calls
            while True:
                _spin_to(due, now, spin_s)
                for port in waits:
                    self._step(port, port._flush_due)
                if not spin_s:
                    break
                now = time.monotonic()
                due = min((port._next_due() for port in waits if port.error is None), default=math.inf)
                if due > now + spin_s:
                    break

    def _step(self, port: PtyPort, step, *args):
        """``step(*args)`` of ``port``; a device's exception is kept in the port's ``error`` (re-raised by its
        close) and the port dropped: None."""
        if port.error is not None:
            return None
        try:
            return step(*args)
        except Exception as exc:
            port.error = exc
            self._drop(port)
            return None


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
