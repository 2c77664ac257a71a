"""Benchmark: a cycle's work in each of the two-bus row's three processes, on simulated time, for callgrind.

Instruction counts do not move with the machine's load, where CPU times do (this machine is shared): each
part below runs the same work whatever the load, and ``--callgrind`` runs it under valgrind's callgrind and
counts the instructions of N cycles only (after a warm-up; the interpreter's start, the imports and the set-up
are not counted), over N. Without ``--callgrind`` it runs once and prints a digest of what the part produced
(replies, states, outputs), so two trees can be compared.

* ``sim``: the simulated devices of the two-bus 1 kHz row: livezmp_mini's 20 XM430s on two chains at 4 Mbps
  with the high-speed adapter, over a shared-memory humanoid (`RemoteHumanoid`, as the devices' process
  sees the physics process), on real ptys served by their `PortServer`'s passes without its thread. A
  cycle: on each bus the client writes a Sync Write of goals and a Fast Sync Read of positions (the
  pipelined loop's packets), the server takes both buses' in as its thread does after a select (`_waits`,
  `_take_in`), writes the replies (`_write_due`), and the client reads them. The select, the spin
  before a reply is due and the wake-ups are the host's and are not counted (see ``bench_live_loop.py``).
  The digest covers every reply's bytes and its due time (µs after the cycle's write) and the goals the
  plant was given.
* ``physics``: the physics process's 1 ms step as its loop makes it (`physics_process`: the devices' goals
  taken, the humanoid stepped, its state published to the shared arrays), on a simulated clock, the demo's
  goals, without the sensors (neither robot of the rows has an IMU sub-controller). The digest covers the
  published arrays of every step.
* ``loop``: the live loop's own cycle on the mock link (`bench_cycle_parts.py`'s run: the demo entered at
  1.5 s, 1 kHz correcting at 125 Hz). The digest covers its summary's estimates.

Run: python benchmarks/bench_cycle_instructions.py PART [--cycles N] [--callgrind]
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import re
import select
import struct
import subprocess
import sys
import tempfile
import termios
import time
import tty

import numpy as np

PARTS = ("sim", "physics", "loop")
WARM_UP = 20  # cycles run before the counted ones: first-call costs (caches, layouts, allocations) stay out
# the C function that wraps the counted cycles (`sys.call_tracing`, which nothing else here calls): callgrind
# collects inside it only
COUNTED = "_PyEval_CallTracing"
BAUD = 4_000_000
PRESENT_POSITION, GOAL_POSITION, TORQUE_ENABLE = 132, 116, 64


def _cycles(cycle, first: int, end: int) -> None:
    for k in range(first, end):
        cycle(k)


def measured(cycle, cycles: int) -> None:
    """``cycle(k)`` for ``WARM_UP`` cycles, then for ``cycles`` more inside the call callgrind counts."""
    _cycles(cycle, 0, WARM_UP)
    sys.call_tracing(_cycles, (cycle, WARM_UP, WARM_UP + cycles))


def _harness_server():
    """A `PortServer` whose passes the harness makes itself, on its own clock (no thread, no spin)."""
    from sim_devices.pty_port import PortServer

    class Harness(PortServer):
        def add(self, port) -> None:
            self._ports.append(port)
            self._serving = tuple(self._ports)

        def remove(self, port) -> None:
            self._drop(port)

    return Harness()


def _shared_humanoid():
    """The mini's humanoid as the devices' process sees it: a `RemoteHumanoid` over arrays (no child)."""
    from livezmp.live.scenarios import make_scenario
    from livezmp.model.robot import load_robot
    from sim_devices.humanoid import SimHumanoid
    from sim_devices.physics_process import RemoteHumanoid, _cells, _Layout, _publish

    robot = load_robot(None, None)
    scenario = make_scenario("demo", robot.body)
    humanoid = SimHumanoid(robot.body, scenario.goals(0.0), clock=lambda: 0.0, device_steps=False)
    layout = _Layout(len(humanoid.position), _cells(humanoid))
    arrays = layout.views(bytearray(8 * layout.size))
    arrays["goal"][:] = humanoid.goal
    _publish(humanoid, arrays, False)
    return robot, scenario, humanoid, arrays, RemoteHumanoid(humanoid, arrays, None)


def sim_part(cycles: int) -> bytes:
    from sim_devices.dynamixel_chain import DynamixelChain
    from sim_devices.dynamixel_packet import Instruction, encode_packet
    from sim_devices.launch import XM430_ZERO
    from sim_devices.plant_split import split_plant

    robot, scenario, _, arrays, remote = _shared_humanoid()
    servos = [robot.config.servos[name] for name in robot.body.joint_names]  # in the order start_devices takes
    sizes = [len(part) for part in np.array_split(np.arange(len(servos)), 2)]
    digest = hashlib.sha256()
    server = _harness_server()
    buses = []
    first = 0
    t0 = time.monotonic() + 10.0  # the cycles' times: after the chains' construction (monotonic s)
    for share, size in zip(split_plant(remote, sizes), sizes, strict=True):
        group = servos[first: first + size]
        first += size
        chain = DynamixelChain([s.id for s in group], share, baud_rate=BAUD, adapter="hs", port_server=server,
                               settings={"return_delay_time": 0})
        for s in group:
            chain.set_register(s.id, "homing_offset", s.zero - XM430_ZERO)
            chain.set_register(s.id, "drive_mode", 1 if s.direction < 0 else 0)
        port = chain.port
        client = os.open(port.path, os.O_RDWR | os.O_NOCTTY)  # the host, at the servos' line speed
        tty.setraw(client)
        attrs = termios.tcgetattr(client)
        attrs[4] = attrs[5] = getattr(termios, f"B{BAUD}")
        termios.tcsetattr(client, termios.TCSANOW, attrs)
        ids = [s.id for s in group]
        for k, i in enumerate(ids):
            chain.on_bytes(encode_packet(i, Instruction.WRITE, bytes((TORQUE_ENABLE, 0, 1))), t0 - 1.0 + 1e-4 * k)
        read = encode_packet(0xFE, Instruction.FAST_SYNC_READ, struct.pack("<HH", PRESENT_POSITION, 4) + bytes(ids))
        # goals that change every cycle, 64 packets made once (the harness's own work stays out of a cycle's)
        writes = [encode_packet(0xFE, Instruction.SYNC_WRITE, struct.pack("<HH", GOAL_POSITION, 4) + b"".join(
            bytes((i,)) + struct.pack("<i", 2048 + (k + i) % 64) for i in ids)) for k in range(64)]
        buses.append((chain, port, client, read, writes))

    def cycle(k: int) -> None:
        now = t0 + 1e-3 * k
        arrays["position"][:] += 1e-4  # the physics moved the joints since the last cycle
        for _, _, client, read, writes in buses:
            os.write(client, writes[k % 64] + read)
        wanted = [chain.stats.packets + 2 for chain, *_ in buses]
        # the server's passes, as its thread makes them: the pty's kernel worker may hand the packets over in parts
        while any(chain.stats.packets < n for (chain, *_), n in zip(buses, wanted, strict=True)):
            served, readers, _, _ = server._waits(server._serving)
            readable, _, _ = select.select(readers, [], [], 1.0)
            server._take_in(served, readable, now)
        replies = []
        for _, port, _, _, _ in buses:
            for due, _, payload in port._pending:
                digest.update(struct.pack("<d", round((due - now) * 1e6, 3)) + payload)
            replies.append(payload)
        server._write_due(served, math.inf)
        for (_, _, client, _, _), payload in zip(buses, replies, strict=True):
            got = b""
            while len(got) < len(payload):
                select.select([client], [], [], 1.0)
                got += os.read(client, 4096)
            if got != payload:
                raise SystemExit(f"cycle {k}: the client read {got.hex()}, the port wrote {payload.hex()}")
        digest.update(arrays["goal"].tobytes())

    measured(cycle, cycles)
    for chain, _, client, _, _ in buses:
        os.close(client)
        chain.close()
    return digest.digest()


def physics_part(cycles: int) -> bytes:
    from livezmp.live.scenarios import make_scenario
    from livezmp.model.robot import load_robot
    from sim_devices.humanoid import SimHumanoid
    from sim_devices.physics_process import _cells, _Layout, _publish, _take_inputs

    body = load_robot(None, None).body
    scenario = make_scenario("demo", body)
    clock = [0.0]
    humanoid = SimHumanoid(body, scenario.goals(0.0), clock=lambda: clock[0], device_steps=False, torque_on=True,
                           fall_after_s=1e9)  # never falls: every step the full cost
    layout = _Layout(len(humanoid.position), _cells(humanoid))
    arrays = layout.views(bytearray(8 * layout.size))
    arrays["torque"][:] = 1.0
    # the demo's lean, made here: the scenario is not the physics
    goals = [scenario.goals(1.5 + k * 1e-3) for k in range(WARM_UP + cycles)]
    digest = hashlib.sha256()

    def cycle(k: int) -> None:
        arrays["goal"][:] = goals[k]  # as the devices wrote them
        clock[0] = (k + 1) * 1e-3
        _take_inputs(humanoid, arrays)
        humanoid.sync()
        _publish(humanoid, arrays, False)  # neither robot of the rows has an IMU sub-controller: no sensors
        digest.update(arrays["position"].tobytes() + arrays["velocity"].tobytes() + arrays["current"].tobytes()
                      + arrays["status"].tobytes())

    measured(cycle, cycles)
    return digest.digest()


def loop_part(cycles: int) -> bytes:
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import bench_cycle_parts as parts

    from livezmp.live.scenarios import make_scenario
    from livezmp.model.robot import load_robot

    body = load_robot(None, None).body
    scenario = make_scenario("demo", body)
    parts.CYCLES = cycles
    parts.loop_run(body, scenario)()  # a first run, not counted: first-call costs (the corrector's set-up)
    summary = sys.call_tracing(parts.loop_run(body, scenario), ())
    return hashlib.sha256(repr(sorted((k, repr(v)) for k, v in summary.items() if k != "timing")).encode()).digest()


def callgrind(part: str, cycles: int) -> float:
    """Instructions a cycle of ``part``: callgrind collecting inside the counted cycles only, over ``cycles``."""
    with tempfile.TemporaryDirectory() as scratch:
        out = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={scratch}/out",
                              "--collect-atstart=no", f"--toggle-collect={COUNTED}",
                              sys.executable, os.path.abspath(__file__), part, "--cycles", str(cycles)],
                             capture_output=True, text=True)
    if out.returncode:
        raise SystemExit(f"{part} under callgrind failed:\n{out.stderr[-3000:]}")
    return int(re.search(r"Collected : (\d+)", out.stderr).group(1)) / cycles


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", choices=PARTS)
    parser.add_argument("--cycles", type=int, default=200, help="cycles (default 200)")
    parser.add_argument("--callgrind", action="store_true",
                        help="instructions a cycle under callgrind (runs this script twice under valgrind)")
    args = parser.parse_args()
    if args.callgrind:
        print(f"{args.part}: {callgrind(args.part, args.cycles) / 1e3:.1f} k instructions a cycle "
              f"(callgrind, {args.cycles} cycles after {WARM_UP if args.part != 'loop' else 'a first run'})")
        return
    run = {"sim": sim_part, "physics": physics_part, "loop": loop_part}[args.part]
    print(f"{args.part}: {args.cycles} cycles, digest {run(args.cycles).hex()[:16]}")


if __name__ == "__main__":
    main()
