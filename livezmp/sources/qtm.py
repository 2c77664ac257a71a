"""Qualisys Track Manager live: ``qtm://HOST[:PORT]`` through the official ``qtm-rt`` client.

The client runs its asyncio loop in a thread of its own: it connects (protocol 1.25 by
default, ``?version=``), reads the parameters (``general``: frame rate; ``3d``: up axis
and marker labels; ``force``: plates with their corners and length unit) and streams
every frame (``3d`` markers in mm, ``force`` per plate force N, moment N·m, application
point in the plates' length unit, in each plate's own axes, turned into the lab's with
the corners, :mod:`livezmp.sources.plate_frame`; ``6d`` rigid bodies named in ``The_6D``:
position mm and rotation matrix, 9 floats column by column as Qualisys' own clients read
them, an untracked body NaN, as the frame's segment poses; then ``skeleton:global``: the segments of
the skeletons QTM solves, named in ``Skeletons``, position mm and quaternion). Frames go in order by
QTM's frame number and timestamp (:class:`~livezmp.sources.udp.Timeline`: late, duplicate, lost, jumps
counted; a restarted numbering followed). A lost connection is reported and re-made every
``retry`` s, parameters read again (a changed marker set is taken as it comes).

QTM timestamps are µs on QTM's own clock, which this machine cannot relate to its own:
``MocapFrame.latency`` is None; ``t`` is the timestamp in s.
"""

from __future__ import annotations

import asyncio
import math
import struct
import threading
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, replace

import numpy as np

from livezmp.checks import MAX_COORDINATE_M, check_frame_period
from livezmp.errors import InputError
from livezmp.model.plate_frame import plate_axes
from livezmp.sources.interface import ErrorLog, SourceStats
from livezmp.sources.mocap_frame import FrameQueue, MocapFrame, PlateSamples, SegmentPoses, parse_up_axis
from livezmp.sources.udp import Timeline

DEFAULT_PORT = 22223  # QTM's little-endian RT port, the one qtm-rt speaks
LENGTH = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}


@dataclass(frozen=True)
class QtmParameters:
    """What the parameters XML says: ``rate`` Hz, ``up`` axis, marker ``labels``, plate
    ``plates`` names and ``axes`` (R, origin m) from their corners, ``length`` m per the
    force component's length unit."""

    rate: float
    up: str
    labels: tuple[str, ...]
    plates: tuple[str, ...]
    axes: tuple[tuple[np.ndarray, np.ndarray], ...]
    length: float
    bodies: tuple[str, ...] = ()  # 6DOF bodies
    skeletons: tuple[tuple[int, ...], ...] = ()  # per skeleton its segments' ids, in the parameters' order
    segments: tuple[str, ...] = ()  # those segments' names, skeleton after skeleton

    @property
    def poses(self) -> tuple[str, ...]:
        """Names of the frame's segment poses: the 6DOF bodies, then the skeletons' segments."""
        return self.bodies + self.segments


def _text(node: ET.Element | None, path: str, where: str) -> str:
    found = None if node is None else node.find(path)
    if found is None or found.text is None:
        raise InputError(f"{where}: parameters XML has no {path}")
    return found.text.strip()


def _number(node: ET.Element | None, path: str, where: str, limit: float = math.inf) -> float:
    """The number at ``path``, finite and within ±``limit``; InputError naming the field otherwise."""
    text = _text(node, path, where)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not abs(value) <= limit:  # NaN fails too
        within = f" within ±{limit:g}" if limit < math.inf else ""
        raise InputError(f"{where}: parameters XML {path}: need a number{within}, got {text[:40]!r}")
    return value


