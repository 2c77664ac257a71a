"""A simulated Qualisys Track Manager real-time server (QTM RT protocol over TCP).

The unmodified ``qtm-rt`` client connects to it on 127.0.0.1. What it serves, little
endian as QTM's little-endian port does:

- on connect, the command packet "QTM RT Interface connected";
- ``version X`` (1.8 … 1.25 accepted, else an error packet), ``qtmversion``,
  ``byteorder``, ``getstate`` (an event packet: capture started);
- ``getparameters general 3d force …``: an XML packet with the frequency, the up axis
  and marker labels (``The_3D``), the plates with their corners (``Force``, lengths mm);
- ``getcurrentframe`` / ``streamframes allframes|frequency:N|frequencydivisor:N
  COMPONENTS`` / ``streamframes stop``: data packets with the ``3d`` component (mm, NaN
  for occluded markers), the ``force`` component (per plate one sample: force N,
  moment N·m, application point mm, in the plate's own axes from its corners) and, for a
  trial with segment poses, the ``6d`` component (header: body count int32, 2D drop and
  out-of-sync rates int16; per body position xyz float32 mm and the 3x3 rotation matrix
  as 9 float32 column by column, as Qualisys' clients read it; bodies named in the
  parameters' ``The_6D``), or, for a server started with ``poses=("skeleton",)`` (QTM's skeleton
  solver), the ``skeleton`` component (``skeleton`` or ``skeleton:global``: skeleton count int32; per
  skeleton its segment count int32 and per segment id int32, position xyz float32 mm, rotation
  quaternion x y z w float32; segments named in the parameters' ``Skeletons``, each a root of its
  own, so local and global poses are the same);
- anything else: an error packet "Parse error".

Packet layouts follow the QTM RT protocol documentation (header: size incl. header,
type; data: timestamp µs, frame number, component count, then per component size,
type and body). The camera system runs whether or not anyone streams: one player
thread plays the trial at its rate; dropped frames are never sent (their numbers are
skipped), late ones go out after later frames. :meth:`kick` drops every client and
:meth:`close` stops the server (a QTM that goes away).
"""

from __future__ import annotations

import socket
import struct
import threading
from dataclasses import dataclass

import numpy as np

from livezmp.model.plate_frame import plate_axes
from sim_devices.impairments import Impairments
from sim_devices.mocap_trial import MocapTrial, PlayCounters, TrialFrame, TrialPlayer
from sim_devices.tcp_accept import accept_until

HEADER = struct.Struct("<II")
TYPE_ERROR, TYPE_COMMAND, TYPE_XML, TYPE_DATA, TYPE_NO_MORE_DATA, TYPE_EVENT = 0, 1, 2, 3, 4, 6
EVENT_CAPTURE_STARTED = 3
COMPONENT_3D, COMPONENT_FORCE, COMPONENT_6D, COMPONENT_SKELETON = 1, 4, 5, 18
VERSIONS = (1, 8), (1, 25)
COMPONENTS = {"3d": COMPONENT_3D, "force": COMPONENT_FORCE, "6d": COMPONENT_6D, "skeleton": COMPONENT_SKELETON,
              "skeleton:global": COMPONENT_SKELETON}
SKELETON = "subject"  # the solved skeleton's name


def packet(kind: int, body: bytes) -> bytes:
    return HEADER.pack(HEADER.size + len(body), kind) + body


def text_packet(kind: int, text: str) -> bytes:
    return packet(kind, text.encode() + b"\0")


