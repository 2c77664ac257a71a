"""A simulated motion-capture streamer: plays a BVH or a C3D trial out live, with impairments.

A BVH goes out in two ways, as real capture software offers them:

- UDP: livezmp frames (JSON or binary, ``docs/frame_format.md``) sent to a target
  address, one datagram per frame, sequence number = frame number;
- TCP: a BVH broadcast server on 127.0.0.1; every connected client gets one text
  line of channel values per frame (optionally with an ``0 Avatar00`` prefix and
  ``||`` ending, as Axis Neuron's string format).

Impairments (seeded, reproducible): Gaussian noise on rotation (degrees) and
position (file units) channels; dropped frames (never sent; their sequence numbers
are skipped); over UDP also late frames (held back and sent after ``late_by`` later
ones) and duplicated frames. Frames go out at real time × ``speed`` (0 = as fast as
possible), looping if asked, for at most ``max_frames``.

A C3D trial's markers and force plates (or generated marker motion, ``generated:RATE``)
go out as a capture system's server: ``--lsl [NAME]`` (LSL outlets,
:mod:`sim_devices.lsl_publisher`), ``--qtm PORT`` (QTM RT, :mod:`sim_devices.qtm_server`),
``--natnet PORT`` (NatNet command port, data to ``--data-port``,
:mod:`sim_devices.natnet_server`), with ``--noise-mm``, ``--gap``, ``--drop``, ``--late``,
``--rate-scale`` (play faster or slower than recorded).

    python -m sim_devices.mocap_streamer walk.bvh --udp 127.0.0.1:9000 --format binary --noise-deg 0.3 --drop 0.02
    python -m sim_devices.mocap_streamer walk.bvh --tcp 9001 --loop
    python -m sim_devices.mocap_streamer trial.c3d --qtm 22223 --loop --drop 0.01
    python -m sim_devices.mocap_streamer generated:240 --natnet 1510 --data-port 1511 --loop
"""

from __future__ import annotations

import argparse
import socket
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from livezmp.errors import InputError
from livezmp.model.bvh import BvhMotion, read_bvh
from livezmp.sources.file_replay import Pacer
from livezmp.sources.frame_format import WireFrame, encode_binary, encode_json
from sim_devices.impairments import Impairments
from sim_devices.tcp_accept import accept_until


@dataclass
class StreamCounters:
    """What the streamer did: frames ``sent`` (counting each copy), ``dropped``,
    ``delayed`` (sent late), ``duplicated``."""

    sent: int = 0
    dropped: int = 0
    delayed: int = 0
    duplicated: int = 0


def paced_frames(motion: BvhMotion, imp: Impairments, speed: float, loop: bool,
                 max_frames: int | None, stop: threading.Event) -> Iterator[tuple[int, float, np.ndarray]]:
    """(frame number, time s, noisy channel values) when each frame is due."""
    rng = np.random.default_rng(imp.seed)
    rot = np.array([c.endswith("rotation") for j in motion.joints for c in j.channels])
    std = np.where(rot, imp.noise_deg, imp.noise_pos)
    pacer = Pacer(speed, motion.source)
    n, k = len(motion.frames), 0
    while not stop.is_set() and (max_frames is None or k < max_frames) and (loop or k < n):
        t = k * motion.frame_time
        if pacer.due(t, 0.1) is None:
            continue
        values = motion.frames[k % n]
        if np.any(std):
            values = values + rng.normal(0.0, 1.0, len(values)) * std
        yield k, t, values
        k += 1


class UdpStreamer:
    """Sends ``motion`` to ``target`` (host, port) as livezmp frames in ``fmt``
    ("json" or "binary"); :meth:`run` blocks until done or ``stop`` is set."""

    def __init__(self, motion: BvhMotion, target: tuple[str, int], fmt: str = "json",
                 impairments: Impairments | None = None, speed: float = 1.0, loop: bool = False,
                 max_frames: int | None = None):
        if fmt not in ("json", "binary"):
            raise InputError(f"frame format {fmt!r}: json or binary")
        self.motion, self.target = motion, target
        self.encode = encode_json if fmt == "json" else encode_binary
        self.imp = impairments or Impairments()
        self.speed, self.loop, self.max_frames = speed, loop, max_frames
        self.counters = StreamCounters()
        self.stop = threading.Event()

    def run(self) -> StreamCounters:
        rng = np.random.default_rng(self.imp.seed + 1)
        held: list[tuple[int, bytes]] = []  # (send after frame number, packet)
        family = socket.AF_INET6 if ":" in self.target[0] else socket.AF_INET
        with socket.socket(family, socket.SOCK_DGRAM) as sock:
            for k, t, values in paced_frames(self.motion, self.imp, self.speed, self.loop, self.max_frames,
                                             self.stop):
                for item in [h for h in held if h[0] <= k]:
                    held.remove(item)
                    self._send(sock, item[1])
                u = rng.random(3)
                if u[0] < self.imp.drop:
                    self.counters.dropped += 1
                    continue
                packet = self.encode(WireFrame(k, t, values))
                if u[1] < self.imp.late:
                    held.append((k + self.imp.late_by, packet))
                    self.counters.delayed += 1
                    continue
                self._send(sock, packet)
                if u[2] < self.imp.duplicate:
                    self._send(sock, packet)
                    self.counters.duplicated += 1
            for _, packet in held:
                self._send(sock, packet)
        return self.counters

    def _send(self, sock: socket.socket, packet: bytes) -> None:
        sock.sendto(packet, self.target)
        self.counters.sent += 1


