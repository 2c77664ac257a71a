"""`livezmp run`: the live balance loop on a servo link.

Open the link, then read → estimate → correct → write at a fixed rate (see
:mod:`livezmp.live.loop`) until ``--duration``, the end of the motion, or Ctrl-C /
SIGTERM; a summary JSON at exit. The loop's options and its running are shared with
``livezmp demo`` (:func:`add_loop_options`, :func:`run_loop`).

``run`` and ``demo`` take ``--contacts auto|sensors|kinematics`` (where the feet's
contacts come from, see :class:`~livezmp.live.loop.LoopConfig`) and ``--record
FILE.mcap`` (:mod:`livezmp.live.recorder`: inputs, results, foot sensors, corrections,
written by a background thread; the file is finished after the safe stop, on every way
out).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from livezmp.checks import FRAME_PERIOD_RANGE, check_output_paths, given_inputs
from livezmp.commands.common import stop_on_signals
from livezmp.commands.startup import Interrupted, Startup, closing_link
from livezmp.errors import InputError
from livezmp.estimate.estimator import EstimatorError
from livezmp.jsonfile import write_json
from livezmp.links import LinkError, make_link
from livezmp.links.bus_timing import DEFAULT_ADAPTER, Adapter, bus_summary, parse_adapter
from livezmp.live import scenarios as sc
from livezmp.live.clock import SPIN_BEFORE_DEADLINE_S, LoopClock
from livezmp.live.config import LoopConfig, SafetyConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.realtime import (
    LOOP_PRIORITY,
    check_priority,
    cpu_wake_latency_us,
    memory_locked,
    parse_cpus,
    realtime_priority,
)
from livezmp.live.recorder import LoopRecorder
from livezmp.live.scenarios import make_scenario
from livezmp.model.robot import Robot, load_robot
from livezmp.recording.writer import stopped_note

# While recording, the recording's writer thread shares the GIL with the loop. It writes while the loop sleeps
# (LoopRecorder.idle), but closing a chunk (about 1 ms of Python every 0.5 s) can run past the loop's wake-up,
# and the woken loop waits for the GIL up to the interpreter's switch interval: 5 ms by default, more than a
# 500 Hz cycle; 0.1 ms here. (Measured, 20 s demo: an unpaced writer at 5 ms raised deadline misses from ~160
# to ~1200; paced, misses are within the run-to-run noise of runs without recording.)
RECORD_SWITCH_INTERVAL_S = 1e-4
# `run` / `demo` exit code of a run that ended, its summary and recording written, whose link failed it: down or
# without valid frames for more than MAX_LOST_SHARE of it, or at its end, or unusable (livezmp.live.link_faults).
# Not 1 (an unexpected error), 2 (a user's mistake) or 128 + N (a signal).
EXIT_LINK_FAILED = 3


# -- shared pieces ------------------------------------------------------------------------------------


def loop_config(args: argparse.Namespace, rate: float) -> LoopConfig:
    for name in ("correct_hz", "watchdog_ms", "max_correction_deg"):
        value = getattr(args, name)
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"--{name.replace('_', '-')} {value}: must be a positive number")
    safety = replace(SafetyConfig(), watchdog_s=args.watchdog_ms / 1e3, drop_torque=args.on_timeout == "torque-off",
                     max_correction_rad=float(np.radians(args.max_correction_deg)))
    config = LoopConfig(rate_hz=rate, correct=not args.no_correct, correct_hz=args.correct_hz, safety=safety,
                        contacts=args.contacts)
    try:  # a rate in range may still be too slow for the loop's estimator settings
        config.estimator_config(rate)
    except EstimatorError as e:
        raise InputError(f"--rate {rate:g}: too slow for the live loop's estimator: {e}") from None
    return config


def check_outputs(args: argparse.Namespace) -> None:
    """Before anything starts: a --record file that exists (it is never overwritten), an output
    in a directory that does not exist, or both outputs naming one file, is a one-line error."""
    if args.record and Path(args.record).exists():
        raise InputError(f"{args.record}: already exists; record to a new file")
    check_output_paths((args.record, "--record"), (getattr(args, "summary_json", None), "--summary-json"),
                       inputs=given_inputs(args))


def open_recorder(args: argparse.Namespace, robot: Robot, config: LoopConfig, source: str) -> LoopRecorder:
    """The --record file, with the loop's settings as its session."""
    est = {"window_s": config.estimator_window_s, "lag_s": config.estimator_lag_s,
           "cutoff_hz": config.estimator_cutoff_hz}
    session = {"source": source, "fps": config.rate_hz, "mode": "full", "ground_z": None, "correct": config.correct,
               "live_loop": {"rate_hz": config.rate_hz, "correct_hz": config.correct_hz, "contacts": config.contacts,
                             "contact_fraction": config.contact_fraction, "estimator": est}}
    return LoopRecorder(args.record, robot.spec, session, robot.body.channel_names, robot.body.joint_names)


