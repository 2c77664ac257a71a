"""OptiTrack NatNet packets (protocol 3.1, as Motive 2.x streams them), both ways.

Facts from the NatNet SDK's packet description (its PacketClient sample and
``NatNetTypes.h``), little endian: every message starts with ``uint16 message id,
uint16 payload bytes``. Ids: 0 connect, 1 server info, 2 request, 3 response, 4 request
model definitions, 5 model definitions, 6 request frame, 7 frame of data, 8 message
string, 9 disconnect, 10 keep-alive, 100 unrecognised request. Strings are
NUL-terminated, except the 256-byte application name of connect/server info.

Only what livezmp uses is laid out here: connect / server info (with the data port and
the high-resolution clock), model definitions with marker sets (type 0), rigid bodies
(type 1: name, id, parent id, offset xyz, then (3.0+) marker count, their positions and
required labels), skeletons (type 2: name, id, bone count, each bone a rigid-body
description) and force plates (type 3), and frames of data with marker sets, rigid
bodies (id, position xyz, orientation quaternion qx qy qz qw, mean marker error, int16
params whose bit 0 says tracking is valid; 3.0+ carries no per-body markers), skeletons
(id, bone count, each bone as a rigid body, bone id = skeleton id << 16 | bone), labelled
markers, force plates and the frame suffix (timecode, timestamp, camera and transmit
stamps). Devices are written empty and refused when read (their count must be 0:
:class:`NatNetError` otherwise, rather than mis-reading the rest).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

import numpy as np

CONNECT, SERVERINFO, REQUEST, RESPONSE, REQUEST_MODELDEF, MODELDEF = 0, 1, 2, 3, 4, 5
REQUEST_FRAMEOFDATA, FRAMEOFDATA, MESSAGESTRING, DISCONNECT, KEEPALIVE, UNRECOGNIZED = 6, 7, 8, 9, 10, 100
HEADER = struct.Struct("<HH")
VERSION = (3, 1, 0, 0)
DATASET_MARKERSET, DATASET_RIGIDBODY, DATASET_SKELETON, DATASET_FORCEPLATE = 0, 1, 2, 3
RIGID_BODY = struct.Struct("<i3f4ffh")  # id, position, quaternion (x, y, z, w), mean error, params


class NatNetError(ValueError):
    """A packet that does not parse."""


_STRUCTS: dict[str, struct.Struct] = {}
LABELLED_MARKER = struct.Struct("<i3ffhf")  # id, position, size, params, residual


class _Reader:
    def __init__(self, data: bytes, offset: int = 0):
        self.data, self.pos = data, offset

    def skip(self, n: int) -> None:
        if self.pos + n > len(self.data):
            raise NatNetError(f"packet ends at byte {len(self.data)}, needs {self.pos + n}")
        self.pos += n

    def take(self, fmt: str):
        s = _STRUCTS.get(fmt) or _STRUCTS.setdefault(fmt, struct.Struct("<" + fmt))
        if self.pos + s.size > len(self.data):
            raise NatNetError(f"packet ends at byte {len(self.data)}, needs {self.pos + s.size}")
        v = s.unpack_from(self.data, self.pos)
        self.pos += s.size
        return v if len(v) > 1 else v[0]

    def floats(self, n: int) -> np.ndarray:
        if self.pos + 4 * n > len(self.data):
            raise NatNetError(f"packet ends at byte {len(self.data)}, needs {self.pos + 4 * n}")
        v = np.frombuffer(self.data, "<f4", n, self.pos).astype(float)
        self.pos += 4 * n
        return v

    def string(self) -> str:
        end = self.data.find(b"\0", self.pos)
        if end < 0:
            raise NatNetError("unterminated string")
        s = self.data[self.pos:end].decode(errors="replace")
        self.pos = end + 1
        return s


def message(kind: int, payload: bytes = b"") -> bytes:
    return HEADER.pack(kind, len(payload)) + payload


def split(packet: bytes) -> tuple[int, bytes]:
    """(message id, payload) of one datagram; NatNetError if its length disagrees."""
    if len(packet) < HEADER.size:
        raise NatNetError(f"{len(packet)} bytes: shorter than the header")
    kind, n = HEADER.unpack_from(packet)
    if len(packet) < HEADER.size + n:
        raise NatNetError(f"payload of {n} bytes announced, {len(packet) - HEADER.size} received")
    return kind, packet[HEADER.size:HEADER.size + n]


def _name256(name: str) -> bytes:
    return name.encode()[:255].ljust(256, b"\0")


def connect_payload(app: str = "livezmp") -> bytes:
    return _name256(app) + bytes([0, 1, 0, 0]) + bytes(VERSION)


@dataclass(frozen=True)
class ServerInfo:
    """``app`` name, ``version`` and ``natnet`` (4 ints), ``clock_hz`` of the
    high-resolution stamps, ``data_port``, ``multicast`` and its ``group`` address."""

    app: str
    version: tuple[int, ...]
    natnet: tuple[int, ...]
    clock_hz: int
    data_port: int
    multicast: bool = False
    group: str = "239.255.42.99"


def pack_server_info(s: ServerInfo) -> bytes:
    group = bytes(int(x) for x in s.group.split("."))
    return (_name256(s.app) + bytes(s.version) + bytes(s.natnet)
            + struct.pack("<QHB", s.clock_hz, s.data_port, int(s.multicast)) + group)


def unpack_server_info(payload: bytes) -> ServerInfo:
    r = _Reader(payload)
    if len(payload) < 256 + 8 + 15:
        raise NatNetError(f"server info of {len(payload)} bytes")
    app = payload[:256].split(b"\0", 1)[0].decode(errors="replace")
    r.pos = 256
    version, natnet = tuple(r.take("4B")), tuple(r.take("4B"))
    clock, port, mc = r.take("QHB")
    group = ".".join(str(b) for b in r.take("4B"))
    return ServerInfo(app, version, natnet, clock, port, bool(mc), group)


@dataclass(frozen=True)
class ForcePlateDef:
    """``id``, ``serial``, ``width``/``length`` and ``corners`` (4, 3) in the stream's
    length unit, ``channels`` names (e.g. Fx Fy Fz Mx My Mz Cx Cy Cz)."""

    id: int
    serial: str
    width: float
    length: float
    corners: np.ndarray
    channels: tuple[str, ...]


@dataclass(frozen=True)
class RigidBodyDef:
    """A rigid body (or skeleton bone): ``name``, ``id``, ``parent`` id (-1 / 0 none), ``offset``
    (3,) from the parent, in the stream's length unit."""

    name: str
    id: int
    parent: int = -1
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class SkeletonDef:
    """A skeleton: ``name``, ``id`` and its ``bones``."""

    name: str
    id: int
    bones: tuple[RigidBodyDef, ...] = ()


