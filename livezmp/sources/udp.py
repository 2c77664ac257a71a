"""Frames over UDP in the livezmp frame format (JSON or binary, see ``docs/frame_format.md``).

``udp://HOST:PORT`` binds a socket; every datagram is checked in this order, and a
failing one is counted in :class:`SourceStats` and dropped: sender on the allowlist
(``rejected``), size (``oversized``), schema (``malformed``), sequence number
(``duplicate`` or ``late``), time strictly increasing (``malformed``). Sequence numbers
compare modulo 2^32 (serial-number arithmetic, as RTP does), and a 64-frame window of
those already seen tells a duplicate from a late frame. A sender that restarts its
sequence from an older number is seen as late until it passes the last one — or until
the resynchronisation rule below moves the stream onto its new numbers.

No packet can lock the stream out. A frame whose sequence number jumps more than
:data:`MAX_SEQ_JUMP` ahead, or whose time jumps more than :data:`MAX_GAP_S` ahead, is
dropped and counted (``jumps``). Dropped late, duplicate, jumped or time-not-increasing
frames are candidates for a new timeline (a restarted sender reuses numbers): when
:data:`RESYNC_FRAMES` of them arrive in a row (no frame accepted in between), each one
to ``WINDOW`` sequence numbers after the previous and later by at most ``MAX_GAP_S``,
the source follows them (``resyncs``): the last one is delivered with ``restart`` set
(and no longer counted among the dropped: each frame is delivered or dropped, once),
so the analysis starts over on the new clock. A single far-ahead packet thus costs
nothing, a restarted sender is followed after ``RESYNC_FRAMES`` frames, and genuine
frames arriving in between clear the candidate run, so stray packets cannot take over.

The allowlist defaults to loopback senders; binding beyond loopback requires one. A skeleton's
frames carry every joint of its file (``rows``: re-expressed clear of gimbal lock frame by frame
where the body's orders are others, and cut to the joints the body is built on); a robot's, the
body's channels.
"""

from __future__ import annotations

import ipaddress
import math
import os
import select
import socket
import struct
import sys
import time

from livezmp.errors import InputError
from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec, SkeletonStream
from livezmp.sources.frame_format import SEQ_MOD, FrameError, decode_frame, max_packet_bytes
from livezmp.sources.interface import ErrorLog, SourceFrame, SourceStats

WINDOW = 64
MAX_SEQ_JUMP = 1024  # frames: ~4 s lost at 240 Hz; a larger jump ahead is suspect
MAX_GAP_S = 5.0  # s of sender time between two frames before a jump is suspect
RESYNC_FRAMES = 8  # consecutive consistent frames that move the stream onto a new timeline
RECV_BUFFER = 4 << 20  # bytes of kernel buffer: a few seconds of frames if the monitor stalls
LOOPBACK = (ipaddress.ip_network("127.0.0.0/8"), ipaddress.ip_network("::1/128"))

Network = ipaddress.IPv4Network | ipaddress.IPv6Network
# Linux's socket option for the kernel's drop count: 40 in asm-generic/socket.h, which every architecture but
# alpha, mips, parisc and sparc uses (Python 3.11's socket module does not name it)
SO_RXQ_OVFL = getattr(socket, "SO_RXQ_OVFL", 40) if sys.platform.startswith("linux") else None


