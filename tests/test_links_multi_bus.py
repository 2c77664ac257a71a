"""One robot on several simulated Dynamixel buses (dynamixel:PATH1+PATH2), through dynamixel-sdk.

Truth: the plant's joint angles and goals, and the wire time of each bus's packets."""

from __future__ import annotations

import time

import numpy as np
import pytest
from sim_support import short_gil_switch  # noqa: F401 - fixture
from test_links_support import HALF_TICK, read_until, rig, servo_config, start_posture

from livezmp.links import make_link
from livezmp.links.base import LinkError
from livezmp.links.bus_timing import ADAPTERS
from livezmp.links.multi_bus import MultiBusLink
from sim_devices.launch import start_devices
from sim_devices.servo_plant import ServoPlant

pytestmark = pytest.mark.usefixtures("short_gil_switch")


def test_two_buses_are_one_robot_read_and_driven_in_joint_order():
    with rig("dynamixel", devices={"buses": 2}, options="timeout=0.1") as r:
        assert isinstance(r.link, MultiBusLink) and len(r.devices.devices) == 2
        assert r.link.pty_ports == 2  # simulated buses: the loop lets the kernel carry their bytes, each bus's
        assert [len(bus.ids) for bus in r.link.buses] == [10, 10]
        frame = r.link.read()
        assert np.abs(frame.positions - start_posture(20)).max() <= HALF_TICK
        target = start_posture(20)[::-1] * 0.5
        r.link.write_goals(target)
        read_until(r.link, lambda p: np.abs(p - target).max() <= 2 * HALF_TICK + 1e-9)
        r.link.write_goals(r.link.read().positions)
        # each bus: a Fast Sync Read of 10 (14 + 10 bytes; reply 8 + 10 x 8) and a Sync Write of 10 (14 + 10 x 5)
        assert [c.bytes_per_cycle for c in r.link.bus_ceilings(ADAPTERS["hs"])] == [24 + 88 + 64] * 2


def test_a_bus_left_idle_while_the_next_one_opens_still_takes_goals(monkeypatch):
    """The second bus opens slowly (0.3 s: a loaded host, a slow adapter) while the first, already open,
    hears nothing: its servos' 0.1 s Bus Watchdog trips and they refuse goals until it is cleared. Each
    bus saw its silence and re-arms its watchdog before its next goals, so both buses follow them."""
    from livezmp.links.dynamixel import DynamixelLink

    opened = []
    original = DynamixelLink.open

    def slow_second_open(self):
        if opened:
            time.sleep(0.3)  # the slow open being modelled, not a wait for a condition
        original(self)
        opened.append(self)

    monkeypatch.setattr(DynamixelLink, "open", slow_second_open)
    with rig("dynamixel", devices={"buses": 2}, options="timeout=0.1&watchdog=0.1") as r:
        target = start_posture(20)[::-1] * 0.5
        r.link.write_goals(target)
        read_until(r.link, lambda p: np.abs(p - target).max() <= 2 * HALF_TICK + 1e-9)


def test_joints_interleaved_over_the_buses_come_back_in_the_links_joint_order():
    """The link's joints in an order that alternates between the buses (the simulated robot puts its first
    ten servos on one port, the rest on the other): each frame and each goal is still in the link's order."""
    config = servo_config(20)
    plant = ServoPlant(20, position=start_posture(20))
    order = [k // 2 + 10 * (k % 2) for k in range(20)]  # joints 0, 10, 1, 11, ...
    names = [list(config.servos)[j] for j in order]
    with start_devices("dynamixel", plant, config, buses=2) as sim:
        link = make_link(f"{sim.url}&timeout=0.1", names, config)
        link.open()
        try:
            assert [list(joints) for joints in link._joints] == [list(range(0, 20, 2)), list(range(1, 20, 2))]
            np.testing.assert_allclose(link.read().positions, start_posture(20)[order], atol=HALF_TICK)
            link.prepare_goals(start_posture(20)[order] * 0.5)
            link.send_prepared()
            read_until(link, lambda p: np.abs(p - start_posture(20)[order] * 0.5).max() <= 2 * HALF_TICK + 1e-9)
            np.testing.assert_allclose(plant.goal, start_posture(20) * 0.5, atol=HALF_TICK)  # in the plant's order
        finally:
            link.close()


def mean_read_time(url: str, names, config, reads: int = 4) -> float:
    link = make_link(url, names, config)
    link.open()
    try:
        start = time.perf_counter()
        for _ in range(reads):
            link.read()
        return (time.perf_counter() - start) / reads
    finally:
        link.close()


def test_the_buses_are_read_at_the_same_time():
    # At 57600 baud a sync read of 20 positions is 34 + 20 x 15 bytes = 58 ms on one wire; split 10 + 10 over
    # two wires each carries 24 + 10 x 15 bytes = 30 ms, and in parallel the read takes that, not twice it.
    config = servo_config(20)
    names = list(config.servos)
    took = {}
    for buses in (1, 2):
        plant = ServoPlant(20, position=start_posture(20))
        with start_devices("dynamixel", plant, config, baud=57600, adapter="none", buses=buses) as sim:
            took[buses] = mean_read_time(sim.url + "&fast=0&timeout=0.5", names, config)
    print(f"one bus {1e3 * took[1]:.1f} ms, two buses {1e3 * took[2]:.1f} ms a read")
    assert took[1] >= 334 * 10 / 57600 and took[2] >= 174 * 10 / 57600  # no read beats its wire
    assert took[2] < 0.65 * took[1]  # in series it would take 348 / 334 of one bus's read


def test_a_servo_on_no_bus_is_named():
    config = servo_config(20)
    names = list(config.servos)
    plant = ServoPlant(19)
    short = type(config)(servos={n: s for n, s in config.servos.items() if s.id != 20}, source="test")
    with start_devices("dynamixel", plant, short, joint_names=names[:19], buses=2) as sim:
        link = make_link(sim.url + "&timeout=0.05", names, config)
        with pytest.raises(LinkError, match=r"servo 20 \(head_tilt\) answered on none of"):
            link.open()


def test_goals_are_converted_once_for_the_robot_and_refused_by_their_bus(monkeypatch):
    """The goals' ticks are made and checked for every joint at once (interleaved joints), each bus's share cut
    from them: the same ticks each bus's own conversion gives, and a goal beyond its servo's range refused in the
    bus's words, nothing sent."""
    from livezmp.links.dynamixel import DynamixelLink

    config = servo_config(20)
    order = [k // 2 + 10 * (k % 2) for k in range(20)]
    names = [list(config.servos)[j] for j in order]
    with start_devices("dynamixel", ServoPlant(20, position=start_posture(20)), config, buses=2) as sim:
        link = make_link(f"{sim.url}&timeout=0.1", names, config)
        link.open()
        try:
            convert, calls = DynamixelLink.goal_ticks, []
            monkeypatch.setattr(DynamixelLink, "goal_ticks", lambda self, p: calls.append(1) or convert(self, p))
            goals = start_posture(20)[order] * 0.5 + np.linspace(-0.3, 0.3, 20)
            link.prepare_goals(goals)
            for bus, joints in zip(link.buses, link._joints, strict=True):
                assert np.array_equal(bus._goal_packet._goals, convert(bus, goals[joints]))
            link.write_goals(goals)
            assert not calls
            goals[7] = 10.0  # rad: past the servo's 4095 ticks
            sent = link.stats.writes
            with pytest.raises(LinkError, match=f"goal for joint '{names[7]}' is 10.0 rad, outside its servo's range"):
                link.write_goals(goals)
            assert link.stats.writes == sent
        finally:
            link.close()
