"""One recorded walk in SI units, from a BVH file, a robot joint-trajectory CSV, or a gait-lab C3D.

A C3D's markers give the marker body as a chain (:mod:`livezmp.model.marker_chain`): its channels are
joint angles (each segment's rotation in its parent's frame, flexion first) and the pelvis' world pose,
in the internal frame (z up, metres).

Rotation channels are read as the file gives them, one angle per channel in the
file's Euler order (no re-parametrisation), converted to radians and unwrapped in time
(a jump of more than 180° between frames is taken as a wrap through ±180°); each
channel is then shifted by whole turns so that its mean lies in (−180°, 180°].
The root is the top-most joint whose position channels move (a BVH's root or Hips, a
robot's base). Its heading is normalised: the whole take is turned about the up axis
so that it walks along the internal +x axis (the net displacement's direction), and
the root's rotation channels are re-extracted in their own Euler order (middle angle
within ±90°). Without this the root's angles would carry the walking direction, and
takes walking in opposite directions would not be comparable. :func:`turn_root`
turns a changed walk back before it is written.

A C3D walk on an instrumented treadmill (:mod:`livezmp.offline.treadmill`) is read in its belts' frame: the root's
ground-plane path less the belt's travel (its mean velocity, split belts: between the two), so the walking speed is
the belt's plus the body's drift, a stride's length the distance the belt carries the feet, and the heading the way
the walk goes on the belt.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from livezmp.checks import check_input_file
from livezmp.errors import InputError
from livezmp.gait.channels import ChannelTag, tag_channels
from livezmp.model.body import BodyModel, soles_over
from livezmp.model.bvh import BvhMotion, read_bvh
from livezmp.model.bvh_body import BvhBodyOptions, body_from_bvh
from livezmp.model.c3d import C3dTrial
from livezmp.model.loop_cycle import find_loop
from livezmp.model.marker_chain import chain_body, chain_frames, segment_names
from livezmp.model.marker_map import MarkerMap, load_marker_map
from livezmp.model.markers import MarkerBodyOptions, MarkerTake, body_from_markers
from livezmp.model.rest_pose import without_rest_pose
from livezmp.model.static_trial import read_walk
from livezmp.model.trajectory_csv import BASE_COLUMNS, JointTrajectory, read_joint_csv
from livezmp.model.urdf_body import body_from_urdf
from livezmp.offline.gaitlab import take_treadmill


@dataclass
class GaitTake:
    """A walk: ``t`` (F,) s; ``q`` (F, n) channel values in SI (m, rad; angles unwrapped);
    ``body`` the body model whose channels ``q`` follows; ``angle_index`` the rotation
    channels' columns; ``tags`` one per rotation channel; ``root_xyz`` the q columns of the
    moving root's x, y, z position in the input frame (−1 where absent, all −1 if the
    root does not move), ``root_rot`` the columns of its rotation channels and
    ``root_seq`` their intrinsic Euler order (e.g. "ZXY"); ``heading`` rad, the angle about
    the up axis the recorded walk is turned from internal +x (``q`` is turned back by it);
    ``origin`` the BVH motion, CSV trajectory or C3D trial it came from."""

    source: str
    t: np.ndarray
    q: np.ndarray
    body: BodyModel
    angle_index: np.ndarray
    tags: list[ChannelTag]
    root_xyz: list[int]
    root_rot: list[int]
    root_seq: str
    heading: float
    origin: BvhMotion | JointTrajectory | C3dTrial
    min_cycles: int = 2  # whole gait cycles the features need (a gait-lab pass over the plates has one or two)
    belt: np.ndarray | None = None  # (2,) m/s a treadmill's belt velocity on the ground plane (turned as q), or None

    @property
    def angles(self) -> np.ndarray:
        """(F, C) rotation channels, rad."""
        return self.q[:, self.angle_index]

    def ground(self) -> np.ndarray:
        """(F, 2) m: the root's position on the ground plane (internal frame: x forward, y; z up); on a treadmill,
        in its belt's frame (the belt's travel since the first frame taken off)."""
        return _ground(self.q, self.body, self.root_xyz, self.t, self.belt)


def _ground(q: np.ndarray, body: BodyModel, root_xyz: list[int], t: np.ndarray | None = None,
            belt: np.ndarray | None = None) -> np.ndarray:
    """(F, 2) m: the root's ground-plane path, less a ``belt``'s travel (velocity (2,) m/s) over the times ``t``
    (F,) s when given."""
    p = np.zeros((len(q), 3))
    for k, col in enumerate(root_xyz):
        if col >= 0:
            p[:, k] = q[:, col]
    g = (p @ _world_from_channels(body).T)[:, :2]
    return g if belt is None else g - np.outer(t - t[0], belt)


def _world_from_channels(body: BodyModel) -> np.ndarray:
    """The rotation from the frame of the root's channels into the internal one (a marker body's
    channels are in the internal frame already)."""
    return np.eye(3) if body.kind == "markers" else body.world_from_input


def turn_root(q: np.ndarray, take: GaitTake, angle: float) -> np.ndarray:
    """Copy of ``q`` (F, n) with the root turned by ``angle`` rad about the up axis (see module doc)."""
    return _turn(q, take.body, take.root_xyz, take.root_rot, take.root_seq, angle)


def _turn(q: np.ndarray, body: BodyModel, root_xyz: list[int], root_rot: list[int], seq: str,
          angle: float) -> np.ndarray:
    out = q.copy()
    w = _world_from_channels(body)
    r_in = w.T @ Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix() @ w  # about the input's up axis
    if min(root_xyz) >= 0:
        out[:, root_xyz] = q[:, root_xyz] @ r_in.T
    if root_rot:
        turned = Rotation.from_matrix(r_in) * Rotation.from_euler(seq, q[:, root_rot])
        with warnings.catch_warnings():
            # at gimbal lock (a z-up export's root turned 90° in a ZXY order) only the sum of the first and third
            # angles is defined: scipy's split (the third 0) keeps the rotation exactly; said once in docs/gait.md
            warnings.filterwarnings("ignore", "Gimbal lock detected", UserWarning)
            out[:, root_rot] = turned.as_euler(seq)
    return out


def unwrap_angles(q: np.ndarray, angle_mask: np.ndarray) -> np.ndarray:
    """Copy of ``q`` (F, n) with angle columns (rad) unwrapped in time, each mean in (−π, π]."""
    out = q.copy()
    a = np.unwrap(q[:, angle_mask], axis=0)
    a -= 2 * np.pi * np.ceil(a.mean(axis=0) / (2 * np.pi) - 0.5)
    out[:, angle_mask] = a
    return out


def _root_columns(body: BodyModel, q: np.ndarray) -> tuple[list[int], list[int], str]:
    """q columns of the x, y, z position and of the rotation channels of the top-most moving
    joint, and the rotations' intrinsic Euler order."""
    moving = [i for i in range(q.shape[1]) if not body.angle_mask[i] and np.ptp(q[:, i]) > 1e-9]
    if not moving:
        return [-1, -1, -1], [], ""
    names = body.channel_names
    if body.kind == "urdf":
        rot = ["base_yaw", "base_pitch", "base_roll"]  # R = Rz·Ry·Rx (body_urdf)
        return [names.index(n) for n in ("base_x", "base_y", "base_z")], [names.index(n) for n in rot], "ZYX"
    if body.kind == "markers":  # the pelvis: x, y, z, yaw, pitch, roll (R = Rz·Ry·Rx)
        return [0, 1, 2], [3, 4, 5], "ZYX"
    joint = names[moving[0]].rsplit(".", 1)[0]
    xyz = [names.index(f"{joint}.{a}position") if f"{joint}.{a}position" in names else -1 for a in "XYZ"]
    rot = [i for i, n in enumerate(names) if n.startswith(f"{joint}.") and n.endswith("rotation")]
    return xyz, rot, "".join(names[i][len(joint) + 1] for i in rot)


