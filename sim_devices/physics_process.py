"""The simulated humanoid's physics in a process of its own, its joint state in shared memory.

Why: a bus's port service and a 1 kHz physics step in one interpreter take turns on the
GIL, so a reply due while a step runs leaves late (on a loaded 2-CPU machine, normal scheduling, a
Fast Sync Read's handling took 0.38 ms at the median and 1.3 ms at the 90th percentile with the
physics thread beside it, 0.26 / 0.33 ms without; the step itself costs about 0.2 ms of CPU). Here the
physics runs in a forked child; the devices' process only reads and writes arrays.

`PhysicsProcess(humanoid, sensors)` forks a child that steps ``humanoid`` to the monotonic
clock (shared by every process) every ``humanoid.dt`` and, after each step, publishes its
joints' position (rad), velocity (rad/s) and current (A), its balance counters and whether it
fell, and, with ``sensors``, its IMU reading and foot cells; at the start of each step it takes
the goals (rad) and torque switches the devices wrote. :attr:`PhysicsProcess.humanoid` is the
devices' face of it: a `JointPlant` (``position``, ``velocity``, ``current`` are views of the
shared arrays) with the `SimHumanoid` readings the simulator's devices and `SimRobot` use.

A device reading all joints may see some at one step and some at the next (no lock between
the processes): as a real bus's servos sample their encoders each on its own clock.
"""

from __future__ import annotations

import contextlib
import math
import mmap
import multiprocessing
import os
import select
import signal
import threading
import time

import numpy as np

from livezmp.errors import InputError
from livezmp.live.scenarios import Push
from sim_devices.humanoid import BalanceCounters, FallEvent, FootForces, ImuReading, SimHumanoid

# status slots: simulated time (s), balance counters (steps, unsupported, worst margin), fell (0/1)
_STATUS = 5
_IMU = 11  # t, quaternion (x, y, z, w), angular velocity (3), specific force (3)


class _Layout:
    """Where each array lies in the shared block (float64 slots)."""

    def __init__(self, n_joints: int, n_cells: tuple[int, int]):
        sizes = {"position": n_joints, "velocity": n_joints, "current": n_joints, "goal": n_joints,
                 "torque": n_joints, "status": _STATUS, "imu": _IMU, "left": n_cells[0], "right": n_cells[1],
                 "cop": 3}  # cop: x, y, has one (0/1)
        self.slices, start = {}, 0
        for name, size in sizes.items():
            self.slices[name] = slice(start, start + size)
            start += size
        self.size = start

    def views(self, buffer) -> dict[str, np.ndarray]:
        whole = np.ndarray((self.size,), dtype=np.float64, buffer=buffer)
        return {name: whole[s] for name, s in self.slices.items()}


def _cells(humanoid: SimHumanoid) -> tuple[int, int]:
    feet = humanoid.body.feet
    return tuple(0 if feet[s].sole_local is None else len(feet[s].sole_local) for s in ("left", "right"))


class RemoteHumanoid:
    """A `SimHumanoid` stepping in a `PhysicsProcess`, seen from the devices' process."""

    def __init__(self, humanoid: SimHumanoid, arrays: dict[str, np.ndarray], ask):
        self.body = humanoid.body
        self.dt = humanoid.dt
        self._a = arrays
        self._ask = ask
        self._fallen: FallEvent | None = None
        self.position, self.velocity, self.current = arrays["position"], arrays["velocity"], arrays["current"]

    # -- JointPlant ---------------------------------------------------------------------------

    def set_goal(self, idx: int, position: float) -> None:
        """Set joint ``idx``'s goal (rad), taken at the next physics step."""
        if not math.isfinite(position):
            raise InputError(f"SimHumanoid.set_goal: joint {idx} ({self.body.joint_names[idx]}): goal {position!r} "
                             "is not a finite angle")
        self._a["goal"][idx] = position

    def set_torque(self, idx: int, on: bool) -> None:
        """Switch joint ``idx``'s torque at the next physics step."""
        self._a["torque"][idx] = 1.0 if on else 0.0

    def step(self, dt: float) -> None:
        """Nothing: the physics process keeps the humanoid current."""

    # -- readings -----------------------------------------------------------------------------

    @property
    def goal(self) -> np.ndarray:
        """The commanded goals (rad)."""
        return self._a["goal"]

    @property
    def t(self) -> float:
        """Simulated time of the published joint state (s)."""
        return float(self._a["status"][0])

    @property
    def counters(self) -> BalanceCounters:
        s = self._a["status"]
        return BalanceCounters(int(s[1]), int(s[2]), float(s[3]))

    @property
    def fallen(self) -> FallEvent | None:
        if self._fallen is None and self._a["status"][4]:
            self._fallen = self._ask("fallen")
        return self._fallen

    def push(self, push: Push) -> None:
        """Schedule a push (its ``start`` is simulated time, s)."""
        self._ask("push", push)

    def imu(self) -> ImuReading:
        """The IMU reading of the latest step (the process was started with sensors)."""
        v = self._a["imu"].copy()
        return ImuReading(float(v[0]), v[1:5], v[5:8], v[8:11])

    def foot_forces(self) -> FootForces:
        """The foot cells of the latest step (the process was started with sensors)."""
        left, right, cop = self._a["left"].copy(), self._a["right"].copy(), self._a["cop"].copy()
        return FootForces(left, right, cop[:2] if cop[2] else None, float(left.sum() + right.sum()))


