"""`livezmp run`, `livezmp sim` and `livezmp demo`: the live balance loop on a servo
link, simulated devices on ptys, and the two together.

* ``run``: open the link, then read → estimate → correct → write at a fixed rate (see
  :mod:`livezmp.live.loop`) until ``--duration``, the end of the motion, or Ctrl-C /
  SIGTERM; a summary JSON at exit.
* ``sim``: a simulated humanoid (:class:`sim_devices.humanoid.SimHumanoid`) behind
  simulated devices of one link kind; prints one JSON line (the link URL and port
  paths) and runs until stopped.
* ``demo``: both together: ``livezmp_mini`` on a simulated Dynamixel bus (or ``--link
  can|fw``) served by a child process (:class:`SimProcess`: its own core and
  interpreter, as a robot is another machine; ``--link mock`` steps the humanoid in
  this process instead), a scenario (by default: lean past the toes and back, then
  swing the arms), a live status line and the summary, with the simulator's own
  verdict (``fell``, ``true_inside_fraction``: the share of its 1 ms steps whose true
  ZMP was inside the support polygon).

``run`` and ``demo`` take ``--contacts auto|sensors|kinematics`` (where the feet's
contacts come from, see :class:`~livezmp.live.loop.LoopConfig`) and ``--record
FILE.mcap`` (:mod:`livezmp.live.recorder`: inputs, results, foot sensors, corrections,
written by a background thread; the file is finished after the safe stop, on every way
out).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from livezmp.commands.common import stop_on_signals
from livezmp.errors import InputError
from livezmp.links import LinkError, open_link
from livezmp.links.mock import MockLink
from livezmp.live.loop import CONTACT_MODES, LiveLoop, LoopConfig
from livezmp.live.realtime import LOOP_PRIORITY, check_priority, realtime_priority
from livezmp.live.recorder import LoopRecorder
from livezmp.live.safety import SafetyConfig
from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec, robot_body
from livezmp.model.demo_robot import demo_robot_path
from livezmp.model.robot_config import RobotConfig, find_robot_config, load_robot_config
from livezmp.model.urdf_body import UrdfBodyOptions
from livezmp.offline.report import write_json
from sim_devices import scenarios as sc
from sim_devices.faults import parse_faults
from sim_devices.humanoid import Push, RealtimeThread, SimHumanoid
from sim_devices.launch import KINDS, humanoid_sensors, start_devices

# The demo's arm swing: 0.6 rad at 0.8 Hz, leaning to 8 mm inside the toes. Uncorrected the
# ZMP stays past the toes long enough to fall; the loop's corrector (estimator lag 30 ms)
# holds it. (The scenario's own default, 2.5 Hz, is faster than the loop can follow.)
ARM_SWING = {"amplitude": 0.6, "frequency": 0.8, "toe_margin": 0.008}
BLEND_S = 1.5  # s, between the parts of a sequence of scenarios (the lean into the arm swing is slow)
# While recording, the recording's writer thread shares the GIL with the loop. It writes while the loop sleeps
# (LoopRecorder.idle), but closing a chunk (about 1 ms of Python every 0.5 s) can run past the loop's wake-up,
# and the woken loop waits for the GIL up to the interpreter's switch interval: 5 ms by default, more than a
# 500 Hz cycle; 0.1 ms here. (Measured, 20 s demo: an unpaced writer at 5 ms raised deadline misses from ~160
# to ~1200; paced, misses are within the run-to-run noise of runs without recording.)
RECORD_SWITCH_INTERVAL_S = 1e-4


def sequence(name: str, parts: list[sc.Scenario], blend_s: float = BLEND_S) -> sc.Scenario:
    """Scenarios one after the other; each part's goals are blended in from where the
    previous one ended over ``blend_s`` seconds (smooth, so no goal jumps)."""
    starts = np.cumsum([0.0] + [p.duration for p in parts])
    ends = [p.goals(p.duration) for p in parts]

    def goals(t: float) -> np.ndarray:
        k = int(np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(parts) - 1))
        local = t - starts[k]
        q = parts[k].goals(local)
        if k == 0 or local >= blend_s:
            return q
        s = sc.smooth_step(local / blend_s)
        return ends[k - 1] + s * (q - ends[k - 1])

    pushes = tuple(replace(p, start=p.start + starts[k]) for k, part in enumerate(parts) for p in part.pushes)
    return sc.Scenario(name, goals, float(starts[-1]), pushes)


SCENARIOS: dict[str, Callable[[BodyModel], sc.Scenario]] = {
    "stand": sc.stand,
    "lean": sc.lean,
    "arm_swing": lambda body, **kw: sc.arm_swing(body, **{**ARM_SWING, **kw}),
    "squat": sc.squat,
    "push": sc.push,
    "demo": lambda body, **kw: sequence("demo", [sc.lean(body, hold_s=2.0),
                                                  sc.arm_swing(body, duration=3.0, **ARM_SWING)], **kw),
}


def make_scenario(name: str, body: BodyModel, **options) -> sc.Scenario:
    """A scenario by name (``SCENARIOS``) for ``body``, with its keyword ``options``;
    InputError naming the choices."""
    if name not in SCENARIOS:
        raise InputError(f"unknown scenario '{name}' (choose from {', '.join(SCENARIOS)})")
    return SCENARIOS[name](body, **options)


# -- shared pieces ------------------------------------------------------------------------------------


@dataclass
class Robot:
    """A robot's body model and its config (feet, servos), from ``--robot`` / ``--robot-config``;
    ``spec`` what the body was built from (for a recording)."""

    urdf: Path
    body: BodyModel
    config: RobotConfig
    spec: BodySpec


def load_robot(urdf: str | None, config: str | None) -> Robot:
    path = Path(urdf) if urdf else demo_robot_path()
    body, spec = robot_body(path, UrdfBodyOptions(config=config))
    robot_config = load_robot_config(config) if config else find_robot_config(path, body.model.name)
    return Robot(path, body, robot_config, spec)


def add_loop_options(p: argparse.ArgumentParser) -> None:
    d, s = LoopConfig(), SafetyConfig()
    p.add_argument("--rate", type=float, help="loop rate, Hz (default: the link's stream rate, else 500)")
    p.add_argument("--no-correct", action="store_true", help="send the command only, no balance corrections")
    p.add_argument("--correct-hz", type=float, default=d.correct_hz,
                   help=f"corrector rate, Hz: every few loop cycles (default {d.correct_hz:g})")
    p.add_argument("--duration", type=float, help="seconds to run; 0 = until Ctrl-C")
    p.add_argument("--summary-json", help="write the run's summary here (JSON)")
    p.add_argument("--watchdog-ms", type=float, default=1e3 * s.watchdog_s,
                   help=f"no valid read for this long → stop commanding (default {1e3 * s.watchdog_s:g})")
    p.add_argument("--on-timeout", choices=["hold", "torque-off"], default="hold",
                   help="what the watchdog does: hold the posture (default) or drop torque")
    p.add_argument("--max-correction-deg", type=float, default=float(np.degrees(s.max_correction_rad)),
                   help="largest correction of any joint, degrees")
    p.add_argument("--quiet", action="store_true", help="no live status line (events are still told)")
    p.add_argument("--realtime-priority", type=int, default=LOOP_PRIORITY,
                   help=f"run the loop under SCHED_FIFO at this priority, 1-99 (default {LOOP_PRIORITY}; "
                        "0 = normal scheduling); if refused it runs at normal priority and says so")
    p.add_argument("--contacts", choices=CONTACT_MODES, default=d.contacts,
                   help="where the feet's contacts come from: the link's foot sensors (a foot is down above "
                        f"{100 * d.contact_fraction:g} %% of the body weight), the kinematics, or auto: the sensors "
                        f"when the link has them (default {d.contacts})")
    p.add_argument("--record", metavar="FILE.mcap",
                   help="record inputs, results, foot sensors and corrections (MCAP, a new file)")


def loop_config(args: argparse.Namespace, rate: float) -> LoopConfig:
    for name in ("correct_hz", "watchdog_ms", "max_correction_deg"):
        value = getattr(args, name)
        if not (np.isfinite(value) and value > 0):
            raise InputError(f"--{name.replace('_', '-')} {value}: must be a positive number")
    safety = replace(SafetyConfig(), watchdog_s=args.watchdog_ms / 1e3, drop_torque=args.on_timeout == "torque-off",
                     max_correction_rad=float(np.radians(args.max_correction_deg)))
    return LoopConfig(rate_hz=rate, correct=not args.no_correct, correct_hz=args.correct_hz, safety=safety,
                      contacts=args.contacts)


def check_record(args: argparse.Namespace) -> None:
    """A --record file that exists is a one-line error before anything starts (it is never overwritten)."""
    if args.record and Path(args.record).exists():
        raise InputError(f"{args.record}: already exists; record to a new file")


def open_recorder(args: argparse.Namespace, robot: Robot, config: LoopConfig, source: str) -> LoopRecorder:
    """The --record file, with the loop's settings as its session."""
    est = {"window_s": config.estimator_window_s, "lag_s": config.estimator_lag_s,
           "cutoff_hz": config.estimator_cutoff_hz}
    session = {"source": source, "fps": config.rate_hz, "mode": "full", "ground_z": None, "correct": config.correct,
               "live_loop": {"rate_hz": config.rate_hz, "correct_hz": config.correct_hz, "contacts": config.contacts,
                             "contact_fraction": config.contact_fraction, "estimator": est}}
    return LoopRecorder(args.record, robot.spec, session, robot.body.channel_names, robot.body.joint_names)