@dataclass(frozen=True)
class ModelDef:
    """Marker sets (name → marker names), rigid bodies, skeletons and force plates."""

    marker_sets: dict[str, tuple[str, ...]] = field(default_factory=dict)
    plates: tuple[ForcePlateDef, ...] = ()
    rigid_bodies: tuple[RigidBodyDef, ...] = ()
    skeletons: tuple[SkeletonDef, ...] = ()


def _cstr(s: str) -> bytes:
    return s.encode() + b"\0"


def _pack_rigid_body_def(b: RigidBodyDef) -> bytes:
    return _cstr(b.name) + struct.pack("<ii3fi", b.id, b.parent, *b.offset, 0)  # no markers


def _unpack_rigid_body_def(r: _Reader) -> RigidBodyDef:
    name = r.string()
    rid, parent, *offset = r.take("ii3f")
    n = r.take("i")
    r.skip(16 * n)  # marker positions (3 floats) and required labels (int) of each
    return RigidBodyDef(name, rid, parent, tuple(offset))


def pack_modeldef(m: ModelDef) -> bytes:
    out = [struct.pack("<i", len(m.marker_sets) + len(m.rigid_bodies) + len(m.skeletons) + len(m.plates))]
    for name, markers in m.marker_sets.items():
        out.append(struct.pack("<i", DATASET_MARKERSET) + _cstr(name) + struct.pack("<i", len(markers))
                   + b"".join(_cstr(x) for x in markers))
    for b in m.rigid_bodies:
        out.append(struct.pack("<i", DATASET_RIGIDBODY) + _pack_rigid_body_def(b))
    for sk in m.skeletons:
        out.append(struct.pack("<i", DATASET_SKELETON) + _cstr(sk.name) + struct.pack("<ii", sk.id, len(sk.bones))
                   + b"".join(_pack_rigid_body_def(b) for b in sk.bones))
    for p in m.plates:
        out.append(struct.pack("<ii", DATASET_FORCEPLATE, p.id) + _cstr(p.serial)
                   + struct.pack("<ff3f", p.width, p.length, 0.0, 0.0, 0.0) + np.zeros(144, "<f4").tobytes()
                   + np.asarray(p.corners, "<f4").tobytes() + struct.pack("<iii", 1, 0, len(p.channels))
                   + b"".join(_cstr(c) for c in p.channels))
    return b"".join(out)


