"""The `livezmp` command: its grammar, and the dispatch to the module that runs each subcommand.

Parsing imports only what the grammar needs (the standard library and a few small
modules of defaults): each subcommand names its handler as ``"module:function"`` under
:mod:`livezmp.commands`, imported after the arguments are parsed, so ``livezmp --help``
and ``livezmp SUBCOMMAND --help`` never load the numerics, Pinocchio or plotting.
User mistakes (:class:`InputError`) print one line and exit with code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import math
import os
import sys
import warnings
from importlib.metadata import PackageNotFoundError, version
from typing import NoReturn

from livezmp.commands.console import outliving_console
from livezmp.commands.startup import Interrupted, finish_interrupted, startup_signals
from livezmp.correct.limits import CorrectionLimits
from livezmp.errors import InputError
from livezmp.gait.takeset import DEFAULT_PATTERN
from livezmp.links.bus_timing import ADAPTERS, DEFAULT_ADAPTER
from livezmp.live.config import CONTACT_MODES, LoopConfig, SafetyConfig
from livezmp.live.realtime import LOOP_PRIORITY
from livezmp.offline.validated import VALIDATED_P95_MM

# Names the grammar offers before anything heavy is imported; tests check them against
# livezmp.live.scenarios.SCENARIOS, sim_devices.launch.KINDS and the dashboard's default.
SCENARIO_NAMES = ("stand", "lean", "arm_swing", "squat", "slope", "edge", "push", "demo")
SIM_LINKS = ("dynamixel", "can", "fw")
BSP_NAMES = ("auto", "adult", "child")  # livezmp.model.anthropometry.BSP_CHOICES
DEFAULT_DASHBOARD = "127.0.0.1:8765"
LOOP_COMMANDS = ("livezmp.commands.run", "livezmp.commands.demo")  # whose start-up signals are told
# commands that carry on when their terminal or output's reader goes (commands.console): a robot's loop, a session
LIVE_COMMANDS = (*LOOP_COMMANDS, "livezmp.commands.monitor")


def package_version() -> str:
    try:
        return version("livezmp")
    except PackageNotFoundError:  # running from a source tree that was never installed
        return "unknown"


class OneLineParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line, as every other user mistake's (argparse prints the usage first:
    two lines or more); ``--help`` still shows the usage. Its subcommands' parsers are of this class too."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="livezmp", description="Real-time balance monitor for humanoid motion.")
    p.add_argument("--version", action="version", version=f"livezmp {package_version()}")
    sub = p.add_subparsers(dest="command", required=True)
    _analysis_commands(sub)
    _monitor_commands(sub)
    _loop_commands(sub)
    _gait_commands(sub)
    _batch_commands(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    module, _, function = args.handler.partition(":")
    # Inputs are checked at the edges and outputs before they are written (never NaN with exit 0),
    # so numerical warnings would only add lines to a one-line error.
    warnings.filterwarnings("ignore", category=RuntimeWarning)
    # what livezmp warns of (a foot's mesh not found) is one line, as its errors are
    warnings.formatwarning = lambda message, *_args, **_kwargs: f"livezmp: warning: {message}\n"
    # run / demo: a signal before their loop runs stops the start-up safely and is told (commands.startup); the
    # handler goes in before the command's modules are imported, which on a loaded machine takes many seconds
    signals = startup_signals() if module in LOOP_COMMANDS else contextlib.nullcontext()
    console = outliving_console() if module in LIVE_COMMANDS else contextlib.nullcontext()
    try:
        with console, signals as args.startup:
            try:
                code = int(getattr(importlib.import_module(module), function)(args) or 0)
            except Interrupted as e:
                return finish_interrupted(e, args.startup, args)
        sys.stdout.flush()  # a reader gone shows here, not as an "Exception ignored" at the interpreter's exit
        return code
    except InputError as e:
        print(f"livezmp: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader of the output went away (`| head`): stop quietly, as SIGPIPE would
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nothing more reaches the closed pipe
        return 141


# -- analyze, correct -----------------------------------------------------------------------------


def add_body_options(p: argparse.ArgumentParser) -> None:
    """Options shared by every command that loads a motion."""
    p.add_argument("--robot", help="URDF of the robot (for a joint-trajectory CSV)")
    p.add_argument("--robot-config", help="robot config TOML (default: beside the URDF, or built in)")
    p.add_argument("--mass", type=float, help="total body mass, kg (default: BVH 70; C3D the plates', else the file's)")
    p.add_argument("--units", choices=["m", "cm", "mm", "in", "cmu"], help="BVH length unit (default: detected)")
    p.add_argument("--up", choices=["y", "z"], help="BVH up axis (default: detected)")
    p.add_argument("--mapping", help="TOML file mapping unknown joint names to segments")
    p.add_argument("--sole-width", type=float, help="sole width for a BVH skeleton, m (default 5.5%% of stature)")
    p.add_argument("--ground", type=float, help="ground height in the input frame, m (default: detected)")
    p.add_argument("--mode", choices=["full", "seed"], default="full",
                   help="ZMP of rigid segments (full) or point masses as in the seed paper (seed)")
    p.add_argument("--cutoff-hz", type=float,
                   help="estimator smoothing cutoff, Hz (default 4 x (rate / 120 Hz)^0.2: 3.0 at 30 Hz, 4 at 120)")


def add_marker_options(p: argparse.ArgumentParser) -> None:
    """How a C3D trial's markers make a body: the marker map and the body-segment table."""
    p.add_argument("--markers", help="C3D marker map (TOML: label renames, or a cluster set's segments and "
                                     "joint-centre rules; docs/validation.md)")
    p.add_argument("--static", metavar="STATIC.c3d",
                   help="a cluster set's static trial: the landmarks (knee, ankle ...) the C3D walk lacks, carried "
                        "by their segment's cluster (docs/validation.md, \"Static trials for cluster sets\")")
    p.add_argument("--bsp", choices=BSP_NAMES, default="auto",
                   help="C3D body-segment table: de Leva's adult, or for a child scaled by Jensen's proportions at "
                        "its age (default auto: child when the file's Age is under 18 or its Height under 1.40 m)")
    p.add_argument("--age", type=float, metavar="YEARS", help="the C3D subject's age, replacing the file's")


