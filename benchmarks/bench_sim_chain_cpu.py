"""Benchmark: CPU per loop cycle of the simulated Dynamixel chain's packet handling, timed alone.

Each cycle of the live loop sends the simulated bus one Fast Sync Read of present positions
and one Sync Write of goal positions. Here they are handed straight to
``DynamixelChain.on_bytes`` (torque on, position mode, return delay 0; the chain's pty is
open at the bus's baud so every servo hears; the plant's physics steps elsewhere, as in its own
process behind ``livezmp demo``), with no select, no pty write and no spin, so
only the simulator's per-packet Python is timed. Beside it in the same run, the baseline:
framing the same two packets (``PacketReader.feed``, CRC included), which any device pays.

Columns: servos on the bus, CPU us per cycle (process_time over all cycles) of framing only, of
the read (the reply built: the plant's registers refreshed, one segment per servo, signed), of the
write (each goal checked and given to the plant) and of both; the load average beside (others
share the machine). On the two-bus 1 kHz row each bus carries 10 servos.

Run: python benchmarks/bench_sim_chain_cpu.py [--cycles 4000]
"""

from __future__ import annotations

import argparse
import os
import struct
import time

import serial
from machine_load import load_averages

from sim_devices.dynamixel_chain import DynamixelChain
from sim_devices.dynamixel_packet import Instruction, PacketReader, encode_packet
from sim_devices.servo_plant import ServoPlant

BAUD = 4_000_000
PRESENT_POSITION, GOAL_POSITION, TORQUE_ENABLE = 132, 116, 64


class ElsewherePlant(ServoPlant):
    """Servos whose physics steps elsewhere: as behind ``livezmp demo``, where the humanoid steps in its
    own process and the devices' process only reads its state (so no physics is timed here)."""

    def step(self, dt: float) -> None:
        pass


def cycle_packets(ids: list[int], cycles: int) -> tuple[bytes, list[bytes]]:
    """The read instruction and one goal write per cycle (goals that change every cycle)."""
    read = encode_packet(0xFE, Instruction.FAST_SYNC_READ, struct.pack("<HH", PRESENT_POSITION, 4) + bytes(ids))
    writes = [encode_packet(0xFE, Instruction.SYNC_WRITE, struct.pack("<HH", GOAL_POSITION, 4) + b"".join(
        bytes((i,)) + struct.pack("<i", 2048 + (k + i) % 64) for i in ids)) for k in range(cycles)]
    return read, writes


def cpu_us(cycles: int, step) -> float:
    """CPU us per call of ``step(k)`` over ``cycles`` calls."""
    c0 = time.process_time()
    for k in range(cycles):
        step(k)
    return 1e6 * (time.process_time() - c0) / cycles


def measure(n: int, cycles: int) -> dict[str, float]:
    ids = list(range(1, n + 1))
    chain = DynamixelChain(ids, ElsewherePlant(n), baud_rate=BAUD, settings={"return_delay_time": 0})
    host = serial.Serial(chain.path, BAUD)  # the line speed the servos hear
    try:
        t0 = time.monotonic()
        for i in ids:
            chain.on_bytes(encode_packet(i, Instruction.WRITE, bytes((TORQUE_ENABLE, 0, 1))), t0)
        read, writes = cycle_packets(ids, cycles)
        reader = PacketReader()
        replies = chain.stats.replies

        def framing(k: int) -> None:
            reader.feed(read, t0 + 1e-3 * k)
            reader.feed(writes[k], t0 + 1e-3 * k)

        out = {"framing": cpu_us(cycles, framing),
               "read": cpu_us(cycles, lambda k: chain.on_bytes(read, t0 + 1e-3 * (k + 1))),
               "write": cpu_us(cycles, lambda k: chain.on_bytes(writes[k], t0 + 1e-3 * (k + 1) + 2e-4))}
        if chain.stats.replies - replies != cycles or chain.stats.unheard:
            raise SystemExit(f"{n} servos: {chain.stats}: not every read was answered")
        return out
    finally:
        host.close()
        chain.close()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=4000)
    args = parser.parse_args()
    print(f"load average at the start: {load_averages()}; {args.cycles} cycles each\n")
    print("| servos | framing only us | read us | write us | read + write us | load |")
    print("|--------|-----------------|---------|----------|-----------------|------|")
    for n in (10, 20):
        x = measure(n, args.cycles)
        print(f"| {n:6d} | {x['framing']:15.1f} | {x['read']:7.1f} | {x['write']:8.1f} | "
              f"{x['read'] + x['write']:15.1f} | {os.getloadavg()[0]:4.1f} |", flush=True)
    print(f"\nload average at the end: {load_averages()}")


if __name__ == "__main__":
    main()
