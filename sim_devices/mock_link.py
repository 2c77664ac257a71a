"""In-process link: a `JointPlant` driven directly, no bus, no faults — for fast loop tests.

    mock:

Registered as the ``mock:`` link URL through the ``livezmp.links`` entry points
(:data:`BACKEND`). ``open_link("mock:", ...)`` makes a `ServoPlant` at rest at 0 rad; build a `MockLink`
yourself to drive another plant (e.g. a simulated humanoid) or to step it on a clock of
your own (e.g. a fixed step per read, for loop tests that must not depend on wall time).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np

from livezmp.links import Backend
from livezmp.links.base import FootSensors, LinkError, LinkFrame, LinkStats
from livezmp.model.robot_config import RobotConfig
from sim_devices.servo_plant import JointPlant, ServoPlant


class MockLink:
    """Joint ``i`` of ``plant`` is ``joint_names[i]``. The plant is stepped to ``clock()`` (s) at every read
    and before every goal change; ``foot_sensors`` / ``imu`` are optional providers of those readings."""

    def __init__(self, plant: JointPlant, joint_names: Sequence[str], *,
                 clock: Callable[[], float] = time.monotonic,
                 foot_sensors: Callable[[], FootSensors] | None = None,
                 imu: Callable[[], dict[str, np.ndarray]] | None = None) -> None:
        if len(plant.position) < len(joint_names):
            raise ValueError(f"MockLink: plant has {len(plant.position)} joints for {len(joint_names)} names")
        self.plant = plant
        self.joint_names = list(joint_names)
        self.stats = LinkStats()
        self._clock = clock
        self._feet = foot_sensors
        self._imu = imu
        self._n = len(joint_names)
        self._time: float | None = None

    def open(self) -> None:
        """Torque on, holding the present posture."""
        self._time = self._clock()
        for i in range(self._n):
            self.plant.set_goal(i, float(self.plant.position[i]))
            self.plant.set_torque(i, True)

    def read(self) -> LinkFrame:
        """The plant's state now (copies)."""
        self._advance()
        self.stats.reads += 1
        n = self._n
        return LinkFrame(t=self._time, positions=self.plant.position[:n].copy(),
                         velocities=self.plant.velocity[:n].copy(), currents=self.plant.current[:n].copy(),
                         feet=self._feet() if self._feet else None, imu=self._imu() if self._imu else None)

    def write_goals(self, positions: np.ndarray) -> None:
        """Goal positions (n,) rad in ``joint_names`` order."""
        goals = np.asarray(positions, dtype=float)
        if goals.shape != (self._n,):
            raise LinkError(f"mock: write_goals needs {self._n} positions, got shape {goals.shape}")
        finite = np.isfinite(goals)
        if not finite.all():
            i = int(np.argmin(finite))
            raise LinkError(f"mock: goal for joint '{self.joint_names[i]}' is not finite: {goals[i]!r}; nothing sent")
        self._advance()
        self.stats.writes += 1
        for i, goal in enumerate(goals.tolist()):
            self.plant.set_goal(i, goal)

    def hold(self) -> None:
        """Goals = the present positions."""
        self.write_goals(self.read().positions)

    def safe_stop(self, drop_torque: bool = False) -> None:
        """Hold, or switch every joint's torque off."""
        if self._time is None:
            return
        if drop_torque:
            for i in range(self._n):
                self.plant.set_torque(i, False)
        else:
            self.hold()

    def reconnect(self) -> bool:
        """Nothing can vanish: always True."""
        return True

    def close(self) -> None:
        """Hold; the plant stays as it is."""
        self.safe_stop()
        self._time = None

    def _advance(self) -> None:
        if self._time is None:
            raise LinkError("mock: link is not open")
        now = self._clock()
        self.plant.step(now - self._time)
        self._time = now


def _build(url: str, target: str, names: list[str], config: RobotConfig, opts: dict, extra: dict) -> MockLink:
    return MockLink(ServoPlant(len(names)), names)


BACKEND = Backend(_build, target=False)
