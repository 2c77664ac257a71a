"""OptiTrack Motive live: ``natnet://HOST[:PORT][?data_port=1511&up=y&timeout=5]``.

livezmp's own NatNet client (:mod:`livezmp.sources.natnet_protocol`), unicast: it binds
the data port (Motive's "Data Port" setting, 1511 by default), sends connect to the
command port (1510), reads the server info and the model definitions (marker set
names, rigid bodies, skeletons and their bones, force plates and their channel names) and
the frame rate (the SDK's ``FrameRate`` request; measured from the frames' timestamps when a
server does not answer it), then
receives frames of data. Rigid bodies and skeleton bones become the frame's segment poses
(by name; an untracked one NaN); markers of
every marker set are delivered (``SET:MARKER`` when there are several sets; an all-zero
position, Motive's mark of an occluded marker, becomes NaN); plates from their channels
Fx Fy Fz (N), Mx My Mz (N·m), Cx Cy Cz (m). NatNet streams metres; it does not carry its
up axis: Motive streams y up unless its Up Axis setting says z (then ``?up=z``).

A receiving thread drains the data socket as datagrams arrive and queues the frames
(at most 4096 wait; more are counted as ``overflow``); a datagram from any address but the server's is
counted as ``rejected`` and dropped (off loopback the data port listens on every interface). Frames go in order by frame
number and timestamp (:class:`~livezmp.sources.udp.Timeline`: late, duplicate, lost, jumps counted; bad
datagrams ``malformed``; a pose whose quaternion or position is not finite untracked). No frame for
``retry`` s: connect is sent again every ``retry`` s (Motive restarted, or a new take)
and the model re-read; a server info answering it after a silence, followed by frames,
counts as a reconnect. NatNet timestamps are Motive's own clock, so
``MocapFrame.latency`` is None.
"""

from __future__ import annotations

import select
import socket
import struct
import threading
import time
from urllib.parse import urlsplit

import numpy as np

from livezmp.errors import InputError
from livezmp.sources import natnet_protocol as nn
from livezmp.sources.interface import ErrorLog, SourceStats
from livezmp.sources.mocap_frame import FrameQueue, MocapFrame, PlateSamples, SegmentPoses, parse_up_axis
from livezmp.sources.udp import KernelDrops, Timeline
from livezmp.sources.url_query import query_params, query_seconds

COMMAND_PORT, DATA_PORT = 1510, 1511
POLL_S = 0.1  # s: the receiving thread looks at its stop flag and the silence this often
QUERY_KEYS = {"data_port", "up", "timeout"}
PLATE_CHANNELS = {"force": ("Fx", "Fy", "Fz"), "moment": ("Mx", "My", "Mz"), "cop": ("Cx", "Cy", "Cz")}


def _int(query: dict, key: str, default: int, url: str) -> int:
    try:
        v = int(query.get(key, default))
    except ValueError:
        v = -1
    if not 0 < v < 65536:
        raise InputError(f"{url}: {key}: need a port number, got {query[key]!r}")
    return v