def parameters_xml(trial: MocapTrial, version: str, parts: list[str], poses: tuple[str, ...] = ("6d",)) -> str:
    """The parameters XML of ``parts`` (general, 3d, force, 6d, skeleton; "all" = every one); the trial's
    segments are listed as 6DOF bodies and/or skeleton segments as ``poses`` says."""
    want = {w.split(":")[0] for w in parts} if "all" not in parts else {"general", "3d", "force", "6d", "skeleton"}
    out = [f"<QTM_Parameters_Ver_{version}>"]
    if "general" in want:
        out.append(f"<General><Frequency>{trial.rate:g}</Frequency><Capture_Time>{trial.n_frames / trial.rate:.6f}"
                   "</Capture_Time></General>")
    if "3d" in want:
        labels = "".join(f"<Label><Name>{n}</Name><RGBColor>65280</RGBColor>"
                         "<Trajectory_Type>Measured</Trajectory_Type></Label>" for n in trial.labels)
        out.append(f"<The_3D><AxisUpwards>{trial.up.upper()}</AxisUpwards><CalibrationTime>2026-01-01 00:00:00"
                   f"</CalibrationTime><Labels>{len(trial.labels)}</Labels>{labels}</The_3D>")
    if "force" in want:
        plates = []
        for i, name in enumerate(trial.plate_names):
            c = trial.corners[i] * 1e3
            corners = "".join(f"<Corner{j + 1}><X>{c[j, 0]:.6f}</X><Y>{c[j, 1]:.6f}</Y><Z>{c[j, 2]:.6f}</Z>"
                              f"</Corner{j + 1}>" for j in range(4))
            plates.append(f"<Plate><Force_Plate_Index>{i + 1}</Force_Plate_Index><Analog_Device_ID>1"
                          f"</Analog_Device_ID><Frequency>{trial.rate:g}</Frequency><Type>Simulated</Type>"
                          f"<Name>{name}</Name><Length>{np.linalg.norm(c[0] - c[1]):.6f}</Length>"
                          f"<Width>{np.linalg.norm(c[0] - c[3]):.6f}</Width><Location>{corners}</Location>"
                          "<Origin><X>0</X><Y>0</Y><Z>0</Z></Origin></Plate>")
        out.append(f"<Force><Unit_Length>mm</Unit_Length><Unit_Force>N</Unit_Force>{''.join(plates)}</Force>")
    if "6d" in want:
        names = trial.segment_names if "6d" in poses else ()
        bodies = "".join(f"<Body><Name>{n}</Name><RGBColor>255</RGBColor></Body>" for n in names)
        out.append(f"<The_6D><Bodies>{len(names)}</Bodies>{bodies}</The_6D>")
    if "skeleton" in want and "skeleton" in poses and trial.segment_names:
        segments = "".join(f'<Segment Name="{n}" ID="{i + 1}"><Solver>Global Optimization</Solver></Segment>'
                           for i, n in enumerate(trial.segment_names))
        out.append(f'<Skeletons><Skeleton Name="{SKELETON}"><Solver>Global Optimization</Solver><Scale>1.000000'
                   f'</Scale><Segments>{segments}</Segments></Skeleton></Skeletons>')
    out.append(f"</QTM_Parameters_Ver_{version}>")
    return "".join(out)


def data_packet(trial: MocapTrial, f: TrialFrame, components: list[int], axes: list) -> bytes:
    """A data packet of frame ``f`` with ``components``; ``axes`` per plate (R, origin)."""
    parts = []
    for comp in components:
        if comp == COMPONENT_3D:
            body = struct.pack("<Ihh", len(f.markers), 0, 0) + (f.markers * 1e3).astype("<f4").tobytes()
        elif comp == COMPONENT_SKELETON:
            n = len(trial.segment_names)
            body = struct.pack("<i", 1 if n else 0)
            if n:  # one skeleton: per segment id, position mm, quaternion x y z w
                from scipy.spatial.transform import Rotation

                quat = Rotation.from_matrix(f.segment_rot).as_quat()
                body += struct.pack("<i", n) + b"".join(
                    struct.pack("<i", i + 1) + np.concatenate([f.segment_pos[i] * 1e3, quat[i]]).astype("<f4").tobytes()
                    for i in range(n))
        elif comp == COMPONENT_6D:
            n = len(trial.segment_names)
            body = struct.pack("<ihh", n, 0, 0)
            if n:  # position mm, then the rotation matrix column by column
                cols = np.swapaxes(f.segment_rot, 1, 2).reshape(n, 9)
                body += np.hstack([f.segment_pos * 1e3, cols]).astype("<f4").tobytes()
        else:
            body = struct.pack("<i", len(axes))
            for i, (R, origin) in enumerate(axes):
                local = np.concatenate([R.T @ f.force[i], R.T @ f.moment[i], (R.T @ (f.cop[i] - origin)) * 1e3])
                body += struct.pack("<iii", i + 1, 1, f.number) + local.astype("<f4").tobytes()
        parts.append(struct.pack("<II", 8 + len(body), comp) + body)
    head = struct.pack("<qII", int(round(f.t * 1e6)), f.number + 1, len(parts))
    return packet(TYPE_DATA, head + b"".join(parts))


@dataclass
class _Client:
    conn: socket.socket
    version: str = "1.25"
    components: tuple[int, ...] = ()
    divisor: int = 0  # 0: not streaming; else every divisor-th frame