MAX_LOOP_HZ = 2000.0
CEILING_SHARE = 0.85  # of a serial bus's ceiling: the default rate leaves the rest for the host's own delays


def loop_rate(args: argparse.Namespace, link) -> float:
    """--rate, else the rate a streaming link sends its state at, else 500 Hz, or on a serial servo bus
    `CEILING_SHARE` of what its wire and adapter allow if that is less."""
    rate = args.rate if args.rate is not None else float(getattr(link, "rate", 500.0))
    if args.rate is None and hasattr(link, "bus_ceilings"):
        ceiling = min(c.ceiling_hz for c in link.bus_ceilings(assumed_adapter(args)))
        rate = min(rate, float(math.floor(CEILING_SHARE * ceiling)))
    lowest = 1.0 / FRAME_PERIOD_RANGE[1]  # the estimator's slowest input
    if not (np.isfinite(rate) and lowest <= rate <= MAX_LOOP_HZ):
        why = "" if args.rate is not None else f" ({CEILING_SHARE:.0%} of what the bus carries: a faster --baud?)"
        raise InputError(f"--rate {rate:g}{why}: must be a number of Hz in [{lowest:g}, {MAX_LOOP_HZ:g}]")
    return rate


def duration_of(args: argparse.Namespace, default: float | None) -> float | None:
    if args.duration is None:
        return default
    if not (np.isfinite(args.duration) and args.duration >= 0):
        raise InputError(f"--duration {args.duration}: must be seconds >= 0 (0 = until Ctrl-C)")
    return args.duration or None


class StatusLine:
    """The live status on stderr: rewritten in place on a terminal, one line a second otherwise."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.tty = sys.stderr.isatty()

    def __call__(self, s: dict) -> None:
        if self.quiet:
            return
        margin = "   n/a  " if s["margin_mm"] is None else f"{s['margin_mm']:+6.1f} mm"
        inside = "n/a" if s["inside_fraction"] is None else f"{100 * s['inside_fraction']:5.1f} %"
        line = (f"t {s['t']:6.1f} s  {s['hz']:6.1f} Hz  {s['support'] or '-':>6}  margin {margin}  inside {inside}  "
                f"misses {s['misses']}  read errors {s['read_errors']}  corrections {s['corrections']}  {s['state']}")
        print(("\r" + line) if self.tty else line, end="" if self.tty else "\n", file=sys.stderr, flush=True)

    def event(self, msg: str) -> None:
        """State changes are told even with --quiet."""
        print(("\n" if self.tty and not self.quiet else "") + f"livezmp: {msg}", file=sys.stderr, flush=True)

    def done(self) -> None:
        if self.tty and not self.quiet:
            print(file=sys.stderr)


def print_summary(s: dict) -> None:
    inside = "n/a" if s["inside_fraction"] is None else f"{100 * s['inside_fraction']:.1f} %"
    p99 = "n/a" if s["p99_latency_ms"] is None else f"{s['p99_latency_ms']:.2f} ms"
    line = (f"{s['cycles']} cycles at {s['achieved_hz']:.1f} Hz ({s['rate_hz']:g} asked), {s['deadline_misses']} "
            f"deadline misses; read errors {s['read_errors']}, write errors {s['write_errors']}, stale frames "
            f"{s['stale_frames']}; {s['corrections_sent']} corrections sent; estimated ZMP inside {inside}; "
            f"latency p99 {p99}; stopped by {s['stopped_by']}")
    down = s.get("link_down")
    if down and down["events"]:
        line += f"; link down {down['seconds']:.1f} s in {down['events']} outage(s)" + (
            ", still down at the end" if down["at_end"] else "")
    if s.get("bus"):
        b = s["bus"]
        size = (f"{b['frames_per_cycle']} frames, {b['bits_per_cycle']} bits" if "bits_per_cycle" in b
                else f"{b['bytes_per_cycle']:g} bytes")
        line += (f"; bus: {b['baud']} baud x {b['buses']}, {b['read']}, {size} = "
                 f"{b['wire_ms_per_cycle']:.2f} ms a cycle + {b['adapter_latency_ms']:.2f} ms adapter: ceiling "
                 f"{b['ceiling_hz']:.0f} Hz, {100 * b['utilisation']:.0f} % used")
    if s.get("fell") is not None:
        true = s.get("true_inside_fraction")
        line += f"; simulator: {'FELL' if s['fell'] else 'did not fall'}"
        line += "" if true is None else f", true ZMP inside {100 * true:.2f} % of its steps"
    print(line, flush=True)


@contextlib.contextmanager
def switch_interval(seconds: float | None):
    """The interpreter's thread switch interval set to ``seconds`` inside the block (None: unchanged)."""
    before = sys.getswitchinterval()
    if seconds is not None:
        sys.setswitchinterval(seconds)
    try:
        yield
    finally:
        sys.setswitchinterval(before)