def unpack_modeldef(payload: bytes) -> ModelDef:
    r = _Reader(payload)
    sets: dict[str, tuple[str, ...]] = {}
    plates, bodies, skeletons = [], [], []
    for _ in range(r.take("i")):
        kind = r.take("i")
        if kind == DATASET_MARKERSET:
            name = r.string()
            sets[name] = tuple(r.string() for _ in range(r.take("i")))
        elif kind == DATASET_RIGIDBODY:
            bodies.append(_unpack_rigid_body_def(r))
        elif kind == DATASET_SKELETON:
            name = r.string()
            sid, n = r.take("ii")
            skeletons.append(SkeletonDef(name, sid, tuple(_unpack_rigid_body_def(r) for _ in range(n))))
        elif kind == DATASET_FORCEPLATE:
            pid, serial = r.take("i"), r.string()
            width, length = r.take("ff")
            r.floats(3 + 144)  # origin, calibration matrix
            corners = r.floats(12).reshape(4, 3)
            r.take("ii")  # plate type, channel data type
            plates.append(ForcePlateDef(pid, serial, width, length, corners,
                                        tuple(r.string() for _ in range(r.take("i")))))
        else:
            raise NatNetError(f"data set type {kind}: only marker sets, rigid bodies, skeletons and force plates "
                              "(0-3) are read")
    return ModelDef(sets, tuple(plates), tuple(bodies), tuple(skeletons))


@dataclass(frozen=True)
class Pose:
    """A rigid body's ``position`` (3,), orientation ``quat`` (4,) x, y, z, w, and whether it is
    ``tracked``."""

    position: np.ndarray
    quat: np.ndarray
    tracked: bool = True


@dataclass(frozen=True)
class FrameOfData:
    """``frame`` number; ``marker_sets`` name → (n, 3) positions; ``plates`` id →
    (channels,) the last sample of each channel; ``timestamp`` s since the server
    started; ``stamp_transmit`` in high-resolution ticks; ``rigid_bodies`` id → pose;
    ``skeletons`` id → bone id (without the skeleton's id) → pose."""

    frame: int
    marker_sets: dict[str, np.ndarray]
    plates: dict[int, np.ndarray]
    timestamp: float
    stamp_transmit: int = 0
    rigid_bodies: dict[int, Pose] = field(default_factory=dict)
    skeletons: dict[int, dict[int, Pose]] = field(default_factory=dict)


def _pack_pose(rid: int, p: Pose) -> bytes:
    return RIGID_BODY.pack(rid, *p.position, *p.quat, 0.0, 1 if p.tracked else 0)