class TcpStreamer:
    """A BVH broadcast server on ``host``:``port`` (0 = any free port), accepting
    clients from creation until :meth:`close`. :meth:`run` (blocking) or
    :meth:`run_in_thread` streams the frames, after the first client connects."""

    def __init__(self, motion: BvhMotion, port: int = 0, host: str = "127.0.0.1",
                 impairments: Impairments | None = None, speed: float = 1.0, loop: bool = False,
                 max_frames: int | None = None, avatar: bool = False, wait_for_client: bool = True):
        self.motion, self.imp = motion, impairments or Impairments()
        self.speed, self.loop, self.max_frames, self.avatar = speed, loop, max_frames, avatar
        self.wait_for_client = wait_for_client
        self.counters = StreamCounters()
        self.stop = threading.Event()
        self.server = socket.create_server((host, port))
        self.server.settimeout(0.1)
        self.port = self.server.getsockname()[1]
        self.clients: list[socket.socket] = []
        self._lock = threading.Lock()
        self._thread: threading.Thread | None = None
        self._closing = threading.Event()
        self._acceptor = threading.Thread(target=self._accept, name="tcp-streamer-accept", daemon=True)
        self._acceptor.start()

    def _accept(self) -> None:
        accept_until(self.server, self._closing, self._add)

    def _add(self, conn: socket.socket) -> None:
        conn.settimeout(1.0)
        with self._lock:
            self.clients.append(conn)

    def line(self, values: np.ndarray) -> bytes:
        text = " ".join(f"{v:.6f}" for v in values)
        return (f"0 Avatar00 {text} ||" if self.avatar else text + "\n").encode()

    def kick(self) -> None:
        """Close every client connection (a broadcast dropping its clients)."""
        with self._lock:
            for c in self.clients:
                c.close()
            self.clients.clear()

    def send_raw(self, data: bytes) -> None:
        """Send bytes as they are to every client (for malformed-input tests)."""
        with self._lock:
            for c in list(self.clients):
                try:
                    c.sendall(data)
                except OSError:
                    self.clients.remove(c)
                    c.close()

    def run(self) -> StreamCounters:
        while self.wait_for_client and not self.clients and not self.stop.wait(0.01):
            pass
        rng = np.random.default_rng(self.imp.seed + 1)
        for _, _, values in paced_frames(self.motion, self.imp, self.speed, self.loop, self.max_frames, self.stop):
            if rng.random() < self.imp.drop:
                self.counters.dropped += 1
                continue
            self.send_raw(self.line(values))
            self.counters.sent += 1
        return self.counters

    def run_in_thread(self) -> threading.Thread:
        self._thread = threading.Thread(target=self.run, name="tcp-streamer", daemon=True)
        self._thread.start()
        return self._thread

    def close(self) -> None:
        self.stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self._closing.set()
        self._acceptor.join(5.0)
        self.kick()
        self.server.close()


def _trial(spec: str):
    from sim_devices.mocap_trial import generated_trial, load_c3d_trial

    if spec.startswith("generated:"):
        try:
            rate = float(spec.split(":", 1)[1])
        except ValueError:
            rate = 0.0
        if not rate > 0:
            raise InputError(f"{spec}: generated:RATE needs a positive rate in Hz")
        return generated_trial(rate, 10.0)
    return load_c3d_trial(spec)