def loop_rate(args: argparse.Namespace, link) -> float:
    """--rate, else the rate a streaming link sends its state at, else 500 Hz."""
    rate = args.rate if args.rate is not None else float(getattr(link, "rate", 500.0))
    if not (np.isfinite(rate) and 0 < rate <= 2000):
        raise InputError(f"--rate {rate}: must be a number of Hz in (0, 2000]")
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
             fell: Callable[[], bool] | None = None, source: str = "") -> dict:
    """The loop on an open ``link`` (``source``: its URL) with the command line's settings;
    the summary. With --record the file is finished after the loop's safe stop, whichever
    way the loop ended, and the summary's ``recording`` says what it holds and dropped."""
    status = StatusLine(args.quiet)
    config = loop_config(args, loop_rate(args, link))
    # made here, its writer thread keeps normal scheduling when this thread asks for SCHED_FIFO
    recorder = open_recorder(args, robot, config, source) if args.record else None
    try:
        loop = LiveLoop(link, robot.body, config, command=command, fell=fell, on_event=status.event,
                        on_status=status, recorder=recorder)
        with (stop_on_signals(loop.request_stop), realtime_priority(args.realtime_priority) as refused,
              switch_interval(RECORD_SWITCH_INTERVAL_S if recorder else None)):
            if refused not in (None, "off"):
                status.event(f"real-time priority {refused}: the loop runs at normal priority")
            summary = loop.run(duration)
    except BaseException as e:
        if recorder is not None:
            recorder.close({"stopped_by": f"error: {type(e).__name__}: {e}"})
        raise
    status.done()
    summary = {**summary, "realtime_priority": args.realtime_priority if refused is None else 0}
    if recorder is not None:
        summary["recording"] = recorder.close(summary)
        if summary["recording"]["dropped_total"] or summary["recording"]["failed"]:
            status.event(f"recording {args.record}: {summary['recording']['dropped_total']} messages dropped "
                         f"(queue full), {summary['recording']['failed']} failed ({summary['recording']['error']})")
    return summary