class PhysicsProcess:
    """Step ``humanoid`` (with a ``clock``, not device-stepped) in a forked child (see the module
    docstring); ``sensors``: publish its IMU and foot cells each step. :meth:`close` stops it."""

    def __init__(self, humanoid: SimHumanoid, sensors: bool = False, start_timeout: float = 30.0):
        if humanoid.clock is None or humanoid.device_steps:
            raise InputError("PhysicsProcess: the humanoid needs a clock and device_steps=False")
        layout = _Layout(len(humanoid.position), _cells(humanoid))
        # anonymous shared memory, mapped in the forked child as here; freed with the last view of it
        arrays = layout.views(mmap.mmap(-1, 8 * layout.size))
        arrays["goal"][:] = humanoid.goal
        arrays["torque"][:] = humanoid.servo.torque_on
        _publish(humanoid, arrays, sensors)
        # forked (os.fork: a simulator process is itself a daemonic child, which multiprocessing does not let
        # have children): the child has the humanoid as it is, without loading the robot again; the caller has
        # no other threads yet (start_sim makes this before its devices)
        self._conn, child = multiprocessing.Pipe()
        self._lock = threading.Lock()
        self.pid = os.fork()
        if self.pid == 0:  # the child: never returns
            code = 1
            try:
                self._conn.close()
                _physics_child(humanoid, arrays, child, sensors)
                code = 0
            finally:
                os._exit(code)
        child.close()
        if not self._conn.poll(start_timeout):
            self.close()
            raise RuntimeError("the physics process did not start")
        self._conn.recv()
        self.humanoid = RemoteHumanoid(humanoid, arrays, self._ask)

    def _ask(self, request: str, argument=None):
        with self._lock:
            self._conn.send((request, argument))
            answer = self._conn.recv()
        if isinstance(answer, BaseException):
            raise answer
        return answer

    def close(self) -> None:
        """Stop the child (an error it met is raised here)."""
        error = None
        with contextlib.suppress(OSError, EOFError):
            error, fallen = self._ask("stop")
            # the fall as the child last saw it: a verdict asked after the close (`livezmp sim`'s closing line)
            # has no pipe to ask it through
            if hasattr(self, "humanoid"):
                self.humanoid._fallen = fallen
        deadline = time.monotonic() + 5.0
        while os.waitpid(self.pid, os.WNOHANG) == (0, 0):
            if time.monotonic() > deadline:
                os.kill(self.pid, signal.SIGKILL)
                os.waitpid(self.pid, 0)
                break
            time.sleep(0.01)
        self._conn.close()
        if isinstance(error, BaseException):
            raise error


def _publish(humanoid: SimHumanoid, a: dict[str, np.ndarray], sensors: bool) -> None:
    """The humanoid's state after a step into the shared arrays."""
    a["position"][:] = humanoid.position
    a["velocity"][:] = humanoid.velocity
    a["current"][:] = humanoid.current
    c = humanoid.counters
    a["status"][:] = (humanoid.t, c.steps, c.unsupported_steps, c.worst_margin, humanoid.fallen is not None)
    if sensors:
        r = humanoid.imu()
        a["imu"][:] = (r.t, *r.quaternion, *r.angular_velocity, *r.specific_force)
        f = humanoid.foot_forces()
        a["left"][:], a["right"][:] = f.left, f.right
        a["cop"][:] = (0.0, 0.0, 0.0) if f.cop is None else (*f.cop, 1.0)


def _take_inputs(humanoid: SimHumanoid, a: dict[str, np.ndarray]) -> None:
    """The goals and torque switches the devices wrote."""
    humanoid.set_goals(a["goal"].copy())
    on = a["torque"] > 0.5
    # seldom (at open and close): the switches compared as bytes (a bool array's are 0 or 1), cheaper than a
    # comparison and its reduction; np.flatnonzero's wrapper is not paid every step
    if on.tobytes() != humanoid.servo.torque_on.tobytes():
        for idx in np.flatnonzero(on != humanoid.servo.torque_on):
            humanoid.set_torque(int(idx), bool(on[idx]))


def _physics_child(humanoid: SimHumanoid, a: dict[str, np.ndarray], conn, sensors: bool) -> None:
    """The physics loop; ``a``: the shared arrays, mapped in this forked child as in its parent."""
    # its parent ends it (stop, or the pipe's end when the parent dies): a Ctrl-C is the parent's to handle
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # normal scheduling even under a real-time simulator: a pty's bytes reach the devices through a kernel
    # worker of normal priority, which a real-time physics step would hold off (measured: the instruction's
    # pickup 81 us after the write at the median with the physics at SCHED_FIFO, 44-66 us with it at normal
    # priority, a loaded 2-CPU machine)
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    conn.send("ready")
    # a request, or the pipe's end, wakes the wait between steps: a poll object made once (Connection.poll makes a
    # selector each call, about 20 us of the step's CPU), its timeout in whole ms rounded up as Connection.poll's
    asked = select.poll()
    asked.register(conn.fileno(), select.POLLIN)
    error: BaseException | None = None
    due = time.monotonic()
    try:
        while True:
            if error is None:
                try:
                    _take_inputs(humanoid, a)
                    humanoid.sync()
                    _publish(humanoid, a, sensors)
                except Exception as e:  # handed to close()
                    error = e
            due = max(due + humanoid.dt, time.monotonic() - humanoid.dt)  # no burst after a stall
            if not asked.poll(math.ceil(max(0.0, due - time.monotonic()) * 1e3)):
                continue
            request, argument = conn.recv()
            if request == "stop":
                conn.send((error, humanoid.fallen))
                return
            if request == "push":
                humanoid.push(argument)
                conn.send(None)
            elif request == "fallen":
                conn.send(humanoid.fallen)
    except EOFError:
        pass
