"""The can: link (firmware_protocol's CAN mapping over python-can's slcan interface) against simulated CAN
servo nodes behind a simulated slcan adapter on a pty.

Truth: the plant's joint angles, the nodes' engines, and the fault injector's counters.
"""

from __future__ import annotations

import contextlib
import threading
import time

import can
import numpy as np
import pytest
from sim_support import short_gil_switch, wait_until  # noqa: F401 - short_gil_switch is a fixture
from test_links_support import NAMES, read_until, rig, servo_config, start_posture

import firmware_protocol as fp
from livezmp.links import make_link
from livezmp.links.base import LinkError
from sim_devices.can_servo import CanServoBus
from sim_devices.firmware_board import PlantBackend, PlantJoints
from sim_devices.servo_plant import ServoPlant

pytestmark = pytest.mark.usefixtures("short_gil_switch")
N = 8  # nodes: few enough for python-can's slcan reader to keep up with their streams on a loaded machine
URL_OPTIONS = "bitrate=1000000&sleep_after_open=0&timeout=0.5"


@contextlib.contextmanager
def servo_bus(n: int = N, **kw):
    """Nodes 1..n on a plant at `start_posture`, and an open link to them."""
    plant = ServoPlant(n, position=start_posture(n))
    config = servo_config(n)
    with CanServoBus(plant, list(config.servos), **kw) as bus:
        link = make_link(f"can:slcan:{bus.path}?{URL_OPTIONS}", list(config.servos), config)
        link.open()
        try:
            yield bus, link, plant
        finally:
            link.close()


def test_open_connects_every_node_and_configures_it():
    with servo_bus() as (bus, link, plant):
        for node in bus.nodes:
            engine = node.engine
            assert engine.state == fp.BoardState.ACTIVE
            assert (engine.watchdog_timeout, engine.watchdog_action) == (0.2, fp.WatchdogAction.HOLD)
            assert engine.rates == fp.StreamRates(30, 0, 0, 10)
        assert plant.torque_on.all()
        frame = link.read()
        np.testing.assert_array_equal(frame.positions, start_posture(N))
        np.testing.assert_array_equal(frame.velocities, 0.0)
        assert frame.device_time is None  # each node has its own clock


def test_overload_is_reported_on_its_joint():
    with rig("can", n=N, faults="overload=7@1.5s") as r:
        deadline = time.monotonic() + 3.0
        while not (frame := r.link.read()).hardware_errors and time.monotonic() < deadline:
            pass
        assert frame.hardware_errors == {r.names[6]: fp.JointError.OVERLOAD | fp.JointError.TORQUE_OFF}
        assert not r.plant.torque_on[6] and r.plant.torque_on[[0, 5, 7]].all()


def test_lost_and_corrupt_transfers_are_counted_and_never_read():
    with servo_bus(status_period=0.25) as (bus, link, plant):
        bus.set_faults("drop=0.01,corrupt=0.01,seed=5")  # after the handshakes: every stream has a sequence
        for _ in range(60):
            frame = link.read()
            np.testing.assert_array_equal(frame.positions, start_posture(N))
            np.testing.assert_array_equal(frame.velocities, 0.0)
        injected = bus.set_faults("")
        end = time.monotonic() + 0.4  # every stream (STATUS each 0.25 s) sends again: losses show as gaps
        while time.monotonic() < end:
            link.read()
        assert injected.dropped > 0 and injected.corrupted > 0
        assert link.stats.read_errors == injected.dropped + injected.corrupted
        assert link.stats.errors_by_kind["bad_crc"] == injected.corrupted  # the transfer CRC caught each one


def test_delayed_transfers_arrive_whole():
    with servo_bus() as (bus, link, plant):
        # held back far less than a stream period (33 ms at 30 Hz): nothing overtakes them even when a loaded
        # machine holds the simulator's thread for 20 ms (a 20 ms delay left 13 ms: one stale transfer at load 2)
        bus.set_faults("delay=0.3:5ms,seed=1")
        for _ in range(20):
            np.testing.assert_array_equal(link.read().positions, start_posture(N))
        injected = bus.set_faults("")
        end = time.monotonic() + 0.2
        while time.monotonic() < end:
            link.read()
        assert injected.delayed > 0
        assert link.stats.read_errors == 0  # every delayed transfer came, later


def test_vanished_adapter_raises_then_reconnect_brings_every_node_back():
    with servo_bus() as (bus, link, plant):
        bus.port.vanish()
        with pytest.raises(LinkError):
            link.read()
        assert link.reconnect() is False
        # their watchdogs: no host, so every node holds
        assert wait_until(lambda: {node.engine.state for node in bus.nodes} == {fp.BoardState.HOLDING}, timeout=3.0)
        bus.port.restore()
        assert link.reconnect() is True
        read_until(link, lambda _: {node.engine.state for node in bus.nodes} == {fp.BoardState.ACTIVE})
        np.testing.assert_array_equal(link.read().positions, start_posture(N))
        target = start_posture(N) * 0.5
        link.write_goals(target)
        read_until(link, lambda p: np.abs(p - target).max() < 1e-6)


def test_open_names_a_node_that_does_not_answer():
    config = servo_config(N)
    with CanServoBus(ServoPlant(N - 1), NAMES[:N - 1]) as bus:  # no node 8
        link = make_link(f"can:slcan:{bus.path}?{URL_OPTIONS}", list(config.servos), config)
        with pytest.raises(LinkError, match="node 8: no HELLO_ACK"):
            link.open()


def test_link_over_python_cans_virtual_bus():
    """The same link on an in-process python-can bus (no file descriptor to wait on: recv's own timeout)."""
    channel = f"links-{time.monotonic_ns()}"
    plant = ServoPlant(3, position=start_posture(3))
    joints = PlantJoints(plant)
    buses = [can.Bus(interface="virtual", channel=channel) for _ in range(3)]
    engines = [fp.BoardEngine(fp.CanTransport(bus, node, role="board"), PlantBackend(joints, [node - 1], [node]),
                              joint_ids=[node], joint_names=[NAMES[node - 1]])
               for node, bus in enumerate(buses, start=1)]
    stop = threading.Event()

    def run_nodes():
        while not stop.wait(0.001):  # nodes poll their bus every millisecond until stopped
            for engine in engines:
                engine.step(0.0)

    thread = threading.Thread(target=run_nodes, daemon=True)
    thread.start()
    link = make_link(f"can:virtual:{channel}?rate=200", NAMES[:3], servo_config(3))
    try:
        link.open()
        np.testing.assert_array_equal(link.read().positions, start_posture(3))
        target = np.array([0.2, -0.1, 0.05], dtype=np.float32).astype(float)
        link.write_goals(target)
        read_until(link, lambda p: np.abs(p - target).max() < 1e-6)
        link.close()
    finally:
        stop.set()
        thread.join(timeout=5)
        for bus in buses:
            bus.shutdown()