def finish(summary: dict, args: argparse.Namespace) -> int:
    if args.summary_json:
        write_json(summary, args.summary_json)
    print_summary(summary)
    return 0


# -- run ------------------------------------------------------------------------------------------


def cmd_run(args: argparse.Namespace) -> int:
    check_priority(args.realtime_priority)
    check_record(args)
    robot = load_robot(args.robot, args.robot_config)
    if args.motion and args.scenario:
        raise InputError("give --motion or --scenario, not both")
    scenario = None
    if args.motion:
        scenario = sc.walk(robot.body, args.motion)
    elif args.scenario:
        scenario = make_scenario(args.scenario, robot.body)
    try:
        link = open_link(args.link, robot.body.joint_names, robot.config)
    except LinkError as e:
        print(f"livezmp: error: {e}", file=sys.stderr)
        return 1
    try:
        summary = run_loop(link, robot, args, scenario.goals if scenario else None,
                           duration_of(args, scenario.duration if scenario else None), source=args.link)
    finally:
        link.close()
    return finish(summary, args)


# -- sim ------------------------------------------------------------------------------------------


@dataclass
class SimRobot:
    """A simulated humanoid stepping in real time, and the devices that serve it."""

    humanoid: SimHumanoid
    thread: RealtimeThread | None
    devices: object | None  # sim_devices.launch.SimDevices; None for the in-process mock link
    scenario: sc.Scenario

    def start_scenario(self) -> None:
        """Scenario time 0 is now: schedule its pushes, count the balance from here."""
        now = self.humanoid.t
        for p in self.scenario.pushes:
            self.humanoid.push(Push(p.force, p.height, now + p.start, p.duration))
        c = self.humanoid.counters
        self._since = (c.steps, c.unsupported_steps)

    def fell(self) -> bool:
        return self.humanoid.fallen is not None

    def verdict(self) -> dict:
        """``fell`` (and why), and the share of simulator steps since :meth:`start_scenario`
        whose true ZMP was inside the support polygon."""
        c = self.humanoid.counters
        steps0, unsupported0 = getattr(self, "_since", (0, 0))
        steps = c.steps - steps0
        fall = self.humanoid.fallen
        return {"fell": fall is not None, "fall": None if fall is None else fall.reason,
                "true_inside_fraction": 1.0 - (c.unsupported_steps - unsupported0) / steps if steps else None}

    def close(self) -> None:
        if self.thread is not None:
            self.thread.stop()
        if self.devices is not None:
            self.devices.close()


