"""The simulated chain's CPU cuts answer as before: the same reply bytes, due at the same times.

A scripted bus session (goal writes, Fast and plain Sync Reads, reads, pings, bulk reads; Status Return Level,
Return Delay Time and hardware errors changed between reads; a bus watchdog that trips; seeded drops, corruptions
and delays) is fed to a chain on fixed times, and every reply's bytes and due time (ns after its instruction)
are hashed: the hash is the one the chain gave before the cuts (session 21, main at 468e900). The Fast Sync
Read's kept answer is also checked against the general path's (`_answer_reads`) as its registers change."""

from __future__ import annotations

import hashlib
import struct
import time

import numpy as np
import pytest
import serial
from sim_support import short_gil_switch  # noqa: F401 - a fixture

from sim_devices.dynamixel_chain import DynamixelChain
from sim_devices.dynamixel_control_table import OVERLOAD_ERROR
from sim_devices.dynamixel_packet import Instruction, encode_packet

pytestmark = pytest.mark.usefixtures("short_gil_switch")

IDS = [1, 2, 3, 4, 5, 6]
BAUD = 1_000_000
# the session's hash as main's chain answered it (before the cuts)
BEFORE = "c47b0824f1cf3b1a69477842015f64826ee29c334e1d250c69d194e0fef2f052"


class ScriptedPlant:
    """Joint states the session sets; stepping does nothing (the physics steps elsewhere); goals are kept."""

    def __init__(self, n: int) -> None:
        self.position, self.velocity, self.current = np.zeros(n), np.zeros(n), np.zeros(n)
        self.goal = np.zeros(n)

    def set_goal(self, idx: int, position: float) -> None:
        self.goal[idx] = position

    def set_torque(self, idx: int, on: bool) -> None:
        pass

    def step(self, dt: float) -> None:
        pass


def packets(k: int) -> list[bytes]:
    """What the host sends in the session's step ``k``."""
    goals = b"".join(bytes((i,)) + struct.pack("<i", 2048 + 40 * i + (k % 50) - (5000 if k % 17 == 0 and i == 2
                                                                                   else 0)) for i in IDS)
    out = [encode_packet(0xFE, Instruction.SYNC_WRITE, struct.pack("<HH", 116, 4) + goals),
           encode_packet(0xFE, Instruction.FAST_SYNC_READ, struct.pack("<HH", 132, 4) + bytes(IDS))]
    if k % 5 == 0:  # PWM, current, velocity, position: every plant-driven register but the clock's tick
        out.append(encode_packet(0xFE, Instruction.SYNC_READ, struct.pack("<HH", 124, 12) + bytes(IDS)))
    if k % 7 == 0:
        out.append(encode_packet(IDS[k % 6], Instruction.READ, struct.pack("<HH", 128, 8)))
    if k % 11 == 0:
        out.append(encode_packet(0xFE, Instruction.PING))
    if k % 23 == 0:
        out.append(encode_packet(0xFE, Instruction.FAST_BULK_READ, b"".join(
            bytes((i,)) + struct.pack("<HH", 132 if i % 2 else 122, 4 if i % 2 else 2) for i in IDS)))
    if k % 13 == 0:  # Status Return Level of servo 3: 0 (silent), 1, 2
        out.append(encode_packet(3, Instruction.WRITE, bytes((68, 0, (k // 13) % 3))))
    return out


def session_hash() -> str:
    plant = ScriptedPlant(len(IDS))
    chain = DynamixelChain(IDS, plant, baud_rate=BAUD, faults="drop=0.05,corrupt=0.05,delay=0.05:2ms,seed=7",
                           settings={"return_delay_time": 5})
    host = serial.Serial(chain.path, BAUD)  # the line speed the servos hear
    digest = hashlib.sha256()
    try:
        t0 = time.monotonic() + 10.0  # after the chain's construction

        def send(data: bytes, now: float) -> None:
            for due, payload in chain.on_bytes(data, now):
                digest.update(struct.pack("<q", round((due - now) * 1e9)) + payload)

        for k, i in enumerate(IDS):
            send(encode_packet(i, Instruction.WRITE, bytes((64, 0, 1))), t0 + 1e-4 * k)  # torque on
        send(encode_packet(5, Instruction.WRITE, bytes((98, 0, 2))), t0 + 1e-3)  # bus watchdog 40 ms
        for k in range(400):
            now = t0 + 2e-3 + 1e-3 * k + (0.05 if k >= 300 else 0.0)  # a 50 ms silence at 300: the watchdog trips
            plant.position[:] = 0.3 * np.sin(0.01 * k + np.arange(len(IDS)))
            plant.velocity[:] = 0.5 * np.cos(0.02 * k + np.arange(len(IDS)))
            plant.current[:] = 0.4 * np.sin(0.03 * k + np.arange(len(IDS)))
            if k % 19 == 0:
                chain.set_register(2, "return_delay_time", (k // 19) % 4 * 25)
            if k == 150:
                chain.trip(4, OVERLOAD_ERROR)
            for data in packets(k):
                send(data, now)
                now += 2e-4
        digest.update(plant.goal.tobytes())
        digest.update(repr(vars(chain.stats)).encode() + repr(vars(chain.fault_counters)).encode())
    finally:
        host.close()
        chain.close()
    return digest.hexdigest()


def test_a_bus_session_replies_byte_for_byte_and_on_time_as_before():
    assert session_hash() == BEFORE


def test_fast_sync_read_answers_as_the_general_path_as_registers_change():
    rng = np.random.default_rng(4)
    with DynamixelChain(IDS, ScriptedPlant(len(IDS)), baud_rate=BAUD) as chain:
        now = time.monotonic()
        silent = 0
        for k in range(300):
            servo = int(rng.choice(IDS))
            what = rng.integers(4)
            if what == 0:
                chain.set_register(servo, "return_delay_time", int(rng.integers(0, 255)))
            elif what == 1:
                chain.set_register(servo, "status_return_level", int(rng.integers(0, 3)))
            elif what == 2:
                chain.set_register(servo, "hardware_error_status", int(rng.choice([0, OVERLOAD_ERROR])))
            ids = bytes(int(i) for i in rng.permutation(IDS)[: rng.integers(1, len(IDS) + 1)])
            now += 1e-3
            chain._sync_plant(now)
            fast = chain._fast_answer(ids, 132, 4, None)
            general = chain._answer_reads([(i, 132, 4) for i in ids], True, None)
            if fast is None:  # a silent servo among them: the general path leaves it out
                silent += 1
                assert any(chain.register(i, "status_return_level") == 0 for i in ids)
            else:  # the same bytes; the delay summed as ticks, not per servo's seconds: to the last bit or two
                assert [payload for _, payload in fast] == [payload for _, payload in general], f"step {k}"
                assert fast[0][0] == pytest.approx(general[0][0], rel=1e-12, abs=0.0), f"step {k}"
        assert 0 < silent < 300
