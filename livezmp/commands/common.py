"""What the subcommands share: body options, loading the motion (or the demo), the
pipeline configuration and running it."""

from __future__ import annotations

import argparse
import contextlib
import signal
from collections.abc import Callable
from dataclasses import replace

from livezmp.balance.pipeline import PipelineConfig
from livezmp.checks import check_number
from livezmp.commands.startup import handling_stop_signals
from livezmp.correct.limits import CorrectionLimits
from livezmp.errors import InputError
from livezmp.estimate.estimator import default_cutoff
from livezmp.model.anthropometry import MAX_AGE_YEARS, MAX_BODY_MASS
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.motion_file import LoadedMotion, trajectory_frames
from livezmp.model.urdf_body import UrdfBodyOptions, body_from_urdf
from livezmp.offline.take import TakeOptions, take_config
from livezmp.offline.treadmill import parse_treadmill
from livezmp.offline.validated import VALIDATED_P95_MM

MAX_GROUND_M = 1000.0  # m from the input's origin
MAX_SOLE_WIDTH_M = 1.0
MAX_TOLERANCE_MM = 1000.0  # a ZMP error of a metre is no measurement: every frame would count as inside
# half the slowest step frequency (1-2.7 Hz): below it no step's acceleration is kept (a walk at 0.1 Hz: every frame
# "flight", no verdict), and far below (1e-9 Hz) the filters' design is singular (scipy's LinAlgError traceback)
MIN_CUTOFF_HZ = 0.5
MAX_CUTOFF_HZ = 5000.0  # half the highest frame rate read (checks.FRAME_PERIOD_RANGE); the rate's own limit later
MAX_ROTATION_DEG = 180.0
MAX_RATE_DEG_S = 36000.0  # 100 turns a second: beyond any joint
MAX_MARGIN_MM = 1000.0  # no support polygon is two metres across
MAX_PERCENT = 1e6  # a population's |CV| or |μ| in %: beyond it every channel passes (or none): no threshold
MAX_MIN_BASE_DEG = 360.0  # a DC or amplitude in degrees: a whole turn


def check_body_options(args: argparse.Namespace) -> None:
    """The body options' numbers: finite and physically possible."""
    check_number(args.mass, "--mass (kg)", 0.0, MAX_BODY_MASS, lo_open=True)
    check_number(args.ground, "--ground (m)", -MAX_GROUND_M, MAX_GROUND_M)
    check_number(args.sole_width, "--sole-width (m)", 0.0, MAX_SOLE_WIDTH_M, lo_open=True)
    check_number(getattr(args, "age", None), "--age (years)", 0.0, MAX_AGE_YEARS, lo_open=True)
    check_number(getattr(args, "tolerance_mm", None), "--tolerance-mm (mm)", 0.0, MAX_TOLERANCE_MM)
    check_number(args.cutoff_hz, "--cutoff-hz (Hz)", MIN_CUTOFF_HZ, MAX_CUTOFF_HZ)


def check_population_options(args: argparse.Namespace) -> None:
    """``gait analyze`` and ``batch gait``'s thresholds: finite and at least 0, before any take is read (a NaN
    threshold passed every comparison as false and wrote NaN into features.json with exit 0)."""
    check_number(args.threshold, "--threshold (%)", 0.0, MAX_PERCENT)
    check_number(args.min_base, "--min-base (deg)", 0.0, MAX_MIN_BASE_DEG)
    check_number(args.min_change, "--min-change (%)", 0.0, MAX_PERCENT)


def load_from_args(args: argparse.Namespace) -> LoadedMotion:
    """The motion named on the command line, or the built-in demo when there is none."""
    check_body_options(args)
    urdf_opts = UrdfBodyOptions(config=args.robot_config)
    if args.motion is None and args.robot:  # the demo is the built-in robot's: the user's would go unanalysed
        raise InputError(f"--robot {args.robot}: give the robot's motion (a joint-trajectory CSV); without one "
                         "the built-in demo robot is analysed, not this one")
    if args.motion is None:
        body = body_from_urdf(demo_robot_path(), urdf_opts)
        traj = demo_trajectory(body.joint_names)
        return LoadedMotion(body, traj.t, trajectory_frames(body, traj), "<demo>", trajectory=traj)
    return take_options(args).load(args.motion)


def take_options(args: argparse.Namespace) -> TakeOptions:
    """The body options of the command line (checked: every command that loads a take comes here)."""
    check_body_options(args)
    return TakeOptions(robot=args.robot, robot_config=args.robot_config, mass=args.mass, units=args.units,
                       up=args.up, mapping=args.mapping, sole_width=args.sole_width, ground=args.ground,
                       mode=args.mode, tolerance_mm=getattr(args, "tolerance_mm", VALIDATED_P95_MM),
                       subject=getattr(args, "subject", None), markers=getattr(args, "markers", None),
                       static=getattr(args, "static", None),
                       cutoff_hz=args.cutoff_hz, bsp=getattr(args, "bsp", "auto"), age=getattr(args, "age", None),
                       treadmill=parse_treadmill(getattr(args, "treadmill", "auto")))


def limits_from_args(args: argparse.Namespace) -> CorrectionLimits:
    """The correction limits of the command line (degrees, deg/s, mm → m)."""
    for deg in args.max_rotation_deg:
        check_number(deg, "--max-rotation-deg (deg)", 0.0, MAX_ROTATION_DEG, lo_open=True)
    check_number(args.max_rate_deg_s, "--max-rate-deg-s (deg/s)", 0.0, MAX_RATE_DEG_S, lo_open=True)
    check_number(args.margin_mm, "--margin-mm (mm)", 0.0, MAX_MARGIN_MM)
    return replace(CorrectionLimits(), max_rotation_deg=tuple(args.max_rotation_deg),
                   max_rate_deg_s=args.max_rate_deg_s, margin_m=args.margin_mm / 1000)


def monitor_config(args: argparse.Namespace, loaded: LoadedMotion, from_file: bool) -> PipelineConfig:
    """:func:`default_config` of a monitored source with the command line's mode, ground height and
    estimator cutoff. Without ``--cutoff-hz``: a file replayed (``from_file``) gets a file's default, as
    `analyze` of it does; a live stream, whose noise is unknown, the default for its rate
    (:func:`default_cutoff`)."""
    cutoff = default_cutoff(loaded.fps) if args.cutoff_hz is None and not from_file else args.cutoff_hz
    return take_config(loaded, args.mode, args.ground, cutoff)


@contextlib.contextmanager
def stop_on_signals(stop: Callable[[str], None]):
    """Ctrl-C, SIGTERM and SIGHUP (:func:`~livezmp.commands.startup.handling_stop_signals`) call ``stop(signal name)``:
    the loop ends its cycle or frame and stops cleanly; the previous handlers come back on exit."""
    with handling_stop_signals(lambda signum, _frame: stop(signal.Signals(signum).name)):
        yield
