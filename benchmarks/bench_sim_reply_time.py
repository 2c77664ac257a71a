"""Benchmark: how much later than the bus model a simulated Dynamixel bus's read reaches the host.

A read on the simulated bus cannot take less than the model's time (livezmp.links.bus_timing:
the adapter's latency out and back, the instruction's and the reply's wire time at the baud, the
return delays); what it takes beyond that is the host's: the client building and decoding the
packets, the pty's hops, and the simulator picking the instruction up and writing the reply
when due. This measures that excess per read (Fast Sync Read of 20 present positions, return
delay 0, then a Sync Write of the goals, at a rate that leaves the bus idle between cycles), the
CPU the client spent in each read (building and decoding its packets: part of the excess), and
the simulator's CPU per cycle (the devices' process; the physics process), with the humanoid's
1 kHz physics in a process of its own (as `livezmp demo` runs it) and, the baseline in the same
run, in a thread of the devices' process (sharing its GIL with the port service; its CPU then
counts with the devices'). Loop SCHED_FIFO 50, simulator 49 when granted. The load average is
printed beside each row (others share the machine).

Run: python benchmarks/bench_sim_reply_time.py [--seconds 5]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
from machine_load import load_averages, run_timed

from livezmp.links import LinkError, open_link
from livezmp.links.bus_timing import ADAPTERS, sync_read_bytes, wire_time
from livezmp.live.clock import LoopClock
from livezmp.live.realtime import LOOP_PRIORITY, realtime_priority
from livezmp.model.robot import load_robot
from sim_devices.process import SimProcess

OP3 = Path("/work/shared/data/robots/robotis_op3.urdf")
# robot, baud, adapter, rate (Hz): the bus idle between a cycle's write and the next read
CONFIGS = [("livezmp_mini", 4_000_000, "ftdi-fs", 250), ("OP3", 2_000_000, "ftdi-fs", 200),
           ("livezmp_mini", 4_000_000, "hs", 500), ("OP3", 2_000_000, "hs", 400)]


def measure(robot, urdf: str | None, baud: int, adapter: str, rate: float, seconds: float, physics: str) -> dict:
    """Read durations (s) beyond the model, failed reads, CPU per cycle (us) of the simulator."""
    n = len(robot.body.joint_names)
    instruction, reply = sync_read_bytes(n, 4, True)
    a = ADAPTERS[adapter]
    model = a.out_s + wire_time(instruction + reply, baud) + a.in_s
    with SimProcess("dynamixel", ("stand", {}), urdf=urdf, realtime_priority=LOOP_PRIORITY - 1,
                    devices={"baud": baud, "adapter": adapter}, physics=physics) as sim, \
            realtime_priority(LOOP_PRIORITY):
        link = open_link(f"{sim.url}&fast=1&return_delay=0&timeout=0.05", robot.body.joint_names, robot.config)
        try:
            excess, client, failed = [], [], 0
            clock = LoopClock(rate)
            cpu0 = sim.cpu_seconds()
            clock.start()
            for _ in range(int(seconds * rate)):
                t0, c0 = time.perf_counter(), time.thread_time()
                try:
                    frame = link.read()
                except LinkError:  # counted
                    failed += 1
                else:
                    excess.append(time.perf_counter() - t0 - model)
                    client.append(time.thread_time() - c0)
                    link.write_goals(frame.positions)
                clock.wait()
            cpu1 = sim.cpu_seconds()
        finally:
            link.close()
    cycles = int(seconds * rate)
    cpu = [1e6 * (b - c) / cycles for b, c in zip(cpu1, cpu0, strict=True)] if cpu0 and cpu1 else [np.nan, np.nan]
    return {"excess": np.array(excess), "client_us": 1e6 * np.mean(client) if client else np.nan,
            "failed": failed, "devices_cpu": cpu[0], "physics_cpu": cpu[1],
            "model_ms": 1e3 * model}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="seconds per row (default 5)")
    args = parser.parse_args()
    robots = {"livezmp_mini": (None, load_robot(None, None)), "OP3": (str(OP3), load_robot(str(OP3), None))}
    print(f"20 simulated XM430s; {os.cpu_count()} CPUs; {args.seconds:g} s per row; "
          f"load average at the start: {load_averages()}\n")
    header = ("| robot        | bus    | adapter | rate Hz | physics | model read ms | excess p50 us | p90 us | "
              "p99 us | max us | client CPU us/read | failed | devices CPU us/cycle | physics CPU us/cycle | load |")
    print(header)
    print("|" + "|".join("-" * len(cell) for cell in header.split("|")[1:-1]) + "|", flush=True)
    for name, baud, adapter, rate in CONFIGS:
        urdf, robot = robots[name]
        for physics in ("thread", "process"):
            x = measure(robot, urdf, baud, adapter, rate, args.seconds, physics)
            q = 1e6 * np.percentile(x["excess"], [50, 90, 99, 100]) if len(x["excess"]) else [np.nan] * 4
            print(f"| {name:<12} | {baud / 1e6:g} Mbps | {adapter:<7} | {rate:7d} | {physics:<7} | "
                  f"{x['model_ms']:13.3f} | {q[0]:13.0f} | {q[1]:6.0f} | {q[2]:6.0f} | {q[3]:6.0f} | "
                  f"{x['client_us']:18.0f} | {x['failed']:6d} | {x['devices_cpu']:20.0f} | {x['physics_cpu']:20.0f} | "
                  f"{os.getloadavg()[0]:4.1f} |", flush=True)


if __name__ == "__main__":
    run_timed(main, end_load=False)
