"""Plays a scenario on the simulated humanoid in simulated time, without a servo bus."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from livezmp.live.scenarios import Scenario
from sim_devices.humanoid import SimHumanoid


class ScenarioPlayer:
    """Feeds a scenario's goals to a humanoid ``rate_hz`` times a second of simulated
    time, without any servo bus: switches every joint's torque on, schedules the
    scenario's pushes, and steps the humanoid between goal updates. ``correct(t,
    goals) -> goals`` (optional) may change each goal vector before it is sent, as a
    live loop's corrector does. Scenario time 0 is the humanoid's time at creation."""

    def __init__(self, humanoid: SimHumanoid, scenario: Scenario, rate_hz: float = 125.0,
                 correct: Callable[[float, np.ndarray], np.ndarray] | None = None):
        self.humanoid = humanoid
        self.scenario = scenario
        self.period = 1.0 / rate_hz
        self.correct = correct
        self.start = humanoid.t
        self.ticks = 0
        for i in range(len(humanoid.position)):
            humanoid.set_torque(i, True)
        for p in scenario.pushes:
            humanoid.push(replace(p, start=self.start + p.start))

    @property
    def t(self) -> float:
        """Scenario time of the next goal update (s)."""
        return self.ticks * self.period

    def tick(self) -> None:
        """Send the goals for the current time and simulate one goal period."""
        t = self.t
        goals = self.scenario.goals(t)
        if self.correct is not None:
            goals = self.correct(t, goals)
        self.humanoid.set_goals(goals)
        self.ticks += 1
        self.humanoid.advance_to(self.start + self.ticks * self.period)

    def run(self, duration: float | None = None) -> None:
        """Play ``duration`` seconds (default: the rest of the scenario)."""
        end = self.scenario.duration if duration is None else self.t + duration
        while self.t < end - 1e-9:
            self.tick()
