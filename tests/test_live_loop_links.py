"""The live loop over the real clients — dynamixel-sdk, python-can's slcan, pyserial —
talking to simulated devices on ptys, with the simulated humanoid behind them.

What reached the device is read back from the device side (the humanoid's servo
goals), so a command lost or garbled on the way would show. Faults are injected by the
devices, whose counters are the truth the loop's counters are compared with."""

from __future__ import annotations

import os
import re
import time

import numpy as np
import pytest
from sim_support import short_gil_switch  # noqa: F401 - fixture

from livezmp.links import LinkError, open_link
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.scenarios import make_scenario
from sim_devices.humanoid import SimHumanoid
from sim_devices.launch import start_devices
from sim_devices.process import SimProcess, beside_loop

pytestmark = pytest.mark.usefixtures("short_gil_switch")

TICK = 2 * np.pi / 4096  # one Dynamixel position tick, rad


class Spy:
    """A link passed through, every call logged with its monotonic time:
    ("read", t, frame), ("read_failed", t), ("write", t, goals), ("safe_stop", t), ("reconnect", t, ok)."""

    def __init__(self, link):
        self.link = link
        self.joint_names, self.stats = link.joint_names, link.stats
        self.rate = getattr(link, "rate", None)
        self.calls: list[tuple] = []
        self.stop_read_errors = 0

    def read(self):
        try:
            frame = self.link.read()
        except LinkError:
            self.calls.append(("read_failed", time.monotonic()))
            raise
        self.calls.append(("read", time.monotonic(), frame))
        return frame

    def write_goals(self, goals):
        self.link.write_goals(goals)
        self.calls.append(("write", time.monotonic(), goals.copy()))

    def safe_stop(self, drop_torque=False):
        self.calls.append(("safe_stop", time.monotonic()))
        before = self.stats.read_errors
        self.link.safe_stop(drop_torque)  # a hold reads the present posture: it may meet a fault too
        self.stop_read_errors += self.stats.read_errors - before

    def reconnect(self):
        ok = self.link.reconnect()
        self.calls.append(("reconnect", time.monotonic(), ok))
        return ok

    def of(self, kind: str) -> list[tuple]:
        return [c for c in self.calls if c[0] == kind]


def run_on_devices(body, config, kind: str, options: str = "", faults: str = "", rate: float | None = None,
                   duration: float = 1.5):
    """Stand for ``duration`` with the loop over ``kind``'s real client; (humanoid, spy, summary, injected)."""
    scenario = make_scenario("stand", body)
    humanoid = SimHumanoid(body, scenario.goals(0.0))
    devices = start_devices(kind, humanoid, config, joint_names=body.joint_names, faults=faults)
    try:
        url = devices.url + ("&" if "?" in devices.url else "?") + options if options else devices.url
        link = open_link(url, body.joint_names, config)
        spy = Spy(link)
        try:
            injected_before = devices.fault_counters
            loop = LiveLoop(spy, body, LoopConfig(rate_hz=rate or spy.rate or 100.0), command=scenario.goals)
            summary = loop.run(duration)
            after = devices.fault_counters  # before close(), whose hold reads once more
            injected = {k: getattr(after, k) - getattr(injected_before, k) for k in ("vanishes", "overloads")}
        finally:
            link.close()
    finally:
        devices.close()
    return humanoid, spy, summary, injected


def writes_follow_good_reads(spy: Spy) -> bool:
    kinds = [c[0] for c in spy.calls]
    return all(i > 0 and kinds[i - 1] == "read" for i, k in enumerate(kinds) if k == "write")


