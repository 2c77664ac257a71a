"""Simulated "MIT mode" CAN motors (`livezmp.links.mit_protocol`), one per joint, on one or more CAN buses.

Each `MitMotorNode` answers every frame on its standard id with one 6-byte state frame on
the master's id (0), as B. Katz's Mini Cheetah firmware does from its CAN receive
interrupt (here with no processing delay: the reply follows the command on the wire):
enter / exit motor mode switch its joint's torque on / off, a command in motor mode sets
its joint's goal position (gains Kp = Kd = 0: limp; otherwise the plant's own position
servo tracks the goal: the gains are not modelled), set-zero is refused (the robot
config's zero is the motor's). A motor's angle is ``zero * 2 pi / ticks_per_rev +
direction * joint angle`` (the robot config's `ServoConfig`, as on a Dynamixel).

`MitMotorBuses` splits the joints in order over ``buses`` CAN buses served by one
simulated socketcand daemon (`socketcand_server`, bus ``can0``, ``can1``...), each frame
taking its wire time at ``bitrate``; :attr:`url` is the ``can:`` link URL that opens them.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence

import numpy as np

from livezmp.links import mit_protocol as mit
from livezmp.model.robot_config import ServoConfig
from sim_devices.can_node import CanFrame
from sim_devices.firmware_board import PlantJoints
from sim_devices.servo_plant import JointPlant
from sim_devices.socketcand_server import SocketcandServer


class MitMotorNode:
    """The motor on CAN id ``servo.id`` driving plant joint ``index`` of ``joints`` (a `CanNode`);
    ``lock`` is shared by every node of the plant, ``clock`` gives monotonic time (s)."""

    def __init__(self, joints: PlantJoints, index: int, servo: ServoConfig, lock: threading.Lock,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.id = servo.id
        self.index = index
        self.joints = joints
        self._offset = servo.zero * 2.0 * math.pi / servo.ticks_per_rev
        self._direction = servo.direction
        self._lock = lock
        self._clock = clock
        self.commands = 0

    def on_frame(self, frame: CanFrame) -> list[CanFrame]:
        if frame.arbitration_id != self.id or frame.is_extended or frame.is_remote \
                or len(frame.data) != mit.COMMAND_BYTES:
            return []
        with self._lock:
            now = self._clock()
            self.joints.advance(now)
            if frame.data == mit.ENTER_MOTOR_MODE:
                self.joints.set_torque(self.index, True, now)
            elif frame.data == mit.EXIT_MOTOR_MODE:
                self.joints.set_torque(self.index, False, now)
            elif frame.data != mit.SET_ZERO:
                self._command(frame.data, now)
            plant = self.joints.plant
            p = self._offset + self._direction * float(plant.position[self.index])
            v = self._direction * float(plant.velocity[self.index])
            reply = mit.pack_reply(self.id, p, v, 0.0)
        return [CanFrame(mit.MASTER_ID, reply)]

    def _command(self, data: bytes, now: float) -> None:
        self.commands += 1
        p, _, kp, kd, _ = mit.unpack_command(data)
        if kp == 0.0 and kd == 0.0:  # limp: the firmware's motor mode with zero gains
            if self.joints.torque[self.index]:
                self.joints.plant.set_torque(self.index, False)
            return
        if self.joints.torque[self.index] and not self.joints.overloaded[self.index]:
            self.joints.plant.set_torque(self.index, True)
            self.joints.plant.set_goal(self.index, self._direction * (p - self._offset))

    def tick(self, now: float) -> list[CanFrame]:
        return []


def split_joints(n: int, buses: int) -> list[np.ndarray]:
    """Joint indices 0..n-1 in order over ``buses`` buses (as even as can be); ValueError if a bus would be empty."""
    if not 1 <= buses <= n:
        raise ValueError(f"buses {buses}: must be 1..{n} (one motor at least on each)")
    return np.array_split(np.arange(n), buses)


class MitMotorBuses:
    """MIT-mode motors for ``plant``'s joints (motor ``servos[i]`` drives joint ``i``) over ``buses``
    CAN buses at ``bitrate`` behind a simulated socketcand daemon on loopback (see module docstring)."""

    def __init__(self, plant: JointPlant, servos: Sequence[ServoConfig], *, buses: int = 1,
                 bitrate: int = 1_000_000) -> None:
        ids = [s.id for s in servos]
        if len(set(ids)) != len(ids) or not all(1 <= i <= 255 for i in ids):
            raise ValueError(f"MIT motors: need distinct CAN ids in 1..255, got {ids}")
        if len(plant.position) < len(servos):
            raise ValueError(f"MIT motors: the plant has {len(plant.position)} joints for {len(servos)} motors")
        self.lock = threading.Lock()
        self.joints = PlantJoints(plant)
        self.nodes = [MitMotorNode(self.joints, i, s, self.lock) for i, s in enumerate(servos)]
        channels = {f"can{k}": [self.nodes[i] for i in part] for k, part in enumerate(split_joints(len(servos), buses))}
        self.server = SocketcandServer(bitrate=bitrate, channels=channels)
        self.fault_counters = self.server.fault_counters

    @property
    def url(self) -> str:
        """The link URL: ``can:socketcand:can0+can1...?protocol=mit&bitrate=...&host=...&port=...``."""
        return (f"can:socketcand:{'+'.join(self.server.channels)}?protocol=mit&bitrate={self.server.bitrate}&"
                f"{self.server.url_options}")

    def close(self) -> None:
        self.server.close()

    def __enter__(self) -> MitMotorBuses:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
