"""MIT-mode CAN motors: the frame layout, the wire time of a frame, and a 20-motor robot's loop rate.

The loop-rate tests run in simulated time (`sim_devices.sim_time_can`): the frames take their
wire time on a simulated clock, the host's computing takes none, so the rate they show is
what the buses physically allow, the same on any machine.
"""

from __future__ import annotations

import random
import socket
import time

import numpy as np
import pytest

from livezmp.errors import InputError
from livezmp.links import make_link
from livezmp.links import mit_protocol as mit
from livezmp.links.base import LinkError, LinkReadError
from livezmp.links.bus_timing import ADAPTERS, bus_summary
from livezmp.links.can_mit import MitCanLink
from livezmp.links.can_timing import crc15, frame_bits, max_frame_bits
from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig
from livezmp.live.loop import LiveLoop
from livezmp.live.scenarios import Poser
from livezmp.model.robot import load_robot
from livezmp.model.robot_config import RobotConfig, ServoConfig
from sim_devices.firmware_board import PlantJoints
from sim_devices.mit_motor import MitMotorBuses, MitMotorNode, split_joints
from sim_devices.servo_plant import ServoPlant
from sim_devices.sim_time_can import SimClock, SimTimeCanBus


def test_a_zero_command_is_the_firmwares_frame():
    # p = v = t = 0 sit mid-range: 0x7FFF, 0x7FF, 0x7FF; Kp = Kd = 0 at the bottom (the frame CubeMars' manual
    # gives for "MIT mode, all zero")
    assert mit.pack_command(0.0, 0.0, 0.0, 0.0, 0.0).hex() == "7fff7ff0000007ff"
    # full scale: 0xFFFF position, 0xFFF everywhere else
    assert mit.pack_command(12.5, 65.0, 500.0, 5.0, 18.0).hex() == "ffffffffffffffff"
    p, v, kp, kd, t = mit.unpack_command(mit.pack_command(1.0, -2.0, 30.0, 0.7, 3.0))
    steps = np.array([25 / 65535, 130 / 4095, 500 / 4095, 5 / 4095, 36 / 4095])  # one count of each field
    assert np.all(np.abs(np.array([p, v, kp, kd, t]) - [1.0, -2.0, 30.0, 0.7, 3.0]) <= steps)
    assert mit.unpack_reply(mit.pack_reply(7, -1.5, 4.0, -2.0))[0] == 7


def _bits(data: bytes) -> str:
    return "".join(f"{b:08b}" for b in data)


def test_frame_bits_count_fields_stuffing_and_interframe_space():
    assert crc15(_bits(b"123456789")) == 0x059E  # the CRC-15/CAN check value (reveng's CRC catalogue)
    # id 0, no data: SOF..CRC is 34 dominant bits (the CRC of zeros is 0): a stuff bit after each 5 -> 6, then
    # 13 bits of delimiters, ACK, end of frame and interframe space
    assert frame_bits(0x000, b"") == 34 + 6 + 13
    # every other frame lies between its unstuffed length and its longest (every possible stuff bit)
    rng = random.Random(5)
    for _ in range(300):
        n = rng.randrange(9)
        ext = rng.random() < 0.5
        ident = rng.randrange(1 << 29) if ext else rng.randrange(1 << 11)
        bits = frame_bits(ident, bytes(rng.randrange(256) for _ in range(n)), ext)
        assert (67 if ext else 47) + 8 * n <= bits <= max_frame_bits(n, ext)
    assert max_frame_bits(8) == 135 and max_frame_bits(8, extended=True) == 160


def _open_raw(port: int, channel: str) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", port), timeout=5.0)
    for command, answer in ((None, b"< hi >"), (f"< open {channel} >", b"< ok >"), ("< rawmode >", b"< ok >")):
        if command:
            sock.sendall(command.encode())
        assert sock.recv(64) == answer
    return sock