class KernelDrops:
    """Reads a UDP socket with the kernel's count of datagrams it dropped there (its receive buffer full), where
    Linux offers it: ``SO_RXQ_OVFL`` attaches the socket's drop count so far to each datagram received, so the
    count is known as of the latest datagram read; :meth:`settle`, before the socket closes, takes the count
    from /proc/net/udp (its ``drops`` column), so drops after the last datagram read are counted too (a flood
    that ends with the buffer full: none of its tail is ever read). Into ``stats.kernel_drops``, which stays
    None where the option is refused."""

    def __init__(self, sock: socket.socket, stats: SourceStats):
        self.sock, self.stats = sock, stats
        self._space = 0
        if SO_RXQ_OVFL is not None:
            try:
                sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            except OSError:
                return
            self._space = socket.CMSG_SPACE(4)
            stats.kernel_drops = 0

    def recvfrom(self, size: int) -> tuple[bytes, tuple]:
        """``sock.recvfrom(size)``, noting the drop count that came with the datagram."""
        if not self._space:
            return self.sock.recvfrom(size)
        data, ancillary, _, address = self.sock.recvmsg(size, self._space)
        for level, kind, value in ancillary:
            if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL and len(value) >= 4:
                # the socket's count when this datagram was queued: those read later may carry an older one
                self.stats.kernel_drops = max(self.stats.kernel_drops, struct.unpack("=I", value[:4])[0])
        return data, address

    def settle(self) -> None:
        """The socket's drop count now, from the kernel's table of UDP sockets (found by the socket's inode);
        nothing where the table cannot be read."""
        if not self._space:
            return
        try:
            inode = str(os.fstat(self.sock.fileno()).st_ino)
            for table in ("/proc/net/udp", "/proc/net/udp6"):
                with open(table, encoding="ascii") as f:
                    for line in f:
                        fields = line.split()
                        if len(fields) >= 13 and fields[9] == inode:
                            self.stats.kernel_drops = max(self.stats.kernel_drops, int(fields[-1]))
                            return
        except (OSError, ValueError):
            return


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


class Resync:
    """The candidate new timeline: a run of dropped frames consistent with each other."""

    def __init__(self):
        self.seq: int | None = None
        self.t = 0.0
        self.run = 0

    def clear(self) -> None:
        self.seq, self.run = None, 0

    def offer(self, seq: int, t: float) -> bool:
        """Add a dropped frame; True when it completes a run of :data:`RESYNC_FRAMES`."""
        follows = (self.seq is not None and 0 < (seq - self.seq) % SEQ_MOD <= WINDOW
                   and 0 < t - self.t <= MAX_GAP_S)
        self.run = self.run + 1 if follows else 1
        self.seq, self.t = seq, t
        return self.run >= RESYNC_FRAMES


