"""One plant behind several simulated buses: each bus drives a contiguous share of its joints.

A `DynamixelChain` steps its plant by the time elapsed since it last did; with two chains on
one plant that would step it twice. `split_plant` hands out `PlantShare` views that step the
plant only by the time no share has stepped it yet, so the plant advances once, by the
furthest any bus has seen.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim_devices.servo_plant import JointPlant


class _Clock:
    """Time each share and the plant itself have been stepped by (s)."""

    def __init__(self) -> None:
        self.plant = 0.0


class PlantShare:
    """Joints ``start:stop`` of ``plant`` as a `JointPlant` of their own (index 0 = joint ``start``)."""

    def __init__(self, plant: JointPlant, start: int, stop: int, clock: _Clock) -> None:
        self._plant = plant
        self._slice = slice(start, stop)
        self._start = start
        self._clock = clock
        self._elapsed = 0.0

    @property
    def position(self) -> np.ndarray:
        return self._plant.position[self._slice]

    @property
    def velocity(self) -> np.ndarray:
        return self._plant.velocity[self._slice]

    @property
    def current(self) -> np.ndarray:
        return self._plant.current[self._slice]

    def set_goal(self, idx: int, position: float) -> None:
        self._plant.set_goal(self._start + idx, position)

    def set_torque(self, idx: int, on: bool) -> None:
        self._plant.set_torque(self._start + idx, on)

    def step(self, dt: float) -> None:
        self._elapsed += dt
        ahead = self._elapsed - self._clock.plant
        if ahead > 0.0:
            self._plant.step(ahead)
            self._clock.plant = self._elapsed


def split_plant(plant: JointPlant, sizes: Sequence[int]) -> list[PlantShare]:
    """Shares of ``plant``'s first ``sum(sizes)`` joints, ``sizes[k]`` joints each, in order."""
    clock = _Clock()
    bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    return [PlantShare(plant, int(a), int(b), clock) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]
