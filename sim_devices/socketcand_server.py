"""A simulated socketcand daemon: CAN nodes reached over TCP, as python-can's ``socketcand`` interface expects.

socketcand (github.com/linux-can/socketcand) serves a Linux CAN interface over TCP; a
real robot runs it on its own computer, next to the CAN adapter. Unmodified python-can
connects with ``can.Bus(interface="socketcand", channel="can0", host=HOST, port=PORT)``.
This server speaks the part of its protocol python-can uses, in raw mode:

    server: < hi >            client: < open can0 >     server: < ok >
    client: < rawmode >       server: < ok >
    client: < send 1A2B3C4D 8 1 2 3 4 5 6 7 8 >        (id in hex, dlc, data bytes in hex)
    server: < frame 1A2B3C4D 1700000000.000123 0102030405060708 >

It listens on 127.0.0.1 (an ephemeral port by default: :attr:`port`). Like the real
daemon it may serve several CAN interfaces (``channels``: name -> its nodes), each client
on a thread of its own, so a robot with one bus per leg opens one connection per bus and
they run in parallel. Frames in both directions take their time on the CAN bus at
``bitrate``: the bits `livezmp.links.can_timing.frame_bits` counts (fields, stuff bits and
interframe space); each bus carries one frame at a time,
so what the nodes send queues behind what is already on it (as on a real bus, where the
lowest id wins arbitration; here the order is first come), and a frame that would wait
more than `MAX_BACKLOG_S` is lost (``frames_lost``: its node's transmit queue overflowed). The nodes (`CanNode`) are
ticked every ``tick_period`` while a client is in raw mode. A frame's timestamp is the
time its last bit left the wire (as SocketCAN stamps a received frame). Why this and not slcan: a
frame is one short line in a TCP segment holding many, which python-can reads 1 kB at a
time, where its slcan reader makes one system call per byte (measured: about 3 000
frames/s, the CAN link's limit on a pty).
"""

from __future__ import annotations

import contextlib
import heapq
import itertools
import math
import re
import select
import socket
import threading
import time
from collections.abc import Mapping, Sequence

from livezmp.links.can_timing import frame_bits
from sim_devices.can_node import CanFrame, CanNode
from sim_devices.faults import FaultCounters

_SEND = re.compile(r"< send ([0-9A-Fa-f]{1,8}) ([0-8]) ?((?:[0-9A-Fa-f]{1,2} ?)*)>")
_COMMAND = re.compile(r"<[^<>]*>")
RAW_SETTLE_S = 0.005  # frames start this long after raw mode's "< ok >", which python-can reads alone
MAX_PENDING = 64 * 1024  # bytes queued for a client that does not read: beyond it they are dropped
MAX_BACKLOG_S = 0.05  # a node's frames that would wait longer for the bus are lost (its transmit queue is full)


def wire_time(frame: CanFrame, bitrate: int) -> float:
    """Seconds ``frame`` holds a bus at ``bitrate`` bit/s (stuff bits and interframe space included)."""
    return frame_bits(frame.arbitration_id, frame.data, frame.is_extended, frame.is_remote, frame.dlc) / bitrate


def encode(frame: CanFrame, stamp: float) -> bytes:
    ident = f"{frame.arbitration_id:08X}" if frame.is_extended else f"{frame.arbitration_id:03X}"
    return f"< frame {ident} {stamp:.6f} {frame.data.hex().upper()} >".encode()


