"""Benchmark: CPU per loop cycle of the Dynamixel packets, dynamixel-sdk's group calls vs the cycle packets.

Each cycle of the live loop builds one Sync Write of goals and takes in one Fast Sync Read
reply. Side by side, on the same pty with the reply already waiting (so only CPU is
measured, no wire or waiting), for a bus of 20 and of 10 servos (two buses at 1 kHz):

* dynamixel-sdk (baseline): GroupSyncWrite.changeParam per servo + txPacket; the reply by
  the sdk's fastSyncReadRx, each servo's 4 bytes taken out and joined (what the link did);
* cycle packets (livezmp.links.dynamixel_cycle_packets): GoalPacket.fill, FastReply.receive.

Columns: servos, the per-cycle CPU (us, process_time over all cycles) and wall time
(median and p99, us) of building the write and of taking in the reply, for each.

Run: python benchmarks/bench_dynamixel_cycle.py [--cycles 5000]
"""

from __future__ import annotations

import argparse
import os
import time
import tty

import numpy as np
from dynamixel_sdk import BROADCAST_ID, GroupSyncWrite, PacketHandler, PortHandler
from machine_load import load_averages

from livezmp.links.dynamixel_cycle_packets import FastReply, GoalPacket
from sim_devices.dynamixel_packet import encode_fast_status


class HeldPort:
    """Where the sdk's txPacket writes: kept, not sent (the same for both sides)."""

    is_using = False

    def clearPort(self):
        pass

    def writePort(self, packet):
        self.sent = bytes(packet)
        return len(packet)


def timed(cycles: int, master: int, reply: bytes, build, take) -> tuple[float, np.ndarray, np.ndarray]:
    """(CPU us per cycle, wall us of each build, of each take)."""
    builds, takes = np.empty(cycles), np.empty(cycles)
    cpu = 0.0
    for k in range(cycles):
        os.write(master, reply)
        c0 = time.process_time()
        t0 = time.perf_counter()
        build(k)
        t1 = time.perf_counter()
        take()
        t2 = time.perf_counter()
        cpu += time.process_time() - c0
        builds[k], takes[k] = t1 - t0, t2 - t1
    return 1e6 * cpu / cycles, 1e6 * builds, 1e6 * takes


def compare(n: int, cycles: int, goals: np.ndarray) -> list[tuple[str, tuple]]:
    """Both sides for a bus of ``n`` servos (goals: ticks (64, n), cycled through)."""
    ids = list(range(1, n + 1))
    reply = encode_fast_status([(0, i, int(t).to_bytes(4, "little")) for i, t in zip(ids, goals[0], strict=True)])
    master, slave = os.openpty()
    tty.setraw(slave)
    sdk_port = PortHandler(os.ttyname(slave))
    sdk_port.openPort()
    try:
        sdk_port.setPacketTimeoutMillis(100)
        ph = PacketHandler(2.0)
        writer = GroupSyncWrite(HeldPort(), ph, 116, 4)
        for i in ids:
            writer.addParam(i, b"\0\0\0\0")

        def sdk_build(k: int) -> None:
            raw = goals[k % 64].tobytes()
            for j, dxl_id in enumerate(ids):
                writer.changeParam(dxl_id, raw[4 * j: 4 * j + 4])
            writer.txPacket()

        def sdk_take() -> None:
            data, _, _ = ph.fastSyncReadRx(sdk_port, BROADCAST_ID, 8 * n)
            b"".join(bytes(data[8 * j + 2: 8 * j + 6]) for j in range(n))

        packet = GoalPacket(ids, 116, b"\0" * 14)
        fast = FastReply(ids, np.dtype([("position", "<i4")]))
        fd = sdk_port.ser.fileno()
        return [("dynamixel-sdk", timed(cycles, master, reply, sdk_build, sdk_take)),
                ("cycle packets", timed(cycles, master, reply, lambda k: packet.fill(goals[k % 64]),
                                        lambda: fast.receive(fd, 0.1)))]
    finally:
        sdk_port.closePort()
        os.close(master)
        os.close(slave)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=5000)
    args = parser.parse_args()
    print(f"load average at the start: {load_averages()}; {args.cycles} cycles each\n")
    print("| servos | packets        | CPU us/cycle | build p50 us | build p99 us | take p50 us | take p99 us |")
    print("|--------|----------------|--------------|--------------|--------------|-------------|-------------|")
    rng = np.random.default_rng(0)
    for n in (20, 10):
        for name, (cpu, builds, takes) in compare(n, args.cycles, rng.integers(0, 4096, (64, n)).astype("<i4")):
            print(f"| {n:6d} | {name:<14} | {cpu:12.1f} | {np.median(builds):12.1f} | "
                  f"{np.percentile(builds, 99):12.1f} | {np.median(takes):11.1f} | {np.percentile(takes, 99):11.1f} |",
                  flush=True)
    print(f"\nload average at the end: {load_averages()}")


if __name__ == "__main__":
    main()