def _make(source: str, t: np.ndarray, q_raw: np.ndarray, body: BodyModel, origin,
          belt: np.ndarray | None = None) -> GaitTake:
    """The walk, turned to head along +x (on a ``belt``, velocity (2,) m/s internal frame: the way it goes on it)."""
    xyz, rot, seq = _root_columns(body, q_raw)
    heading = 0.0
    if min(xyz) >= 0:
        g = _ground(q_raw, body, xyz, t, belt)
        d = g[-1] - g[0]
        if np.hypot(*d) > 1e-6:
            heading = float(np.arctan2(d[1], d[0]))
            q_raw = _turn(q_raw, body, xyz, rot, seq, -heading)
    if belt is not None:
        c, s = np.cos(heading), np.sin(heading)
        belt = np.array([[c, s], [-s, c]]) @ belt  # turned with the walk
    q = unwrap_angles(q_raw, body.angle_mask)
    tags = tag_channels(body, q.mean(axis=0), source)
    return GaitTake(source, t, q, body, np.nonzero(body.angle_mask)[0], tags, xyz, rot, seq, heading, origin,
                    belt=belt)


def take_from_bvh(motion: BvhMotion, up: str | None = None, units: str | None = None) -> GaitTake:
    """A BVH walk; ``up`` is the file's up axis ("y" or "z"; None = detect, as ``analyze``), ``units`` its length unit
    (None = detect)."""
    if up not in (None, "y", "z"):
        raise InputError(f"{motion.source}: up axis must be 'y' or 'z', got {up!r}")
    body = body_from_bvh(motion, BvhBodyOptions(units=units, up_axis=up))
    t = np.arange(len(motion.frames)) * motion.frame_time
    return _make(motion.source, t, body.channels_to_q(body.input_rows(motion.frames)), body, motion)