def parse_parameters(xml: str, where: str) -> QtmParameters:
    """The :class:`QtmParameters` of a ``getparameters general 3d force 6d skeleton`` reply."""
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as e:
        raise InputError(f"{where}: parameters XML: {e}") from None
    rate = _number(root, "General/Frequency", where)
    if not rate > 0:
        raise InputError(f"{where}: parameters XML General/Frequency: need a positive number of Hz, got {rate:g}")
    check_frame_period(1.0 / rate, f"{where}: parameters XML General/Frequency {rate:g} Hz")
    the3d = root.find("The_3D")
    try:
        up = parse_up_axis(_text(the3d, "AxisUpwards", where), where)
    except ValueError as e:
        raise InputError(str(e)) from None
    labels = tuple(_text(lab, "Name", where) for lab in (the3d.findall("Label") if the3d is not None else []))
    force = root.find("Force")
    unit = _text(force, "Unit_Length", where) if force is not None and force.find("Unit_Length") is not None else "mm"
    if unit not in LENGTH:
        raise InputError(f"{where}: Force/Unit_Length {unit!r} is not one of {', '.join(LENGTH)}")
    names, axes = [], []
    for plate in force.findall("Plate") if force is not None else []:
        names.append(_text(plate, "Name", where))
        corners = np.array([[_number(plate, f"Location/Corner{j}/{a}", where, 1e3 * MAX_COORDINATE_M) for a in "XYZ"]
                            for j in range(1, 5)]) * 1e-3  # QTM's locations are in mm
        axes.append(plate_axes(corners))
    six = root.find("The_6D")
    bodies = tuple(_text(b, "Name", where) for b in (six.findall("Body") if six is not None else []))
    ids, segment_names = [], []
    for skeleton in root.findall("Skeletons/Skeleton"):
        segments = list(skeleton.iter("Segment"))  # nested under their parents from protocol 1.22 on
        try:
            ids.append(tuple(int(seg.get("ID", "")) for seg in segments))
        except ValueError:
            raise InputError(f"{where}: parameters XML: skeleton {skeleton.get('Name')!r} has a segment "
                             "without a numeric ID") from None
        segment_names += [f"{seg.get('Name')}" for seg in segments]
    return QtmParameters(rate, up, labels, tuple(names), tuple(axes), LENGTH[unit], bodies, tuple(ids),
                         tuple(segment_names))


# component bodies after their 8-byte header, as the QTM RT protocol documentation lays them out (little
# endian): 3D: marker count uint32, 2D drop and out-of-sync rates int16 x 2, then x y z float32 per marker;
# force: plate count int32, per plate id, sample count, sample number int32 and 9 float32 per sample
# (force xyz, moment xyz, application point xyz); 6D: body count int32, rates int16 x 2, per body x y z
# and the 3x3 rotation matrix float32. Read as numpy blocks rather than one record per marker.
# skeleton: skeleton count int32, per skeleton segment count int32, per segment id int32, position xyz
# float32 mm, rotation quaternion x y z w float32.
COUNT_RATES = struct.Struct("<Ihh")
PLATE = struct.Struct("<iii")
F4 = np.dtype("<f4")
SEGMENT = np.dtype([("id", "<i4"), ("pos", "<f4", 3), ("quat", "<f4", 4)])


def _block(data: bytes, pos: int, rows: int, cols: int) -> np.ndarray:
    """(rows, cols) float of float32 at ``pos``; ValueError if the packet is shorter."""
    return np.frombuffer(data, F4, rows * cols, pos).reshape(rows, cols).astype(float)


