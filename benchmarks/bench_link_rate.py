"""Benchmark: sustainable read + write cycle rate of each servo link, 20 servos, simulated devices.

One cycle = ``link.read()`` (verified joint state of all 20 joints) + ``link.write_goals``
(a slow sine around the start posture), back to back, as the live loop does. Rows:

* baseline: the bare client doing the same bus work without the link (dynamixel-sdk's
  GroupSyncRead + GroupSyncWrite with getData / changeParam per servo; firmware_protocol's
  HostSession polling for a JOINT_STATE and sending SET_GOALS), side by side with the link;
* dynamixel: sync read and Fast Sync Read;
* fw: JOINT_STATE streamed at 1000 Hz (the board's limit), so a cycle waits for the next one;
* can: one node per servo behind an slcan adapter; JOINT_STATE at 20 Hz, the link's
  default 30 Hz, and 60 Hz (where python-can's slcan reader, one system call per byte,
  falls behind: the row shows how the link fails); the same nodes behind a simulated
  socketcand daemon on loopback TCP (python-can's socketcand interface) at 30 to 200 Hz;
  and the same link over python-can's in-process virtual bus (no bus at all);
* mock: the in-process plant, the link's own cost;
* dynamixel with the simulated humanoid (livezmp_mini: whole-body dynamics every 1 ms of
  simulated time) as the plant instead of 20 independent servos.

The simulated devices run in a thread of this process (they share the GIL with the
client) or, for the serial links, in a process of their own (the machine's other core).
The GIL switch interval is 0.5 ms (the default 5 ms makes a thread's reply wait for the
busy-polling client). The Dynamixel chain's bytes take their wire time at 1 Mbps behind a
full-speed FTDI adapter (1.5 ms a transaction: livezmp.links.bus_timing); the socketcand
daemon's CAN frames take theirs at 1 Mbit/s (a JOINT_STATE round of 20 one-joint nodes is
60 frames, 7.9 ms); the slcan, firmware-board and virtual-bus rows cost no wire time.
"failed" counts reads that raised LinkReadError.

Run: python benchmarks/bench_link_rate.py [--seconds 1.5]
"""

from __future__ import annotations

import argparse
import contextlib
import math
import multiprocessing
import os
import sys
import threading
import time
from pathlib import Path

import can
import numpy as np
from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler

import firmware_protocol as fp
import livezmp
from livezmp.links import make_link
from livezmp.links.base import LinkError, LinkReadError
from livezmp.live.scenarios import Poser
from livezmp.model.robot_config import RobotConfig, ServoConfig, find_robot_config
from livezmp.model.urdf_body import body_from_urdf
from sim_devices.firmware_board import PlantBackend, PlantJoints
from sim_devices.humanoid import SimHumanoid
from sim_devices.launch import start_devices
from sim_devices.mock_link import MockLink
from sim_devices.servo_plant import ServoPlant

N = 20
NAMES = [f"joint{i:02d}" for i in range(N)]
CONFIG = RobotConfig(servos={name: ServoConfig(name, i + 1) for i, name in enumerate(NAMES)}, source="bench")
START = np.linspace(-0.5, 0.5, N)
WARMUP = 20
MINI_URDF = Path(livezmp.__file__).parent / "data" / "robots" / "livezmp_mini.urdf"
MINI_CONFIG = find_robot_config(MINI_URDF, "livezmp_mini")


def goals(k: int, start: np.ndarray = START, amplitude: float = 0.2) -> np.ndarray:
    return start + amplitude * math.sin(0.01 * k)


def measure(cycle, seconds: float) -> tuple[np.ndarray, int]:
    """Cycle times (s) over ``seconds`` after a warm-up, and how many cycles raised LinkReadError."""
    times, failed, k = [], 0, 0
    end = math.inf
    while time.perf_counter() < end:
        start = time.perf_counter()
        try:
            cycle(k)
        except LinkReadError:
            failed += 1
        times.append(time.perf_counter() - start)
        k += 1
        if k == WARMUP:
            times.clear()
            failed = 0
            end = time.perf_counter() + seconds
    return np.array(times), failed


# -- devices: in this process, or served from another one -----------------------------------------