class QtmServer:
    """A QTM RT server on ``host``:``port`` (0: any free port) playing ``trial``; see the
    module docstring. :meth:`start` starts the camera (the player thread). ``poses``: the trial's
    segment poses (when it has them) as 6DOF bodies ("6d"), as a solved skeleton ("skeleton"), or both."""

    def __init__(self, trial: MocapTrial, port: int = 0, host: str = "127.0.0.1",
                 impairments: Impairments | None = None, speed: float = 1.0, loop: bool = True,
                 max_frames: int | None = None, poses: tuple[str, ...] = ("6d",)):
        self.trial, self.poses = trial, poses
        self.player = TrialPlayer(trial, impairments, speed, loop, max_frames)
        self.axes = [plate_axes(c) for c in trial.corners]
        self.server = socket.create_server((host, port))
        self.server.settimeout(0.1)
        self.host, self.port = host, self.server.getsockname()[1]
        self.clients: list[_Client] = []
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._current: TrialFrame | None = None
        self._thread = threading.Thread(target=self._accept, name="qtm-accept", daemon=True)
        self._thread.start()

    @property
    def counters(self) -> PlayCounters:
        return self.player.counters

    def start(self) -> QtmServer:
        self.player.start(self._frame, "qtm-camera")
        return self

    def streaming_clients(self) -> int:
        with self._lock:
            return sum(1 for c in self.clients if c.divisor)

    def _accept(self) -> None:
        accept_until(self.server, self._closing, self._add)

    def _add(self, conn: socket.socket) -> None:
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(conn)
        with self._lock:
            self.clients.append(client)
        self._write(client, text_packet(TYPE_COMMAND, "QTM RT Interface connected"))
        threading.Thread(target=self._serve, args=(client,), name="qtm-client", daemon=True).start()

    def _write(self, client: _Client, data: bytes) -> None:
        try:
            client.conn.sendall(data)
        except OSError:
            self._drop(client)

    def _drop(self, client: _Client) -> None:
        with self._lock:
            if client in self.clients:
                self.clients.remove(client)
        client.conn.close()

    def _serve(self, client: _Client) -> None:
        buf = b""
        while not self._closing.is_set():
            try:
                chunk = client.conn.recv(65536)
            except OSError:
                chunk = b""
            if not chunk:
                self._drop(client)
                return
            buf += chunk
            while len(buf) >= HEADER.size:
                size, kind = HEADER.unpack_from(buf)
                if size < HEADER.size:
                    self._drop(client)
                    return
                if len(buf) < size:
                    break
                body, buf = buf[HEADER.size:size], buf[size:]
                if kind == TYPE_COMMAND:
                    self._command(client, body.rstrip(b"\0").decode(errors="replace").strip())
                else:
                    self._write(client, text_packet(TYPE_ERROR, "Parse error"))

    def _command(self, client: _Client, cmd: str) -> None:
        words = cmd.split()
        verb = words[0].lower() if words else ""
        if verb == "version" and len(words) == 2:
            try:
                v = tuple(int(x) for x in words[1].split("."))
            except ValueError:
                v = ()
            if len(v) == 2 and VERSIONS[0] <= v <= VERSIONS[1]:
                client.version = words[1]
                self._write(client, text_packet(TYPE_COMMAND, f"Version set to {words[1]}"))
            else:
                self._write(client, text_packet(TYPE_ERROR, "Version NOT supported"))
        elif verb == "qtmversion":
            self._write(client, text_packet(TYPE_COMMAND, "QTM Version is 2024.1 (livezmp simulator)"))
        elif verb == "byteorder":
            self._write(client, text_packet(TYPE_COMMAND, "Byte order is little endian"))
        elif verb == "getstate":
            self._write(client, packet(TYPE_EVENT, bytes([EVENT_CAPTURE_STARTED])))
        elif verb == "getparameters":
            self._write(client, text_packet(TYPE_XML, parameters_xml(self.trial, client.version,
                                                                      [w.lower() for w in words[1:]] or ["all"],
                                                                      self.poses)))
        elif verb == "getcurrentframe" and self._components(words[1:]) is not None:
            f = self._current
            comps = self._components(words[1:])
            self._write(client, data_packet(self.trial, f, comps, self.axes) if f is not None
                        else packet(TYPE_NO_MORE_DATA, b""))
        elif verb == "streamframes" and len(words) == 2 and words[1].lower() == "stop":
            client.divisor = 0
        elif verb == "streamframes" and len(words) >= 3 and self._components(words[2:]) is not None:
            divisor = self._divisor(words[1].lower())
            if divisor is None:
                self._write(client, text_packet(TYPE_ERROR, "Parse error"))
                return
            client.components = tuple(self._components(words[2:]))
            client.divisor = divisor
        else:
            self._write(client, text_packet(TYPE_ERROR, "Parse error"))

    @staticmethod
    def _components(words: list[str]) -> list[int] | None:
        comps = [COMPONENTS.get(w.lower()) for w in words]
        return None if not comps or None in comps else comps

    def _divisor(self, spec: str) -> int | None:
        kind, _, n = spec.partition(":")
        if kind == "allframes" and not n:
            return 1
        try:
            value = float(n)
        except ValueError:
            return None
        if kind == "frequency" and value > 0:
            return max(int(round(self.trial.rate / value)), 1)
        if kind == "frequencydivisor" and value >= 1:
            return int(value)
        return None

    def _frame(self, f: TrialFrame) -> None:
        self._current = f
        with self._lock:
            streaming = [c for c in self.clients if c.divisor and f.number % c.divisor == 0]
        for c in streaming:
            self._write(c, data_packet(self.trial, f, list(c.components), self.axes))

    def kick(self) -> None:
        """Close every client connection."""
        with self._lock:
            clients, self.clients = self.clients, []
        for c in clients:
            try:
                c.conn.shutdown(socket.SHUT_RDWR)  # wakes the client's serving thread, tells the client
            except OSError:
                pass
            c.conn.close()

    def join(self) -> None:
        """Wait until the trial has been played (forever with loop; Ctrl-C interrupts)."""
        self.player.join()

    def close(self) -> None:
        self.player.close()
        self._closing.set()
        self.server.close()
        self.kick()
        self._thread.join(5.0)