class NatNetSource:
    """Client of a NatNet server; see the module docstring."""

    def __init__(self, url: str, retry: float = 1.0):
        u = urlsplit(url)
        query = query_params(url, QUERY_KEYS)
        try:
            self.server = (u.hostname or "127.0.0.1", u.port or COMMAND_PORT)
            self.up = parse_up_axis(query.get("up", "y"), url)
        except ValueError as e:
            raise InputError(f"{url}: {e}") from None
        timeout = query_seconds(query, "timeout", 5.0, url)
        self.name, self.retry = url, retry
        self.stats, self.errors = SourceStats(), ErrorLog()
        self.order = Timeline(self.stats, self.errors)
        self.cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.data.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.data.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        try:
            self.cmd.connect(self.server)
            # frames are taken from the server's address only: off loopback the data socket listens on every
            # interface, where anyone on the network could otherwise send it frames
            self.server_ip = self.cmd.getpeername()[0]
            self.data.bind(("127.0.0.1" if self.server[0] in ("127.0.0.1", "localhost") else "",
                            _int(query, "data_port", DATA_PORT, url)))
        except OSError as e:
            self._close_sockets()
            raise InputError(f"{url}: cannot open the NatNet sockets: {e.strerror or e}") from None
        self.data.setblocking(False)
        self.receiver = KernelDrops(self.data, self.stats)
        self._closed = False
        self._silent_since: float | None = None
        self._last_connect = 0.0
        if not self._handshake(timeout):
            self._close_sockets()
            raise InputError(f"{url}: no NatNet server answered within {timeout:g} s")
        self.queue = FrameQueue(self.stats)
        self._thread = threading.Thread(target=self._receive, name="natnet-client", daemon=True)
        self._thread.start()

    def _request(self, kind: int, payload: bytes, want: int, timeout: float) -> bytes | None:
        try:
            self.cmd.send(nn.message(kind, payload))
        except OSError:
            return None
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            if not select.select([self.cmd], [], [], left)[0]:
                break
            try:
                got, payload_in = nn.split(self.cmd.recv(65536))
            except (OSError, nn.NatNetError):
                return None
            if got == want:
                return payload_in
            if got == nn.UNRECOGNIZED:  # a server without this request
                return None
        return None

    def _handshake(self, timeout: float) -> bool:
        """Connect and read the model; False if the server does not answer."""
        self._last_connect = time.monotonic()
        info = self._request(nn.CONNECT, nn.connect_payload(), nn.SERVERINFO, timeout)
        model = info is not None and self._request(nn.REQUEST_MODELDEF, b"", nn.MODELDEF, timeout)
        if not model:
            return False
        try:
            self.info, m = nn.unpack_server_info(info), nn.unpack_modeldef(model)
        except nn.NatNetError as e:
            self.errors.report("malformed", f"{self.name}: server info / model: {e}")
            return False
        self.clock_hz = self.info.clock_hz
        # the NatNet SDK's "FrameRate" request, answered with the rate as a float32; else measured
        rate = self._request(nn.REQUEST, b"FrameRate\0", nn.RESPONSE, timeout)
        if rate is not None and len(rate) >= 4 and struct.unpack_from("<f", rate)[0] > 0:
            self._dt = 1.0 / struct.unpack_from("<f", rate)[0]
        many = len(m.marker_sets) > 1
        self.sets = m.marker_sets
        self.labels = tuple(f"{s}:{x}" if many else x for s, xs in m.marker_sets.items() for x in xs)
        # rigid bodies by name, then each skeleton's bones (by bone name: what a body's segments are called)
        self.bodies = [(None, b.id) for b in m.rigid_bodies] + [(sk.id, b.id) for sk in m.skeletons for b in sk.bones]
        self.segment_names = tuple(b.name for b in m.rigid_bodies) + tuple(b.name for sk in m.skeletons
                                                                           for b in sk.bones)
        self.plate_ids = tuple(p.id for p in m.plates)
        self.plate_names = tuple(p.serial or f"plate{p.id}" for p in m.plates)
        self.plate_index = {}
        for q, names in PLATE_CHANNELS.items():
            self.plate_index[q] = np.array([[p.channels.index(c) if c in p.channels else -1 for c in names]
                                            for p in m.plates], int).reshape(-1, 3)
        return True

    @property
    def finished(self) -> bool:
        return self._closed

    @property
    def nominal_dt(self) -> float | None:
        """The server's answer to "FrameRate", else (it carries no rate otherwise) measured from the
        frames' timestamps."""
        return self._dt

    _dt: float | None = None
    _last_stamp: float | None = None
    _rejoined = False

    def _frame(self, payload: bytes, received: float) -> MocapFrame | None:
        try:
            f = nn.unpack_frame(payload)
            markers = np.concatenate([f.marker_sets[s] for s in self.sets]) if self.sets else np.zeros((0, 3))
        except (nn.NatNetError, KeyError, ValueError) as e:
            self.stats.malformed += 1
            self.errors.report("malformed", f"{self.name}: frame of data: {e}")
            return None
        if len(markers) != len(self.labels):
            self.stats.malformed += 1
            self.errors.report("malformed", f"{self.name}: {len(markers)} markers, the model has {len(self.labels)}")
            return None
        if self._rejoined:  # frames again after connecting anew: the server's numbers may restart
            self._rejoined = False
            self.stats.reconnects += 1
            self.order.restart()
        restart = self.order.admit(f.frame, f.timestamp, self.name)
        if restart is None:
            return None
        if self._last_stamp is not None and f.timestamp > self._last_stamp and self._dt is None:
            self._dt = f.timestamp - self._last_stamp
        self._last_stamp = f.timestamp
        markers = np.where(np.all(markers == 0.0, axis=1, keepdims=True), np.nan, markers)
        k = len(self.plate_ids)
        out = {q: np.full((k, 3), np.nan if q == "cop" else 0.0) for q in PLATE_CHANNELS}
        for i, pid in enumerate(self.plate_ids):
            values = f.plates.get(pid)
            if values is None:
                continue
            for q, idx in self.plate_index.items():
                ok = (idx[i] >= 0) & (idx[i] < len(values))
                out[q][i, ok] = values[idx[i][ok]]
        return MocapFrame(f.timestamp, received, f.frame, self.labels, markers, self.up,
                          PlateSamples(self.plate_names, out["force"], out["moment"], out["cop"]),
                          segments=self._segments(f), restart=restart)

    def _segments(self, f: nn.FrameOfData) -> SegmentPoses:
        """The frame's rigid bodies and skeleton bones in the model's order (untracked: NaN)."""
        from scipy.spatial.transform import Rotation

        k = len(self.bodies)
        pos, quat, tracked = np.full((k, 3), np.nan), np.tile([0.0, 0.0, 0.0, 1.0], (k, 1)), np.zeros(k, bool)
        for i, (sid, bid) in enumerate(self.bodies):
            p = f.rigid_bodies.get(bid) if sid is None else f.skeletons.get(sid, {}).get(bid)
            # a pose with a non-finite or zero quaternion (not a rotation) or position counts as untracked
            if p is not None and p.tracked and np.any(p.quat) and np.isfinite(p.quat).all() \
                    and np.isfinite(p.position).all():
                pos[i], quat[i], tracked[i] = p.position, p.quat, True
        rot = Rotation.from_quat(quat).as_matrix() if k else np.zeros((0, 3, 3))
        return SegmentPoses(self.segment_names, pos, rot, tracked)

    def _keep_connected(self, now: float) -> None:
        if self._silent_since is None:
            self._silent_since = now
        if now - self._silent_since >= self.retry and now - self._last_connect >= self.retry:
            self.errors.report("disconnected", f"{self.name}: no frames for {now - self._silent_since:.1f} s; "
                                               "connecting again")
            if self._handshake(min(self.retry, 0.5)):
                self._rejoined = True
                self._silent_since = now

    def _receive(self) -> None:
        """The receiving thread: drains the data socket as datagrams arrive (the kernel's buffer holds
        only a fraction of a second at 1 kHz), hands frames to the queue, reconnects on silence."""
        while not self._closed:
            try:
                packet, (sender, _) = self.receiver.recvfrom(65536)
            except BlockingIOError:
                self._keep_connected(time.monotonic())
                try:
                    select.select([self.data], [], [], POLL_S)
                except (OSError, ValueError):  # closed meanwhile
                    return
                continue
            except OSError:
                return
            if sender != self.server_ip:
                self.order.drop("rejected", f"{self.name}: a datagram from {sender}, not the server "
                                            f"{self.server_ip}: dropped")
                continue
            now = time.monotonic()
            self._silent_since = None
            try:
                kind, payload = nn.split(packet)
            except nn.NatNetError as e:
                self.stats.malformed += 1
                self.errors.report("malformed", f"{self.name}: {e}")
                continue
            f = self._frame(payload, now) if kind == nn.FRAMEOFDATA else None
            if f is not None:
                self.queue.put(f)

    def read(self, timeout: float) -> MocapFrame | None:
        return None if self._closed else self.queue.get(timeout)

    def _close_sockets(self) -> None:
        self.cmd.close()
        self.data.close()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._thread.join(1.0)
            try:
                self.cmd.send(nn.message(nn.DISCONNECT))
            except OSError:
                pass
            self.receiver.settle()
            self._close_sockets()
