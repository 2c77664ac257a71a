"""Load a motion file into a body model plus its frames: a BVH, a gait-lab C3D (markers), or a
robot joint-trajectory CSV with its URDF."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from livezmp.checks import check_input_file
from livezmp.errors import InputError
from livezmp.model.base_placement import BasePlacer, place_base
from livezmp.model.body import BodyModel
from livezmp.model.bvh import BvhMotion, read_bvh, write_bvh
from livezmp.model.bvh_body import DEFAULT_MASS, BvhBodyOptions, body_from_bvh
from livezmp.model.c3d import C3dTrial
from livezmp.model.euler_orders import gimbal_orders, reexpressed, restore
from livezmp.model.loop_cycle import Loop, find_loop
from livezmp.model.markers import MarkerBodyOptions, body_from_markers
from livezmp.model.mimic import follow
from livezmp.model.rest_pose import without_rest_pose
from livezmp.model.static_trial import read_walk
from livezmp.model.trajectory_csv import JointTrajectory, read_joint_csv, write_joint_csv
from livezmp.model.urdf_body import UrdfBodyOptions, body_from_urdf


@dataclass
class LoadedMotion:
    """``frames`` (F, nq) raw input channels in the body's channel order (a BVH's: of the joints its model is built
    on); ``times`` (F,) s."""

    body: BodyModel
    times: np.ndarray
    frames: np.ndarray
    source: str
    bvh: BvhMotion | None = None  # as the file has it; ``frames`` re-express the joints of ``bvh_orders``
    bvh_orders: dict[int, str] = field(default_factory=dict)  # joints near gimbal lock (livezmp.model.euler_orders)
    trajectory: JointTrajectory | None = None
    c3d: C3dTrial | None = None
    rest_frames: int = 0  # a BVH's leading rest-pose frames, held at its first moving pose (livezmp.model.rest_pose)
    loop: Loop | None = None  # a looped cycle's (livezmp.model.loop_cycle), over the columns of ``frames``

    @property
    def fps(self) -> float:
        """Mean frame rate (Hz) over ``times`` (s); 0 for a single frame."""
        return float((len(self.times) - 1) / (self.times[-1] - self.times[0])) if len(self.times) > 1 else 0.0


def load_motion(path: str | Path, robot: str | Path | None = None, bvh_options: BvhBodyOptions | None = None,
                urdf_options: UrdfBodyOptions | None = None, c3d_mass: float | None = None,
                markers: MarkerBodyOptions | None = None, static: str | Path | None = None) -> LoadedMotion:
    """Load ``path``: ``.bvh`` or ``.c3d`` on its own, ``.csv`` with ``robot`` (a URDF). A C3D's body
    (``markers`` options; the landmarks it lacks from the ``static`` trial, if given) weighs ``c3d_mass`` kg, else
    the file's subject mass, else 70 kg (plates are for :mod:`livezmp.offline.gaitlab`)."""
    p = check_input_file(path, "motion file")
    suffix = p.suffix.lower()
    if suffix == ".bvh":
        if robot is not None:
            raise InputError(f"{p}: --robot is for a joint-trajectory CSV; a BVH carries its own skeleton")
        motion = read_bvh(p)
        held, rest = without_rest_pose(motion)
        orders = gimbal_orders(held)
        clear = reexpressed(held, orders)
        body = body_from_bvh(clear, bvh_options)
        times = np.arange(len(motion.frames)) * motion.frame_time
        loop = find_loop(held.channel_labels(), held.frames, held.frame_time)
        return LoadedMotion(body, times, body.input_rows(clear.frames), str(p), bvh=motion, bvh_orders=orders,
                            rest_frames=rest, loop=loop and replace(loop, positions=body.input_rows(loop.positions)))
    if suffix == ".c3d":
        trial = read_walk(p, static)
        take = body_from_markers(trial, replace(markers or MarkerBodyOptions(),
                                                total_mass=c3d_mass or trial.mass_kg or DEFAULT_MASS))
        times = (take.first_frame + np.arange(len(take.frames))) / trial.rate
        return LoadedMotion(take.body, times, take.frames, str(p), c3d=trial)
    if suffix == ".csv":
        if robot is None:
            raise InputError(f"{p}: a joint-trajectory CSV needs --robot ROBOT.urdf")
        body = body_from_urdf(robot, urdf_options)
        traj = read_joint_csv(p, body.joint_names)
        return LoadedMotion(body, traj.t, trajectory_frames(body, traj), str(p), trajectory=traj)
    raise InputError(f"{p}: unknown motion format {suffix!r} (.bvh, .c3d, or .csv with --robot)")


def trajectory_frames(body: BodyModel, traj: JointTrajectory, placer: BasePlacer | None = None) -> np.ndarray:
    """Robot frames in the body's channel order (base x, y, z, yaw, pitch, roll, joints).

    Without base columns the base is placed so the stance foot stays flat on the ground (by
    ``placer`` when given: a take read in pieces carries it from one piece to the next)."""
    q = follow(traj.q, body.mimics)  # a mimic joint where its parent puts it, whatever its column says
    if traj.base is None:
        base = place_base(body, q, placer)
    else:
        x, y, z, roll, pitch, yaw = traj.base.T
        base = np.column_stack([x, y, z, yaw, pitch, roll])
    return np.hstack([base, q])


def write_motion(loaded: LoadedMotion, frames: np.ndarray, path: str | Path) -> None:
    """Write ``frames`` (F, nq, the body's raw channels) in the format ``loaded`` came from: a BVH with
    its skeleton (every joint: those the model dropped as the file has them), or a joint-trajectory CSV with its
    joint names (base as x, y, z, roll, pitch, yaw); a BVH's leading rest-pose frames as the file has them."""
    bvh, body = loaded.bvh, loaded.body
    if bvh is not None:
        restored = body.input_rows(restore(bvh, loaded.bvh_orders, body.into_input(bvh.frames, frames)))
        rows = body.into_input(bvh.frames, restored)
        rows[: loaded.rest_frames] = bvh.frames[: loaded.rest_frames]
        write_bvh(replace(bvh, frames=rows), path)
        return
    traj = loaded.trajectory
    if traj is None:
        raise InputError(f"{loaded.source}: writing this motion back is supported for BVH and joint CSV only")
    q = loaded.body.channels_to_q(frames)
    nb = len(loaded.body.base_channels)
    base = q[:, [0, 1, 2, 5, 4, 3]] if traj.base is not None else None  # back to the CSV's (x, y, z, r, p, y)
    write_joint_csv(JointTrajectory(traj.t, q[:, nb:], traj.joint_names, base), path)