def start_sim(robot: Robot, kind: str, scenario: sc.Scenario, faults: str = "") -> SimRobot:
    """The humanoid at the scenario's first posture (torque off until a link opens it),
    stepping in real time, behind devices of ``kind`` (a firmware board with its foot
    sensors). For ``mock`` there are no devices and no stepping thread: the in-process
    mock link steps it at each read."""
    if kind not in (*KINDS, "mock"):
        raise InputError(f"--link {kind}: expected one of {', '.join((*KINDS, 'mock'))}")
    if kind == "mock" and faults:
        raise InputError("--fault: the mock link has no devices to inject faults into")
    # the mock link steps the humanoid at each read; behind devices, only its thread does,
    # once per physics step, so no device reply waits for physics
    humanoid = SimHumanoid(robot.body, scenario.goals(0.0), clock=time.monotonic, device_steps=kind == "mock")
    if kind == "mock":
        return SimRobot(humanoid, None, None, scenario)
    thread = RealtimeThread(humanoid, period=humanoid.dt).start()
    try:
        # the firmware board reads the humanoid's foot cells (its true centre of pressure)
        feet = humanoid_sensors(humanoid)[0] if kind == "fw" else None
        devices = start_devices(kind, humanoid, robot.config, joint_names=robot.body.joint_names, faults=faults,
                                foot_sensors=feet)
    except BaseException:
        thread.stop()
        raise
    return SimRobot(humanoid, thread, devices, scenario)


def sim_process_setup() -> None:
    """The simulator's threads (port server, physics) hand the GIL over within 0.1 ms
    rather than 5 ms, so a reply is not held up behind a physics step."""
    sys.setswitchinterval(1e-4)


def cmd_sim(args: argparse.Namespace) -> int:
    check_priority(args.realtime_priority)
    robot = load_robot(args.robot, args.robot_config)
    scenario = make_scenario(args.scenario, robot.body)
    check_faults(args.fault)
    sim_process_setup()
    stop = threading.Event()
    # the devices' threads inherit the priority: they stand in for hardware, which no other
    # program on the computer delays
    with realtime_priority(args.realtime_priority) as refused:
        sim = start_sim(robot, args.link, scenario, args.fault)
        try:
            sim.start_scenario()
            print(json.dumps({"link": args.link, "url": sim.devices.url, "ports": [p.path for p in sim.devices.ports],
                              "robot": str(robot.urdf), "scenario": scenario.name, "faults": args.fault,
                              "realtime_priority": args.realtime_priority if refused is None else 0}), flush=True)
            with stop_on_signals(lambda _name: stop.set()):
                while not stop.wait(0.2):
                    pass
        finally:
            sim.close()
    v = sim.verdict()
    print(f"livezmp sim: stopped; the robot {'fell: ' + v['fall'] if v['fell'] else 'did not fall'}",
          file=sys.stderr, flush=True)
    return 0


