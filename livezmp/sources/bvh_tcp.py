"""BVH over TCP: one frame of channel values per line, for a known BVH hierarchy.

Motion-capture software broadcasts BVH as text frames over a TCP server; livezmp
connects as a client (``tcp://HOST:PORT``). A frame is the channel values of the
hierarchy in file order (degrees and file length units), separated by spaces, ended by
a newline or by ``||``. A leading avatar index and name (``0 Avatar00 ...``, as in Axis
Neuron's string broadcast) is skipped. Lines with the wrong value count, non-numbers,
non-finite values, or longer than the limit are counted and dropped. The lines carry no
time: frame k is at ``k × frame period``. A dropped connection is reported and
re-opened every ``retry`` seconds; frames keep counting on. Each line, every joint of the
hierarchy, is made the body's channels by ``rows`` (joints the body analyses in other rotation
orders re-expressed, those it does not build dropped).
"""

from __future__ import annotations

import re
import select
import socket
import time

import numpy as np

from livezmp.checks import MAX_CHANNEL_VALUE, first_out_of_range
from livezmp.errors import InputError
from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec, SkeletonStream
from livezmp.sources.interface import ErrorLog, SourceFrame, SourceStats

DELIMITER = re.compile(rb"\r?\n|\|\|")
CONNECT_TIMEOUT = 2.0


def parse_frame_line(line: bytes, n_channels: int) -> np.ndarray:
    """Channel values of one frame line; raises :class:`InputError` naming the problem."""
    toks = line.split()
    if len(toks) == n_channels + 2 and toks[0].isdigit():
        toks = toks[2:]  # avatar index and name
    if len(toks) != n_channels:
        raise InputError(f"{len(toks)} values, the hierarchy has {n_channels} channels")
    try:
        values = np.array([float(t) for t in toks])
    except ValueError:
        raise InputError("non-numeric value") from None
    bad = first_out_of_range(values, MAX_CHANNEL_VALUE)
    if bad is not None:
        raise InputError(f"value {bad[0]} is not finite or beyond ±{MAX_CHANNEL_VALUE:g}")
    return values


class BvhTcpSource:
    """Client of a BVH broadcast at ``host``:``port`` (see the module docstring);
    ``frame_time`` s per frame; lines longer than ``max_line`` bytes are dropped; ``rows`` makes each line's values
    the body's channels (None: they are)."""

    def __init__(self, host: str, port: int, body: BodyModel, body_spec: BodySpec, frame_time: float,
                 max_line: int | None = None, retry: float = 0.5, rows: SkeletonStream | None = None):
        self.name = f"tcp://{host}:{port}"
        self.host, self.port = host, port
        self.body, self.body_spec = body, body_spec
        self.nominal_dt = frame_time
        self.rows = rows
        self.n_channels = body.nq if rows is None else rows.n_channels
        self.max_line = max_line or 1024 + 32 * self.n_channels
        self.retry = retry
        self.stats, self.errors = SourceStats(), ErrorLog()
        self._buf = bytearray()
        self._skipping = False  # inside an over-long line, up to its delimiter
        self._k = 0
        self._closed = False
        self._next_try = 0.0
        self.sock: socket.socket | None = None
        try:
            self.sock = socket.create_connection((host, port), timeout=CONNECT_TIMEOUT)
        except OSError as e:
            raise InputError(f"{self.name}: cannot connect: {e.strerror or e}") from None
        self.sock.setblocking(False)

    @property
    def finished(self) -> bool:
        return self._closed

    def _disconnect(self, why: str) -> None:
        if self.sock is not None:
            self.sock.close()
        self.sock = None
        self._buf.clear()
        self._skipping = False
        self._next_try = time.monotonic() + self.retry
        self.errors.report("disconnected", f"{self.name}: {why}")

    def _reconnect(self) -> None:
        if time.monotonic() < self._next_try:
            return
        try:
            sock = socket.create_connection((self.host, self.port), timeout=min(self.retry, CONNECT_TIMEOUT))
        except OSError as e:
            self._next_try = time.monotonic() + self.retry
            self.errors.report("disconnected", f"{self.name}: cannot reconnect: {e.strerror or e}")
            return
        sock.setblocking(False)
        self.sock = sock
        self.stats.reconnects += 1

    def _next_line(self) -> bytes | None:
        """The next complete line in the buffer, or None; drops over-long lines."""
        while True:
            m = DELIMITER.search(self._buf)
            if m is None:
                if len(self._buf) > self.max_line:
                    self._buf.clear()
                    if not self._skipping:
                        self._count("oversized", f"line longer than {self.max_line} bytes")
                    self._skipping = True
                return None
            line = bytes(self._buf[: m.start()])
            del self._buf[: m.end()]
            if self._skipping:
                self._skipping = False
                continue
            if len(line) > self.max_line:
                self._count("oversized", f"line of {len(line)} bytes, limit {self.max_line}")
                continue
            if line.strip():
                return line

    def _count(self, kind: str, message: str) -> None:
        setattr(self.stats, kind, getattr(self.stats, kind) + 1)
        self.errors.report(kind, f"{self.name}: frame {self._k}: {message}")

    def _frame(self, line: bytes) -> SourceFrame | None:
        try:
            values = parse_frame_line(line, self.n_channels)
        except InputError as e:
            self._count("malformed", str(e))
            return None
        t = self._k * self.nominal_dt
        self._k += 1
        self.stats.delivered += 1
        return SourceFrame(t, values if self.rows is None else self.rows(values), None, time.monotonic())

    def read(self, timeout: float) -> SourceFrame | None:
        deadline = time.monotonic() + timeout
        while not self._closed:
            line = self._next_line()
            if line is not None:
                frame = self._frame(line)
                if frame is not None or time.monotonic() >= deadline:  # a flood of bad lines returns in time
                    return frame
                continue
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            if self.sock is None:
                self._reconnect()
                if self.sock is None:
                    time.sleep(min(left, max(0.0, self._next_try - time.monotonic())))
                continue
            if not select.select([self.sock], [], [], left)[0]:
                return None
            try:
                data = self.sock.recv(65536)
            except BlockingIOError:
                continue
            except OSError as e:
                self._disconnect(f"connection lost: {e.strerror or e}")
                continue
            if not data:
                self._disconnect("connection closed by the server")
                continue
            self._buf += data
        return None

    def close(self) -> None:
        self._closed = True
        if self.sock is not None:
            self.sock.close()
            self.sock = None
