"""Benchmark: the live balance loop on simulated Dynamixel buses with wire time, through dynamixel-sdk.

The simulated humanoid (true ZMP from its whole-body dynamics at 1 kHz) runs in its own
process, as `livezmp demo` runs it, behind XM430 chains whose bytes take their wire time
(10 bits at the baud), whose servos wait their Return Delay Time, and whose USB-serial
adapter adds its latency (full-speed FTDI, latency timer 1 ms: 0.5 ms out + 1 ms back; or
a high-speed adapter: 0.06 + 0.13 ms). The loop runs here on absolute deadlines under
SCHED_FIFO with its memory locked (the simulator just below it,
standing in for the servos' own hardware). Each configuration is run side by side:

* bus only (baseline): the same clock and link, read + write of the present posture each
  cycle, no estimation or correction: what the bus and simulator alone allow;
* the live loop (read → estimate → correct at 125 Hz → write), the `demo` scenario, under
  SCHED_FIFO as `livezmp run` runs it: on the simulator's ptys each cycle sleeps 20 us a port after
  sending before its work (livezmp.live.loop.PTY_SEND_PAUSE_S: the kernel worker that carries a
  pty's bytes runs first) and the CPUs are kept awake while it runs (a 0 us CPU latency request,
  livezmp.live.realtime.awake_cpus; the ``sched`` column says ``awake`` when the kernel's target was 0),
  with the simulator's devices and physics on the last CPU (SimProcess's ``cpus``). Where the target
  was not met, also as before those three (``FIFO50 before``: no pause, idle CPUs halt, the simulator
  on any CPU), and under normal scheduling (loop and simulator both). ``--pairs N`` repeats the
  before/after SCHED_FIFO rows N times, alternated (the machine's load drifts).

Each row asks for 85 % of its bus's ceiling (the physical maximum of one read + one write
cycle: wire time of the packet sizes + return delays + the adapter's round trip; see
livezmp.links.bus_timing), capped at 500 Hz (1 kHz for the two-bus row): the target is that
rate with < 1 % missed deadlines. Columns: robot, bus, read, adapter, return delay, ceiling,
scheduling, asked and achieved rate, achieved / ceiling, missed deadlines, p99
sense-to-command latency, the mean read and loop-work (estimate + correct) time, whether the
simulated robot fell, failed reads, the 1-minute load average after the row (others share
the machine), and the CPU time per cycle of the loop's process and of the simulator's (its
devices' process, whose port service spins through the last 0.1 ms before each reply is due,
and its physics process), of that the physics process's alone, and the share of the machine's CPU time its
hypervisor stole during the row (/proc/stat: a row run while it rises was slowed by others). The first
rows are the loop's own work flat out on the mock link (no bus), with the median and 99th percentile of a
cycle's length: the long cycles are the corrector's (at 1 kHz its root rotation in one cycle, its legs' IK in the next).

Run: python benchmarks/bench_live_loop.py [--seconds 10] [--only TEXT ...] [--physics thread] [--pairs N]

``--physics thread`` steps the simulated humanoid in a thread of the devices' process (sharing its
GIL with the port service), as the simulator did before its physics got a process of its own: the
baseline for the simulator's own timing.

``--only`` keeps the rows whose label (robot, bus, read, adapter, return delay, faults, e.g.
``livezmp_mini 4 Mbps x 2 fast sync hs 0 us``) contains TEXT; ``--only "x 2"`` runs the two-bus row.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import time
from pathlib import Path

from machine_load import cpu_times, load_averages, run_timed, steal_percent

from livezmp.histogram import TimingHistogram
from livezmp.links import LinkError, open_link
from livezmp.links.bus_timing import ADAPTERS, BusCeiling, sync_read_bytes, sync_write_bytes
from livezmp.live import loop as loop_module
from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.realtime import LOOP_PRIORITY, cpu_wake_latency_us, realtime_priority
from livezmp.live.scenarios import make_scenario
from livezmp.model.robot import load_robot
from sim_devices.mock_link import MockLink
from sim_devices.process import SimProcess, beside_loop
from sim_devices.servo_plant import ServoPlant

OP3 = Path("/work/shared/data/robots/robotis_op3.urdf")
# the simulator (devices and physics) on the last CPU, the loop on the others (see SimProcess's cpus)
SIM_CPUS = beside_loop()


@contextlib.contextmanager
def pty_pause(seconds: float):
    """The live loop's pause after sending on a pty set to ``seconds`` inside the block (0: as before it had one)."""
    kept, loop_module.PTY_SEND_PAUSE_S = loop_module.PTY_SEND_PAUSE_S, seconds
    try:
        yield
    finally:
        loop_module.PTY_SEND_PAUSE_S = kept


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
            "read": 1e3 * read.mean, "work": 0.0, "fell": None, "failed": failed}


