"""Benchmark: the live balance loop on the simulated 20-servo Dynamixel bus, through dynamixel-sdk.

The simulated humanoid (livezmp_mini: 20 XM430s on one chain, true ZMP from its
whole-body dynamics at 1 kHz) runs in its own process, as `livezmp demo` runs it; the
loop runs here at the asked rate on absolute deadlines. Rows, side by side in one run:

* loop work only: the live loop flat out over the mock link on plain servos (no bus,
  no simulator, no sleeping): its own CPU cost per cycle;
* bus only (baseline): the same clock and link, read + write of the present posture
  each cycle, no estimation or correction: what the bus and simulator alone allow;
* the live loop (read → estimate → correct → write), sync read and fast sync read,
  the corrector at 125 Hz (the default: every 4th cycle at 500 Hz) and every cycle;
* the live loop asked for twice the rate (1 kHz by default);
* faults: fast sync read with 1 % of replies dropped and 1 % corrupted, the reply
  reply timeout cut to 3 ms once the link is open (a drop costs one timeout);
* the live loop and simulator at normal scheduling priority: every other row runs the
  loop under SCHED_FIFO (as `livezmp run` does by default) and the simulator's devices
  just below it (they stand in for servo hardware, which nothing on the computer delays).

The command is the `demo` scenario (lean past the toes and back, then the arm swing,
which goes on to the end of the run), so the corrector is working. Columns: achieved
rate, share of cycles that missed their deadline, skipped deadlines, sense-to-command
latency (read start to goal write done), the mean time of each stage of a cycle and
their sum (busy: 1000 / busy is the rate the loop could sustain), whether the
simulated robot fell, the share of the simulator's 1 ms steps whose true ZMP was
inside the support polygon, and failed reads.

Run: python benchmarks/bench_live_loop.py [--seconds 60] [--rate 500]
"""

from __future__ import annotations

import argparse
import os
import time

from livezmp.histogram import TimingHistogram
from livezmp.links import LinkError, open_link
from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.realtime import LOOP_PRIORITY, realtime_priority
from livezmp.live.scenarios import make_scenario
from livezmp.model.robot import load_robot
from sim_devices.mock_link import MockLink
from sim_devices.process import SimProcess
from sim_devices.servo_plant import ServoPlant


def bus_only(link, rate: float, seconds: float) -> dict:
    """Read + write every cycle on the loop's clock: the baseline."""
    clock = LoopClock(rate)
    latency, read, write = TimingHistogram(), TimingHistogram(), TimingHistogram()
    clock.start()
    failed = 0
    for _ in range(int(seconds * rate)):
        t0 = clock.now()
        try:
            frame = link.read()
        except LinkError:  # counted; the baseline just goes on
            failed += 1
        else:
            t1 = clock.now()
            link.write_goals(frame.positions)
            t2 = clock.now()
            read.add(t1 - t0)
            write.add(t2 - t1)
            latency.add(t2 - t0)
        clock.wait()
    st = clock.stats()
    return {"cycles": st.cycles, "achieved_hz": st.achieved_hz, "deadline_misses": st.deadline_misses,
            "skipped": st.skipped, "p50": 1e3 * latency.quantile(0.5), "p99": 1e3 * latency.quantile(0.99),
            "stages": f"{1e3 * read.mean:.2f} / - / - / {1e3 * write.mean:.2f}", "busy": 1e3 * latency.mean,
            "fell": None, "failed": failed, "inside": None}


def live(link, robot, sim, rate: float, seconds: float, correct_hz: float) -> dict:
    scenario = make_scenario("demo", robot.body)
    sim.start_scenario()
    loop = LiveLoop(link, robot.body, LoopConfig(rate_hz=rate, correct_hz=correct_hz), command=scenario.goals,
                    fell=sim.fell)
    s = loop.run(seconds)
    truth = sim.verdict()["true_inside_fraction"]
    means = [s["timing"][k]["mean_ms"] or 0.0 for k in ("read", "estimate", "correct", "write")]
    stages = " / ".join(f"{m:.2f}" for m in means)
    return {"cycles": s["cycles"], "achieved_hz": s["achieved_hz"], "deadline_misses": s["deadline_misses"],
            "skipped": s["clock"]["skipped_cycles"], "p50": s["p50_latency_ms"], "p99": s["p99_latency_ms"],
            "stages": stages, "busy": sum(means), "fell": s["fell"], "failed": s["failed_reads"], "inside": truth}


