"""Benchmark: where a simulated bus's bytes wait in the kernel, while the live loop runs (root, tracefs).

A pty carries no byte by itself: a write queues ``flush_to_ldisc`` on the kernel's unbound
workqueue, and a kernel worker of normal priority (a kworker, SCHED_OTHER) moves the bytes to
the other side and wakes its reader. Each cycle of the loop on a simulated bus needs two such
hops (the loop's write out to the simulator, the simulator's reply back; a real USB-serial
adapter needs only the reply's). This runs rows of ``bench_live_loop.py`` (the live loop under
SCHED_FIFO, the `demo` scenario) with the kernel's scheduling traced (ftrace: sched_switch,
sched_wakeup, workqueue events; a trace instance of its own, on the monotonic clock) and prints,
for each direction: how long the worker waited for a CPU after its work was queued (median, 90th,
99th percentile), how often the scheduler put it on the writer's own CPU, and, for the waits
over 100 us, who held the CPU it waited on: the loop (SCHED_FIFO), the simulator's devices
(SCHED_FIFO, just below), its physics process (normal priority), other programs, or nobody (an
idle CPU waking up). Beside them: the share of the two CPUs each used, the real-time share
against the kernel's limit (``sched_rt_runtime_us``), the loop's garbage collections and its
missed deadlines. Each row runs four ways, alternated ``--pairs`` times: ``before`` (the loop
going straight from its write to its work, idle CPUs halting, the simulator on any CPU), ``pause``
(the loop sleeping `PTY_SEND_PAUSE_S` after sending on a pty), ``pause+awake`` (also a 0 us CPU
latency request held, as `livezmp run` does) and ``now`` (also the simulator's devices and physics
on the last CPU, as bench_live_loop runs it).

Run (as root): python benchmarks/bench_tty_worker.py [--seconds 4] [--only TEXT ...] [--pairs 2]
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import re
from collections import Counter, defaultdict
from dataclasses import dataclass, field

import numpy as np
from bench_live_loop import CONFIGS, OP3, SIM_CPUS, label, live, predicted_ceiling, pty_pause
from machine_load import load_averages, run_timed

from livezmp.links import open_link
from livezmp.live.loop import PTY_SEND_PAUSE_S
from livezmp.live.realtime import LOOP_PRIORITY, realtime_priority
from livezmp.model.robot import load_robot
from sim_devices.process import SimProcess

TRACEFS = "/sys/kernel/tracing"
EVENTS = ("sched/sched_switch", "sched/sched_wakeup", "workqueue/workqueue_queue_work",
          "workqueue/workqueue_execute_start")
LONG_WAIT_S = 1e-4
_LINE = re.compile(r"^\s*.+?-(\d+)\s+\[(\d+)\]\s+\S+\s+([\d.]+): (\w+): (.*)$")
DEFAULT_ROWS = ("OP3 2 Mbps fast sync hs", "livezmp_mini 4 Mbps fast sync ftdi-fs", "x 2")


@contextlib.contextmanager
def kernel_trace(buffer_kb: int = 30_000):
    """A trace instance of our own (the machine's main trace untouched), removed on exit; yields a
    function that starts recording, and one that stops it and returns the text."""
    path = f"{TRACEFS}/instances/livezmp-bench-{os.getpid()}"
    os.mkdir(path)

    def put(name: str, value) -> None:
        with open(f"{path}/{name}", "w") as f:
            f.write(str(value))

    def start() -> None:
        put("trace", "")
        put("tracing_on", 1)

    def stop() -> str:
        put("tracing_on", 0)
        with open(f"{path}/trace") as f:
            return f.read()

    try:
        put("tracing_on", 0)
        put("trace_clock", "mono")  # time.monotonic's clock: the trace lines up with the loop's times
        put("buffer_size_kb", buffer_kb)
        for event in EVENTS:
            put(f"events/{event}/enable", 1)
        yield start, stop
    finally:
        with contextlib.suppress(OSError):
            put("tracing_on", 0)
        os.rmdir(path)


@dataclass
class Hops:
    """Per pty write: (writer is the loop, wait s, woken onto the writer's CPU, who held the CPU over a long wait)."""

    waits: dict[bool, list[float]] = field(default_factory=lambda: {True: [], False: []})
    same_cpu: dict[bool, list[bool]] = field(default_factory=lambda: {True: [], False: []})
    holders: dict[bool, Counter] = field(default_factory=lambda: {True: Counter(), False: Counter()})
    share: Counter = field(default_factory=Counter)  # CPU-seconds by who
    span: float = 0.0


def analyse(text: str, who) -> Hops:
    """The pty hops in a trace; ``who(pid)`` names a task (loop, devices, physics, other, idle)."""
    hops = Hops()
    running: dict[int, tuple[float, int]] = {}  # cpu -> (since, pid)
    intervals: dict[int, list[tuple[float, float, str]]] = defaultdict(list)
    queued: dict[str, tuple[float, bool, int]] = {}  # work struct -> (t, by the loop, writer's cpu)
    woken: dict[int, tuple[float, int]] = {}  # kworker pid -> (its last wake-up, the cpu it was put on)
    waiting: list[tuple[float, float, int, bool]] = []  # (queued, started, cpu, by the loop)
    first = last = None
    for line in text.splitlines():
        m = _LINE.match(line)
        if m is None:
            continue
        pid, cpu, t, event, rest = int(m[1]), int(m[2]), float(m[3]), m[4], m[5]
        first, last = first or t, t
        if event == "sched_switch":
            if cpu in running:
                since, p = running[cpu]
                intervals[cpu].append((since, t, who(p)))
            running[cpu] = (t, int(re.search(r"next_pid=(\d+)", rest)[1]))
        elif event == "sched_wakeup" and "comm=kworker" in rest:
            woken[int(re.search(r" pid=(\d+)", rest)[1])] = (t, int(re.search(r"target_cpu=(\d+)", rest)[1]))
        elif event == "workqueue_queue_work" and "function=flush_to_ldisc" in rest and who(pid) in ("loop", "devices"):
            queued[re.search(r"work struct=(\w+)", rest)[1]] = (t, who(pid) == "loop", cpu)
        elif event == "workqueue_execute_start" and "flush_to_ldisc" in rest:
            q = queued.pop(re.search(r"work struct (\w+)", rest)[1], None)
            if q is not None:
                t_woken, put_on = woken.get(pid, (-1.0, cpu))
                hops.waits[q[1]].append(t - q[0])
                hops.same_cpu[q[1]].append((put_on if t_woken >= q[0] else cpu) == q[2])
                waiting.append((q[0], t, cpu, q[1]))
    for a, b, cpu, by_loop in waiting:
        if b - a > LONG_WAIT_S:
            for s, e, name in intervals[cpu]:
                if e > a and s < b:
                    hops.holders[by_loop][name] += min(b, e) - max(a, s)
    for spans in intervals.values():
        for s, e, name in spans:
            hops.share[name] += e - s
    hops.span = (last - first) if first is not None else 0.0
    return hops


# name: (the loop's pause after sending on a pty, CPUs kept awake, the simulator's CPUs)
VARIANTS = {"before": (0.0, False, None), "pause": (PTY_SEND_PAUSE_S, False, None),
            "pause+awake": (PTY_SEND_PAUSE_S, True, None), "now": (PTY_SEND_PAUSE_S, True, SIM_CPUS)}


def traced_row(robot, urdf, config: tuple, seconds: float, pause: float, awake: bool,
               cpus: frozenset[int] | None) -> tuple[dict, Hops, int]:
    """One live-loop row of bench_live_loop with the kernel traced: (its figures, the hops, GC collections)."""
    name, baud, buses, fast, delay, adapter, cap, faults, _ = config
    ceiling = predicted_ceiling(len(robot.body.joint_names), buses, fast, delay, baud, adapter)
    rate = min(cap, round(0.85 * ceiling))
    collections = [0]

    def count(phase: str, _info: dict) -> None:
        collections[0] += phase == "start"

    with kernel_trace() as (start, stop), \
            SimProcess("dynamixel", ("demo", {}), faults, urdf=urdf, realtime_priority=LOOP_PRIORITY - 1,
                       devices={"baud": baud, "adapter": adapter, "buses": buses}, cpus=cpus) as sim, \
            realtime_priority(LOOP_PRIORITY, lock_memory=True, awake=awake), pty_pause(pause):
        link = open_link(f"{sim.url}&fast={int(fast)}&return_delay={delay}", robot.body.joint_names, robot.config)
        devices = {int(t) for t in os.listdir(f"/proc/{sim._proc.pid}/task")}
        with open(f"/proc/{sim._proc.pid}/task/{sim._proc.pid}/children") as f:
            physics = {int(p) for p in f.read().split()}
        gc.callbacks.append(count)
        try:
            start()
            x = live(link, robot, sim, rate, seconds, 125.0)
            text = stop()
        finally:
            gc.callbacks.remove(count)
            link.close()
    x["rate"] = rate
    loop = os.getpid()

    def who(pid: int) -> str:
        if pid == loop:
            return "loop"
        if pid in devices:
            return "devices"
        if pid in physics:
            return "physics"
        return "idle" if pid == 0 else "other"

    return x, analyse(text, who), collections[0]


def quantiles_us(v: list[float]) -> str:
    return " / ".join(f"{1e6 * np.quantile(v, q):4.0f}" for q in (0.5, 0.9, 0.99)) if v else "-"


def held(c: Counter) -> str:
    total = sum(c.values())
    return ", ".join(f"{k} {100 * v / total:.0f}%" for k, v in c.most_common(3)) if total else "-"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=4.0, help="seconds per row (default 4)")
    parser.add_argument("--only", action="append", metavar="TEXT",
                        help=f"rows whose label contains TEXT (default: {'; '.join(DEFAULT_ROWS)})")
    parser.add_argument("--pairs", type=int, default=2,
                        help=f"rows {' / '.join(VARIANTS)}, alternated this many times (default 2)")
    args = parser.parse_args()
    if not os.path.isdir(f"{TRACEFS}/instances") or os.geteuid() != 0:
        parser.error(f"needs root and tracefs at {TRACEFS}")
    wanted = args.only or DEFAULT_ROWS
    configs = [c for c in CONFIGS if any(text in label(c) for text in wanted) and not c[7]]
    robots = {"livezmp_mini": (None, load_robot(None, None)), "OP3": (str(OP3), load_robot(str(OP3), None))}
    with open("/proc/sys/kernel/sched_rt_runtime_us") as f, open("/proc/sys/kernel/sched_rt_period_us") as g:
        rt_limit = int(f.read()) / int(g.read())
    print(f"live loop SCHED_FIFO {LOOP_PRIORITY}, simulator's devices {LOOP_PRIORITY - 1}, its physics normal; "
          f"{os.cpu_count()} CPUs; {args.seconds:g} s per row; real-time limit {100 * rt_limit:.0f} % of each CPU; "
          f"load average at the start: {load_averages()}")
    print("kworker wait: from flush_to_ldisc queued to it running, us (p50 / p90 / p99); own CPU: the worker was put "
          f"on the writer's CPU; held by: who ran on its CPU during the waits over {1e6 * LONG_WAIT_S:.0f} us\n")
    header = ("| row                                     | loop        | missed % | out: kworker wait | own CPU | "
              "out: held by                           | back: kworker wait | own CPU | back: held by"
              "                          | CPU share loop / devices / physics / other / idle | RT share | GC | load |")
    print(header)
    print("|" + "|".join("-" * len(c) for c in header.split("|")[1:-1]) + "|", flush=True)
    for config in configs:
        urdf, robot = robots[config[0]]
        for variant in list(VARIANTS) * args.pairs:
            x, hops, collections = traced_row(robot, urdf, config, args.seconds, *VARIANTS[variant])
            span = max(hops.span, 1e-9)
            share = " / ".join(f"{hops.share[k] / span:.2f}" for k in ("loop", "devices", "physics", "other", "idle"))
            rt = (hops.share["loop"] + hops.share["devices"]) / span
            print(f"| {label(config):<39} | {variant:<11} | "
                  f"{100 * x['deadline_misses'] / max(x['cycles'], 1):8.2f} | {quantiles_us(hops.waits[True]):>17} | "
                  f"{100 * np.mean(hops.same_cpu[True]):6.0f}% | {held(hops.holders[True]):<38} | "
                  f"{quantiles_us(hops.waits[False]):>18} | {100 * np.mean(hops.same_cpu[False]):6.0f}% | "
                  f"{held(hops.holders[False]):<38} | {share:<49} | {rt:8.2f} | {collections:2d} | "
                  f"{os.getloadavg()[0]:4.1f} |", flush=True)


if __name__ == "__main__":
    run_timed(main)
