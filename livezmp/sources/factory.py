"""``open_source(spec)``: the source a path or URL names.

- ``walk.bvh``: replay of a BVH file; ``trial.c3d``: of a gait-lab C3D's marker body;
  ``motion.csv``: of a joint-trajectory CSV (with ``robot``, its URDF);
  ``session.mcap``: of a livezmp recording's input frames;
- ``udp://HOST:PORT[?allow=NET,...&max_bytes=N]``: livezmp frames over UDP;
- ``tcp://HOST:PORT[?max_line=N]``: a BVH broadcast (one line per frame).

Stream sources need their body: ``skeleton`` (a BVH file, for udp and tcp) or
``robot`` (a URDF, for udp), and their frame rate: ``fps``, else the skeleton file's
frame time (the estimator is tuned to it; frames still carry their own times).

- ``lsl://…``, ``qtm://…``, ``natnet://…``: a capture system's labelled markers (and force plates)
  through the marker body (:mod:`.marker_stream`), calibrated on ``calibration`` (a C3D trial of the
  subject) or on the stream's first seconds;
- ``dynamixel:…``, ``can:…``, ``fw:…``: a servo link (``livezmp.links`` URL forms),
  watched without commanding it at ``fps`` (100 Hz by default); needs ``robot``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import numpy as np

from livezmp.errors import InputError
from livezmp.model.body import BodyModel
from livezmp.model.body_spec import (
    BodySpec,
    SkeletonStream,
    clear_skeleton,
    marker_body,
    read_skeleton,
    robot_body,
    skeleton_body,
)
from livezmp.model.bvh_body import DEFAULT_MASS, BvhBodyOptions
from livezmp.model.c3d import read_c3d
from livezmp.model.loop_cycle import find_loop
from livezmp.model.markers import MarkerBodyOptions
from livezmp.model.motion_file import trajectory_frames
from livezmp.model.static_trial import read_walk
from livezmp.model.trajectory_csv import read_joint_csv
from livezmp.model.urdf_body import UrdfBodyOptions
from livezmp.sources.bvh_tcp import BvhTcpSource
from livezmp.sources.file_replay import FileReplaySource
from livezmp.sources.interface import Source
from livezmp.sources.mcap_replay import McapReplaySource
from livezmp.sources.mocap_factory import MOCAP_SCHEMES, open_mocap_source
from livezmp.sources.udp import UdpSource, parse_allowlist

SCHEMES = ("udp", "tcp")
QUERY_KEYS = {"udp": {"allow", "max_bytes"}, "tcp": {"max_line"}}


@dataclass(frozen=True)
class SourceOptions:
    """``skeleton`` BVH file / ``robot`` URDF giving a stream's body (``robot`` also goes
    with a CSV); ``fps`` a stream's frame rate (Hz); ``speed`` and ``loop`` for replays."""

    bvh: BvhBodyOptions = field(default_factory=BvhBodyOptions)
    urdf: UrdfBodyOptions = field(default_factory=UrdfBodyOptions)
    robot: str | None = None
    skeleton: str | None = None
    fps: float | None = None
    speed: float = 1.0
    loop: bool = False
    mass: float | None = None  # kg; None: a C3D's subject mass, else the BVH default
    calibration: str | None = None  # a C3D trial calibrating a capture stream's marker body
    static: str | None = None  # a cluster set's static trial, for a C3D replayed (livezmp.model.static_trial)
    markers: MarkerBodyOptions = field(default_factory=MarkerBodyOptions)  # a marker body's options (mass set here)


def _replay(path: Path, o: SourceOptions) -> Source:
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        if o.loop:
            raise InputError(f"{path}: --loop is for motion files, not recordings")
        return McapReplaySource(str(path), o.speed)
    if suffix == ".bvh":
        sk = read_skeleton(path)
        if not sk.has_motion:
            raise InputError(f"{path}: a hierarchy without frames; nothing to replay")
        sk = clear_skeleton(sk)
        body, spec = skeleton_body(sk, o.bvh)
        times = np.arange(len(sk.motion.frames)) * sk.motion.frame_time
        cycle = find_loop(sk.motion.channel_labels(), sk.motion.frames, sk.motion.frame_time) if o.loop else None
        return FileReplaySource(str(path), body, spec, times, body.input_rows(sk.motion.frames), o.speed, o.loop,
                                cycle and replace(cycle, positions=body.input_rows(cycle.positions)))
    if suffix == ".c3d":
        trial = read_walk(path, o.static)
        take, spec = marker_body(trial, replace(o.markers, total_mass=o.mass or trial.mass_kg or DEFAULT_MASS))
        times = (take.first_frame + np.arange(len(take.frames))) / trial.rate
        return FileReplaySource(str(path), take.body, spec, times, take.frames, o.speed, o.loop)
    if suffix == ".csv":
        if o.robot is None:
            raise InputError(f"{path}: a joint-trajectory CSV needs --robot ROBOT.urdf")
        body, spec = robot_body(o.robot, o.urdf)
        traj = read_joint_csv(path, body.joint_names)
        return FileReplaySource(str(path), body, spec, traj.t, trajectory_frames(body, traj), o.speed, o.loop)
    raise InputError(f"{path}: unknown source file type {suffix!r} (.bvh, .c3d, .csv with --robot, .mcap)")