def test_the_simulated_bus_holds_each_frame_its_bit_count():
    # five commands in one TCP segment queue on the bus: each reply ends (its SocketCAN timestamp) one command
    # and one reply after the one before, to the bit at 125 kbit/s (8 us a bit; stamps in us)
    servos = [ServoConfig(f"j{i}", i + 1, zero=0) for i in range(5)]
    plant = ServoPlant(5, position=np.linspace(-0.4, 0.4, 5))
    commands = [mit.pack_command(0.1 * k, 0.0, 20.0, 0.5, 0.0) for k in range(5)]
    with MitMotorBuses(plant, servos, bitrate=125_000) as motors:
        sock = _open_raw(motors.server.port, "can0")
        try:
            sock.sendall(b"".join(f"< send {k + 1:03X} 8 {' '.join(f'{b:x}' for b in c)} >".encode()
                                  for k, c in enumerate(commands)))
            text, deadline = "", time.monotonic() + 5.0
            while text.count("< frame") < 5 and time.monotonic() < deadline:
                text += sock.recv(4096).decode()
        finally:
            sock.close()
    frames = [line.split() for line in text.split("< frame ")[1:]]
    stamps = np.array([float(f[1]) for f in frames])
    replies = [bytes.fromhex(f[2]) for f in frames]
    assert [r[0] for r in replies] == [1, 2, 3, 4, 5]
    bits = [frame_bits(k + 1, commands[k]) + frame_bits(0, replies[k]) for k in range(5)]
    assert np.diff(stamps) == pytest.approx(np.array(bits[1:]) / 125_000, abs=2e-6)


def _sim_time_robot(buses: int, rate: float, seconds: float) -> dict:
    """livezmp_mini's 20 joints as MIT motors on ``buses`` simulated-time CAN buses at 1 Mbit/s, the live
    loop at ``rate`` Hz on the same clock for ``seconds``: its summary and the link."""
    robot = load_robot(None, None)
    names = robot.body.joint_names
    standing = Poser(robot.body).standing()
    servos = [ServoConfig(name, i + 1) for i, name in enumerate(names)]
    clock = SimClock(100.0)
    joints = PlantJoints(ServoPlant(len(names), position=standing))
    nodes = [MitMotorNode(joints, i, s, lock=_NoLock(), clock=clock.now) for i, s in enumerate(servos)]
    channels = [f"can{k}" for k in range(buses)]
    sim_buses = {ch: SimTimeCanBus([nodes[i] for i in part], clock, channel=ch)
                 for ch, part in zip(channels, split_joints(len(names), buses), strict=True)}
    link = MitCanLink("sim", names, servos, channels, sim_buses.__getitem__, timeout=0.01, clock=clock.now)
    link.open()
    loop = LiveLoop(link, robot.body, LoopConfig(rate_hz=rate), command=lambda t: standing,
                    clock=LoopClock(rate, now=clock.now, sleep=clock.sleep))
    summary = loop.run(seconds)
    link.close()
    return {**summary, "link": link, "frames": sum(b.frames for b in sim_buses.values())}


class _NoLock:
    """One thread here: the nodes need no lock."""

    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> None:
        return None


def test_a_20_motor_can_robot_runs_the_loop_at_200_hz_on_four_buses():
    s = _sim_time_robot(buses=4, rate=200.0, seconds=2.0)
    assert s["cycles"] >= 399 and s["achieved_hz"] == pytest.approx(200.0, rel=0.01)
    assert s["deadline_misses"] == 0 and s["failed_reads"] == 0
    # two frames a motor a cycle: 40 a cycle, 10 on each bus, whose wire time (about 1.1 ms) is the ceiling
    assert s["frames"] / s["cycles"] == pytest.approx(40, abs=1)
    ceilings = s["link"].bus_ceilings(ADAPTERS["none"])
    assert len(ceilings) == 4 and all(c.frames_per_cycle == 10 for c in ceilings)
    assert min(c.ceiling_hz for c in ceilings) > 800
    # the run summary's bus block: the bits of one command and one reply per motor on the busiest bus
    bus = bus_summary(ceilings, "state", s["achieved_hz"])
    assert bus["frames_per_cycle"] == 10 and bus["buses"] == 4
    assert bus["ceiling_hz"] == pytest.approx(1e6 / bus["bits_per_cycle"], abs=0.1)
    assert 5 * (111 + 95) <= bus["bits_per_cycle"] <= 5 * (max_frame_bits(8) + max_frame_bits(6))


def test_one_bus_is_bound_by_its_wire_time():
    # the same 40 frames on one bus take about 4.4 ms: 200 Hz fits, 250 Hz (4 ms a cycle) cannot
    ceiling = _sim_time_robot(buses=1, rate=200.0, seconds=0.5)["link"].bus_ceilings(ADAPTERS["none"])[0]
    assert 200 < ceiling.ceiling_hz < 250
    s = _sim_time_robot(buses=1, rate=250.0, seconds=0.5)
    assert s["achieved_hz"] < 0.95 * 250 and s["deadline_misses"] > 0.5 * s["cycles"]


