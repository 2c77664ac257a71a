"""Frames over UDP in the livezmp frame format (JSON or binary, see ``docs/frame_format.md``).

``udp://HOST:PORT`` binds a socket; every datagram is checked in this order, and a
failing one is counted in :class:`SourceStats` and dropped: sender on the allowlist
(``rejected``), size (``oversized``), schema (``malformed``), sequence number
(``duplicate`` or ``late``), time strictly increasing (``malformed``). Sequence numbers
compare modulo 2^32 (serial-number arithmetic, as RTP does), and a 64-frame window of
those already seen tells a duplicate from a late frame. A sender that restarts its
sequence from an older number is seen as late until it passes the last one.

The allowlist defaults to loopback senders; binding beyond loopback requires one.
"""

from __future__ import annotations

import ipaddress
import select
import socket
import time

from livezmp.errors import InputError
from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec
from livezmp.sources.frame_format import SEQ_MOD, FrameError, decode_frame, max_packet_bytes
from livezmp.sources.interface import ErrorLog, SourceFrame, SourceStats

WINDOW = 64
RECV_BUFFER = 4 << 20  # bytes of kernel buffer: a few seconds of frames if the monitor stalls
LOOPBACK = (ipaddress.ip_network("127.0.0.0/8"), ipaddress.ip_network("::1/128"))

Network = ipaddress.IPv4Network | ipaddress.IPv6Network


class SequenceFilter:
    """In-order delivery by sequence number. :meth:`check` returns "ok", "duplicate" or
    "late" for a packet; :meth:`accept` marks an ok packet delivered; ``lost`` counts the
    numbers skipped by accepted packets."""

    def __init__(self):
        self.last: int | None = None
        self.seen = 0  # bit i: sequence (last - i) has been received
        self.lost = 0

    def check(self, seq: int) -> str:
        if self.last is None:
            return "ok"
        d = (seq - self.last) % SEQ_MOD
        if d == 0:
            return "duplicate"
        if d < SEQ_MOD // 2:
            return "ok"
        back = SEQ_MOD - d
        return "duplicate" if back < WINDOW and self.seen >> back & 1 else "late"

    def accept(self, seq: int) -> None:
        if self.last is None:
            self.last, self.seen = seq, 1
            return
        d = (seq - self.last) % SEQ_MOD
        self.lost += d - 1
        self.seen = ((self.seen << d) | 1) & ((1 << WINDOW) - 1)
        self.last = seq


def parse_allowlist(text: str, where: str) -> tuple[Network, ...]:
    """Comma-separated addresses or CIDR networks → networks."""
    out = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        try:
            out.append(ipaddress.ip_network(item, strict=False))
        except ValueError:
            raise InputError(f"{where}: allow: {item!r} is not an IP address or network") from None
    if not out:
        raise InputError(f"{where}: allow: empty allowlist")
    return tuple(out)


def is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


class UdpSource:
    """Listens on ``host``:``port`` (see the module docstring). ``max_bytes`` is the
    datagram size limit (default :func:`max_packet_bytes`); ``nominal_dt`` the expected
    frame period, if known."""

    def __init__(self, host: str, port: int, body: BodyModel, body_spec: BodySpec,
                 allow: tuple[Network, ...] | None = None, max_bytes: int | None = None,
                 nominal_dt: float | None = None):
        self.name = f"udp://{host}:{port}"
        if allow is None and not is_loopback(host):
            raise InputError(f"{self.name}: listening beyond loopback needs an allowlist of senders "
                             "(?allow=ADDRESS[/BITS],...)")
        self.body, self.body_spec, self.nominal_dt = body, body_spec, nominal_dt
        self.allow = allow or LOOPBACK
        self.max_bytes = max_packet_bytes(body.nq) if max_bytes is None else max_bytes
        self.stats, self.errors = SourceStats(), ErrorLog()
        self.sequence = SequenceFilter()
        self._last_t: float | None = None
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECV_BUFFER)
        try:
            self.sock.bind((host, port))
        except OSError as e:
            self.sock.close()
            raise InputError(f"{self.name}: cannot listen: {e.strerror}") from None
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]
        self.name = f"udp://{host}:{self.port}"
        self._closed = False

    @property
    def finished(self) -> bool:
        return self._closed

    def _drop(self, kind: str, message: str, sender: str) -> None:
        setattr(self.stats, kind, getattr(self.stats, kind) + 1)
        self.errors.report(kind, f"{self.name}: from {sender}: {message}")

    def _accept(self, data: bytes, sender: str, received: float) -> SourceFrame | None:
        try:
            if not any(ipaddress.ip_address(sender.split("%")[0]) in n for n in self.allow):
                self._drop("rejected", "sender not on the allowlist", sender)
                return None
            f = decode_frame(data, self.body.nq, self.max_bytes)
        except FrameError as e:
            self._drop(e.kind, str(e), sender)
            return None
        verdict = self.sequence.check(f.seq)
        if verdict != "ok":
            self._drop(verdict, f"seq {f.seq} after {self.sequence.last}", sender)
            return None
        if self._last_t is not None and not f.t > self._last_t:
            self._drop("malformed", f"field t: {f.t} does not increase (last {self._last_t})", sender)
            return None
        self.sequence.accept(f.seq)
        self.stats.lost = self.sequence.lost
        self.stats.delivered += 1
        self._last_t = f.t
        return SourceFrame(f.t, f.channels, f.contacts, received)

    def read(self, timeout: float) -> SourceFrame | None:
        deadline = time.monotonic() + timeout
        while not self._closed:
            try:
                data, addr = self.sock.recvfrom(65536)
            except BlockingIOError:
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                select.select([self.sock], [], [], left)
                continue
            now = time.monotonic()
            frame = self._accept(data, addr[0], now)
            if frame is not None or now >= deadline:  # a flood of bad packets still returns in time
                return frame
        return None

    def close(self) -> None:
        self._closed = True
        self.sock.close()
