"""Benchmark: the simulated humanoid's cost per internal step, and its share of a 500 Hz loop.

One internal step (1 ms of simulated time) = the servo plant's step, the base placement,
one Pinocchio centroidal-dynamics call (the true ZMP), the contacts, the support polygon
(rebuilt only when the soles in contact move), the clamp and the fall check. Rows, side
by side in one run, per robot:

* baselines: a bare 20-joint ServoPlant step (what a servo bus drives without the
  humanoid) and one ``compute_zmp`` call (the dynamics alone);
* the humanoid playing each scenario, goals sent at 125 Hz (their cost included);
* the sensors, per reading: foot force cells and IMU.

The last column is the share of one core the simulation takes to keep up with real
time: the step cost over its 1 ms; a 500 Hz live loop in the same process has 2 ms per
period, of which the simulation takes two steps.

Run: python benchmarks/bench_sim_humanoid.py [--quick]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import livezmp
from livezmp.balance.zmp import compute_zmp
from livezmp.live import scenarios as sc
from livezmp.model.base_placement import BasePlacer
from livezmp.model.urdf_body import body_from_urdf
from sim_devices.humanoid import SimHumanoid
from sim_devices.scenario_player import ScenarioPlayer
from sim_devices.servo_plant import ServoPlant

ROBOTS = {
    "op3": Path(__file__).resolve().parents[2] / "shared" / "data" / "robots" / "robotis_op3.urdf",
    "mini": Path(livezmp.__file__).parent / "data" / "robots" / "livezmp_mini.urdf",
}
H = 1e-3


def best_us(run, calls: int, repeats: int) -> float:
    """Best of ``repeats`` of the mean time per call of ``run(calls)`` in microseconds."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run(calls)
        times.append((time.perf_counter() - start) / calls)
    return 1e6 * min(times)


def scenario_step_us(body, scenario: sc.Scenario, steps: int, repeats: int) -> float:
    """Per-step cost of playing ``scenario`` (goals at 125 Hz) from 0.5 s in."""
    times = []
    for _ in range(repeats):
        h = SimHumanoid(body, scenario.goals(0.0), fall_after_s=1e9)  # never fall: keep the full cost
        player = ScenarioPlayer(h, scenario, rate_hz=125.0)
        player.run(0.5)
        start = time.perf_counter()
        player.run(steps * H)
        times.append((time.perf_counter() - start) / steps)
    return 1e6 * min(times)


def rows_for(name: str, steps: int, repeats: int) -> list[tuple[str, float]]:
    body = body_from_urdf(ROBOTS[name])
    stand = sc.Poser(body).standing()
    plant = ServoPlant(len(stand), position=stand)
    plant.torque_on[:] = True
    plant.goal[:] = stand + 0.1

    def servo(n):
        for _ in range(n):
            plant.step(H)

    q = np.concatenate([BasePlacer(body).update(stand), stand])
    v, a = np.full(body.nq, 0.1), np.full(body.nq, 0.5)
    data = body.model.createData()

    def dynamics(n):
        for _ in range(n):
            compute_zmp(body.model, data, q, v, a)

    rows = [(f"{name}: baseline ServoPlant(20) step", best_us(servo, steps, repeats)),
            (f"{name}: baseline compute_zmp", best_us(dynamics, steps, repeats))]
    for scenario in (sc.stand(body), sc.lean(body), sc.arm_swing(body), sc.squat(body)):
        rows.append((f"{name}: SimHumanoid step, {scenario.name}", scenario_step_us(body, scenario, steps, repeats)))
    swing = sc.arm_swing(body)
    h = SimHumanoid(body, swing.goals(0.0), fall_after_s=1e9)
    ScenarioPlayer(h, swing).run(1.0)

    def forces(n):
        for _ in range(n):
            h.foot_forces()

    def imu(n):
        for _ in range(n):
            h.imu()

    rows += [(f"{name}: foot_forces() reading", best_us(forces, steps, repeats)),
             (f"{name}: imu() reading", best_us(imu, steps, repeats))]
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps and repeats")
    quick = parser.parse_args().quick
    steps, repeats = (300, 3) if quick else (2000, 5)
    print(f"{'what':48s} {'us/call':>9s} {'core share at 1 ms steps':>26s}")
    for name in ROBOTS:
        for label, us in rows_for(name, steps, repeats):
            share = f"{us / (1e6 * H) * 100:5.1f} %" if "step" in label else ""
            print(f"{label:48s} {us:9.1f} {share:>26s}")


if __name__ == "__main__":
    main()