def check_drove(s: dict, spy: Spy, device_goals: np.ndarray, atol: float) -> None:
    assert s["good_frames"] >= 0.8 * s["cycles"] > 0
    assert s["commands_sent"] == s["good_frames"] == len(spy.of("write"))
    assert writes_follow_good_reads(spy)
    assert s["stopped_by"] == "duration"
    # the device holds the goals of the loop's last write (the final safe stop holds right there)
    last_goals = spy.of("write")[-1][2]
    np.testing.assert_allclose(device_goals, last_goals, atol=atol)
    # and the loop read what the servos were at
    assert np.abs(spy.of("read")[-1][2].positions - last_goals).max() < 0.02
    for key in ("cycles", "achieved_hz", "deadline_misses", "read_errors", "write_errors", "stale_frames",
                "corrections_sent", "inside_fraction", "max_latency_ms", "p99_latency_ms", "fell"):
        assert key in s


def report(kind: str, s: dict) -> None:
    print(f"{kind}: {s['cycles']} cycles at {s['achieved_hz']:.1f} Hz of {s['rate_hz']:g}, {s['good_frames']} good "
          f"frames, {s['deadline_misses']} misses, p99 latency {s['p99_latency_ms']:.2f} ms")


@pytest.mark.parametrize(("kind", "options", "atol"), [("dynamixel", "", 3 * TICK), ("fw", "rate=100", 1e-6)])
def test_loop_drives_the_robot_through_dynamixel_sdk_and_pyserial(mini, mini_config, kind, options, atol):
    humanoid, spy, s, _ = run_on_devices(mini, mini_config, kind, options)
    report(kind, s)
    check_drove(s, spy, humanoid.servo.goal, atol)
    assert humanoid.fallen is None


@pytest.mark.parametrize(("transport", "rate"), [("slcan", 20), ("socketcand", 40)])
def test_loop_drives_the_robot_through_python_can(mini, mini_config, transport, rate):
    """Twenty CAN servo nodes stream 3 frames each per state, behind a simulated slcan adapter (more than
    python-can's slcan reader takes in while sharing a process with them, so the simulator runs in its own
    process here, as the demo's does) or a simulated socketcand daemon on loopback TCP (frames taking their
    time on a 1 Mbit/s bus), through python-can's own interfaces."""
    scenario = make_scenario("stand", mini)
    with SimProcess("can", ("stand", {}), devices={"can_transport": transport}) as sim:
        assert sim.url.startswith(f"can:{transport}:")
        spy = Spy(open_link(sim.url + f"&rate={rate}&timeout=0.5", mini.joint_names, mini_config))
        try:
            s = LiveLoop(spy, mini, LoopConfig(rate_hz=spy.rate), command=scenario.goals, fell=sim.fell).run(1.5)
        finally:
            spy.link.close()
        servos = sim.servos()
    report(f"can over {transport}", s)
    check_drove(s, spy, servos["goal"], 1e-6)
    assert s["fell"] is False


def stand_on_a_faulty_chain(mini, mini_config, faults: str, fast: bool, seconds: float):
    """The loop standing livezmp_mini at 100 Hz for ``seconds`` on a Dynamixel chain with ``faults``, in
    its own process; (spy, summary, replies the chain dropped or corrupted during the loop)."""
    scenario = make_scenario("stand", mini)
    with SimProcess("dynamixel", ("stand", {}), faults) as sim:
        # a 60 ms reply timeout (the default is 34 ms), as a loaded machine may hold the simulator
        # up that long
        link = open_link(f"{sim.url}&fast={int(fast)}&timeout=0.06", mini.joint_names, mini_config)
        spy = Spy(link)
        try:
            before = sim.verdict()["injected_faults"]
            s = LiveLoop(spy, mini, LoopConfig(rate_hz=100.0), command=scenario.goals, fell=sim.fell).run(seconds)
            after = sim.verdict()["injected_faults"]  # before close(), whose hold reads once more
        finally:
            link.close()
    return spy, s, sum(after[k] - before[k] for k in ("dropped", "corrupted"))