def start(kind: str, humanoid: bool, options: dict | None = None):
    """Devices of ``kind`` over 20 servos (`start_devices` ``options``), or over the simulated livezmp_mini
    humanoid."""
    if not humanoid:
        return start_devices(kind, ServoPlant(N, position=START), CONFIG, **(options or {}))
    body = body_from_urdf(MINI_URDF)
    return start_devices(kind, SimHumanoid(body, Poser(body).standing()), MINI_CONFIG, joint_names=body.joint_names)


def serve(kind: str, humanoid: bool, conn, options: dict | None = None) -> None:
    """Subprocess body: serve ``kind``'s devices until told to stop."""
    sys.setswitchinterval(5e-4)
    with start(kind, humanoid, options) as devices:
        conn.send(devices.url)
        conn.recv()


@contextlib.contextmanager
def devices_url(kind: str, where: str, humanoid: bool = False, options: dict | None = None):
    if where == "same process":
        with start(kind, humanoid, options) as devices:
            yield devices.url
        return
    context = multiprocessing.get_context("spawn")
    parent, child = context.Pipe()
    process = context.Process(target=serve, args=(kind, humanoid, child, options), daemon=True)
    process.start()
    try:
        yield parent.recv()
    finally:
        parent.send("stop")
        process.join(timeout=10)


@contextlib.contextmanager
def virtual_can_nodes():
    """Twenty BoardEngine nodes on python-can's virtual bus, stepped by a thread; yields the link URL."""
    channel = f"bench-{time.monotonic_ns()}"
    joints = PlantJoints(ServoPlant(N, position=START))
    buses = [can.Bus(interface="virtual", channel=channel) for _ in range(N)]
    engines = [fp.BoardEngine(fp.CanTransport(bus, node, role="board"), PlantBackend(joints, [node - 1], [node]),
                              joint_ids=[node], joint_names=[NAMES[node - 1]]) for node, bus in enumerate(buses, 1)]
    stop = threading.Event()

    def run() -> None:
        while not stop.is_set():
            for engine in engines:
                engine.step(0.0)
            time.sleep(2e-4)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    try:
        yield f"can:virtual:{channel}"
    finally:
        stop.set()
        thread.join(timeout=5)
        for bus in buses:
            bus.shutdown()


# -- the rows ---------------------------------------------------------------------------------------

def run_link(url: str, seconds: float, names: list[str] = NAMES, config: RobotConfig = CONFIG,
             start: np.ndarray = START, amplitude: float = 0.2) -> tuple[np.ndarray, int] | LinkError:
    """The link's cycle (goals: a slow sine around ``start``); the LinkError instead if it cannot open."""
    link = make_link(url, names, config)
    try:
        link.open()
    except LinkError as err:
        return err
    try:
        return measure(lambda k: (link.read(), link.write_goals(goals(k, start, amplitude))), seconds)
    finally:
        link.close()


def run_sdk(url: str, fast: bool, seconds: float) -> tuple[np.ndarray, int]:
    """The bare dynamixel-sdk loop; a link configures the servos first (and leaves the bus watchdog off)."""
    setup = make_link(url + "&timeout=0.1&watchdog=0", NAMES, CONFIG)
    setup.open()  # torque on, return delay 0
    setup.close()
    port = PortHandler(url.partition(":")[2].partition("?")[0])
    port.openPort()
    ph = PacketHandler(2.0)
    reader = GroupSyncRead(port, ph, 126, 10)
    writer = GroupSyncWrite(port, ph, 116, 4)
    for dxl_id in range(1, N + 1):
        reader.addParam(dxl_id)
        writer.addParam(dxl_id, [0, 8, 0, 0])
    read = reader.fastSyncRead if fast else reader.txRxPacket

    def cycle(k: int) -> None:
        if read() != COMM_SUCCESS:
            raise LinkReadError("sync read failed")
        [reader.getData(i, 132, 4) for i in range(1, N + 1)]
        ticks = np.rint(2048 + goals(k) * 4096 / (2 * math.pi)).astype("<i4").tobytes()
        for i in range(N):
            writer.changeParam(i + 1, ticks[4 * i: 4 * i + 4])
        writer.txPacket()

    try:
        return measure(cycle, seconds)
    finally:
        port.closePort()


