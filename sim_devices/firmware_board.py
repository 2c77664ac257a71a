"""A simulated firmware board: firmware_protocol's `BoardEngine` over a `JointPlant`, served on a pty.

Unmodified pyserial clients (``firmware_protocol.SerialTransport``, the ``fw:`` link) open
:attr:`FirmwareBoard.path`. Joint ``i`` of the plant is the board's joint
``joint_ids[i]`` named ``joint_names[i]`` (names as in HELLO_ACK, 1-16 ASCII characters).

`PlantBackend` is the board hardware: it steps the plant lazily by the elapsed time
(`PlantJoints`, shared by every board or node that drives one plant) whenever a sample or
a command needs it, holds the present position when torque comes on (as servos do),
reports TORQUE_OFF and latched OVERLOAD bits, and reads the optional providers:
``foot_sensors() -> livezmp.links.base.FootSensors`` (per side "left"/"right": four corner
forces N, front-left, front-right, rear-left, rear-right; centre of pressure in the sole
frame, m, or None) and ``imu() -> {"orientation": (w, x, y, z), "angular_velocity": rad/s,
"acceleration": m/s^2 specific force}`` (SPEC.md §1 frames).

Faults (see `faults`): ``drop``/``corrupt``/``delay`` act on each frame the board sends
(corrupt changes one byte of the frame before COBS stuffing, so the framing survives and
the host rejects exactly that frame); ``overload=ID@T`` latches OVERLOAD on joint id ``ID``
and drops its torque for good; ``vanish`` unplugs the port (the board keeps running, its
watchdog holds; frames sent meanwhile are lost, as a USB device's with no host).
`FirmwareBoard.set_faults` swaps the random faults at run time (e.g. ``""`` to heal).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence

import numpy as np

import firmware_protocol as fp
from firmware_protocol.cobs import cobs_decode, cobs_encode
from livezmp.links.base import FootSensors
from sim_devices.faults import FaultCounters, FaultInjector, FaultSpec
from sim_devices.pty_port import PtyDevice, PtyPort, Reply
from sim_devices.servo_plant import JointPlant

SUPPORTED_FAULTS = frozenset({"drop", "corrupt", "delay", "overload", "vanish"})
SIDES = ("left", "right")  # FOOT_SENSORS foot_id 0 and 1
MIN_STEP_RATE = 100.0  # Hz: the engine runs at least this often (watchdog, STATUS) besides its streams
FootProvider = Callable[[], FootSensors]
ImuProvider = Callable[[], dict[str, np.ndarray]]


class PlantJoints:
    """A `JointPlant` stepped lazily to the time of each access, with torque state and latched overloads.

    Share one per plant between the boards or nodes that drive it; all calls from one thread.
    """

    def __init__(self, plant: JointPlant) -> None:
        self.plant = plant
        n = len(plant.position)
        self.torque = np.zeros(n, dtype=bool)
        self.overloaded = np.zeros(n, dtype=bool)
        for i in range(n):
            plant.set_torque(i, False)  # a board powers up with its servos limp
        self._time: float | None = None

    def advance(self, now: float) -> None:
        """Step the plant to monotonic time ``now`` (s)."""
        if self._time is not None and now > self._time:
            self.plant.step(now - self._time)
        if self._time is None or now > self._time:
            self._time = now

    def set_torque(self, index: int, on: bool, now: float) -> None:
        """Torque of joint ``index``; switching on holds the present position; an overloaded joint stays off."""
        self.advance(now)
        on = on and not self.overloaded[index]
        if on and not self.torque[index]:
            self.plant.set_goal(index, float(self.plant.position[index]))
        self.torque[index] = on
        self.plant.set_torque(index, on)

    def overload(self, index: int, now: float) -> None:
        """Latch an overload on joint ``index``: its torque goes off until the simulation ends."""
        self.overloaded[index] = True
        self.set_torque(index, False, now)


class PlantBackend:
    """The `BoardBackend` of a board (or CAN node) whose joint ``joint_ids[k]`` is plant joint ``indices[k]``."""

    def __init__(self, joints: PlantJoints, indices: Sequence[int], joint_ids: Sequence[int], *,
                 foot_sensors: FootProvider | None = None, imu: ImuProvider | None = None,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.joints = joints
        self.indices = np.asarray(indices, dtype=int)
        self.joint_ids = tuple(joint_ids)
        self._index_of = dict(zip(self.joint_ids, self.indices.tolist(), strict=True))
        self._feet = foot_sensors
        self._imu = imu
        self._clock = clock

    @property
    def capabilities(self) -> fp.Capability:
        caps = fp.Capability.JOINT_CURRENT
        if self._feet is not None:
            caps |= fp.Capability.FOOT_SENSORS
        if self._imu is not None:
            caps |= fp.Capability.IMU
        return caps

    def overload(self, joint_id: int) -> bool:
        """Latch an overload on ``joint_id`` if it is one of ours; True if it was."""
        index = self._index_of.get(joint_id)
        if index is not None:
            self.joints.overload(index, self._clock())
        return index is not None

    def joint_state(self, board_time_us: int) -> fp.JointState:
        joints = self.joints
        joints.advance(self._clock())
        plant, idx = joints.plant, self.indices
        error = np.where(joints.torque[idx], 0, int(fp.JointError.TORQUE_OFF))
        error |= np.where(joints.overloaded[idx], int(fp.JointError.OVERLOAD), 0)
        return fp.JointState(board_time_us, self.joint_ids, tuple(plant.position[idx].tolist()),
                             tuple(plant.velocity[idx].tolist()), tuple(plant.current[idx].tolist()),
                             tuple(error.tolist()))

    def foot_sensors(self, board_time_us: int) -> fp.FootSensors | None:
        if self._feet is None:
            return None
        feet = self._feet()
        sides = [(k, side) for k, side in enumerate(SIDES) if side in feet.forces]
        cops = [feet.cop.get(side) for _, side in sides]
        return fp.FootSensors(board_time_us, tuple(k for k, _ in sides),
                              tuple(tuple(float(f) for f in feet.forces[side]) for _, side in sides),
                              tuple(0.0 if c is None else float(c[0]) for c in cops),
                              tuple(0.0 if c is None else float(c[1]) for c in cops))

    def imu(self, board_time_us: int) -> fp.Imu | None:
        if self._imu is None:
            return None
        reading = self._imu()
        return fp.Imu(board_time_us, tuple(float(v) for v in reading["orientation"]),
                      tuple(float(v) for v in reading["angular_velocity"]),
                      tuple(float(v) for v in reading["acceleration"]))

    def supply_voltage(self) -> float:
        return 12.0

    def set_goals(self, ids: Sequence[int], positions: Sequence[float]) -> None:
        joints = self.joints
        joints.advance(self._clock())
        for joint_id, position in zip(ids, positions, strict=True):
            joints.plant.set_goal(self._index_of[joint_id], position)

    def set_torque(self, ids: Sequence[int], enable: Sequence[bool]) -> None:
        now = self._clock()
        for joint_id, on in zip(ids, enable, strict=True):
            self.joints.set_torque(self._index_of[joint_id], on, now)

    def hold(self) -> None:
        joints = self.joints
        joints.advance(self._clock())
        for index in self.indices.tolist():
            joints.plant.set_goal(index, float(joints.plant.position[index]))

    def drop_torque(self) -> None:
        now = self._clock()
        for index in self.indices.tolist():
            self.joints.set_torque(index, False, now)


def step_period(rates: fp.StreamRates) -> float:
    """How often (s) a board engine with these stream rates needs stepping."""
    fastest = max(rates.joint_state_hz, rates.foot_sensors_hz, rates.imu_hz, rates.heartbeat_hz, MIN_STEP_RATE)
    return 1.0 / fastest


class _Wire:
    """The board's end of the serial line, as the pyserial-like port `SerialTransport` expects."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.timeout = 0.0
        self.inbox = bytearray()
        self.outbox: list[bytes] = []

    @property
    def in_waiting(self) -> int:
        return len(self.inbox)

    def read(self, size: int = 1) -> bytes:
        data = bytes(self.inbox[:size])
        del self.inbox[:size]
        return data

    def write(self, data: bytes) -> int:
        self.outbox.append(bytes(data))
        return len(data)

    def close(self) -> None:
        """Nothing to release."""