@pytest.mark.parametrize("fast", [False, True], ids=["sync_read", "fast_sync_read"])
def test_dropped_and_corrupted_replies_are_counted_and_never_drive_a_command(mini, mini_config, fast):
    """1 % of the servos' replies dropped and 1 % corrupted: the link's error count equals
    what the chain injected; the loop's failed reads are the reads with a fault (all of
    them with a fast sync read's single reply), and no write follows a failed read. The
    chain runs in its own process: sharing this one, a busy machine could stall it past
    the reply timeout and add timeouts nobody injected."""
    spy, s, faults = stand_on_a_faulty_chain(mini, mini_config, "drop=0.01,corrupt=0.01,seed=7", fast, 3.0)
    failed = len(spy.of("read_failed"))
    print(f"injected {faults}; link read errors {s['read_errors']}, failed reads {failed} of "
          f"{failed + len(spy.of('read'))}; {s['cycles']} cycles at {s['achieved_hz']:.1f} Hz of 100")
    assert faults > (2 if fast else 10)  # up to 300 reads of 1 or 20 replies
    assert s["read_errors"] == faults
    in_reads = faults - spy.stop_read_errors  # the final hold reads the posture: it may meet one too
    assert failed == s["failed_reads"] and (failed == in_reads if fast else 0 < failed <= in_reads)
    assert writes_follow_good_reads(spy)
    assert s["commands_sent"] == s["good_frames"] == len(spy.of("write"))
    assert s["fell"] is False


def test_port_vanishing_trips_the_watchdog_and_the_loop_reconnects(mini, mini_config):
    """The port disappears for 1 s during the run: within the 100 ms watchdog the loop
    stops commanding (hold), retries every 0.25 s, and commands again once the port is back."""
    vanish_at, gone_for = 1.2, 1.0
    humanoid, spy, s, injected = run_on_devices(mini, mini_config, "dynamixel",
                                                faults=f"vanish={vanish_at}s+{gone_for}s", rate=100.0, duration=3.5)
    assert injected["vanishes"] == 1
    first_fail = spy.of("read_failed")[0][1]
    last_good = max(c[1] for c in spy.of("read") if c[1] < first_fail)
    stop = next(c[1] for c in spy.of("safe_stop") if c[1] > first_fail)
    reconnected = next(c[1] for c in spy.of("reconnect") if c[2])
    print(f"safe stop {1e3 * (stop - last_good):.1f} ms after the last good read; reconnected "
          f"{1e3 * (reconnected - first_fail):.0f} ms after the port went; {s['events']}")
    assert 0.1 <= stop - last_good <= 0.1 + 0.1  # the watchdog, within a cycle and scheduling slack
    assert not [c for c in spy.of("write") if first_fail <= c[1] <= reconnected]
    assert gone_for - 0.1 <= reconnected - first_fail <= gone_for + 0.25 + 0.5
    assert s["watchdog_trips"] == 1 and s["resumes"] == 1 and s["reconnects"] >= 1
    assert s["state"] == "running" and s["stopped_by"] == "duration"
    after = [c for c in spy.of("write") if c[1] > reconnected]
    assert len(after) > 50  # commanding again for the rest of the run
    np.testing.assert_allclose(humanoid.servo.goal, after[-1][2], atol=3 * TICK)
    assert humanoid.fallen is None


def test_a_servo_overload_is_reported_and_latches_a_safe_stop(mini, mini_config):
    """Servo 13 (r_knee) overloads 1 s after the chain starts: its shutdown drops its torque;
    the loop reports the joint and its error bits and commands nothing more."""
    humanoid, spy, s, _ = run_on_devices(mini, mini_config, "dynamixel", faults="overload=13@1.0s", rate=100.0,
                                         duration=2.0)
    overload = 0x20  # Hardware Error Status bit 5 (e-manual)
    assert s["hardware_errors"] == {"r_knee": overload}
    assert s["halted"] == "hardware error on r_knee" and s["state"] == "halted"
    first = next(c[1] for c in spy.of("read") if c[2].hardware_errors)
    assert not [c for c in spy.of("write") if c[1] > first]
    assert len(spy.of("write")) > 20 and any("servo r_knee: hardware error 0x20" in e for e in s["events"])