def test_url_errors_name_the_option():
    config = RobotConfig(servos={"a": ServoConfig("a", 1), "b": ServoConfig("b", 300)}, source="robot.toml")
    with pytest.raises(InputError, match="servo id 300 cannot be an MIT-mode motor's CAN id"):
        make_link("can:socketcand:can0?protocol=mit", ["a", "b"], config)
    with pytest.raises(InputError, match="option 'kp' must be a number in 0..500"):
        make_link("can:socketcand:can0?protocol=mit&kp=900", ["a"], config)
    with pytest.raises(InputError, match="option 'protocol' must be firmware or mit"):
        make_link("can:socketcand:can0?protocol=rmd", ["a"], config)
    with pytest.raises(InputError, match="need protocol=mit"):
        make_link("can:socketcand:can0+can1", ["a"], config)


def _sim_time_link(silent: set[int] = frozenset()):
    """Four MIT motors (ids 1..4) on two simulated-time buses, those in ``silent`` absent; the link, unopened,
    and the buses."""
    servos = [ServoConfig(f"j{i}", i + 1, zero=0) for i in range(4)]
    clock = SimClock()
    joints = PlantJoints(ServoPlant(4, position=[0.1, 0.2, 0.3, 0.4]))
    nodes = [MitMotorNode(joints, i, s, lock=_NoLock(), clock=clock.now) for i, s in enumerate(servos)]
    buses = {"a": SimTimeCanBus([n for n in nodes[:2] if n.id not in silent], clock),
             "b": SimTimeCanBus([n for n in nodes[2:] if n.id not in silent], clock)}
    link = MitCanLink("sim", [s.joint for s in servos], servos, ["a", "b"], buses.__getitem__, clock=clock.now)
    return link, buses, nodes


def test_open_finds_each_motors_bus_and_names_one_that_does_not_answer():
    link, buses, nodes = _sim_time_link()
    link.open()
    assert [list(j) for j in link._on_bus] == [[0, 1], [2, 3]]
    assert link.read().positions == pytest.approx([0.1, 0.2, 0.3, 0.4], abs=25 / 65535)
    link, _, _ = _sim_time_link(silent={3})
    with pytest.raises(LinkError, match=r"motor 3 \(j2\) answered on none of a, b"):
        link.open()


def test_a_motor_that_stops_answering_fails_the_read_and_bad_goals_send_nothing():
    link, buses, nodes = _sim_time_link()
    link.open()
    link.read()
    sent = buses["a"].frames + buses["b"].frames
    with pytest.raises(LinkError, match="finite"):
        link.write_goals(np.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(LinkError, match="beyond the motors"):
        link.write_goals(np.array([0.0, 20.0, 0.0, 0.0]))
    assert buses["a"].frames + buses["b"].frames == sent
    link.write_goals(np.array([0.0, 0.1, 0.2, 0.3]))
    assert nodes[3].joints.plant.goal[3] == pytest.approx(0.3, abs=25 / 65535)
    buses["b"].nodes.remove(nodes[3])  # after its answer to those goals: the next read's request goes unanswered
    link.read()
    with pytest.raises(LinkReadError, match=r"no state from 1 motor\(s\) \(j3\)"):
        link.read()
    assert link.stats.read_errors == 1


def test_a_socketcand_daemon_that_is_not_there_is_told_within_a_second():
    """python-can retries a refused connection for 10 s in a busy loop: the link's open (and each reconnection
    of a running loop to a daemon that had gone: it froze the loop that long) took 10 s on main."""
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    config = load_robot(None, None).config
    for url in (f"can:socketcand:can0?protocol=mit&host=127.0.0.1&port={port}",
                f"can:socketcand:can0?host=127.0.0.1&port={port}"):
        link = make_link(url, list(config.servos), config)
        start = time.monotonic()
        with pytest.raises(LinkError, match="refused"):
            link.open()
        assert time.monotonic() - start < 3.0


def test_a_link_without_buses_at_the_end_has_no_bus_summary():
    """A run whose MIT-mode buses were gone at its end (the reconnection failed): main's bus_summary raised
    ValueError (max of nothing) after the loop, before the recording was finished and the summary written."""
    assert bus_summary([], "state", 100.0) is None
