"""Benchmark: where a simulated Dynamixel bus cycle's time goes, request by request.

The bus-only cycle of `bench_live_loop.py` (read the present positions, write them back as goals,
sleep to the next absolute deadline) against the simulator in its own process (devices, physics
process), with timestamps on both sides of the pty (one clock, ``time.monotonic``):

* ``write``: the client writes the read's instruction;
* ``pickup``: the simulated chain has read it (its port thread's ``now``);
* ``due``: when the bus model says the reply reaches the host (adapter out, wire, return delays,
  adapter in), counted from the pickup;
* ``sent``: the port wrote the reply to the pty;
* ``have``: the client has the whole verified reply.

Printed per configuration: the medians and 99th percentiles of the stages (``pickup - write``: the
pty's delivery to the simulator; ``sent - due``: the simulator's lateness against its model;
``have - sent``: the pty's delivery back and the client's wake-up), the read's excess over what the
bus model allows from the client's write (``have - write - model``), missed deadlines, failed reads
(a lost reply is counted and the cycle goes on, as in the live loop; the pipelined cycle's goals are
then built from a read asked again, up to READ_TRIES times), and the CPU per cycle of the client, of the
devices' process and of the simulated chain's packet handling alone.

Run: python benchmarks/bench_bus_timeline.py [--seconds 5] [--only TEXT ...]
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import itertools
import os
import tempfile
import time
from pathlib import Path

import numpy as np
from machine_load import load_averages

from livezmp.links import LinkError, open_link
from livezmp.live.clock import LoopClock
from livezmp.live.realtime import LOOP_PRIORITY, fine_timer_slack, realtime_priority
from livezmp.model.robot import load_robot
from sim_devices import process as sim_process
from sim_devices.process import SimProcess

OP3 = Path("/work/shared/data/robots/robotis_op3.urdf")

MAX_EVENTS = 200_000  # per kind, bounded: a 5 s row at 1 kHz is 5 000 cycles
READ_TRIES = 8  # a read that builds the pipelined cycle's goals, asked again after a lost reply


def _traced_child(trace_path: str, *args) -> None:
    """`sim_process._sim_child` with the simulated chains' packet timing recorded, saved on exit."""
    from sim_devices.dynamixel_chain import DynamixelChain
    from sim_devices.pty_port import PtyPort

    picked, sent = [], []
    cpu = [0.0]
    on_bytes, flush = DynamixelChain.on_bytes, PtyPort._flush

    def traced_on_bytes(self, data, now):
        c0 = time.thread_time()
        replies = on_bytes(self, data, now)
        cpu[0] += time.thread_time() - c0
        if len(picked) < MAX_EVENTS:
            picked.append((now, len(data), min((due for due, _ in replies), default=np.nan)))
        return replies

    def traced_flush(self, master, now):
        before = len(self._out) + sum(len(p[2]) for p in self._pending if p[0] <= now)
        flush(self, master, now)
        if before and len(sent) < MAX_EVENTS:
            sent.append((time.monotonic(), before - len(self._out)))

    DynamixelChain.on_bytes, PtyPort._flush = traced_on_bytes, traced_flush
    try:
        sim_process._sim_child(*args)
    finally:
        np.savez(trace_path, picked=np.array(picked).reshape(-1, 3), sent=np.array(sent).reshape(-1, 2),
                 chain_cpu=np.array(cpu))


def bus_cycles(link, rate: float, seconds: float, pipelined: bool) -> dict:
    """The bus-only cycle with the client's times: read, write back, sleep to the deadline; or
    ``pipelined`` as the live loop's bus sees it: at the deadline the goals and the next read's
    instruction in one write, then that read's reply waited for, the next goals built, sleep."""
    clock = LoopClock(rate)
    n = int(seconds * rate)
    times = np.full((n, 2), np.nan)
    failed = [0]

    def prepare_from_a_read() -> None:
        """Goals built from a fresh read; a lost reply is counted and the read asked again (as the live loop
        goes on after one): the pipelined cycle's first read and the one after a failed cycle."""
        for _ in range(READ_TRIES):
            try:
                link.prepare_goals(link.read().positions)
                return
            except LinkError:
                failed[0] += 1
        raise LinkError(f"no read in {READ_TRIES} tries")

    if pipelined:
        prepare_from_a_read()
    clock.start()
    cpu0 = time.process_time()
    for k in range(n):
        times[k, 0] = time.monotonic()
        try:
            if pipelined:
                link.send_prepared()
            frame = link.read()
        except LinkError:
            failed[0] += 1
            if pipelined:
                prepare_from_a_read()
            clock.wait()
            continue
        times[k, 1] = time.monotonic()
        if pipelined:
            link.prepare_goals(frame.positions)
        else:
            link.write_goals(frame.positions)
        clock.wait()
    cpu = time.process_time() - cpu0
    st = clock.stats()
    return {"times": times, "cpu_us": 1e6 * cpu / n, "missed": 100 * st.deadline_misses / max(st.cycles, 1),
            "achieved": st.achieved_hz, "failed": failed[0]}