def test_on_a_bad_bus_the_loop_runs_and_counts_what_it_lost(mini, mini_config):
    """5 % of the replies dropped and 5 % corrupted (a bad cable): `open` retries the servos it has
    not heard, and the loop runs, commanding only after good reads, every lost reply counted."""
    spy, s, faults = stand_on_a_faulty_chain(mini, mini_config, "drop=0.05,corrupt=0.05,seed=3", True, 2.0)
    print(f"injected {faults}; failed reads {s['failed_reads']} of {s['cycles']}; {s['achieved_hz']:.1f} Hz")
    assert s["stopped_by"] == "duration" and s["fell"] is False
    assert s["read_errors"] == faults > 0
    assert 0 < s["failed_reads"] < 0.25 * s["cycles"]  # about 10 % of the fast sync reads' single replies
    assert s["commands_sent"] == s["good_frames"] == len(spy.of("write")) and writes_follow_good_reads(spy)


def test_a_bus_losing_a_fifth_of_its_replies_stops_the_run_with_the_measured_loss(mini, mini_config):
    scenario = make_scenario("stand", mini)
    with SimProcess("dynamixel", ("stand", {}), "drop=0.1,corrupt=0.12,seed=5") as sim:
        try:
            link = open_link(f"{sim.url}&fast=1&timeout=0.06", mini.joint_names, mini_config)
        except LinkError as e:  # open may already have seen enough
            message = str(e)
        else:
            try:
                s = LiveLoop(link, mini, LoopConfig(rate_hz=100.0), command=scenario.goals).run(10.0)
            finally:
                link.close()
            assert s["cycles"] < 600  # well before the end: a window of 400 replies is enough to know
            message = s["stopped_by"]
    print(message)
    assert re.search(r"lost or corrupted (\d+) % of the last \d+ replies \(more than 15 %\)", message)
    assert 15 < int(re.search(r"corrupted (\d+) %", message).group(1)) < 30


def allowed_cpus(pid: int, tid: int) -> set[int]:
    """The CPUs thread ``tid`` of process ``pid`` may run on, as the kernel reports them."""
    with open(f"/proc/{pid}/task/{tid}/status") as f:
        text = next(line for line in f if line.startswith("Cpus_allowed_list:")).split()[1]
    return {c for part in text.split(",") for c in range(int(part.split("-")[0]), int(part.split("-")[-1]) + 1)}


def test_a_simulator_placed_on_a_cpu_keeps_its_devices_and_physics_there():
    """SimProcess(cpus=...): every thread of the devices' process and the physics process it forked may run
    on those CPUs only; this process keeps all of its own."""
    mine = os.sched_getaffinity(0)
    last = max(mine)
    with SimProcess("dynamixel", ("stand", {}), cpus=frozenset({last})) as sim:
        pid = sim._proc.pid
        with open(f"/proc/{pid}/task/{pid}/children") as f:
            physics = [int(p) for p in f.read().split()]
        threads = [(pid, int(t)) for t in os.listdir(f"/proc/{pid}/task")] + [(p, p) for p in physics]
        assert len(physics) == 1 and len(threads) >= 3  # main, port server, physics at least
        assert all(allowed_cpus(p, t) == {last} for p, t in threads)
    assert os.sched_getaffinity(0) == mine


def test_beside_the_loop_is_the_last_cpu_the_loop_is_not_pinned_to():
    """`beside_loop` (where `livezmp demo` and bench_live_loop put the simulator): the last CPU this thread may
    use, the one below it when the loop is pinned there, anywhere (None) on a single CPU or with none left."""
    mine = os.sched_getaffinity(0)
    cpus = sorted(mine)
    if len(cpus) > 1:
        assert beside_loop() == {cpus[-1]}
        assert beside_loop(frozenset(cpus[-1:])) == {cpus[-2]}
    assert beside_loop(frozenset(cpus)) is None
    os.sched_setaffinity(0, {cpus[0]})  # this thread alone
    try:
        assert beside_loop() is None
    finally:
        os.sched_setaffinity(0, mine)