FELL_FLAG_EVERY_S = 0.02  # how often a SimProcess's child looks for a fall to flag


def _sim_child(conn, fell_flag, urdf: str | None, config: str | None, kind: str, scenario: tuple[str, dict],
               faults: str, priority: int) -> None:
    """A :class:`SimProcess`'s child: serve the devices, answer requests on ``conn``, set
    ``fell_flag`` (a multiprocessing Event) once the robot has fallen."""
    sim = None
    # the devices stand in for hardware, which no other program delays (refused: normal priority)
    with realtime_priority(priority):
        try:
            sim_process_setup()
            robot = load_robot(urdf, config)
            sim = start_sim(robot, kind, make_scenario(scenario[0], robot.body, **scenario[1]), faults)
            conn.send({"url": sim.devices.url, "ports": [p.path for p in sim.devices.ports]})
            while True:
                if not conn.poll(FELL_FLAG_EVERY_S):
                    if sim.fell():
                        fell_flag.set()
                    continue
                request = conn.recv()
                if request == "start":
                    sim.start_scenario()
                    conn.send(None)
                elif request == "verdict":
                    conn.send({**sim.verdict(), "injected_faults": vars(sim.devices.fault_counters)})
                elif request == "servos":
                    servo = sim.humanoid.servo
                    conn.send({"goal": servo.goal.copy(), "position": servo.position.copy()})
                else:
                    break
        except (InputError, ValueError) as e:
            conn.send({"error": str(e)})
        except (EOFError, KeyboardInterrupt):
            pass
        finally:
            if sim is not None:
                sim.close()


class SimProcess:
    """The simulated humanoid and its devices in a child process — its own core and
    interpreter, as a real robot is another machine — driven over a pipe: ``url`` and
    ``ports`` of its devices; :meth:`start_scenario`, :meth:`fell`, :meth:`verdict`;
    :meth:`vanish` / :meth:`restore` its ports. ``scenario``: (name, keyword arguments);
    ``realtime_priority``: SCHED_FIFO priority of the child's threads (0: normal; if refused,
    normal)."""

    def __init__(self, kind: str, scenario: tuple[str, dict], faults: str = "", urdf: str | None = None,
                 config: str | None = None, start_timeout: float = 60.0, realtime_priority: int = 0):
        ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: no threads or locks inherited
        self._conn, child = ctx.Pipe()
        # the fall is a flag the child raises, so the loop's frequent question costs no round trip
        self._fell = ctx.Event()
        self._proc = ctx.Process(target=_sim_child, args=(child, self._fell, urdf, config, kind, scenario, faults,
                                                             realtime_priority),
                                 name="livezmp-sim", daemon=True)
        self._proc.start()
        child.close()
        try:
            if not self._conn.poll(start_timeout):
                raise LinkError(f"the simulator did not start within {start_timeout:g} s")
            hello = self._conn.recv()
        except (LinkError, EOFError) as e:
            self.close()
            raise LinkError(str(e) or "the simulator process exited before it started (its error is above)") from None
        if "error" in hello:
            self.close()
            raise InputError(hello["error"])
        self.url, self.ports = hello["url"], hello["ports"]

    def _ask(self, request: str):
        self._conn.send(request)
        return self._conn.recv()

    def start_scenario(self) -> None:
        self._ask("start")

    def fell(self) -> bool:
        """Whether the robot fell (seen within FELL_FLAG_EVERY_S of the fall)."""
        return self._fell.is_set()

    def verdict(self) -> dict:
        return self._ask("verdict")

    def servos(self) -> dict:
        return self._ask("servos")

    def close(self) -> None:
        """Stop the child (politely, then by force after 5 s)."""
        with contextlib.suppress(OSError, BrokenPipeError):
            self._conn.send("stop")
        self._proc.join(5.0)
        if self._proc.is_alive():
            self._proc.kill()
            self._proc.join()
        self._conn.close()

    def __enter__(self) -> SimProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# -- demo -----------------------------------------------------------------------------------------


