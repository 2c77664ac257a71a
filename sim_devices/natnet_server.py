"""A simulated OptiTrack Motive NatNet server (protocol 3.1, unicast) over UDP loopback.

As Motive does: a command socket (``command_port``, 1510 by default) answers connect
with server info (the data port, a 10 MHz high-resolution clock), model-definition
requests with the marker set, skeleton and force plates, the "FrameRate" request with
the rate (float32), keep-alives silently, anything else with "unrecognised request";
every frame of data goes to each connected client's address at ``data_port`` (1511 by
default; Motive's setting, which the client binds). Positions are in metres with y up
(Motive's streaming default): a z-up trial is turned (x, y, z) → (x, z, −y). Force
plates stream Fx Fy Fz (N), Mx My Mz (N·m), Cx Cy Cz (m, centre of pressure) in the
same axes. Occluded markers are sent as (0, 0, 0), as Motive sends them in marker sets.
A trial with segment poses (:func:`~sim_devices.mocap_trial.with_segments`) also streams
them as a skeleton (id 1, one bone per segment, named as the segment, each pose a
position and an x, y, z, w quaternion); ``markers=False`` streams the skeleton alone.
:meth:`close` stops answering and sending (Motive quits).
"""

from __future__ import annotations

import socket
import struct
import threading
import time

import numpy as np

from livezmp.sources import natnet_protocol as nn
from sim_devices.impairments import Impairments
from sim_devices.mocap_trial import MocapTrial, PlayCounters, TrialFrame, TrialPlayer

CLOCK_HZ = 10_000_000
SKELETON_ID = 1
CHANNELS = ("Fx", "Fy", "Fz", "Mx", "My", "Mz", "Cx", "Cy", "Cz")


def to_y_up(trial: MocapTrial) -> np.ndarray:
    """Rotation (3, 3) taking the trial's axes to Motive's y-up axes."""
    if trial.up == "+y":
        return np.eye(3)
    if trial.up == "+z":
        return np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    raise ValueError(f"{trial.source}: up axis {trial.up}: only +z and +y trials are turned to Motive's axes")


class NatNetServer:
    """Serves ``trial`` over NatNet on ``host``; ``command_port`` 0 = any free port."""

    def __init__(self, trial: MocapTrial, command_port: int = 0, data_port: int = 1511, host: str = "127.0.0.1",
                 impairments: Impairments | None = None, speed: float = 1.0, loop: bool = True,
                 max_frames: int | None = None, name: str = "trial", markers: bool = True):
        self.trial, self.data_port, self.set_name, self.markers = trial, data_port, name, markers
        self.R = to_y_up(trial)
        self.player = TrialPlayer(trial, impairments, speed, loop, max_frames)
        self.cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.cmd.bind((host, command_port))
        self.cmd.settimeout(0.1)
        self.host, self.command_port = host, self.cmd.getsockname()[1]
        self.data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.clients: set[str] = set()
        self._lock = threading.Lock()
        self._closing = threading.Event()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._serve, name="natnet-command", daemon=True)
        self._thread.start()

    @property
    def counters(self) -> PlayCounters:
        return self.player.counters

    def modeldef(self) -> nn.ModelDef:
        plates = tuple(nn.ForcePlateDef(i + 1, f"SIM{i + 1}", float(np.linalg.norm(c[0] - c[3])),
                                        float(np.linalg.norm(c[0] - c[1])), c @ self.R.T, CHANNELS)
                       for i, c in enumerate(self.trial.corners))
        bones = tuple(nn.RigidBodyDef(name, i + 1, 0) for i, name in enumerate(self.trial.segment_names))
        skeletons = (nn.SkeletonDef(self.set_name, SKELETON_ID, bones),) if bones else ()
        return nn.ModelDef({self.set_name: self.trial.labels} if self.markers else {}, plates, (), skeletons)

    def start(self) -> NatNetServer:
        self.player.start(self._frame, "natnet-camera")
        return self

    def _serve(self) -> None:
        while not self._closing.is_set():
            try:
                data, addr = self.cmd.recvfrom(65536)
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                kind, payload = nn.split(data)
            except nn.NatNetError:
                continue
            if kind == nn.CONNECT:
                with self._lock:
                    self.clients.add(addr[0])
                info = nn.ServerInfo("Motive", (2, 3, 0, 0), nn.VERSION, CLOCK_HZ, self.data_port)
                reply = nn.message(nn.SERVERINFO, nn.pack_server_info(info))
            elif kind == nn.REQUEST_MODELDEF:
                reply = nn.message(nn.MODELDEF, nn.pack_modeldef(self.modeldef()))
            elif kind == nn.REQUEST and payload.rstrip(b"\0") == b"FrameRate":  # the SDK's rate request
                reply = nn.message(nn.RESPONSE, struct.pack("<f", self.trial.rate))
            elif kind == nn.KEEPALIVE:
                continue
            elif kind == nn.DISCONNECT:
                with self._lock:
                    self.clients.discard(addr[0])
                continue
            else:
                reply = nn.message(nn.UNRECOGNIZED)
            self.cmd.sendto(reply, addr)

    def _frame(self, f: TrialFrame) -> None:
        pos = np.nan_to_num(f.markers @ self.R.T, nan=0.0)
        plates = {i + 1: np.concatenate([self.R @ f.force[i], self.R @ f.moment[i], self.R @ f.cop[i]])
                  for i in range(len(f.force))}
        ticks = int((time.monotonic() - self._t0) * CLOCK_HZ)
        skeletons = {}
        if f.segment_pos is not None:
            from scipy.spatial.transform import Rotation

            quat = Rotation.from_matrix(self.R @ f.segment_rot).as_quat()  # x, y, z, w
            skeletons[SKELETON_ID] = {i + 1: nn.Pose(self.R @ p, q) for i, (p, q) in
                                      enumerate(zip(f.segment_pos, quat, strict=True))}
        sets = {self.set_name: pos} if self.markers else {}
        packet = nn.message(nn.FRAMEOFDATA, nn.pack_frame(nn.FrameOfData(f.number, sets, plates, f.t, ticks,
                                                                          skeletons=skeletons)))
        with self._lock:
            clients = list(self.clients)
        for ip in clients:
            try:
                self.data.sendto(packet, (ip, self.data_port))
            except OSError:
                pass

    def join(self) -> None:
        """Wait until the trial has been played (forever with loop; Ctrl-C interrupts)."""
        self.player.join()

    def close(self) -> None:
        self.player.close()
        self._closing.set()
        self._thread.join(5.0)
        self.cmd.close()
        self.data.close()