def take_from_trajectory(traj: JointTrajectory, body: BodyModel) -> GaitTake:
    """A robot walk from a joint-trajectory CSV and the robot's URDF body model (z up)."""
    q = np.zeros((len(traj.t), body.nq))
    names = body.channel_names
    for k, n in enumerate(traj.joint_names):
        q[:, names.index(n)] = traj.q[:, k]
    if traj.base is not None:
        for k, n in enumerate(BASE_COLUMNS):
            q[:, names.index(n)] = traj.base[:, k]
    return _make(traj.source, traj.t, q, body, traj)


def take_from_c3d(trial: C3dTrial, mmap: MarkerMap | None = None,
                  treadmill: str | tuple[float, float] = "auto") -> GaitTake:
    """A gait-lab walk: the marker body of ``trial`` (through the marker map ``mmap``, if any) as a chain (joint
    angles), over the frames where every needed marker is seen; times from the trial's first frame (s). On a
    ``treadmill`` ("auto": found from the feet, "off", or the (left, right) belt speeds, m/s) in its belts' frame."""
    take = body_from_markers(trial, MarkerBodyOptions(marker_map=mmap))
    names = segment_names(take.body)
    t = (take.first_frame + np.arange(len(take.frames))) / trial.rate
    walk = _make(trial.source, t, chain_frames(names, take.frames), chain_body(take.body), trial,
                 _belt(treadmill, take, trial.rate))
    return replace(walk, min_cycles=1)


def _belt(asked: str | tuple[float, float], take: MarkerTake, rate: float) -> np.ndarray | None:
    """The belt velocity (2,) m/s (internal frame; split belts: their mean) of the treadmill a marker ``take`` at
    ``rate`` Hz walks on, or None (:func:`livezmp.offline.gaitlab.take_treadmill` on its raw frames' soles and
    pelvis)."""
    if asked == "off":  # the soles are not needed
        return None
    found = take_treadmill(asked, take, soles_over(take.body, take.frames), take.frames[:, :3], rate)
    return None if found is None else found.mean_velocity


# A looped cycle (its last frame repeats its first: Mixamo's walks) holds one or a few gait cycles; read as a walk it
# is played on this many laps, so that two whole gait cycles lie within wherever the thigh's cycle starts in the lap
LOOP_LAPS = 4


def _played_on(motion: BvhMotion) -> BvhMotion:
    """``motion`` played on for :data:`LOOP_LAPS` laps when it is a looped cycle (:mod:`livezmp.model.loop_cycle`),
    else itself."""
    loop = find_loop(motion.channel_labels(), motion.frames, motion.frame_time)
    return motion if loop is None else replace(motion, frames=loop.rows(motion.frames, 0, LOOP_LAPS * loop.period + 1))


def load_take(path: str | Path, up: str | None = None, units: str | None = None, urdf: str | Path | None = None,
              markers: str | Path | None = None, static: str | Path | None = None,
              treadmill: str | tuple[float, float] = "auto") -> GaitTake:
    """Read a walk from a ``.bvh`` or ``.c3d`` file (through the marker map file ``markers``, and with the
    landmarks it lacks from the ``static`` trial, if given; on a ``treadmill``, :func:`take_from_c3d`), or a
    ``.csv`` joint trajectory (needs ``urdf``)."""
    p = Path(path)
    for option, name in ((markers, "--markers"), (static, "--static")):
        if option and p.suffix.lower() != ".c3d":
            raise InputError(f"{option}: {name} is for C3D walks (got {p})")
    if treadmill != "auto" and p.suffix.lower() != ".c3d":
        raise InputError(f"--treadmill is for C3D walks (got {p})")
    if p.suffix.lower() == ".bvh":
        return take_from_bvh(_played_on(without_rest_pose(read_bvh(p))[0]), up, units)
    if p.suffix.lower() == ".c3d":
        return take_from_c3d(read_walk(check_input_file(p, "walk"), static),
                             load_marker_map(markers) if markers else None, treadmill)
    if p.suffix.lower() == ".csv":
        if urdf is None:
            raise InputError(f"{p}: a joint-trajectory CSV needs the robot's URDF (--urdf)")
        body = body_from_urdf(urdf)
        return take_from_trajectory(read_joint_csv(p, body.joint_names), body)
    raise InputError(f"{p}: unknown walk format {p.suffix!r} (.bvh, .c3d or .csv)")
