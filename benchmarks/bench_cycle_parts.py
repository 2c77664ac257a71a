"""Benchmark: where a live-loop cycle's CPU goes, and a simulated-humanoid physics step's, part by part.

Both run on simulated time, so every run does the same work whatever the machine's load: the loop's own
work on the mock link (livezmp_mini, the ``demo`` scenario entered at 1.5 s, 1 kHz correcting at 125 Hz:
read → guard → base placement → estimator → ZMP → soles and contacts → support polygon and clamp →
corrector → command → goal limiter → write), and the simulated humanoid's 1 ms step (the same scenario's
goals): goal shaping, servo plant, base placement, ZMP dynamics, soles, support polygon, clamp, fall check.

Columns: the part, its share of the cycle (or step) under cProfile (which weighs Python calls more than
numpy's and Pinocchio's own work: read the shares as where to look), and that share of the CPU a cycle
measured without the profiler in the same run (the baseline: the whole, the minimum and median over
repeats of thread CPU time). The mock link's read steps its own servo plant (the simulated robot's share,
not the loop's); the corrector's parts include its own base placement, which the base-placement row also
counts. The simulated buses' devices are timed by ``bench_sim_chain_cpu.py`` (their packets) and
``bench_live_loop.py`` (their process's CPU a cycle, the ptys' system calls and the spin before a reply
included).

Run: python benchmarks/bench_cycle_parts.py [--repeats 8]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import statistics
import time

from machine_load import load_averages, run_timed

from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.scenarios import make_scenario
from livezmp.model.robot import load_robot
from sim_devices.humanoid import SimHumanoid
from sim_devices.mock_link import MockLink
from sim_devices.servo_plant import ServoPlant
from sim_devices.sim_time_can import SimClock  # time that moves only when the loop sleeps

START_S = 1.5  # where the loop enters the demo scenario (s): the lean brings the corrector in
CYCLES = 1000

# (part, function name, a piece of its file's path): cProfile's cumulative time of each
LOOP_PARTS = [("read (mock link's own servo plant)", "read", "mock_link"), ("frame guard", "check", "safety"),
              ("base placement", "update", "base_placement"), ("estimator (Kalman, spline)", "step", "estimator.py"),
              ("ZMP dynamics", "compute_zmp", "zmp.py"), ("soles", "foot_soles", "body.py"),
              ("lowest sole corners", "lowest_sole_points", "body.py"), ("contacts", "update_lowest", "contacts.py"),
              ("support polygon + clamp", "support_and_clamp", "support.py"),
              ("corrector (root rotation, legs' IK)", "_correct", "loop.py"), ("command", "_command", "loop.py"),
              ("goal limiter", "apply", "safety"), ("write (mock link)", "write_goals", "mock_link"),
              ("timing histograms", "add", "histogram.py")]
PHYSICS_PARTS = [("goal shaping", "update", "humanoid.py"), ("servo plant", "step", "servo_plant"),
                 ("base placement", "update", "base_placement"), ("base angles continued", "_continued", "humanoid"),
                 ("ZMP dynamics", "compute_zmp", "zmp.py"), ("push wrench", "_push_wrench", "humanoid"),
                 ("soles", "foot_soles", "body.py"), ("support polygon (kept)", "_polygon", "humanoid"),
                 ("clamp", "clamp_to_vertices", "support.py"), ("fall check", "_check_fall", "humanoid")]


def loop_run(body, scenario):
    """A fresh loop over the mock link on simulated time: a function running it for ``CYCLES`` cycles."""
    clock = SimClock()
    link = MockLink(ServoPlant(len(body.joint_names), position=scenario.goals(START_S)), body.joint_names,
                    clock=clock.now)
    link.open()
    loop = LiveLoop(link, body, LoopConfig(rate_hz=1000.0, correct_hz=125.0),
                    command=lambda t: scenario.goals(t + START_S),
                    clock=LoopClock(1000.0, now=clock.now, sleep=clock.sleep))
    return lambda: loop.run(CYCLES / 1000.0)


def physics_run(body, scenario):
    """A fresh humanoid at the scenario's start, stepped to 0.3 s: a function stepping it ``CYCLES`` more steps."""
    h = SimHumanoid(body, scenario.goals(0.0), fall_after_s=1e9)  # never falls: every step the full cost
    goals = [scenario.goals(k * 1e-3) for k in range(300 + CYCLES)]  # made here: the scenario is not the physics

    def steps(k0: int, n: int) -> None:
        for k in range(k0, k0 + n):
            h.set_goals(goals[k])  # as the physics process takes the devices' goals every step
            h.advance_to((k + 1) * 1e-3)

    steps(0, 300)
    return lambda: steps(300, CYCLES)


def cpu_us(make, repeats: int) -> list[float]:
    """Thread CPU (us) a cycle of ``make()()`` over ``repeats`` fresh runs (the making not timed)."""
    out = []
    for _ in range(repeats):
        run = make()
        t0 = time.thread_time()
        run()
        out.append(1e6 * (time.thread_time() - t0) / CYCLES)
    return out


def shares(make, whole: tuple[str, str], parts: list[tuple[str, str, str]]) -> list[tuple[str, float]]:
    """Each part's share of ``whole`` (function name, file piece) under cProfile, and the rest's."""
    run = make()
    profile = cProfile.Profile()
    profile.enable()
    run()
    profile.disable()
    stats = pstats.Stats(profile).stats

    def cumulative(name: str, file: str) -> float:
        return sum(v[3] for k, v in stats.items() if k[2] == name and file in k[0])

    total = cumulative(*whole)
    out = [(label, cumulative(name, file) / total) for label, name, file in parts]
    return out + [("the rest (bookkeeping between the parts)", 1.0 - sum(s for _, s in out))]


def table(title: str, times: list[float], rows: list[tuple[str, float]]) -> None:
    low, mid = min(times), statistics.median(times)
    print(f"\n{title}: {low:.1f} us CPU (min of {len(times)} runs of {CYCLES}; median {mid:.1f}), load "
          f"{load_averages()}\n")
    print("| part                                     | share | us (of the min) |")
    print("|------------------------------------------|-------|-----------------|")
    for label, share in rows:
        print(f"| {label:<40} | {100 * share:4.1f}% | {share * low:15.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=8, help="unprofiled runs of each (default 8)")
    repeats = parser.parse_args().repeats
    body = load_robot(None, None).body
    scenario = make_scenario("demo", body)
    print(f"livezmp_mini, demo scenario; load average at the start: {load_averages()}")
    loop_run(body, scenario)()  # warm: first-call costs out of the figures
    table("the loop's own work a 1 kHz cycle (mock link, correcting at 125 Hz)",
          cpu_us(lambda: loop_run(body, scenario), repeats),
          shares(lambda: loop_run(body, scenario), ("_cycle", "loop.py"), LOOP_PARTS))
    table("the simulated humanoid's physics step (1 ms)", cpu_us(lambda: physics_run(body, scenario), repeats),
          shares(lambda: physics_run(body, scenario), ("_step_once", "humanoid.py"), PHYSICS_PARTS))


if __name__ == "__main__":
    run_timed(main)
