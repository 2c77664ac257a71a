"""What the subcommands share: body options, loading the motion (or the demo), the
pipeline configuration and running it."""

from __future__ import annotations

import argparse
import contextlib
import signal
from collections.abc import Callable

import numpy as np

from livezmp.balance.pipeline import PipelineConfig, default_config
from livezmp.checks import check_number
from livezmp.model.bvh_body import DEFAULT_MASS, BvhBodyOptions
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.motion_file import LoadedMotion, load_motion, trajectory_frames
from livezmp.model.segments import load_mapping
from livezmp.model.urdf_body import UrdfBodyOptions, body_from_urdf

MAX_BODY_MASS = 1000.0  # kg
MAX_GROUND_M = 1000.0  # m from the input's origin
MAX_SOLE_WIDTH_M = 1.0


def check_body_options(args: argparse.Namespace) -> None:
    """The body options' numbers: finite and physically possible."""
    check_number(args.mass, "--mass (kg)", 0.0, MAX_BODY_MASS, lo_open=True)
    check_number(args.ground, "--ground (m)", -MAX_GROUND_M, MAX_GROUND_M)
    check_number(args.sole_width, "--sole-width (m)", 0.0, MAX_SOLE_WIDTH_M, lo_open=True)


def load_from_args(args: argparse.Namespace) -> LoadedMotion:
    """The motion named on the command line, or the built-in demo when there is none."""
    check_body_options(args)
    urdf_opts = UrdfBodyOptions(config=args.robot_config)
    if args.motion is None:
        body = body_from_urdf(demo_robot_path(), urdf_opts)
        traj = demo_trajectory(body.joint_names)
        return LoadedMotion(body, traj.t, trajectory_frames(body, traj), "<demo>", trajectory=traj)
    mapping = load_mapping(args.mapping) if args.mapping else None
    bvh_opts = BvhBodyOptions(total_mass=args.mass or DEFAULT_MASS, units=args.units, up_axis=args.up, mapping=mapping,
                              sole_width=args.sole_width)
    return load_motion(args.motion, args.robot, bvh_opts, urdf_opts, c3d_mass=args.mass)


def pipeline_config(args: argparse.Namespace, loaded: LoadedMotion) -> PipelineConfig:
    """:func:`default_config` with the command line's mode and ground height."""
    ground = None
    if args.ground is not None:
        up = "xyz".index(loaded.body.up_axis)
        p = np.zeros(3)
        p[up] = args.ground
        ground = float((loaded.body.world_from_input @ p)[2])
    return default_config(loaded.body, loaded.fps, args.mode, ground)


@contextlib.contextmanager
def stop_on_signals(stop: Callable[[str], None]):
    """Ctrl-C and SIGTERM call ``stop(signal name)``: the loop ends its cycle or frame and
    stops cleanly; the previous handlers come back on exit."""
    handler = lambda signum, _frame: stop(signal.Signals(signum).name)  # noqa: E731
    old = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