def timeline(client: np.ndarray, picked: np.ndarray, sent: np.ndarray) -> dict:
    """Per read: the stages (s), matching each client read with the first pickup after its write that
    scheduled a reply, and the first reply write after that pickup."""
    reads = picked[~np.isnan(picked[:, 2])]
    ok = ~np.isnan(client[:, 1])
    write, have = client[ok, 0], client[ok, 1]
    i = np.searchsorted(reads[:, 0], write)
    keep = i < len(reads)
    write, have, i = write[keep], have[keep], i[keep]
    pickup, due = reads[i, 0], reads[i, 2]
    j = np.minimum(np.searchsorted(sent[:, 0], due - 2e-4), len(sent) - 1)  # the port spins from due - 0.1 ms
    return {"pickup": pickup - write, "late": sent[j, 0] - due, "back": have - sent[j, 0],
            "model": due - pickup, "excess": have - write - (due - pickup)}


def run(robot, options: str, devices: dict, rate: float, seconds: float, pipelined: bool) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        trace = os.path.join(tmp, "trace.npz")
        original = sim_process._sim_child
        sim_process._sim_child = functools.partial(_traced_child, trace)
        try:
            sim = SimProcess("dynamixel", ("demo", {}), realtime_priority=LOOP_PRIORITY - 1, devices=devices)
        finally:
            sim_process._sim_child = original
        with sim, realtime_priority(LOOP_PRIORITY, lock_memory=True):
            link = open_link(f"{sim.url}&{options}", robot.body.joint_names, robot.config)
            try:
                sim0 = sim.cpu_seconds()
                x = bus_cycles(link, rate, seconds, pipelined)
                sim1 = sim.cpu_seconds()
            finally:
                link.close()
        data = np.load(trace)
        picked, sent, chain_cpu = data["picked"], data["sent"], float(data["chain_cpu"][0])
    n = len(x["times"])
    x["devices_us"] = 1e6 * (sim1[0] - sim0[0]) / n if sim0 and sim1 else np.nan
    x["physics_us"] = 1e6 * (sim1[1] - sim0[1]) / n if sim0 and sim1 else np.nan
    x["chain_us"] = 1e6 * chain_cpu / max(len(picked), 1)
    x.update(timeline(x["times"], picked, sent))
    return x


CONFIGS = [  # label, robot, baud, adapter, buses, rate
    ("mini 4 Mbps ftdi-fs", "livezmp_mini", 4_000_000, "ftdi-fs", 1, 371),
    ("OP3 2 Mbps hs", "OP3", 2_000_000, "hs", 1, 481),
    ("mini 4 Mbps x 2 hs", "livezmp_mini", 4_000_000, "hs", 2, 1000),
]


def clock_lateness(rate: float, seconds: float) -> np.ndarray:
    """How late (s) the loop's clock wakes for each deadline, sleeping between them (no work)."""
    clock = LoopClock(rate)
    clock.start()
    ticks = [clock.wait() for _ in range(int(rate * seconds))]
    return np.array([tick.woke - tick.deadline for tick in ticks])


def quantiles(v: np.ndarray) -> str:
    return f"{1e6 * np.median(v):5.0f} / {1e6 * np.quantile(v, 0.99):5.0f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="seconds per row (default 5)")
    parser.add_argument("--only", action="append", metavar="TEXT", help="rows whose label contains TEXT")
    parser.add_argument("--cycle", choices=("both", "plain", "pipelined"), default="both",
                        help="the bus-only cycle: read then write (plain), as the live loop (pipelined), or both")
    args = parser.parse_args()
    for fine in (False, True):
        with fine_timer_slack() if fine else contextlib.nullcontext():
            late = clock_lateness(500.0, min(args.seconds, 2.0))
        print(f"loop clock at 500 Hz, normal scheduling, timer slack {'1 ns' if fine else 'default (50 us)'}: "
              f"wakes {quantiles(late)} us late (median / p99)")
    robots = {"livezmp_mini": load_robot(None, None), "OP3": load_robot(str(OP3), None)}
    print(f"bus-only cycle (read, write back, sleep), SCHED_FIFO {LOOP_PRIORITY} / {LOOP_PRIORITY - 1}; "
          f"{os.cpu_count()} CPUs; load average at the start: {load_averages()}")
    print("stages in us, median / p99: pickup = sim read - client write; model = due - pickup; "
          "late = reply written - due; back = client has - reply written; excess = have - write - model\n")
    header = ("| row                 | cycle     | Hz   | achieved | missed % | pickup      | model       | "
              "late        | back        | excess      | failed reads | client CPU us | devices CPU us | "
              "chain us/pickup | physics us | load |")
    print(header)
    print("|" + "|".join("-" * len(c) for c in header.split("|")[1:-1]) + "|", flush=True)
    cycles = {"both": (False, True), "plain": (False,), "pipelined": (True,)}[args.cycle]
    for (name, robot_name, baud, adapter, buses, rate), pipelined in itertools.product(CONFIGS, cycles):
        if args.only and not any(t in name for t in args.only):
            continue
        x = run(robots[robot_name], "fast=1&return_delay=0", {"baud": baud, "adapter": adapter, "buses": buses},
                rate, args.seconds, pipelined)
        print(f"| {name:<19} | {'pipelined' if pipelined else 'plain':<9} | {rate:4d} | {x['achieved']:8.1f} | "
              f"{x['missed']:8.2f} | {quantiles(x['pickup'])} | "
              f"{quantiles(x['model'])} | {quantiles(x['late'])} | {quantiles(x['back'])} | "
              f"{quantiles(x['excess'])} | {x['failed']:12d} | {x['cpu_us']:13.0f} | {x['devices_us']:14.0f} | "
              f"{x['chain_us']:15.0f} | "
              f"{x['physics_us']:10.0f} | {os.getloadavg()[0]:4.1f} |", flush=True)


if __name__ == "__main__":
    main()