def run_loop(link, robot: Robot, args: argparse.Namespace, command, duration: float | None,
             fell: Callable[[], bool] | None = None, source: str = "", startup: Startup | None = None) -> dict:
    """The loop on an open ``link`` (``source``: its URL) with the command line's settings;
    the summary. With --record the file is finished after the loop's safe stop, whichever
    way the loop ended, and the summary's ``recording`` says what it holds and dropped.
    ``startup``: the command's (:mod:`livezmp.commands.startup`), whose signal handler then asks
    the loop to stop once it is made (without one, the loop installs its own)."""
    if startup is not None:
        startup.enter("preparing the loop")
    status = StatusLine(args.quiet)
    config = loop_config(args, loop_rate(args, link))
    # made here, its writer thread keeps normal scheduling when this thread asks for SCHED_FIFO
    recorder = open_recorder(args, robot, config, source) if args.record else None
    try:
        cpus = loop_cpus(args)
        # on its own CPUs the loop wakes by sleep then spin (livezmp.live.clock); sharing them, it sleeps
        clock = LoopClock(config.rate_hz, spin_s=SPIN_BEFORE_DEADLINE_S if cpus else 0.0)
        loop = LiveLoop(link, robot.body, config, command=command, clock=clock, fell=fell, on_event=status.event,
                        on_status=status, recorder=recorder)
        priority, required = loop_priority(args)
        with (stop_on_signals(loop.request_stop) if startup is None else startup.running(loop.request_stop),
              realtime_priority(priority, cpus, lock_memory=required, required=required, awake=True) as refused,
              switch_interval(RECORD_SWITCH_INTERVAL_S if recorder else None)):
            if refused not in (None, "off"):
                status.event(f"real-time priority {refused}: the loop runs at normal priority")
            locked, wake_latency = memory_locked(), cpu_wake_latency_us()
            summary = loop.run(duration)
        status.done()
        summary = {**summary, "realtime_priority": priority if refused is None else 0, "memory_locked": locked,
                   "cpu_wake_latency_us": wake_latency,
                   "placeholder_inertias": list(robot.body.placeholder_inertias)}
        if hasattr(link, "bus_ceilings"):  # a serial servo bus: what its wire and adapter allow
            summary["bus"] = bus_summary(link.bus_ceilings(assumed_adapter(args)), link.read_label,
                                         summary["achieved_hz"])
    except BaseException as e:  # also in the summary's making: the recording is finished on every way out
        if recorder is not None:
            totals = recorder.close({"stopped_by": str(e) if isinstance(e, Interrupted)
                                     else f"error: {type(e).__name__}: {e}"})
            if startup is not None:
                startup.recording = totals
        raise
    if recorder is not None:
        summary["recording"] = rec = recorder.close(summary)
        if rec["dropped_total"] or rec["failed"] or rec["file_error"]:
            status.event(f"recording {args.record}: {rec['dropped_total']} messages dropped (queue full), "
                         f"{rec['failed']} failed ({rec['error']})" + (stopped_note(args.record)
                                                                     if rec["file_error"] else ""))
    return summary