def add_treadmill_option(p: argparse.ArgumentParser) -> None:
    """``--treadmill``: a C3D walk on an instrumented treadmill (livezmp.offline.treadmill)."""
    p.add_argument("--treadmill", default="auto", metavar="auto|off|SPEED[,RIGHT]",
                   help="C3D walk on an instrumented treadmill: its feet's contacts, support, plausibility and speed "
                        "judged on the belts. auto (default): found from the stance feet; off: a floor at rest; "
                        "SPEED: belt speed, m/s, running against the way the subject faces (LEFT,RIGHT: split belts)")


def _analysis_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("analyze", help="ZMP, support and balance of a motion file (BVH, C3D, or CSV + URDF)")
    p.add_argument("motion", nargs="?", help="motion file (.bvh, .c3d, or .csv with --robot); default: built-in demo")
    p.add_argument("--out", help="per-frame CSV (zmp.csv)")
    p.add_argument("--summary-json", help="summary JSON")
    p.add_argument("--plot", help="figure (PNG)")
    p.add_argument("--tolerance-mm", type=float, default=VALIDATED_P95_MM,
                   help=f"ZMP uncertainty for inside_fraction_tol, mm (default {VALIDATED_P95_MM:g}: validated p95)")
    p.add_argument("--subject", help="subject file from `livezmp calibrate` (a BVH's or C3D's head, arms and trunk)")
    add_marker_options(p)
    add_treadmill_option(p)
    add_body_options(p)
    p.set_defaults(handler="livezmp.commands.analyze:cmd_analyze")

    p = sub.add_parser("calibrate", help="subject parameters (a placed HAT's or a tracked thorax' mass and centre of "
                       "mass) from force-plate C3D trials")
    p.add_argument("trials", nargs="+", help="C3D trials of one subject with force plates")
    p.add_argument("-o", "--output", default="subject.toml", help="subject file to write (default subject.toml)")
    p.add_argument("--mass", type=float, help="body mass, kg (default: the plates', else the file's)")
    add_marker_options(p)
    p.set_defaults(handler="livezmp.commands.calibrate:cmd_calibrate")

    p = sub.add_parser("correct", help="root and hip corrections that keep the ZMP inside the support polygon")
    p.add_argument("motion", nargs="?", help="motion file (.bvh, .c3d, or .csv with --robot)")
    p.add_argument("-o", "--output", required=True, help="corrected motion (same format as the input)")
    p.add_argument("--report", help="report JSON")
    p.add_argument("--subject", help="subject file from `livezmp calibrate` (a BVH's or C3D's head, arms and trunk)")
    add_marker_options(p)
    add_body_options(p)
    add_correction_limits(p)
    p.set_defaults(handler="livezmp.commands.correct:cmd_correct")