def _unpack_pose(r: _Reader) -> tuple[int, Pose]:
    rid, x, y, z, qx, qy, qz, qw, _, params = r.take("i3f4ffh")
    return rid, Pose(np.array([x, y, z]), np.array([qx, qy, qz, qw]), bool(params & 1))


def pack_frame(f: FrameOfData) -> bytes:
    out = [struct.pack("<ii", f.frame, len(f.marker_sets))]
    for name, pos in f.marker_sets.items():
        out.append(_cstr(name) + struct.pack("<i", len(pos)) + np.asarray(pos, "<f4").tobytes())
    out.append(struct.pack("<ii", 0, len(f.rigid_bodies)))  # no unlabelled markers
    out += [_pack_pose(rid, p) for rid, p in f.rigid_bodies.items()]
    out.append(struct.pack("<i", len(f.skeletons)))
    for sid, bones in f.skeletons.items():
        out.append(struct.pack("<ii", sid, len(bones)))
        out += [_pack_pose(sid << 16 | bid, p) for bid, p in bones.items()]
    labelled = [p for pos in f.marker_sets.values() for p in pos]
    out.append(struct.pack("<i", len(labelled)))
    for i, p in enumerate(labelled):
        occluded = not np.any(p)
        out.append(LABELLED_MARKER.pack(i + 1, *p, 0.014, 1 if occluded else 0, 0.0))
    out.append(struct.pack("<i", len(f.plates)))
    for pid, values in f.plates.items():
        out.append(struct.pack("<ii", pid, len(values)) + b"".join(struct.pack("<if", 1, v) for v in values))
    out.append(struct.pack("<iIIdQQQhi", 0, 0, 0, f.timestamp, f.stamp_transmit, f.stamp_transmit,
                           f.stamp_transmit, 0, 0))
    return b"".join(out)


ONE_SAMPLE = np.dtype([("n", "<i4"), ("value", "<f4")])  # a channel carrying one sample: its count, its value


def _plate_channels(r: _Reader, nch: int) -> np.ndarray:
    """(nch,) the newest sample of each of a plate's channels (NaN for a channel without samples). Channels
    of one sample each (a plate at the camera rate) are read as one block; others one by one."""
    end = r.pos + ONE_SAMPLE.itemsize * nch
    if 0 <= nch and end <= len(r.data):
        block = np.frombuffer(r.data, ONE_SAMPLE, nch, r.pos)
        if (block["n"] == 1).all():
            r.pos = end
            return block["value"].astype(float)
    values = np.empty(max(nch, 0))
    for c in range(nch):
        n = r.take("i")
        samples = r.floats(n)
        values[c] = samples[-1] if n else np.nan
    return values


def unpack_frame(payload: bytes) -> FrameOfData:
    r = _Reader(payload)
    frame = r.take("i")
    sets = {}
    for _ in range(r.take("i")):
        name = r.string()
        sets[name] = r.floats(3 * r.take("i")).reshape(-1, 3)
    r.floats(3 * r.take("i"))  # unlabelled markers
    bodies = dict(_unpack_pose(r) for _ in range(r.take("i")))
    skeletons = {}
    for _ in range(r.take("i")):
        sid, n = r.take("ii")
        skeletons[sid] = {rid & 0xFFFF: p for rid, p in (_unpack_pose(r) for _ in range(n))}
    r.skip(LABELLED_MARKER.size * r.take("i"))  # labelled markers: the marker sets carry their positions
    plates = {}
    for _ in range(r.take("i")):
        pid, nch = r.take("ii")
        plates[pid] = _plate_channels(r, nch)
    if r.take("i"):
        raise NatNetError(f"frame {frame}: devices are not read by livezmp's NatNet client")
    _, _, timestamp, _, _, transmit, _, _ = r.take("IIdQQQhi")  # ... params, end of data
    return FrameOfData(frame, sets, plates, timestamp, transmit, bodies, skeletons)