def live(link, robot, sim, rate: float, seconds: float, correct_hz: float) -> dict:
    scenario = make_scenario("demo", robot.body)
    sim.start_scenario()
    loop = LiveLoop(link, robot.body, LoopConfig(rate_hz=rate, correct_hz=correct_hz), command=scenario.goals,
                    fell=sim.fell)
    s = loop.run(seconds)
    truth = sim.verdict()["true_inside_fraction"]
    means = {k: s["timing"][k]["mean_ms"] or 0.0 for k in ("read", "estimate", "correct", "write")}
    return {"cycles": s["cycles"], "achieved_hz": s["achieved_hz"], "deadline_misses": s["deadline_misses"],
            "p99": s["p99_latency_ms"] or 0.0, "read": means["read"], "work": means["estimate"] + means["correct"],
            "fell": s["fell"], "failed": s["failed_reads"], "inside": truth}


class FlatOutClock(LoopClock):
    """A clock that never sleeps and keeps the length of each cycle (s) in ``lengths``: its work alone."""

    def __init__(self, rate: float):
        super().__init__(rate, sleep=lambda _: None)
        self.lengths = TimingHistogram(span_s=0.01)
        self._ended = math.nan

    def start(self):
        tick = super().start()
        self._ended = self.now()
        return tick

    def wait(self):
        self.lengths.add(self.now() - self._ended)
        tick = super().wait()
        self._ended = self.now()
        return tick


def compute_only(robot, rate: float, seconds: float, correct_hz: float) -> dict:
    """The loop's own work, flat out: the mock link over plain servos (no bus, no
    simulator, no sleeping), so each cycle is read → estimate → correct → write of CPU only."""
    scenario = make_scenario("demo", robot.body)
    link = MockLink(ServoPlant(len(robot.body.joint_names), position=scenario.goals(0.0)), robot.body.joint_names)
    link.open()
    clock = FlatOutClock(rate)
    t0 = time.perf_counter()
    s = LiveLoop(link, robot.body, LoopConfig(rate_hz=rate, correct_hz=correct_hz), command=scenario.goals,
                 clock=clock).run(seconds)
    wall = time.perf_counter() - t0
    means = [s["timing"][k]["mean_ms"] or 0.0 for k in ("read", "estimate", "correct", "write")]
    return {"cycles": s["cycles"], "achieved_hz": s["cycles"] / wall, "deadline_misses": 0, "skipped": 0,
            "p50": s["p50_latency_ms"], "p99": s["p99_latency_ms"], "stages": " / ".join(f"{m:.2f}" for m in means),
            "busy": sum(means), "fell": None, "failed": s["failed_reads"], "inside": None,
            "cycle": (1e3 * clock.lengths.quantile(0.5), 1e3 * clock.lengths.quantile(0.99))}


def row(robot, robot_urdf: str | None, options: str, rate: float, seconds: float, devices: dict,
        baseline: bool, correct_hz: float = 125.0, faults: str = "", priority: int = LOOP_PRIORITY,
        physics: str = "process", before: bool = False) -> dict:
    """One row; ``before``: the loop without its pty pause, the CPUs left to halt and the simulator on any CPU
    (the baseline)."""
    with SimProcess("dynamixel", ("demo", {}), faults, urdf=robot_urdf, realtime_priority=max(priority - 1, 0),
                    devices=devices, physics=physics, cpus=None if before else SIM_CPUS) as sim, \
            realtime_priority(priority, lock_memory=True, awake=not before), \
            pty_pause(0.0 if before else loop_module.PTY_SEND_PAUSE_S):
        url = f"{sim.url}&{options}" if options else sim.url
        link = open_link(url, robot.body.joint_names, robot.config)
        try:
            kept_awake = cpu_wake_latency_us() == 0  # the kernel's aggregate of every request on the machine
            loop0, sim0, cpu0 = time.process_time(), sim.cpu_seconds(), cpu_times()
            x = bus_only(link, rate, seconds) if baseline else live(link, robot, sim, rate, seconds, correct_hz)
            loop1, sim1, cpu1 = time.process_time(), sim.cpu_seconds(), cpu_times()
        finally:
            link.close()
    cycles = max(x["cycles"], 1)
    x["awake"] = kept_awake
    x["steal"] = steal_percent(cpu0, cpu1)
    x["loop_cpu"] = 1e6 * (loop1 - loop0) / cycles
    if sim0 is None or sim1 is None:
        x["sim_cpu"] = x["physics_cpu"] = math.nan
    else:
        x["sim_cpu"] = 1e6 * (sum(sim1) - sum(sim0)) / cycles
        x["physics_cpu"] = 1e6 * (sim1[1] - sim0[1]) / cycles
    return x