def serve_capture(args: argparse.Namespace) -> str:
    """Plays a C3D (or generated) trial from a simulated capture server until done or Ctrl-C."""
    trial = _trial(args.motion)
    if args.skeleton or args.skeleton_only:
        from sim_devices.mocap_trial import with_segments

        if (args.natnet is None and args.qtm is None) or args.motion.startswith("generated:"):
            raise InputError("--skeleton: a C3D trial served over --natnet or --qtm")
        trial = with_segments(trial, args.motion)
    # QTM always streams its 3D component: a skeleton without markers is every marker occluded
    gap = 1.0 if args.skeleton_only and args.qtm is not None else args.gap
    imp = Impairments(noise_pos=args.noise_mm * 1e-3, gap=gap, drop=args.drop, late=args.late, seed=args.seed)
    play = {"impairments": imp, "speed": args.speed, "loop": args.loop, "max_frames": args.frames}
    if args.lsl is not None:
        from sim_devices.lsl_publisher import LslPublisher

        server = LslPublisher(trial, name=args.lsl, source_id=args.lsl, **play)
        print(f"publishing LSL streams {args.lsl!r} (MoCap) and {args.lsl + ' plates'!r} (Force): "
              f"lsl://{args.lsl}", flush=True)
        counters = server.run()
    else:
        if args.qtm is not None:
            from sim_devices.qtm_server import QtmServer

            server = QtmServer(trial, args.qtm, **play, poses=("skeleton",) if trial.segment_names else ("6d",))
            print(f"serving QTM RT on qtm://127.0.0.1:{server.port}", flush=True)
        else:
            from sim_devices.natnet_server import NatNetServer

            server = NatNetServer(trial, args.natnet, args.data_port, markers=not args.skeleton_only, **play)
            print(f"serving NatNet on natnet://127.0.0.1:{server.command_port}?data_port={args.data_port}",
                  flush=True)
        try:
            server.start().join()
        finally:
            server.close()
        counters = server.counters
    return (f"sent {counters.sent}, dropped {counters.dropped}, late {counters.out_of_order}, "
            f"marker gaps {counters.gaps}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sim_devices.mocap_streamer", description=__doc__.splitlines()[0])
    p.add_argument("motion", help="a BVH file (--udp, --tcp), or a C3D file or generated:RATE (--lsl, --qtm, --natnet)")
    out = p.add_mutually_exclusive_group(required=True)
    out.add_argument("--udp", metavar="HOST:PORT", help="send livezmp frames to this address")
    out.add_argument("--tcp", type=int, metavar="PORT", help="serve a BVH broadcast on 127.0.0.1:PORT")
    out.add_argument("--lsl", nargs="?", const="livezmp-sim", metavar="NAME", help="publish LSL streams")
    out.add_argument("--qtm", type=int, metavar="PORT", help="serve QTM RT on 127.0.0.1:PORT (0: any)")
    out.add_argument("--natnet", type=int, metavar="PORT", help="serve NatNet commands on 127.0.0.1:PORT")
    p.add_argument("--data-port", type=int, default=1511, help="NatNet data port the client binds")
    p.add_argument("--skeleton", action="store_true", help="NatNet, QTM: also stream the marker body's segments "
                                                           "as a solved skeleton")
    p.add_argument("--skeleton-only", action="store_true", help="NatNet, QTM: stream the skeleton without markers "
                                                                "(QTM: every marker occluded)")
    p.add_argument("--noise-mm", type=float, default=0.0, help="marker noise std (mm; capture servers)")
    p.add_argument("--gap", type=float, default=0.0, help="marker occlusion probability per frame")
    p.add_argument("--format", choices=["json", "binary"], default="json", help="UDP frame format")
    p.add_argument("--avatar", action="store_true", help="TCP lines as '0 Avatar00 values ||'")
    p.add_argument("--speed", type=float, default=1.0)
    p.add_argument("--loop", action="store_true")
    p.add_argument("--frames", type=int, help="stop after this many frames")
    p.add_argument("--noise-deg", type=float, default=0.0)
    p.add_argument("--noise-pos", type=float, default=0.0)
    p.add_argument("--drop", type=float, default=0.0)
    p.add_argument("--late", type=float, default=0.0)
    p.add_argument("--duplicate", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args(argv)
    try:
        if args.lsl is not None or args.qtm is not None or args.natnet is not None:
            print(serve_capture(args))
            return 0
        motion = read_bvh(args.motion)
        imp = Impairments(noise_deg=args.noise_deg, noise_pos=args.noise_pos, drop=args.drop, late=args.late,
                          duplicate=args.duplicate, seed=args.seed)
        if args.udp:
            host, _, port = args.udp.rpartition(":")
            if not port.isdigit():
                raise InputError(f"--udp {args.udp!r}: need HOST:PORT")
            c = UdpStreamer(motion, (host.strip("[]"), int(port)), args.format, imp, args.speed, args.loop,
                            args.frames).run()
        else:
            s = TcpStreamer(motion, args.tcp, impairments=imp, speed=args.speed, loop=args.loop,
                            max_frames=args.frames, avatar=args.avatar)
            print(f"serving BVH on tcp://127.0.0.1:{s.port}", flush=True)
            try:
                c = s.run()
            finally:
                s.close()
    except InputError as e:
        print(f"mocap_streamer: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    print(f"sent {c.sent}, dropped {c.dropped}, late {c.delayed}, duplicated {c.duplicated}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