def add_correction_limits(p: argparse.ArgumentParser) -> None:
    """The limits of the balance correction (``correct``, ``batch correct``)."""
    d = CorrectionLimits()
    p.add_argument("--max-rotation-deg", type=float, nargs=3, metavar=("ROLL", "PITCH", "YAW"),
                   default=list(d.max_rotation_deg), help="largest root rotation per axis, degrees")
    p.add_argument("--max-rate-deg-s", type=float, default=d.max_rate_deg_s, help="largest root rotation rate, deg/s")
    p.add_argument("--margin-mm", type=float, default=1000 * d.margin_m,
                   help="how far inside the support polygon to aim, mm")


# -- monitor, replay, recover ---------------------------------------------------------------------


def _sink_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--dashboard", nargs="?", const=DEFAULT_DASHBOARD, metavar="HOST:PORT",
                   help=f"serve the live dashboard (default address {DEFAULT_DASHBOARD})")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a dashboard address beyond loopback; a token is then generated and required")
    p.add_argument("--token", action="store_true", help="require a generated token for the dashboard on loopback too")
    p.add_argument("--record", metavar="FILE.mcap", help="record inputs, results, corrections, alarms, faults")
    p.add_argument("--tui", action="store_true", help="live status table in the terminal")
    p.add_argument("--alarm-command", metavar="CMD",
                   help="run CMD on every alarm event (LIVEZMP_ALARM* environment variables)")
    p.add_argument("--summary-json", metavar="FILE",
                   help="at exit, write frames in/analysed/dropped, latency percentiles and estimator settings")


def _monitor_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("monitor", help="watch balance live: a file replayed in real time, udp://, tcp:// streams, "
                                       "capture systems, a servo link (read only)")
    p.add_argument("motion", nargs="?", metavar="SOURCE",
                   help="motion file (.bvh, .c3d, .csv with --robot, .mcap), udp://HOST:PORT[?allow=NET,...] "
                        "(livezmp frames), tcp://HOST:PORT (BVH broadcast), lsl://NAME, qtm://HOST, natnet://HOST "
                        "(capture systems' markers and plates), a link URL with --robot (dynamixel:PATH, "
                        "can:INTERFACE:CHANNEL, fw:URL; read only, no commands); default: built-in demo")
    p.add_argument("--calibration", metavar="TRIAL.c3d",
                   help="a capture stream's subject: C3D trial (same marker labels) calibrating the marker body "
                        "(default: the stream's first 2 s)")
    p.add_argument("--window-s", type=float, help="estimator spline window, s (default 0.4)")
    p.add_argument("--lag-s", type=float, help="estimator output lag, s (default 0.1; analyze of a C3D uses 0.8 / 0.4)")
    p.add_argument("--frames", type=int, metavar="N", help="stop after N input frames (default: at the end or Ctrl-C)")
    p.add_argument("--skeleton", help="BVH file giving a stream's skeleton (hierarchy, optional frames)")
    p.add_argument("--fps", type=float, help="a stream's frame rate, Hz (default: the skeleton file's)")
    p.add_argument("--speed", type=float, default=1.0, help="replay speed factor for files (0 = as fast as possible)")
    p.add_argument("--loop", action="store_true", help="replay a file over and over")
    p.add_argument("--alarm-after", type=float, default=200.0, metavar="MS",
                   help="alarm when the ZMP is out of support for this long, ms (default 200)")
    p.add_argument("--correct", action="store_true", help="run the online balance correction and record it")
    p.add_argument("--subject", help="subject file from `livezmp calibrate` (a BVH's or C3D's head, arms and trunk)")
    p.add_argument("--realtime-priority", type=int, default=0, metavar="N",
                   help="run the monitor, its capture client and dashboard under SCHED_FIFO at this priority, 1-99 "
                        "(default 0: normal scheduling); if refused it runs at normal priority and says so")
    _sink_options(p)
    add_marker_options(p)
    add_body_options(p)
    p.set_defaults(handler="livezmp.commands.monitor:cmd_monitor")

    p = sub.add_parser("replay", help="re-run the analysis of a recorded session (MCAP)")
    p.add_argument("recording", help="an MCAP recording of `livezmp monitor --record` or of the live loop's "
                   "`run|demo --record`")
    p.add_argument("--speed", type=float, default=0.0, help="speed factor (default 0: as fast as possible)")
    _sink_options(p)
    p.set_defaults(handler="livezmp.commands.monitor:cmd_replay")

    p = sub.add_parser("recover", help="make a complete MCAP file of a recording cut short by a crash")
    p.add_argument("broken", help="the unfinished recording")
    p.add_argument("-o", "--out", required=True, help="the repaired file to write")
    p.set_defaults(handler="livezmp.commands.monitor:cmd_recover")