class FirmwareBoard(PtyDevice):
    """A board driving ``plant``'s joints, at :attr:`path` (see module docstring).

    ``joint_ids`` default to 1..n. ``status_period`` (s) and ``max_rate_hz`` go to the
    `BoardEngine`. Bad arguments raise ValueError naming them.
    """

    def __init__(self, plant: JointPlant, joint_names: Sequence[str], joint_ids: Sequence[int] | None = None, *,
                 foot_sensors: FootProvider | None = None, imu: ImuProvider | None = None,
                 faults: str | FaultSpec = "", status_period: float = 1.0, max_rate_hz: int = 1000,
                 device_id: int = 1, name: str = "ttyFW") -> None:
        ids = list(range(1, len(joint_names) + 1)) if joint_ids is None else list(joint_ids)
        if len(ids) != len(joint_names) or len(set(ids)) != len(ids) or not all(0 <= i <= 255 for i in ids):
            raise ValueError(f"FirmwareBoard: need one distinct joint id in 0..255 per joint name, got {ids}")
        if len(plant.position) < len(ids):
            raise ValueError(f"FirmwareBoard: plant has {len(plant.position)} joints for {len(ids)} names")
        self._faults = FaultInjector(faults, supported=SUPPORTED_FAULTS, device="firmware board")
        self._check_overloads(self._faults.spec, ids)
        self._lock = threading.Lock()
        self.backend = PlantBackend(PlantJoints(plant), range(len(ids)), ids, foot_sensors=foot_sensors, imu=imu)
        self._wire = _Wire(name)
        self.engine = fp.BoardEngine(fp.SerialTransport(self._wire, role="board"), self.backend, joint_ids=ids,
                                     joint_names=list(joint_names), device_id=device_id,
                                     capabilities=self.backend.capabilities, status_period=status_period,
                                     max_rate_hz=max_rate_hz)
        self._wire.outbox.clear()  # the transport's opening delimiter: nobody is listening yet
        self._next_step = -math.inf
        self._faults.start(time.monotonic())
        self._port: PtyPort | None = None
        self._port = PtyPort(self, name)  # last: its thread calls back into this object (even before this returns)

    # -- public API -------------------------------------------------------------------------------

    def set_faults(self, faults: str | FaultSpec) -> FaultCounters:
        """Inject ``faults`` from now on (timed events counted from now; the old spec's pending ones are
        dropped, and a vanished port comes back); returns the previous injector's counters, final from here on."""
        injector = FaultInjector(faults, supported=SUPPORTED_FAULTS, device="firmware board")
        self._check_overloads(injector.spec, self.backend.joint_ids)
        with self._lock:
            injector.start(time.monotonic())
            old, self._faults = self._faults, injector
        self._port.restore()  # outside our lock: the port thread holds the port's lock when it calls us
        return old.counters

    # -- ByteDevice -------------------------------------------------------------------------------

    def on_bytes(self, data: bytes, now: float) -> list[Reply]:
        with self._lock:
            self._wire.inbox += data
            return self._step(now)

    def poll(self, now: float) -> list[Reply]:
        with self._lock:
            for event in self._faults.due_events(now):
                if event.kind == "overload":
                    self.backend.overload(event.arg)
                elif event.kind == "vanish":
                    self._port.vanish()
                    self._wire.inbox.clear()
                elif event.kind == "restore":
                    self._port.restore()
            if now < self._next_step:
                return []
            return self._step(now)

    def next_deadline(self) -> float:
        with self._lock:
            return min(self._next_step, self._faults.next_event_time())

    # -- internals --------------------------------------------------------------------------------

    @staticmethod
    def _check_overloads(spec: FaultSpec, ids: Sequence[int]) -> None:
        missing = sorted({joint for joint, _ in spec.overloads} - set(ids))
        if missing:
            raise ValueError(f"fault spec field 'overload': no joint with id {missing[0]} on this board")

    def _step(self, now: float) -> list[Reply]:
        self.engine.step(0.0)
        self._next_step = now + step_period(self.engine.rates)
        frames, self._wire.outbox = self._wire.outbox, []
        if self._port is None or not self._port.present:
            return []  # nobody on the line: what the board sends is lost, not a fault
        replies = []
        for frame in frames:
            dropped, corrupt, delay = self._faults.reply_fate()
            if dropped:
                continue
            if corrupt and len(frame) > 1:
                raw = cobs_decode(frame[:-1])
                frame = cobs_encode(self._faults.corrupt(raw, 0, len(raw))) + b"\0"
            replies.append((now + delay, frame))
        return replies