def predicted_ceiling(n_servos: int, buses: int, fast: bool, return_delay_us: float, baud: int,
                      adapter: str) -> float:
    """Hz: one read of positions + one write of goals on the busiest bus (servos split evenly)."""
    n = -(-n_servos // buses)
    per_cycle = sum(sync_read_bytes(n, 4, fast)) + sync_write_bytes(n, 4)
    return BusCeiling(baud, per_cycle, n * return_delay_us * 1e-6, ADAPTERS[adapter]).ceiling_hz


# robot, baud, buses, fast, return delay (us), adapter, rate cap (Hz), faults, the loop also without SCHED_FIFO
CONFIGS = [
    ("livezmp_mini", 1_000_000, 1, True, 0, "ftdi-fs", 500, "", False),
    ("livezmp_mini", 2_000_000, 1, True, 0, "ftdi-fs", 500, "", True),
    ("livezmp_mini", 4_000_000, 1, True, 0, "ftdi-fs", 500, "", True),
    ("livezmp_mini", 1_000_000, 1, False, 0, "ftdi-fs", 500, "", False),
    ("livezmp_mini", 1_000_000, 1, True, 500, "ftdi-fs", 500, "", False),
    ("livezmp_mini", 4_000_000, 1, True, 0, "hs", 500, "", True),
    ("OP3", 1_000_000, 1, True, 0, "ftdi-fs", 500, "", False),
    ("OP3", 2_000_000, 1, True, 0, "ftdi-fs", 500, "", True),
    ("OP3", 4_000_000, 1, True, 0, "ftdi-fs", 500, "", True),
    ("OP3", 2_000_000, 1, True, 0, "hs", 500, "", True),
    ("livezmp_mini", 4_000_000, 2, True, 0, "hs", 1000, "", True),
    ("livezmp_mini", 1_000_000, 1, True, 0, "ftdi-fs", 500, "drop=0.05,corrupt=0.05", False),
]


def label(config: tuple) -> str:
    """A row's name for --only: robot, bus, read, adapter, return delay, faults."""
    name, baud, buses, fast, delay, adapter, _, faults, _ = config
    bus = f"{baud / 1e6:g} Mbps" + (f" x {buses}" if buses > 1 else "")
    return f"{name} {bus} {'fast sync' if fast else 'sync'} {adapter} {delay} us" + (f" {faults}" if faults else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="seconds per row (default 10)")
    parser.add_argument("--only", action="append", metavar="TEXT",
                        help="run only the rows whose label contains TEXT (repeatable), e.g. 'x 2'")
    parser.add_argument("--no-mock", action="store_true", help="skip the loop-work-only lines (mock link)")
    parser.add_argument("--pairs", type=int, default=1, metavar="N",
                        help="the SCHED_FIFO live loop as before (no pty pause, CPUs halt) and as now, N times "
                             "alternated, on the rows that also run the baselines (default 1)")
    parser.add_argument("--physics", choices=("process", "thread"), default="process",
                        help="the simulated humanoid's physics in a process of its own (default) or in a thread "
                             "of the devices' process (the old way: the baseline)")
    args = parser.parse_args()
    configs = [c for c in CONFIGS if not args.only or any(text in label(c) for text in args.only)]
    if not configs:
        parser.error(f"--only {args.only}: no row matches; the rows: " + "; ".join(map(label, CONFIGS)))
    robots = {"livezmp_mini": (None, load_robot(None, None)), "OP3": (str(OP3), load_robot(str(OP3), None))}
    sec = args.seconds
    with realtime_priority(LOOP_PRIORITY) as refused:
        scheduling = (f"SCHED_FIFO {LOOP_PRIORITY} for the loop, {LOOP_PRIORITY - 1} for the simulator"
                      if refused is None else f"normal scheduling (real-time priority {refused})")
    print(f"20 simulated XM430s per robot (simulator in its own process); {os.cpu_count()} CPUs; {sec:g} s per row; "
          f"{scheduling}; physics in a {args.physics}; "
          f"load average at the start: {load_averages()}")
    print("the live loop reads, writes and estimates every cycle and corrects at 125 Hz (every round(rate / 125)-th "
          "cycle: the summary's correct_every, 8 at 1 kHz)\n")
    mini = robots["livezmp_mini"][1]
    for rate, correct_hz in () if args.no_mock else ((500.0, 125.0), (500.0, 500.0), (1000.0, 125.0)):
        x = compute_only(mini, rate, min(sec, 5.0), correct_hz)
        print(f"loop work only (mock link, no bus), livezmp_mini, {rate:g} Hz asked, correct at {correct_hz:g} Hz: "
              f"{x['achieved_hz']:.0f} Hz flat out, read / estimate / correct / write {x['stages']} ms, "
              "a cycle p50 / p99 {:.2f} / {:.2f} ms".format(*x["cycle"]), flush=True)
    header = ("| robot        | bus            | read      | adapter | delay us | ceiling Hz | loop      | "
              "sched         | asked Hz | achieved Hz | of ceiling | missed % | p99 ms | read ms | work ms | fell | "
              "failed reads | loop CPU us | sim CPU us | physics us | steal % | load |")
    print("\n" + header)
    print("|" + "|".join("-" * len(cell) for cell in header.split("|")[1:-1]) + "|", flush=True)
    for name, baud, buses, fast, delay, adapter, cap, faults, both in configs:
        urdf, robot = robots[name]
        ceiling = predicted_ceiling(len(robot.body.joint_names), buses, fast, delay, baud, adapter)
        rate = min(cap, round(0.85 * ceiling))
        options = f"fast={int(fast)}&return_delay={delay}" + ("&timeout=0.01" if faults else "")
        devices = {"baud": baud, "adapter": adapter, "buses": buses}
        bus = f"{baud / 1e6:g} Mbps" + (f" x {buses}" if buses > 1 else "")
        read = "fast sync" if fast else "sync"
        # (bus only, priority, as before the pty pause and awake CPUs)
        runs = [(True, LOOP_PRIORITY, False)] + [(False, 0, False)] * both
        runs += [(False, LOOP_PRIORITY, True), (False, LOOP_PRIORITY, False)] * (args.pairs if both else 0)
        runs += [] if both else [(False, LOOP_PRIORITY, False)]
        for baseline, priority, before in runs:
            x = row(robot, urdf, options, rate, sec, devices, baseline, faults=faults, priority=priority,
                    physics=args.physics, before=before)
            fell = "-" if x["fell"] is None else ("yes" if x["fell"] else "no")
            loop = "bus only" if baseline else ("loop, 5+5%" if faults else "live loop")
            sched = ((f"FIFO{priority}" if priority and refused is None else "normal") + " before" * before
                     + " awake" * x["awake"])
            print(f"| {name:<12} | {bus:<14} | {read:<9} | {adapter:<7} | {delay:8d} | {ceiling:10.0f} | {loop:<9} | "
                  f"{sched:<13} | {rate:8d} | {x['achieved_hz']:11.1f} | {100 * x['achieved_hz'] / ceiling:9.1f}% | "
                  f"{100 * x['deadline_misses'] / max(x['cycles'], 1):8.2f} | {x['p99']:6.2f} | {x['read']:7.3f} | "
                  f"{x['work']:7.3f} | {fell:>4} | {x['failed']:12d} | {x['loop_cpu']:11.0f} | {x['sim_cpu']:10.0f} | "
                  f"{x['physics_cpu']:10.0f} | {x['steal']:7.2f} | "
                  f"{os.getloadavg()[0]:4.1f} |", flush=True)


if __name__ == "__main__":
    run_timed(main)
