"""A simulated humanoid behind its simulated devices, in this process or in a child process.

:func:`start_sim` starts the humanoid stepping in real time behind devices of one link
kind (``livezmp sim``, the in-process ``mock`` demo); :class:`SimProcess` runs the same in
a child process — its own core and interpreter, as a real robot is another machine — for
``livezmp demo``, the tests and the benchmarks. Either way the humanoid's physics steps in a
process of its own (:mod:`sim_devices.physics_process`), beside its devices.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import sys
import time
import warnings
from dataclasses import dataclass, replace

from livezmp.errors import InputError
from livezmp.links import LinkError
from livezmp.links.bus_timing import DEFAULT_ADAPTER, parse_adapter
from livezmp.live import scenarios as sc
from livezmp.live.realtime import realtime_priority
from livezmp.live.scenarios import make_scenario
from livezmp.model.robot import Robot, load_robot
from sim_devices.faults import parse_faults
from sim_devices.humanoid import RealtimeThread, SimHumanoid
from sim_devices.launch import KINDS, humanoid_imu, humanoid_sensors, start_devices
from sim_devices.physics_process import PhysicsProcess, RemoteHumanoid


@dataclass
class SimRobot:
    """A simulated humanoid stepping in real time, and the devices that serve it. ``humanoid``: the
    `SimHumanoid` itself (mock link) or its face in this process (`RemoteHumanoid`) while a
    `PhysicsProcess` steps it."""

    humanoid: SimHumanoid | RemoteHumanoid
    physics: PhysicsProcess | RealtimeThread | None
    devices: object | None  # sim_devices.launch.SimDevices; None for the in-process mock link
    scenario: sc.Scenario

    def start_scenario(self) -> None:
        """Scenario time 0 is now: schedule its pushes, count the balance from here."""
        now = self.humanoid.t
        for p in self.scenario.pushes:
            self.humanoid.push(replace(p, start=now + p.start))
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
        try:
            if self.devices is not None:
                self.devices.close()
        finally:
            if isinstance(self.physics, RealtimeThread):
                self.physics.stop()
            elif self.physics is not None:
                self.physics.close()


def start_sim(robot: Robot, kind: str, scenario: sc.Scenario, faults: str = "", physics: str = "process",
              **devices) -> SimRobot:
    """The humanoid at the scenario's first posture (torque off until a link opens it),
    stepping in real time, behind devices of ``kind`` (a firmware board with its foot
    sensors). For ``mock`` there are no devices and no stepping thread: the in-process
    mock link steps it at each read. Behind devices, it steps in a `PhysicsProcess` of its own, so no
    device's reply waits for a physics step (``physics="thread"``: in a `RealtimeThread` of this process
    instead, sharing its GIL with the devices, the benchmarks' baseline). ``devices``: `start_devices`
    options (baud, adapter, buses, can_transport)."""
    if kind not in (*KINDS, "mock"):
        raise InputError(f"--link {kind}: expected one of {', '.join((*KINDS, 'mock'))}")
    if kind == "mock" and faults:
        raise InputError("--fault: the mock link has no devices to inject faults into")
    # the mock link steps the humanoid at each read; behind devices, only its physics process does
    humanoid = SimHumanoid(robot.body, scenario.goals(0.0), clock=time.monotonic, device_steps=kind == "mock",
                           slope=scenario.slope, edge=scenario.edge)
    if kind == "mock":
        return SimRobot(humanoid, None, None, scenario)
    # the firmware board reads the humanoid's foot cells (its true centre of pressure) and its IMU (the CAN
    # nodes do not: on slcan their frames would crowd a bus python-can already reads slowly); so does the
    # robot's IMU sub-controller on a Dynamixel bus
    sensors = kind == "fw" or (kind == "dynamixel" and robot.config.imu is not None)
    if physics == "thread":
        stepper, remote = RealtimeThread(humanoid, period=humanoid.dt).start(), humanoid
    elif physics == "process":
        stepper = PhysicsProcess(humanoid, sensors=sensors)  # before the devices: forked without their threads
        remote = stepper.humanoid
    else:
        raise InputError(f"physics '{physics}': expected process or thread")
    try:
        feet, imu = humanoid_sensors(remote) if kind == "fw" else (None, None)
        if kind == "dynamixel" and sensors:
            imu = humanoid_imu(remote)
        devices = start_devices(kind, remote, robot.config, joint_names=robot.body.joint_names, faults=faults,
                                foot_sensors=feet, imu=imu, **devices)
    except BaseException:
        SimRobot(remote, stepper, None, scenario).close()
        raise
    return SimRobot(remote, stepper, devices, scenario)


def sim_process_setup() -> None:
    """The simulator's threads (port servers; the physics too when it is a thread) hand the GIL
    over within 0.1 ms rather than 5 ms, so a reply is not held up behind another thread."""
    sys.setswitchinterval(1e-4)


def check_faults(spec: str) -> None:
    """A bad fault spec is a one-line error before anything starts."""
    try:
        parse_faults(spec)
    except ValueError as e:
        raise InputError(f"--fault: {e}") from None


def device_options(args: argparse.Namespace) -> dict:
    """--baud, --adapter, --buses and --can-protocol as `start_devices` options (defaults left out); InputError
    on a bad one, before anything starts."""
    options = {}
    mit = getattr(args, "can_protocol", "firmware") == "mit"
    if mit:
        if args.link != "can":
            raise InputError("--can-protocol: only the can link has a protocol to choose")
        options |= {"can_protocol": "mit", "can_transport": "socketcand"}
    if args.baud is not None:
        if args.baud <= 0:
            raise InputError(f"--baud {args.baud}: must be a positive number of bit/s")
        options["baud"] = args.baud
    if args.adapter != DEFAULT_ADAPTER:
        try:
            parse_adapter(args.adapter)
        except ValueError as e:
            raise InputError(f"--adapter: {e}") from None
        options["adapter"] = args.adapter
    if args.buses != 1:
        if args.link != "dynamixel" and not mit:
            raise InputError("--buses: only the dynamixel link and MIT-mode CAN motors have several buses")
        options["buses"] = args.buses
    return options



FELL_FLAG_EVERY_S = 0.02  # how often a SimProcess's child looks for a fall to flag


def beside_loop(loop_cpus: frozenset[int] | None = None) -> frozenset[int] | None:
    """Where a simulator serving a live loop runs (`SimProcess`'s ``cpus``): the last CPU this process may use
    that the loop is not pinned to (``loop_cpus``; None: not pinned), as ``bench_live_loop.py`` places it (see
    `SimProcess`); None (anywhere) with a single CPU or none left over."""
    allowed = os.sched_getaffinity(0)
    free = sorted(allowed - (loop_cpus or frozenset()))
    return frozenset(free[-1:]) if len(allowed) > 1 and free else None


def _sim_child(conn, fell_flag, urdf: str | None, config: str | None, kind: str, scenario: tuple[str, dict],
               faults: str, priority: int, devices: dict, physics: str, cpus: frozenset[int] | None = None) -> None:
    """A :class:`SimProcess`'s child: serve the devices, answer requests on ``conn``, set
    ``fell_flag`` (a multiprocessing Event) once the robot has fallen."""
    sim = None
    # the devices stand in for hardware, which no other program delays (refused: normal priority); their threads
    # and the physics process, started inside, keep these CPUs
    with realtime_priority(priority, cpus):
        try:
            sim_process_setup()
            with warnings.catch_warnings():  # the command loaded the same robot and told its warnings once
                warnings.simplefilter("ignore", UserWarning)
                robot = load_robot(urdf, config)
            sim = start_sim(robot, kind, make_scenario(scenario[0], robot.body, **scenario[1]), faults, physics,
                            **devices)
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
                    conn.send({"goal": sim.humanoid.goal.copy(), "position": sim.humanoid.position.copy()})
                else:
                    break
        except (InputError, ValueError) as e:
            conn.send({"error": str(e)})
        except (EOFError, KeyboardInterrupt):
            pass
        finally:
            if sim is not None:
                sim.close()


def _cpu_seconds(pid: int) -> float:
    """CPU time (user + system, s) process ``pid`` has used, all its threads (OSError if it is gone)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # utime, stime (clock ticks)


class SimProcess:
    """The simulated humanoid and its devices in a child process — its own core and
    interpreter, as a real robot is another machine — driven over a pipe: ``url`` and
    ``ports`` of its devices; :meth:`start_scenario`, :meth:`fell`, :meth:`verdict`;
    :meth:`vanish` / :meth:`restore` its ports. ``scenario``: (name, keyword arguments);
    ``realtime_priority``: SCHED_FIFO priority of the child's threads (0: normal; if refused,
    normal); ``devices``: `start_devices` options (baud, adapter, buses, can_transport); ``physics``: as
    `start_sim`'s; ``cpus``: the CPUs the simulator (devices and physics) runs on (None: any).

    Placement: with the simulator on a CPU of its own and the loop on the others, the kernel worker that
    carries a pty's bytes finds a CPU free of the physics (normal priority, a 0.2-0.5 ms step the worker
    waited behind). Measured on 2 CPUs with the loop's pty pause and awake CPUs, load 0.6-0.9, two
    alternated pairs: OP3 at 2 Mbps (hs) 1.1-1.7 % missed -> 0.4-1.0 %; two 4 Mbps buses at 1 kHz
    21-27 % -> 8-13 %."""

    def __init__(self, kind: str, scenario: tuple[str, dict], faults: str = "", urdf: str | None = None,
                 config: str | None = None, start_timeout: float = 60.0, realtime_priority: int = 0,
                 devices: dict | None = None, physics: str = "process", cpus: frozenset[int] | None = None):
        ctx = multiprocessing.get_context("spawn")  # a fresh interpreter: no threads or locks inherited
        self._conn, child = ctx.Pipe()
        # the fall is a flag the child raises, so the loop's frequent question costs no round trip
        self._fell = ctx.Event()
        self._proc = ctx.Process(target=_sim_child, args=(child, self._fell, urdf, config, kind, scenario, faults,
                                                             realtime_priority, devices or {}, physics, cpus),
                                 name="livezmp-sim", daemon=True)
        self._proc.start()
        try:
            child.close()
            if not self._conn.poll(start_timeout):
                raise LinkError(f"the simulator did not start within {start_timeout:g} s")
            hello = self._conn.recv()
        except (LinkError, EOFError) as e:
            self.close()
            raise LinkError(str(e) or "the simulator process exited before it started (its error is above)") from None
        except BaseException:  # a signal while it starts (livezmp.commands.startup.Interrupted): the child stopped too
            self.close()
            raise
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

    def cpus(self) -> frozenset[int]:
        """The CPUs the child process may run on (OSError if it is gone)."""
        return frozenset(os.sched_getaffinity(self._proc.pid))

    def cpu_seconds(self) -> tuple[float, float] | None:
        """CPU time (user + system, s) used so far by the child process (all its threads: the devices) and
        by its children (the physics process); None where /proc cannot tell (not Linux, or the child is gone)."""
        try:
            devices = _cpu_seconds(self._proc.pid)
            with open(f"/proc/{self._proc.pid}/task/{self._proc.pid}/children") as f:
                physics = sum(_cpu_seconds(int(pid)) for pid in f.read().split())
        except OSError:
            return None
        return devices, physics

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