def frame_of_packet(packet, p: QtmParameters, received: float) -> MocapFrame:
    """A :class:`MocapFrame` of a ``qtm_rt.QRTPacket`` with 3D (and force, 6D) components; ValueError or
    struct.error for a packet shorter than its counts say."""
    from qtm_rt.packet import QRTComponentType

    data, where = packet.data, packet.components
    markers = np.full((len(p.labels), 3), np.nan)
    pos = where.get(QRTComponentType.Component3d)
    if pos is not None:
        n = min(COUNT_RATES.unpack_from(data, pos)[0], len(p.labels))
        markers[:n] = _block(data, pos + COUNT_RATES.size, n, 3) * 1e-3
    k = len(p.plates)
    force, moment, cop = np.zeros((k, 3)), np.zeros((k, 3)), np.full((k, 3), np.nan)
    pos = where.get(QRTComponentType.ComponentForce)
    if k and pos is not None:
        (plates,), pos = struct.unpack_from("<i", data, pos), pos + 4
        for _ in range(plates):
            pid, count, _ = PLATE.unpack_from(data, pos)
            pos += PLATE.size + 36 * count
            i = pid - 1
            if not 0 <= i < k or count <= 0:
                continue
            s = _block(data, pos - 36, 1, 9)[0]  # the newest sample of the frame
            R, origin = p.axes[i]
            force[i], moment[i] = R @ s[0:3], R @ s[3:6]
            cop[i] = R @ (s[6:9] * p.length) + origin
    return MocapFrame(packet.timestamp * 1e-6, received, packet.framenumber, p.labels, markers, p.up,
                      PlateSamples(p.plates, force, moment, cop), segments=_bodies(packet, p))


def _bodies(packet, p: QtmParameters) -> SegmentPoses:
    """The 6D component's bodies and the skeleton component's segments (named by the parameters) as
    segment poses; an untracked one NaN."""
    from qtm_rt.packet import QRTComponentType

    k = len(p.bodies)
    names = p.poses
    pos, rot = np.full((len(names), 3), np.nan), np.tile(np.eye(3), (len(names), 1, 1))
    at = packet.components.get(QRTComponentType.Component6d)
    if k and at is not None:
        n = min(COUNT_RATES.unpack_from(packet.data, at)[0], k)
        block = _block(packet.data, at + COUNT_RATES.size, n, 12)
        pos[:n] = block[:, :3] * 1e-3
        rot[:n] = block[:, 3:].reshape(n, 3, 3).transpose(0, 2, 1)  # the matrix column by column
    at = packet.components.get(QRTComponentType.ComponentSkeleton)
    if p.skeletons and at is not None:
        _skeleton_segments(packet.data, at, p.skeletons, pos[k:], rot[k:])
    tracked = np.isfinite(pos).all(axis=1) & np.isfinite(rot).all(axis=(1, 2))
    return SegmentPoses(names, pos, rot, tracked)


def _skeleton_segments(data: bytes, at: int, skeletons: tuple[tuple[int, ...], ...], pos: np.ndarray,
                       rot: np.ndarray) -> None:
    """Fill ``pos`` (m) and ``rot`` (rotation matrices), rows in the parameters' segment order, from the
    skeleton component at ``at`` (global poses); a segment the packet lacks, or without a rotation, stays NaN
    (untracked)."""
    from scipy.spatial.transform import Rotation

    (count,), at = struct.unpack_from("<i", data, at), at + 4
    row = 0
    for ids in skeletons[:max(count, 0)]:
        (n,), at = struct.unpack_from("<i", data, at), at + 4
        block = np.frombuffer(data, SEGMENT, n, at)
        at += SEGMENT.itemsize * n
        index = {sid: row + i for i, sid in enumerate(ids)}
        rows = np.array([index.get(int(sid), -1) for sid in block["id"]], int)
        quat = block["quat"].astype(float)
        ok = (rows >= 0) & np.isfinite(quat).all(axis=1) & (np.abs(quat).sum(axis=1) > 0)
        if ok.any():
            pos[rows[ok]] = block["pos"][ok] * 1e-3
            rot[rows[ok]] = Rotation.from_quat(quat[ok]).as_matrix()
        row += len(ids)


