"""Benchmark: the live balance loop of the 20-servo humanoid on simulated CAN buses with wire time.

The simulated livezmp_mini (true ZMP from its whole-body dynamics) runs in its own process
behind a simulated socketcand daemon on loopback (python-can's socketcand interface here),
whose CAN frames take their wire time at 1 Mbit/s, stuff bits included
(livezmp.links.can_timing). The loop runs here on absolute deadlines (the `demo` scenario:
read -> estimate -> correct at 125 Hz -> write). Rows:

* firmware protocol, one node per servo on one bus (the previous CAN link): a JOINT_STATE
  stream (3 extended frames a joint) and SET_GOALS (1 frame): 80 frames a cycle; its
  ceiling is estimated from 80 frames of the mean length of random 8-byte extended frames;
* MIT mode (livezmp.links.mit_protocol): one 8-byte command and one 6-byte state reply a
  motor, standard ids: 40 frames a cycle, on 1, 2 or 4 buses read in parallel (one per limb,
  as legged robots run one bus per leg). Their ceiling is the busiest bus's frames' wire
  time (the link's ``bus`` summary), adapter latency 0 (SocketCAN on the robot's computer).

Columns: protocol, buses, frames a cycle, bits and wire time a cycle on the busiest bus,
ceiling, asked and achieved rate, achieved / ceiling, missed deadlines, p99 sense-to-command
latency, mean read time, whether the robot fell, failed reads, and the link's CPU time a
cycle here (process time / cycles: estimate + correct included).

Run: python benchmarks/bench_can_loop.py [--seconds 10]
"""

from __future__ import annotations

import argparse
import os
import random
import time

from machine_load import load_averages, run_timed

from livezmp.links import open_link
from livezmp.links.base import LinkError
from livezmp.links.bus_timing import ADAPTERS
from livezmp.links.can_timing import frame_bits
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.realtime import LOOP_PRIORITY, realtime_priority
from livezmp.live.scenarios import make_scenario
from livezmp.model.robot import load_robot
from sim_devices.process import SimProcess

ROWS = [  # protocol, buses, asked rate (Hz)
    ("firmware", 1, 30),
    ("firmware", 1, 200),
    ("mit", 1, 200),
    ("mit", 2, 200),
    ("mit", 4, 200),
    ("mit", 4, 400),
]


def firmware_bits_per_cycle(n_joints: int) -> float:
    """80 frames for 20 one-joint nodes: the mean bits of random 8-byte extended frames, times 4 a joint."""
    rng = random.Random(1)
    mean = sum(frame_bits(rng.randrange(1 << 29), rng.randbytes(8), True) for _ in range(2000)) / 2000
    return 4 * n_joints * mean


def run_row(robot, protocol: str, buses: int, rate: float, seconds: float) -> dict:
    devices = {"can_transport": "socketcand"}
    if protocol == "mit":
        devices |= {"can_protocol": "mit", "buses": buses}
    with SimProcess("can", ("demo", {}), devices=devices, realtime_priority=LOOP_PRIORITY - 1) as sim, \
            realtime_priority(LOOP_PRIORITY):
        url = sim.url + ("&timeout=0.02" if protocol == "mit" else f"&rate={int(rate)}")
        link = open_link(url, robot.body.joint_names, robot.config)
        try:
            sim.start_scenario()
            loop = LiveLoop(link, robot.body, LoopConfig(rate_hz=rate, correct_hz=125.0),
                            command=make_scenario("demo", robot.body).goals, fell=sim.fell)
            cpu = time.process_time()
            s = loop.run(seconds)
            cpu = time.process_time() - cpu
            ceilings = link.bus_ceilings(ADAPTERS["none"]) if protocol == "mit" else None
        finally:
            link.close()
    n = len(robot.body.joint_names)
    if ceilings:
        busiest = max(ceilings, key=lambda c: c.cycle_s)
        frames, bits, hz = busiest.frames_per_cycle, busiest.bits_per_cycle, busiest.ceiling_hz
    else:
        frames, bits = 4 * n, firmware_bits_per_cycle(n)
        hz = 1e6 / bits
    return {"frames": frames, "bits": bits, "ceiling": hz, "cycles": s["cycles"], "hz": s["achieved_hz"],
            "misses": s["deadline_misses"], "p99": s["p99_latency_ms"] or 0.0,
            "read": s["timing"]["read"]["mean_ms"] or 0.0, "fell": s["fell"], "failed": s["failed_reads"],
            "cpu_ms": 1e3 * cpu / max(s["cycles"], 1)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="seconds per row (default 10)")
    args = parser.parse_args()
    robot = load_robot(None, None)
    with realtime_priority(LOOP_PRIORITY) as refused:
        scheduling = "SCHED_FIFO" if refused is None else f"normal scheduling (real-time priority {refused})"
    print(f"livezmp_mini, {len(robot.body.joint_names)} servos, CAN at 1 Mbit/s (simulator in its own process); "
          f"{os.cpu_count()} CPUs; {args.seconds:g} s per row; {scheduling}; load average at the start: "
          f"{load_averages()}\n")
    header = ("| protocol | buses | frames/cycle/bus | bits/cycle/bus | wire ms | ceiling Hz | asked Hz | "
              "achieved Hz | of ceiling | missed % | p99 ms | read ms | cpu ms/cycle | fell | failed reads |")
    print(header)
    print("|" + "|".join("-" * len(cell) for cell in header.split("|")[1:-1]) + "|", flush=True)
    for protocol, buses, rate in ROWS:
        try:
            x = run_row(robot, protocol, buses, rate, args.seconds)
        except LinkError as err:  # a row past its bus's ceiling may not even open: the rows after it still run
            print(f"| {protocol:<8} | {buses:5d} | link failed: {err} |", flush=True)
            continue
        fell = "-" if x["fell"] is None else ("yes" if x["fell"] else "no")
        approx = "~" if protocol == "firmware" else " "
        print(f"| {protocol:<8} | {buses:5d} | {x['frames']:16d} | {approx}{x['bits']:13.0f} | "
              f"{x['bits'] / 1e3:7.2f} | {x['ceiling']:10.0f} | {rate:8.0f} | {x['hz']:11.1f} | "
              f"{100 * x['hz'] / x['ceiling']:9.1f}% | "
              f"{100 * x['misses'] / max(x['cycles'], 1):8.2f} | {x['p99']:6.2f} | {x['read']:7.3f} | "
              f"{x['cpu_ms']:12.2f} | {fell:>4} | {x['failed']:12d} |", flush=True)


if __name__ == "__main__":
    run_timed(main)