class Timeline:
    """The rules of the module docstring for one stream of (sequence number, time) frames, counted into
    ``stats`` and reported to ``errors``: :meth:`admit` says whether a frame is delivered and whether the
    analysis must start over with it. Used by every stream with frame numbers: UDP frames and the capture
    systems' (their frame numbers and stamps; :class:`~livezmp.sources.mocap_frame.InOrder`)."""

    def __init__(self, stats: SourceStats, errors: ErrorLog):
        self.stats, self.errors = stats, errors
        self.sequence, self.resync = SequenceFilter(), Resync()
        self._lost_before = 0  # lost before the last new timeline
        self._last_t: float | None = None
        self._new = False  # the next delivered frame starts a new timeline

    def drop(self, kind: str, message: str) -> None:
        """Count a dropped frame as ``kind`` (a :class:`SourceStats` field) and report ``message``."""
        setattr(self.stats, kind, getattr(self.stats, kind) + 1)
        self.errors.report(kind, message)

    def admit(self, seq: int, t: float, where: str) -> bool | None:
        """Frame ``seq`` (modulo 2^32) at ``t`` s (the sender's clock): None when dropped (counted, and
        reported naming ``where``), else True when the analysis starts over with it (a new timeline:
        resynchronised, or the first frame after :meth:`restart`), False when it follows on."""
        if not math.isfinite(t):  # no candidate for a new timeline either: it has no place on one
            self.drop("malformed", f"{where}: time {t} is not a finite number of seconds")
            return None
        seq %= SEQ_MOD
        verdict = self.sequence.check(seq)
        last = self.sequence.last
        if verdict == "ok" and last is not None and (seq - last) % SEQ_MOD > MAX_SEQ_JUMP:
            verdict, why = "jumps", f"seq {seq} jumps ahead of {last}"
        elif verdict == "ok" and self._last_t is not None and not t > self._last_t:
            verdict, why = "malformed", f"field t: {t} does not increase (last {self._last_t})"
        elif verdict == "ok" and self._last_t is not None and t - self._last_t > MAX_GAP_S:
            verdict, why = "jumps", f"field t: {t} jumps {t - self._last_t:.3g} s ahead"
        else:
            why = f"seq {seq} after {last}"
        restart = self._new
        if verdict != "ok":
            self.drop(verdict, f"{where}: {why}")
            if not self.resync.offer(seq, t):
                return None
            setattr(self.stats, verdict, getattr(self.stats, verdict) - 1)  # delivered after all: not dropped
            self.stats.resyncs += 1
            self.errors.report("resync", f"{where}: following a new timeline at seq {seq}, t {t:g} s after "
                                         f"{RESYNC_FRAMES} consistent frames")
            self.sequence = SequenceFilter()
            restart = True
        self.resync.clear()
        self.sequence.accept(seq)
        self.stats.lost = self._lost_before + self.sequence.lost
        if restart:
            self._lost_before = self.stats.lost
        self.stats.delivered += 1
        self._last_t, self._new = t, False
        return restart

    def restart(self) -> None:
        """The stream was connected anew: its numbers and clock may start afresh; the next frame delivered
        starts a new timeline. The lost count stays."""
        self._lost_before = self.stats.lost
        self.sequence, self._last_t, self._new = SequenceFilter(), None, True
        self.resync.clear()


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
                 nominal_dt: float | None = None, rows: SkeletonStream | None = None):
        self.name = f"udp://{host}:{port}"
        if allow is None and not is_loopback(host):
            raise InputError(f"{self.name}: listening beyond loopback needs an allowlist of senders "
                             "(?allow=ADDRESS[/BITS],...)")
        self.body, self.body_spec, self.nominal_dt = body, body_spec, nominal_dt
        self.rows = rows
        self.n_channels = body.nq if rows is None else rows.n_channels
        self.allow = allow or LOOPBACK
        self.max_bytes = max_packet_bytes(self.n_channels) if max_bytes is None else max_bytes
        self.stats, self.errors = SourceStats(), ErrorLog()
        self.timeline = Timeline(self.stats, self.errors)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.sock = socket.socket(family, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECV_BUFFER)
        try:
            self.sock.bind((host, port))
        except OSError as e:
            self.sock.close()
            raise InputError(f"{self.name}: cannot listen: {e.strerror}") from None
        self.sock.setblocking(False)
        self.receiver = KernelDrops(self.sock, self.stats)
        self.port = self.sock.getsockname()[1]
        self.name = f"udp://{host}:{self.port}"
        self._closed = False

    @property
    def finished(self) -> bool:
        return self._closed

    def _accept(self, data: bytes, sender: str, received: float) -> SourceFrame | None:
        try:
            if not any(ipaddress.ip_address(sender.split("%")[0]) in n for n in self.allow):
                self.timeline.drop("rejected", f"{self.name}: from {sender}: sender not on the allowlist")
                return None
            f = decode_frame(data, self.n_channels, self.max_bytes)
        except FrameError as e:
            self.timeline.drop(e.kind, f"{self.name}: from {sender}: {e}")
            return None
        restart = self.timeline.admit(f.seq, f.t, f"{self.name}: from {sender}")
        if restart is None:
            return None
        channels = f.channels
        if self.rows is not None:
            if restart:
                self.rows.restart()
            channels = self.rows(channels)
        return SourceFrame(f.t, channels, f.contacts, received, restart=restart)

    def read(self, timeout: float) -> SourceFrame | None:
        deadline = time.monotonic() + timeout
        while not self._closed:
            try:
                data, addr = self.receiver.recvfrom(65536)
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
        if not self._closed:
            self.receiver.settle()
        self._closed = True
        self.sock.close()