class QtmSource:
    """Client of a QTM RT server at ``host``:``port``; see the module docstring."""

    def __init__(self, host: str, port: int = DEFAULT_PORT, version: str = "1.25", retry: float = 0.5,
                 connect_timeout: float = 5.0, queue: int = 4096):
        self.name = f"qtm://{host}:{port}"
        self.host, self.port, self.version, self.retry = host, port, version, retry
        self.stats, self.errors = SourceStats(), ErrorLog()
        self.order = Timeline(self.stats, self.errors)
        self.queue = FrameQueue(self.stats, queue)
        self.params: QtmParameters | None = None
        self._closed = False
        self._sessions = 0
        self._ready = threading.Event()
        self._failure: str | None = None
        self._refused: InputError | None = None  # the parameters of the first connection, refused
        self._loop = asyncio.new_event_loop()
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._loop.run_until_complete, args=(self._run(),),
                                        name="qtm-client", daemon=True)
        self._thread.start()
        if not self._ready.wait(connect_timeout) or self.params is None:
            self.close()
            if self._refused is not None:
                raise self._refused
            raise InputError(f"{self.name}: cannot connect: {self._failure or 'no answer'}")

    @property
    def nominal_dt(self) -> float:
        return 1.0 / self.params.rate

    @property
    def up(self) -> str:
        return self.params.up

    @property
    def labels(self) -> tuple[str, ...]:
        return self.params.labels

    @property
    def finished(self) -> bool:
        return self._closed

    async def _session(self) -> None:
        """One connection: parameters, then frames until it drops."""
        import qtm_rt

        lost = asyncio.Event()
        conn = await qtm_rt.connect(self.host, self.port, version=self.version,
                                    on_disconnect=lambda exc: lost.set(), timeout=5)
        if conn is None:
            self._failure = "connection refused or version not accepted"
            return
        try:
            xml = await conn.get_parameters(["general", "3d", "force", "6d", "skeleton"])
            try:
                params = parse_parameters(xml.decode(errors="replace"), self.name)
            except InputError as e:
                self._refuse(e)
                return
            components = (["3d"] + ["force"] * bool(params.plates) + ["6d"] * bool(params.bodies)
                          + ["skeleton:global"] * bool(params.skeletons))
            self.params = params
            if self._sessions:
                self.stats.reconnects += 1
                self.order.restart()
            self._sessions += 1
            # QTM answers streamframes with its first frame: a camera not yet running
            # answers later, so the answer is not awaited before the source is ready
            streaming = asyncio.ensure_future(conn.stream_frames(frames="allframes", components=components,
                                                                 on_packet=self._on_packet))
            self._ready.set()
            waits = [asyncio.ensure_future(self._stop.wait()), asyncio.ensure_future(lost.wait())]
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
            for task in [*waits, streaming]:
                task.cancel()
        except (TimeoutError, qtm_rt.QRTCommandException) as e:
            self._failure = str(e)
        finally:
            if conn.has_transport():
                conn.disconnect()

    def _refuse(self, e: InputError) -> None:
        """Parameters that cannot be streamed: at connection, the source's one-line error at once; on a
        reconnect, a malformed packet counted and reported (the client retries; the thread goes on)."""
        if self._sessions:
            self.stats.malformed += 1
            self.errors.report("malformed", f"{e}; retrying every {self.retry:g} s")
        else:
            self._refused = e
            self._ready.set()

    async def _run(self) -> None:
        self._stop = asyncio.Event()
        while not self._stop.is_set():
            await self._session()
            if self._stop.is_set():
                break
            self.errors.report("disconnected", f"{self.name}: connection lost; retrying every {self.retry:g} s")
            try:
                await asyncio.wait_for(self._stop.wait(), self.retry)
            except TimeoutError:
                pass

    def _on_packet(self, packet) -> None:
        received = time.monotonic()
        if self.params is None:
            return
        try:  # parsed first, as NatNet's: a malformed frame is not delivered
            frame = frame_of_packet(packet, self.params, received)
        except (ValueError, struct.error) as e:
            self.stats.malformed += 1
            self.errors.report("malformed", f"{self.name}: frame {packet.framenumber}: {e}")
            return
        restart = self.order.admit(packet.framenumber, frame.t, self.name)
        if restart is not None:
            self.queue.put(replace(frame, restart=True) if restart else frame)

    def read(self, timeout: float) -> MocapFrame | None:
        return None if self._closed else self.queue.get(timeout)

    def close(self) -> None:
        self._closed = True
        if self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(5.0)