# -- run, sim, demo -------------------------------------------------------------------------------


def add_loop_options(p: argparse.ArgumentParser) -> None:
    d, s = LoopConfig(), SafetyConfig()
    p.add_argument("--rate", type=float, help="loop rate, Hz (default: the link's stream rate, else 500, or 85 %% "
                                              "of a serial bus's ceiling if less)")
    p.add_argument("--no-correct", action="store_true", help="send the command only, no balance corrections")
    p.add_argument("--correct-hz", type=float, default=d.correct_hz,
                   help=f"corrector rate, Hz: every few loop cycles (default {d.correct_hz:g})")
    p.add_argument("--duration", type=float, help="seconds to run; 0 = until Ctrl-C")
    p.add_argument("--summary-json", help="write the run's summary here (JSON)")
    p.add_argument("--watchdog-ms", type=float, default=1e3 * s.watchdog_s,
                   help=f"no valid read for this long → stop commanding (default {1e3 * s.watchdog_s:g})")
    p.add_argument("--on-timeout", choices=["hold", "torque-off"], default="hold",
                   help="what the watchdog does: hold the posture (default) or drop torque")
    p.add_argument("--max-correction-deg", type=float, default=math.degrees(s.max_correction_rad),
                   help="largest correction of any joint, degrees")
    p.add_argument("--quiet", action="store_true", help="no live status line (events are still told)")
    p.add_argument("--realtime-priority", type=int,
                   help=f"run the loop under SCHED_FIFO at this priority, 1-99, with its memory locked; given, a "
                        f"refusal is an error; by default it asks for {LOOP_PRIORITY} and, if refused, runs at "
                        "normal priority and says so (0 = normal scheduling)")
    p.add_argument("--cpu", help="pin the loop to these CPUs, e.g. 1 or 2,3 (default: anywhere)")
    p.add_argument("--contacts", choices=CONTACT_MODES, default=d.contacts,
                   help="where the feet's contacts come from: the link's foot sensors (a foot is down above "
                        f"{100 * d.contact_fraction:g} %% of the body weight), the kinematics, or auto: the sensors "
                        f"when the link has them (default {d.contacts})")
    p.add_argument("--record", metavar="FILE.mcap",
                   help="record inputs, results, foot sensors and corrections (MCAP, a new file)")