def loop_priority(args: argparse.Namespace) -> tuple[int, bool]:
    """(SCHED_FIFO priority, whether a refusal is an error): --realtime-priority given is a
    requirement (0: normal scheduling); not given, LOOP_PRIORITY is asked for, best effort."""
    if args.realtime_priority is None:
        return LOOP_PRIORITY, False
    check_priority(args.realtime_priority)
    return args.realtime_priority, args.realtime_priority > 0


def loop_cpus(args: argparse.Namespace) -> frozenset[int] | None:
    """--cpu as a set of CPU numbers (None: not pinned); InputError on a bad one."""
    return None if args.cpu is None else parse_cpus(args.cpu)


def check_realtime(args: argparse.Namespace) -> None:
    """Bad --realtime-priority or --cpu, or a required priority the system refuses: InputError,
    before anything is opened (the policy is asked for and given back at once)."""
    priority, required = loop_priority(args)
    loop_cpus(args)
    if required:
        with realtime_priority(priority, required=True):
            pass


def adapter_option(text: str) -> Adapter:
    """--adapter: a USB-serial adapter by name or its round-trip latency in ms (InputError otherwise)."""
    try:
        return parse_adapter(text)
    except ValueError as e:
        raise InputError(f"--adapter: {e}") from None


def assumed_adapter(args: argparse.Namespace) -> Adapter:
    """The adapter the bus ceiling assumes: --adapter-latency-ms, else the simulated --adapter, else the default."""
    if getattr(args, "adapter_latency_ms", None) is not None:
        ms = args.adapter_latency_ms
        if not (np.isfinite(ms) and 0 <= ms < 1e3):
            raise InputError(f"--adapter-latency-ms {ms}: must be milliseconds >= 0")
        return parse_adapter(ms)
    return adapter_option(getattr(args, "adapter", DEFAULT_ADAPTER))


def finish(summary: dict, args: argparse.Namespace) -> int:
    """Print and write the summary (printed first: a file that cannot be written is then one line after it); the
    exit code: 0, or EXIT_LINK_FAILED (told on stderr, last). A summary file that cannot be written is an
    InputError (exit 2), but after a failed link only its line: the run's own failure is the exit code."""
    print_summary(summary)
    failed = summary.get("link_failed")
    if args.summary_json:
        try:
            write_json(summary, args.summary_json)
        except InputError as e:
            if not failed:
                raise
            print(f"livezmp: error: {e}", file=sys.stderr, flush=True)
    if failed:
        print(f"livezmp: the link failed the run: {failed}", file=sys.stderr, flush=True)
        return EXIT_LINK_FAILED
    return 0


# -- run ------------------------------------------------------------------------------------------


def cmd_run(args: argparse.Namespace) -> int:
    args.startup.enter("checking the options")
    check_realtime(args)
    check_outputs(args)
    assumed_adapter(args)  # a bad --adapter-latency-ms is told before anything starts
    if args.motion and args.scenario:
        raise InputError("give --motion or --scenario, not both")
    return finish(run_on_link(args, args.startup), args)


def run_on_link(args: argparse.Namespace, startup: Startup) -> dict:
    """`run` after its checks: the robot, its link, the loop; the summary. ``startup``: the command line's
    (``args.startup``, installed by :func:`livezmp.cli.main`)."""
    startup.enter("loading the robot")
    robot = load_robot(args.robot, args.robot_config)
    scenario = None
    if args.motion:
        scenario = sc.walk(robot.body, args.motion)
    elif args.scenario:
        scenario = make_scenario(args.scenario, robot.body)
    try:
        with closing_link(make_link(args.link, robot.body.joint_names, robot.config), startup) as link:
            return run_loop(link, robot, args, scenario.goals if scenario else None,
                            duration_of(args, scenario.duration if scenario else None), source=args.link,
                            startup=startup)
    except LinkError as e:
        if startup.link_opened:
            raise
        # a device that is not there is a user mistake, as for `monitor`
        raise InputError(f"{args.link}: cannot open the link: {e}") from None