def demo_in_process(robot: Robot, args: argparse.Namespace, scenario: sc.Scenario) -> dict:
    """The mock link: the humanoid stepped by the loop's own reads, in this process."""
    sim = start_sim(robot, "mock", scenario, args.fault)
    feet, _ = humanoid_sensors(sim.humanoid)
    link = MockLink(sim.humanoid, robot.body.joint_names, foot_sensors=feet)
    link.open()
    try:
        sim.start_scenario()
        summary = run_loop(link, robot, args, scenario.goals, duration_of(args, scenario.duration), fell=sim.fell,
                           source="mock:")
    finally:
        link.close()
    return {**summary, **sim.verdict(), "link_url": "mock:"}


def demo_with_devices(robot: Robot, args: argparse.Namespace, scenario: sc.Scenario) -> dict:
    """A real link (dynamixel-sdk, python-can, pyserial) to the simulator in a child process."""
    with SimProcess(args.link, (args.scenario, {}), args.fault,
                    realtime_priority=max(args.realtime_priority - 1, 0)) as sim:
        url = sim.url + (f"&{args.link_options}" if args.link_options else "")
        link = open_link(url, robot.body.joint_names, robot.config)
        try:
            sim.start_scenario()
            summary = run_loop(link, robot, args, scenario.goals, duration_of(args, scenario.duration),
                               fell=sim.fell, source=url)
        finally:
            link.close()
        return {**summary, **sim.verdict(), "link_url": url}


def check_faults(spec: str) -> None:
    """A bad fault spec is a one-line error before anything starts."""
    try:
        parse_faults(spec)
    except ValueError as e:
        raise InputError(f"--fault: {e}") from None


def cmd_demo(args: argparse.Namespace) -> int:
    check_priority(args.realtime_priority)
    check_record(args)
    robot = load_robot(None, None)
    scenario = make_scenario(args.scenario, robot.body)
    check_faults(args.fault)
    try:
        summary = (demo_in_process if args.link == "mock" else demo_with_devices)(robot, args, scenario)
    except LinkError as e:
        print(f"livezmp: error: {e}", file=sys.stderr)
        return 1
    summary["scenario"] = scenario.name
    return finish(summary, args)


# -- parsers --------------------------------------------------------------------------------------


def add_run_commands(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="the live balance loop on a servo link")
    p.add_argument("--robot", required=True, help="URDF of the robot")
    p.add_argument("--robot-config", help="robot config TOML (default: beside the URDF, or built in)")
    p.add_argument("--link", required=True, help="dynamixel:PATH, can:INTERFACE:CHANNEL, fw:URL or mock:")
    p.add_argument("--motion", help="joint-trajectory CSV to play as the command (default: hold the first posture)")
    p.add_argument("--scenario", help=f"built-in scenario as the command ({', '.join(SCENARIOS)})")
    add_loop_options(p)
    p.set_defaults(func=cmd_run)

    p = sub.add_parser("sim", help="simulated humanoid behind simulated devices on ptys, until stopped")
    p.add_argument("--robot", help="URDF of the robot (default: the built-in livezmp_mini)")
    p.add_argument("--robot-config", help="robot config TOML (default: beside the URDF, or built in)")
    p.add_argument("--link", required=True, choices=KINDS, help="which devices to simulate")
    p.add_argument("--scenario", default="stand",
                   help=f"initial posture and pushes ({', '.join(SCENARIOS)}; default stand)")
    p.add_argument("--fault", default="", help="fault spec, e.g. drop=0.01,corrupt=0.01,vanish=3s+1s")
    p.add_argument("--realtime-priority", type=int, default=LOOP_PRIORITY - 1,
                   help=f"run the devices under SCHED_FIFO at this priority, 1-99 (default {LOOP_PRIORITY - 1}, "
                        "just below the loop's; 0 = normal scheduling)")
    p.set_defaults(func=cmd_sim)

    p = sub.add_parser("demo", help="the live loop on the built-in simulated humanoid")
    p.add_argument("--link", default="dynamixel", choices=[*KINDS, "mock"], help="simulated link (default dynamixel)")
    p.add_argument("--link-options", default="", help="extra link URL options, e.g. fast=1&timeout=0.005")
    p.add_argument("--scenario", default="demo", help=f"{', '.join(SCENARIOS)} (default demo: lean, then arm swing)")
    p.add_argument("--fault", default="", help="fault spec for the simulated devices")
    add_loop_options(p)
    p.set_defaults(func=cmd_demo)