def compute_only(robot, rate: float, seconds: float, correct_hz: float) -> dict:
    """The loop's own work, flat out: the mock link over plain servos (no bus, no
    simulator, no sleeping), so each cycle is read → estimate → correct → write of CPU only."""
    scenario = make_scenario("demo", robot.body)
    link = MockLink(ServoPlant(len(robot.body.joint_names), position=scenario.goals(0.0)), robot.body.joint_names)
    link.open()
    clock = LoopClock(rate, sleep=lambda _: None)
    t0 = time.perf_counter()
    s = LiveLoop(link, robot.body, LoopConfig(rate_hz=rate, correct_hz=correct_hz), command=scenario.goals,
                 clock=clock).run(seconds)
    wall = time.perf_counter() - t0
    means = [s["timing"][k]["mean_ms"] or 0.0 for k in ("read", "estimate", "correct", "write")]
    return {"cycles": s["cycles"], "achieved_hz": s["cycles"] / wall, "deadline_misses": 0, "skipped": 0,
            "p50": s["p50_latency_ms"], "p99": s["p99_latency_ms"], "stages": " / ".join(f"{m:.2f}" for m in means),
            "busy": sum(means), "fell": None, "failed": s["failed_reads"], "inside": None}


def row(options: str, rate: float, seconds: float, robot, correct_hz: float = 125.0, faults: str = "",
        baseline: bool = False, priority: int = LOOP_PRIORITY) -> dict:
    with SimProcess("dynamixel", ("demo", {}), faults, realtime_priority=max(priority - 1, 0)) as sim, \
            realtime_priority(priority):
        url = f"{sim.url}&{options}" if options else sim.url
        for attempt in range(3):  # with faults injected from the start, opening may fail: try again
            try:
                link = open_link(url, robot.body.joint_names, robot.config)
                break
            except LinkError:
                if attempt == 2:
                    raise
        try:
            return bus_only(link, rate, seconds) if baseline else live(link, robot, sim, rate, seconds, correct_hz)
        finally:
            link.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="seconds per row (default 60)")
    parser.add_argument("--rate", type=float, default=500.0, help="loop rate, Hz (default 500)")
    args = parser.parse_args()
    robot = load_robot(None, None)
    r, sec = args.rate, args.seconds
    with realtime_priority(LOOP_PRIORITY) as refused:
        scheduling = (f"SCHED_FIFO {LOOP_PRIORITY} for the loop, {LOOP_PRIORITY - 1} for the simulator"
                      if refused is None else f"normal scheduling (real-time priority {refused})")
    print(f"livezmp_mini, 20 simulated XM430s (simulator in its own process); {os.cpu_count()} CPUs; "
          f"{sec:g} s per row; asked {r:g} Hz unless the row says otherwise; {scheduling} unless the row says "
          "otherwise\n")
    header = ("| loop                                   |      Hz | missed % | skipped |  p50 ms |  p99 ms | "
              "read / estimate / correct / write, mean ms | busy ms | fell | inside % | failed reads |")
    print(header)
    print("|" + "|".join("-" * len(cell) for cell in header.split("|")[1:-1]) + "|", flush=True)
    for correct_hz in (125.0, r):
        x = compute_only(robot, r, min(sec, 10.0), correct_hz)
        label = f"loop work only, correct at {correct_hz:g} Hz"
        print(f"| {label:<38} | {x['achieved_hz']:7.1f} | {'-':>8} | {'-':>7} | {x['p50']:7.3f} | {x['p99']:7.3f} | "
              f"{x['stages']:<42} | {x['busy']:7.3f} | {'-':>4} | {'-':>8} | {'-':>12} |", flush=True)
    rows = [
        ("bus only, sync read (baseline)", "fast=0", r, sec, {"baseline": True}),
        ("bus only, fast sync read (baseline)", "fast=1", r, sec, {"baseline": True}),
        ("live loop, sync read", "fast=0", r, sec, {}),
        ("live loop, fast sync read", "fast=1", r, sec, {}),
        ("live loop, fast, correct every cycle", "fast=1", r, sec, {"correct_hz": r}),
        ("live loop, fast sync read, 1 kHz", "fast=1", 2 * r, sec, {}),
        ("live loop, fast, normal priority", "fast=1", r, sec, {"priority": 0}),
        # 3 ms: return delays are 0 once open (open itself waits the sdk's own timeout)
        ("live loop, fast, 1% drop + 1% corrupt", "fast=1&timeout=0.003", r, sec,
         {"faults": "drop=0.01,corrupt=0.01"}),
    ]
    for label, options, rate, seconds, kw in rows:
        x = row(options, rate, seconds, robot, **kw)
        fell = "-" if x["fell"] is None else ("yes" if x["fell"] else "no")
        inside = "-" if x["inside"] is None else f"{100 * x['inside']:.2f}"
        print(f"| {label:<38} | {x['achieved_hz']:7.1f} | {100 * x['deadline_misses'] / max(x['cycles'], 1):8.2f} | "
              f"{x['skipped']:7d} | {x['p50']:7.3f} | {x['p99']:7.3f} | {x['stages']:<42} | {x['busy']:7.3f} | "
              f"{fell:>4} | {inside:>8} | {x['failed']:12d} |", flush=True)
    print(f"\nload average at the end: {', '.join(f'{v:.2f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    t0 = time.monotonic()
    main()
    print(f"took {time.monotonic() - t0:.0f} s")