def _loop_commands(sub: argparse._SubParsersAction) -> None:
    scenarios = ", ".join(SCENARIO_NAMES)
    p = sub.add_parser("run", help="the live balance loop on a servo link")
    p.add_argument("--robot", required=True, help="URDF of the robot")
    p.add_argument("--robot-config", help="robot config TOML (default: beside the URDF, or built in)")
    p.add_argument("--link", required=True, help="dynamixel:PATH, can:INTERFACE:CHANNEL, fw:URL or mock:")
    p.add_argument("--motion", help="joint-trajectory CSV to play as the command (default: hold the first posture)")
    p.add_argument("--scenario", help=f"built-in scenario as the command ({scenarios})")
    p.add_argument("--adapter-latency-ms", type=float,
                   help="round-trip latency of the USB-serial adapter, for the bus ceiling in the summary "
                        "(default 1.5: a full-speed FTDI with its latency timer at 1 ms)")
    add_loop_options(p)
    p.set_defaults(handler="livezmp.commands.run:cmd_run")

    p = sub.add_parser("sim", help="simulated humanoid behind simulated devices on ptys, until stopped")
    p.add_argument("--robot", help="URDF of the robot (default: the built-in livezmp_mini)")
    p.add_argument("--robot-config", help="robot config TOML (default: beside the URDF, or built in)")
    p.add_argument("--link", required=True, choices=SIM_LINKS, help="which devices to simulate")
    p.add_argument("--scenario", default="stand", help=f"initial posture and pushes ({scenarios}; default stand)")
    p.add_argument("--fault", default="", help="fault spec, e.g. drop=0.01,corrupt=0.01,vanish=3s+1s")
    add_device_options(p)
    p.add_argument("--realtime-priority", type=int, default=LOOP_PRIORITY - 1,
                   help=f"run the devices under SCHED_FIFO at this priority, 1-99 (default {LOOP_PRIORITY - 1}, "
                        "just below the loop's; 0 = normal scheduling)")
    p.set_defaults(handler="livezmp.commands.sim:cmd_sim")

    p = sub.add_parser("demo", help="the live loop on a simulated humanoid (default: the built-in livezmp_mini)")
    p.add_argument("--robot", help="URDF of any humanoid (default: the built-in livezmp_mini)")
    p.add_argument("--robot-config", help="robot config TOML (default: beside the URDF, or built in; without one, "
                                          "servo ids in joint order and default soles)")
    p.add_argument("--link", default="dynamixel", choices=[*SIM_LINKS, "mock"],
                   help="simulated link (default dynamixel)")
    p.add_argument("--link-options", default="", help="extra link URL options, e.g. fast=1&timeout=0.005")
    p.add_argument("--scenario", default="demo", help=f"{scenarios} (default demo: lean, then arm swing)")
    p.add_argument("--fault", default="", help="fault spec for the simulated devices")
    p.add_argument("--sim-cpu", help="CPUs for the simulator's devices and physics, e.g. 1, or any (default: the "
                                     "last CPU the loop is not pinned to by --cpu, given two or more)")
    add_device_options(p)
    add_loop_options(p)
    p.set_defaults(handler="livezmp.commands.demo:cmd_demo")


def add_device_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--baud", type=int, help="line rate of the simulated bus, bit/s (CAN: its bitrate; "
                                            "default 1000000)")
    p.add_argument("--adapter", default=DEFAULT_ADAPTER,
                   help=f"the simulated bus's USB-serial adapter: {', '.join(ADAPTERS)} or a round-trip latency in "
                        f"ms (default {DEFAULT_ADAPTER}: full-speed FTDI, latency timer 1 ms)")
    p.add_argument("--buses", type=int, default=1, help="split the servos over this many simulated buses "
                                                         "(Dynamixel, or CAN with --can-protocol mit)")
    p.add_argument("--can-protocol", choices=("firmware", "mit"), default="firmware",
                   help="simulated CAN servos: firmware_protocol nodes behind slcan (default), or MIT-mode motors "
                        "(one command frame, one state frame) behind a socketcand daemon")


# -- gait -----------------------------------------------------------------------------------------


def _gait_input_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--up", choices=("y", "z"),
                   help="BVH up axis (default: detected, as analyze does; ground = the other two)")
    p.add_argument("--units", choices=("m", "cm", "mm", "in", "cmu"), help="BVH length unit (default: detect)")
    p.add_argument("--urdf", help="robot URDF, for joint-trajectory CSV walks")
    p.add_argument("--markers", help="C3D marker map (TOML), for C3D walks whose labels need one (as for analyze)")
    p.add_argument("--static", metavar="STATIC.c3d",
                   help="a cluster set's static trial, for C3D walks (as for analyze)")


def add_population_options(p: argparse.ArgumentParser) -> None:
    """How takes are labelled and compared across people (``gait analyze``, ``batch gait``)."""
    p.add_argument("--manifest", help="CSV with columns path,subject,condition instead of inputs")
    p.add_argument("--pattern", default=DEFAULT_PATTERN,
                   help="regex on file names with groups (?P<condition>) and optionally (?P<subject>)")
    p.add_argument("--base", required=True, help="base condition, e.g. normal")
    p.add_argument("--variant", type=_variant, action="append", required=True, metavar="LABEL=CONDITION",
                   help="a variant, e.g. fast=active (repeatable)")
    p.add_argument("--threshold", type=float, default=250.0, help="feature parts: |CV| ≤ this, %% (default 250)")
    p.add_argument("--min-base", type=float, default=1.0,
                   help="DC or amplitude below this (deg) in the base: no ratio (default 1)")
    p.add_argument("--min-change", type=float, default=1.0,
                   help="feature parts also need |μ| ≥ this, %% (default 1; 0 = the paper's rule)")


def _variant(text: str) -> tuple[str, str]:
    label, sep, cond = text.partition("=")
    if not sep or not label or not cond:
        raise argparse.ArgumentTypeError(f"expected LABEL=CONDITION (e.g. fast=active), got {text!r}")
    return label, cond