def run_session(url: str, seconds: float) -> tuple[np.ndarray, int]:
    """The bare firmware_protocol host session loop."""
    transport = fp.SerialTransport(url.partition(":")[2].partition("?")[0])
    session = fp.HostSession(transport)
    hello = session.connect()
    session.set_rates(1000, 0, 0, 10)
    session.set_torque(hello.joint_ids, True)

    def cycle(k: int) -> None:
        while not any(isinstance(m, fp.JointState) for m in session.poll(0.005)):
            pass
        session.send_goals(hello.joint_ids, goals(k).tolist())

    try:
        return measure(cycle, seconds)
    finally:
        transport.close()


def run_mock(seconds: float) -> tuple[np.ndarray, int]:
    link = MockLink(ServoPlant(N, position=START), NAMES)
    link.open()
    return measure(lambda k: (link.read(), link.write_goals(goals(k))), seconds)


def rows(seconds: float):
    """(link, client, devices, where, measurement) per row, measured in turn."""
    for where in ("same process", "own process"):
        with devices_url("dynamixel", where) as url:
            for fast in (False, True):
                read = "fast sync read" if fast else "sync read"
                yield "dynamixel", f"dynamixel-sdk, {read} (baseline)", "XM430 chain", where, \
                    run_sdk(url, fast, seconds)
                yield "dynamixel", f"link, {read}", "XM430 chain", where, \
                    run_link(f"{url}&fast={int(fast)}&timeout=0.1", seconds)
        with devices_url("fw", where) as url:
            yield "fw", "HostSession (baseline)", "firmware board", where, run_session(url, seconds)
            yield "fw", "link, 1000 Hz stream", "firmware board", where, run_link(f"{url}&rate=1000", seconds)
    with devices_url("can", "same process") as url:
        for rate in (20, 30, 60):
            yield "can", f"link, slcan, {rate} Hz streams", "20 servo nodes", "same process", \
                run_link(f"{url}&rate={rate}&timeout=0.5", seconds)
    with devices_url("can", "own process", options={"can_transport": "socketcand"}) as url:
        for rate in (30, 60, 100, 200):
            yield "can", f"link, socketcand, {rate} Hz streams", "20 servo nodes", "own process", \
                run_link(f"{url}&rate={rate}&timeout=0.5", seconds)
    with virtual_can_nodes() as url:
        yield "can", "link, virtual bus, 200 Hz streams", "20 servo nodes", "same process", \
            run_link(f"{url}?rate=200&timeout=0.5", seconds)
    yield "mock", "link", "ServoPlant", "same process", run_mock(seconds)
    body = body_from_urdf(MINI_URDF)
    posture = Poser(body).standing()
    for where in ("same process", "own process"):
        with devices_url("dynamixel", where, humanoid=True) as url:
            for fast in (False, True):
                read = "fast sync read" if fast else "sync read"
                yield "dynamixel", f"link, {read}", "SimHumanoid", where, \
                    run_link(f"{url}&fast={int(fast)}&timeout=0.1", seconds, body.joint_names, MINI_CONFIG, posture,
                             amplitude=0.02)  # a gentle sway: a humanoid that fell would stop computing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.5, help="measured time per row (s)")
    args = parser.parse_args()
    sys.setswitchinterval(5e-4)
    print(f"{N} servos, read + write_goals per cycle; {os.cpu_count()} CPUs, {args.seconds:g} s per row\n")
    header = (f"| {'link':<9} | {'client':<40} | {'devices':<15} | {'where':<12} | {'cycles/s':>8} | "
              f"{'p50 ms':>7} | {'p99 ms':>7} | {'failed':>6} |")
    print(header)
    print("|" + "|".join("-" * len(cell) for cell in header.split("|")[1:-1]) + "|")
    notes = []
    for link, client, devices, where, result in rows(args.seconds):
        if isinstance(result, LinkError):
            notes.append(f"[{len(notes) + 1}] {client}: {result}")
            print(f"| {link:<9} | {client:<40} | {devices:<15} | {where:<12} | {'-':>8} | {'-':>7} | {'-':>7} | "
                  f"{f'[{len(notes)}]':>6} |", flush=True)
            continue
        times, failed = result
        p50, p99 = np.percentile(times, [50, 99]) * 1e3
        print(f"| {link:<9} | {client:<40} | {devices:<15} | {where:<12} | {len(times) / times.sum():8.0f} | "
              f"{p50:7.3f} | {p99:7.3f} | {failed:6d} |", flush=True)
    for note in notes:
        print(note)


if __name__ == "__main__":
    main()