class SocketcandServer:
    """Serve ``nodes`` as CAN interface ``channel`` on 127.0.0.1:``port``, or each of ``channels``
    (interface name -> its nodes, one bus each) instead (see module docstring)."""

    def __init__(self, nodes: Sequence[CanNode] = (), *, channel: str = "can0", bitrate: int = 1_000_000,
                 tick_period: float = 1e-3, port: int = 0,
                 channels: Mapping[str, Sequence[CanNode]] | None = None) -> None:
        if bitrate <= 0 or not tick_period > 0:
            raise ValueError(f"SocketcandServer: bitrate and tick_period must be > 0, got {bitrate}, {tick_period}")
        self.channels = {channel: list(nodes)} if channels is None else {k: list(v) for k, v in channels.items()}
        self.nodes = [node for group in self.channels.values() for node in group]
        self.channel = next(iter(self.channels))
        self.bitrate = bitrate
        self.tick_period = tick_period
        self.fault_counters = FaultCounters()  # no adapter faults here
        self.frames_from_host = self.frames_to_host = self.frames_lost = 0
        self._listener = socket.create_server(("127.0.0.1", port))
        self._listener.setblocking(False)
        self.port = self._listener.getsockname()[1]
        self._wake_r, self._wake_w = socket.socketpair()
        self._closed = False
        self.error: Exception | None = None
        self._clients: list[threading.Thread] = []
        self._thread = threading.Thread(target=self._run, name=f"socketcand-{self.port}", daemon=True)
        self._thread.start()

    @property
    def url_options(self) -> str:
        """The ``can:socketcand:CHANNEL`` link options that reach this server."""
        return f"host=127.0.0.1&port={self.port}&tcp_tune=1"

    def close(self) -> None:
        """Stop serving; re-raise a failure of the serving thread."""
        if self._closed:
            return
        self._closed = True
        with contextlib.suppress(OSError):
            self._wake_w.send(b"x")
        self._thread.join(timeout=5.0)
        for client in self._clients:
            client.join(timeout=5.0)
        for s in (self._listener, self._wake_r, self._wake_w):
            s.close()
        if self.error is not None:
            raise RuntimeError(f"simulated socketcand on port {self.port} failed: {self.error!r}") from self.error

    def __enter__(self) -> SocketcandServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- serving ----------------------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while not self._closed:
                readable, _, _ = select.select([self._listener, self._wake_r], [], [], None)
                if self._closed:
                    return
                if self._listener in readable:
                    try:
                        client, _ = self._listener.accept()
                    except BlockingIOError:
                        continue
                    self._clients = [t for t in self._clients if t.is_alive()]
                    thread = threading.Thread(target=self._client, args=(client,), daemon=True,
                                              name=f"socketcand-{self.port}-client")
                    self._clients.append(thread)
                    thread.start()
        except Exception as exc:  # kept and re-raised by close()
            self.error = exc

    def _client(self, client: socket.socket) -> None:
        try:
            with client:
                self._serve(client)
        except Exception as exc:  # kept and re-raised by close()
            self.error = exc

    def _serve(self, client: socket.socket) -> None:
        """One client until it disconnects (or the server closes)."""
        nodes: list[CanNode] = []
        client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client.setblocking(False)
        state = "hello"  # -> "open" -> "raw"
        inbox = ""
        out = bytearray(b"< hi >")
        pending: list[tuple[float, int, bytes]] = []  # (due, seq, line) towards the host
        seq = itertools.count()
        bus_free = -math.inf
        next_tick = math.inf
        while not self._closed:
            due = min(next_tick, pending[0][0] if pending else math.inf)
            timeout = None if due == math.inf else max(0.0, due - time.monotonic())
            readable, _, _ = select.select([client, self._wake_r], [client] if out else [], [], timeout)
            now = time.monotonic()
            if client in readable:
                try:
                    data = client.recv(65536)
                except (BlockingIOError, InterruptedError):
                    data = None
                except OSError:
                    return
                if data == b"":
                    return  # the client went
                if data:
                    inbox += data.decode("ascii", errors="replace")
                    *commands, inbox = _split(inbox)
                    for command in commands:
                        if state == "raw":
                            bus_free = self._from_host(nodes, command, now, bus_free, pending, seq)
                        elif state == "hello" and command[7:-2] in self.channels and command[:7] == "< open ":
                            state = "open"
                            nodes = self.channels[command[7:-2]]
                            out += b"< ok >"
                        elif state == "open" and command == "< rawmode >":
                            state = "raw"
                            client.sendall(b"< ok >")  # on its own: python-can reads it as one message
                            next_tick = now + RAW_SETTLE_S
                        else:
                            out += b"< error >"
            if state == "raw" and now >= next_tick:
                next_tick = max(next_tick + self.tick_period, now)
                frames = [f for node in nodes for f in node.tick(now)]
                bus_free = self._to_host(frames, now, bus_free, pending, seq)
            while pending and pending[0][0] <= now:
                out += heapq.heappop(pending)[2]
            if len(out) > MAX_PENDING:
                del out[: len(out) - MAX_PENDING]
            if out:
                try:
                    sent = client.send(out)
                except BlockingIOError:
                    sent = 0
                except OSError:
                    return
                del out[:sent]

    def _from_host(self, nodes: list[CanNode], command: str, now: float, bus_free: float, pending: list,
                   seq) -> float:
        match = _SEND.fullmatch(command)
        if match is None:
            return bus_free
        ident, dlc, data = match.groups()
        raw = bytes(int(b, 16) for b in data.split())
        if len(raw) != int(dlc):
            return bus_free
        frame = CanFrame(int(ident, 16), raw, is_extended=len(ident) > 3)
        self.frames_from_host += 1
        on_bus = max(now, bus_free) + wire_time(frame, self.bitrate)
        answers = [reply for node in nodes for reply in node.on_frame(frame)]
        return self._to_host(answers, on_bus, on_bus, pending, seq)

    def _to_host(self, frames: list[CanFrame], now: float, bus_free: float, pending: list, seq) -> float:
        t = max(now, bus_free)
        wall = time.time() - time.monotonic()  # monotonic -> epoch, for the frames' timestamps
        for frame in frames:
            if t - now > MAX_BACKLOG_S:
                self.frames_lost += 1
                continue
            t += wire_time(frame, self.bitrate)
            heapq.heappush(pending, (t, next(seq), encode(frame, t + wall)))
            self.frames_to_host += 1
        return t


def _split(text: str) -> list[str]:
    """Complete ``< ... >`` commands in ``text``, then the unfinished rest (last item)."""
    commands = _COMMAND.findall(text)
    end = text.rfind(">")
    return [*commands, text[end + 1:] if end >= 0 else text]