def _gait_commands(subparsers: argparse._SubParsersAction) -> None:
    gait = subparsers.add_parser("gait", help="walking analysis and speed control (paper 003)",
                                 description="Gait features across people, and walking-speed control.")
    sub = gait.add_subparsers(dest="gait_command", required=True)

    p = sub.add_parser("analyze", help="features common across people: K, μ, σ, CV, feature parts")
    p.add_argument("inputs", nargs="*", help="walk files or directories (labelled by --pattern)")
    p.add_argument("--out", required=True, help="output directory for tables, plot and features.json")
    add_population_options(p)
    _gait_input_options(p)
    add_treadmill_option(p)
    p.set_defaults(handler="livezmp.commands.gait:cmd_analyze")

    p = sub.add_parser("synth", help="change a base walk towards a variant using only its feature parts")
    p.add_argument("base_walk", help="BVH file, or joint-trajectory CSV with --urdf")
    p.add_argument("--features", required=True, help="features.json from gait analyze")
    p.add_argument("--to", required=True, help="variant label, e.g. fast")
    p.add_argument("--amount", type=float, default=1.0, help="0 = base walk … 1 = the variant (default 1)")
    p.add_argument("-o", "--output", required=True, help="output walk (same format as the input)")
    p.add_argument("--balance", action="store_true", help="pass the result through the balance correction")
    _gait_input_options(p)
    p.set_defaults(handler="livezmp.commands.gait:cmd_synth")

    p = sub.add_parser("compare", help="cycle-normalised joint-angle RMS error of walk A against walks B")
    p.add_argument("walk", help="walk A")
    p.add_argument("others", nargs="+", help="walk(s) B; with several, the mean error is the last number")
    _gait_input_options(p)
    add_treadmill_option(p)
    p.set_defaults(handler="livezmp.commands.gait:cmd_compare")


# -- batch ----------------------------------------------------------------------------------------


def _batch_common(p: argparse.ArgumentParser, kinds: str) -> None:
    p.add_argument("sources", nargs="*", metavar="DIR_OR_GLOB", help="directories (searched recursively), "
                   f"files or glob patterns of takes ({kinds})")
    p.add_argument("--out", required=True, help="output directory: takes.parquet, takes.csv, takes/...")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, default=2, help="local cluster: worker processes (default 2)")
    where.add_argument("--scheduler", metavar="tcp://HOST:8786", help="use this running Dask scheduler")
    p.add_argument("--dashboard-address", default="127.0.0.1:0",
                   help="local cluster's dashboard address (default: loopback, a free port)")


def _batch_commands(subparsers: argparse._SubParsersAction) -> None:
    batch = subparsers.add_parser("batch", help="whole motion libraries on a Dask cluster",
                                  description="Process every take of a library, one Dask task per take.")
    sub = batch.add_subparsers(dest="batch_command", required=True)
    p = sub.add_parser("analyze", help="ZMP analysis of every take: a table (Parquet, CSV) and per-take outputs")
    _batch_common(p, ".bvh, .c3d; .csv with --robot")
    p.add_argument("--tolerance-mm", type=float, default=VALIDATED_P95_MM,
                   help=f"ZMP uncertainty for inside_fraction_tol, mm (default {VALIDATED_P95_MM:g}: validated p95)")
    p.add_argument("--subject",
                   help="subject file from `livezmp calibrate` (C3D takes: HAT or thorax mass and centre of mass)")
    p.add_argument("--plot", action="store_true", help="also write each take's figure (zmp.png, as analyze --plot)")
    add_marker_options(p)
    add_body_options(p)
    p.set_defaults(handler="livezmp.commands.batch:cmd_analyze")

    p = sub.add_parser("correct", help="balance correction of every take: corrected files and a table")
    _batch_common(p, ".bvh; .csv with --robot")
    add_body_options(p)
    add_correction_limits(p)
    p.set_defaults(handler="livezmp.commands.batch:cmd_correct")

    p = sub.add_parser("gait", help="gait features of every take (on the cluster), then the population (paper 003)")
    _batch_common(p, ".bvh; .csv with --urdf")
    add_population_options(p)
    _gait_input_options(p)
    p.set_defaults(handler="livezmp.commands.batch:cmd_gait")


if __name__ == "__main__":
    sys.exit(main())
