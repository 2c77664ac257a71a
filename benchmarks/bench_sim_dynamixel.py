"""Benchmark: a dynamixel-sdk control loop against 20 simulated XM430 servos on one pty.

One loop iteration = read the 20 present positions (GroupSyncRead.txRxPacket, or
GroupSyncRead.fastSyncRead) + write 20 goal positions (GroupSyncWrite.txPacket),
with torque on so the simulator also steps its plant. Rows, side by side in one run:

* canned (baseline): a device on the same kind of pty that answers each read
  with precomputed bytes and does nothing else: the cost of the client and the
  pty alone;
* the simulator;
* the simulator with wire time emulated at 1 Mbps (10 bits per byte,
  instruction and replies), as on a real bus at 1 Mbaud.

Each runs in the client's process (a thread: it shares the GIL with the
client, which busy-polls its port) and in its own process (the other core).
Return Delay Time is 0 on every servo. Without wire-time emulation bytes cost
no bus time: those rows measure software only.

Run: python benchmarks/bench_sim_dynamixel.py [--seconds 2]
"""

from __future__ import annotations

import argparse
import math
import multiprocessing
import os
import time

import numpy as np
from dynamixel_sdk import COMM_SUCCESS, GroupSyncRead, GroupSyncWrite, PacketHandler, PortHandler

from sim_devices.dynamixel_chain import DynamixelChain
from sim_devices.dynamixel_packet import HEADER, Instruction, encode_fast_status, encode_status
from sim_devices.pty_port import PtyPort

IDS = list(range(1, 21))
PRESENT_POSITION, GOAL_POSITION = 132, 116


class Canned:
    """Answers sync reads / fast sync reads with fixed replies; no CRC check, no state."""

    def __init__(self) -> None:
        data = (2048).to_bytes(4, "little")
        self.replies = {
            Instruction.SYNC_READ: b"".join(encode_status(i, 0, data) for i in IDS),
            Instruction.FAST_SYNC_READ: encode_fast_status((0, i, data) for i in IDS),
        }
        self.buffer = bytearray()

    def on_bytes(self, data: bytes, now: float):
        self.buffer += data
        replies = []
        while (start := self.buffer.find(HEADER)) >= 0 and len(self.buffer) >= start + 7:
            end = start + 7 + (self.buffer[start + 5] | self.buffer[start + 6] << 8)
            if len(self.buffer) < end:
                break
            reply = self.replies.get(self.buffer[start + 7])
            if reply:
                replies.append((now, reply))
            del self.buffer[:end]
        return replies

    def poll(self, now: float):
        return []

    def next_deadline(self) -> float:
        return math.inf


def make_device(kind: str):
    """(device to close, path) for a row's device kind."""
    if kind == "canned":
        port = PtyPort(Canned())
        return port, port.path
    chain = DynamixelChain(IDS, settings={"return_delay_time": 0}, emulate_wire_time=kind == "wire")
    return chain, chain.path


def serve(kind: str, conn) -> None:
    """Subprocess body: serve a device until told to stop."""
    device, path = make_device(kind)
    conn.send(path)
    conn.recv()
    device.close()


def control_loop(path: str, fast: bool, seconds: float) -> tuple[np.ndarray, int]:
    """Loop times (s) and the number of failed transactions over ``seconds`` of looping."""
    port = PortHandler(path)
    assert port.openPort()
    ph = PacketHandler(2.0)
    reader = GroupSyncRead(port, ph, PRESENT_POSITION, 4)
    writer = GroupSyncWrite(port, ph, GOAL_POSITION, 4)
    torque = GroupSyncWrite(port, ph, 64, 1)
    for dxl_id in IDS:
        reader.addParam(dxl_id)
        writer.addParam(dxl_id, list((2048).to_bytes(4, "little")))
        torque.addParam(dxl_id, [1])
    torque.txPacket()
    read = reader.fastSyncRead if fast else reader.txRxPacket
    times = []
    failures = 0
    warmup = 50
    end = math.inf
    k = 0
    while time.perf_counter() < end:
        start = time.perf_counter()
        failures += read() != COMM_SUCCESS
        goal = 2048 + int(200 * math.sin(k * 0.01))
        for dxl_id in IDS:
            writer.changeParam(dxl_id, list(goal.to_bytes(4, "little")))
        failures += writer.txPacket() != COMM_SUCCESS
        times.append(time.perf_counter() - start)
        k += 1
        if k == warmup:
            times.clear()
            failures = 0
            end = time.perf_counter() + seconds
    port.closePort()
    return np.array(times), failures


def run_row(kind: str, where: str, fast: bool, seconds: float) -> tuple[np.ndarray, int]:
    if where == "same process":
        device, path = make_device(kind)
        try:
            return control_loop(path, fast, seconds)
        finally:
            device.close()
    parent, child = multiprocessing.get_context("spawn").Pipe()
    process = multiprocessing.get_context("spawn").Process(target=serve, args=(kind, child), daemon=True)
    process.start()
    path = parent.recv()
    try:
        return control_loop(path, fast, seconds)
    finally:
        parent.send("stop")
        process.join(timeout=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.5, help="measured time per row (s)")
    args = parser.parse_args()
    kinds = [("canned replies (baseline)", "canned"), ("simulator", "sim"), ("simulator, 1 Mbps wire time", "wire")]
    rows = [(label, kind, where) for label, kind in kinds for where in ("same process", "own process")]
    print(f"20 servos, sync write of goal positions + read of present positions; "
          f"{os.cpu_count()} CPUs, {args.seconds:g} s per row\n")
    header = f"| {'device':<28} | {'where':<12} | {'read':<14} | {'loops/s':>8} | {'p50 ms':>7} | " \
             f"{'p99 ms':>7} | {'failed':>6} |"
    print(header)
    print("|" + "|".join("-" * (len(cell)) for cell in header.split("|")[1:-1]) + "|")
    for label, kind, where in rows:
        for fast in (False, True):
            times, failures = run_row(kind, where, fast, args.seconds)
            p50, p99 = np.percentile(times, [50, 99]) * 1e3
            read = "fast sync read" if fast else "sync read"
            print(f"| {label:<28} | {where:<12} | {read:<14} | {len(times) / times.sum():8.0f} | {p50:7.3f} | "
                  f"{p99:7.3f} | {failures:6d} |", flush=True)


if __name__ == "__main__":
    main()