def _stream_body(spec: str, o: SourceOptions, robot_ok: bool
                 ) -> tuple[BodyModel, BodySpec, float | None, SkeletonStream | None]:
    """Body, spec and frame period (s) of a stream source, and for a skeleton what makes each streamed row (every
    joint of the skeleton file) the body's channels: the re-expression into the orders its body is built in, for a
    skeleton whose frames come near gimbal lock, and the cut to the joints the body is built on. Those orders are
    decided before the first frame, from the skeleton file's frames, and kept: a joint that switched orders
    mid-stream would change the meaning of its three channels under the estimator, whose history (up to a 180° step
    in each) would turn into spurious accelerations. A skeleton whose frames never near the lock (a T-pose) leaves
    the file's orders."""
    if o.skeleton and o.robot:
        raise InputError(f"{spec}: give --skeleton or --robot, not both")
    dt = 1.0 / o.fps if o.fps else None
    if o.skeleton:
        sk = read_skeleton(o.skeleton)
        clear = clear_skeleton(sk)
        body, bspec = skeleton_body(clear, o.bvh)
        return body, bspec, dt or (sk.motion.frame_time if sk.has_motion else None), SkeletonStream(sk, clear, body)
    if o.robot and robot_ok:
        body, bspec = robot_body(o.robot, o.urdf)
        return body, bspec, dt, None
    need = "--skeleton FILE.bvh or --robot ROBOT.urdf" if robot_ok else "--skeleton FILE.bvh (its BVH hierarchy)"
    raise InputError(f"{spec}: a stream needs the body it carries: {need}")


LINK_SCHEMES = ("dynamixel", "can", "fw")


def _link(spec: str, o: SourceOptions) -> Source:
    """A servo link watched at ``--fps`` (default 100 Hz); needs ``--robot``."""
    from livezmp.links.base import LinkError
    from livezmp.model.robot_config import find_robot_config, load_robot_config
    from livezmp.sources.link_source import LinkSource

    if not o.robot:
        raise InputError(f"{spec}: a servo link needs the robot it drives: --robot ROBOT.urdf")
    body, bspec = robot_body(o.robot, o.urdf)
    config = load_robot_config(o.urdf.config) if o.urdf.config else find_robot_config(o.robot, body.model.name)
    try:
        return LinkSource(spec, body, bspec, config, o.fps or 100.0)
    except LinkError as e:
        raise InputError(f"{spec}: cannot open the link: {e}") from None


def _capture(spec: str, o: SourceOptions) -> Source:
    """A capture stream through the marker body (see :mod:`livezmp.sources.marker_stream`)."""
    from livezmp.sources.marker_stream import MarkerStreamSource

    trial = read_c3d(o.calibration) if o.calibration else None
    mass = o.mass or (trial.mass_kg if trial else None) or DEFAULT_MASS
    mocap = open_mocap_source(spec)
    try:
        return MarkerStreamSource(mocap, trial, replace(o.markers, total_mass=mass))
    except BaseException:
        mocap.close()
        raise


def _int_param(query: dict, key: str, spec: str) -> int | None:
    if key not in query:
        return None
    try:
        v = int(query[key][-1])
    except ValueError:
        v = 0
    if v <= 0:
        raise InputError(f"{spec}: {key}: need a positive integer, got {query[key][-1]!r}")
    return v


def open_source(spec: str, options: SourceOptions | None = None) -> Source:
    """Open the source ``spec`` names (see the module docstring)."""
    o = options or SourceOptions()
    if o.fps is not None and not o.fps > 0:
        raise InputError(f"{spec}: --fps must be positive, got {o.fps}")
    if o.calibration and urlsplit(spec).scheme not in MOCAP_SCHEMES:  # a file or link carries its own body
        raise InputError(f"{spec}: --calibration is for capture streams (lsl://, qtm://, natnet://)")
    if spec.split(":", 1)[0] in LINK_SCHEMES:
        return _link(spec, o)
    if "://" not in spec:
        path = Path(spec)
        if not path.exists():
            raise InputError(f"{spec}: no such file (or give a stream: udp://HOST:PORT, tcp://HOST:PORT, lsl://NAME, "
                             "qtm://HOST, natnet://HOST, or a link URL such as dynamixel:PATH)")
        return _replay(path, o)
    url = urlsplit(spec)
    if url.scheme in MOCAP_SCHEMES:
        return _capture(spec, o)
    if url.scheme not in SCHEMES:
        raise InputError(f"{spec}: unknown source scheme {url.scheme!r} (udp://, tcp://, lsl://, qtm://, natnet://, "
                         "or a file)")
    try:
        host, port = url.hostname, url.port
    except ValueError:
        host, port = None, None
    if not host or port is None:
        raise InputError(f"{spec}: need HOST:PORT, e.g. {url.scheme}://127.0.0.1:9000")
    query = parse_qs(url.query, keep_blank_values=True)
    unknown = set(query) - QUERY_KEYS[url.scheme]
    if unknown:
        raise InputError(f"{spec}: unknown parameter {sorted(unknown)[0]!r} "
                         f"(one of {', '.join(sorted(QUERY_KEYS[url.scheme]))})")
    body, bspec, dt, rows = _stream_body(spec, o, robot_ok=url.scheme == "udp")
    if dt is None:
        raise InputError(f"{spec}: the stream's frame rate is unknown (no frame time in a skeleton file); give --fps")
    if url.scheme == "udp":
        allow = parse_allowlist(",".join(query["allow"]), spec) if "allow" in query else None
        return UdpSource(host, port, body, bspec, allow, _int_param(query, "max_bytes", spec), dt, rows)
    return BvhTcpSource(host, port, body, bspec, dt, _int_param(query, "max_line", spec), rows=rows)
