"""The dynamixel: link (dynamixel-sdk, Protocol 2.0) against the simulated XM430 chain on a pty.

Truth: the plant's joint angles, the servos' registers, and the fault injector's counters.
"""

from __future__ import annotations

import contextlib
import struct
import time
from dataclasses import replace
from unittest import mock

import numpy as np
import pytest
from sim_support import short_gil_switch, wait_until  # noqa: F401 - short_gil_switch is a fixture
from test_links_support import (
    HALF_TICK,
    TEST_OPTIONS,
    plant_now,
    read_until,
    rig,
    servo_config,
    start_posture,
    with_options,
)

from livezmp.links import make_link
from livezmp.links.base import LinkError, LinkReadError
from livezmp.links.bus_timing import ADAPTERS
from livezmp.links.dynamixel import FAST_SYNC_READ_FIRMWARE, DynamixelLink
from livezmp.links.reply_loss import ReplyLoss
from livezmp.model.robot_config import RobotConfig
from sim_devices.dynamixel_chain import DynamixelChain
from sim_devices.dynamixel_control_table import OVERLOAD_ERROR
from sim_devices.launch import start_devices
from sim_devices.servo_plant import ServoPlant

pytestmark = pytest.mark.usefixtures("short_gil_switch")


def chain_of(r):
    return r.devices.devices[0]


def test_a_short_read_timeout_does_not_stop_the_open():
    # the servos come with factory return delays (20 x 0.5 ms for one sync read): open waits the
    # sdk's own timeout, and only the reads after it are cut to 6 ms
    # (6 ms: a sync read of 20 positions is 3.3 ms on the wire at 1 Mbps, plus 1.5 ms of USB adapter)
    with rig("dynamixel", options="timeout=0.006&fast=0") as r:
        ids = [s.id for s in r.config.servos.values()]
        assert [chain_of(r).register(i, "return_delay_time") for i in ids] == [0] * 20
        r.link.read()
        assert r.link._port.packet_timeout == pytest.approx(6.0)  # ms, as the sdk keeps it


def true_ticks(r) -> np.ndarray:
    """Present Position of every servo, read from the simulated servos themselves."""
    return np.array([chain_of(r).register(s.id, "present_position") for s in r.config.servos.values()])


def test_open_sets_return_delay_arms_watchdog_and_enables_torque():
    with rig("dynamixel") as r:
        chain = chain_of(r)
        ids = [s.id for s in r.config.servos.values()]
        assert [chain.register(i, "return_delay_time") for i in ids] == [0] * 20  # factory 250 before open
        assert [chain.register(i, "bus_watchdog") for i in ids] == [5] * 20  # 0.1 s in 20 ms units
        assert [chain.register(i, "torque_enable") for i in ids] == [1] * 20
        assert r.plant.torque_on.all()


def test_positions_follow_each_servos_zero_and_direction():
    with rig("dynamixel") as r:
        frame = r.link.read()
        ticks = true_ticks(r)
        expected = [s.to_rad(t) for s, t in zip(r.config.servos.values(), ticks, strict=True)]
        np.testing.assert_array_equal(frame.positions, expected)
        assert np.abs(frame.positions - start_posture(20)).max() <= HALF_TICK
        reversed_ = [s.direction < 0 for s in r.config.servos.values()]
        assert any(reversed_) and not all(reversed_)  # the config does exercise both directions


def test_fast_sync_read_reads_the_same_as_sync_read():
    with rig("dynamixel", options="timeout=0.1&fast=0") as r:
        assert not r.link.fast_read
        slow = r.link.read()
        fast_link = make_link(with_options(r.devices.url, "fast=1&timeout=0.1&read=state"), r.names, r.config)
        fast_link.open()
        try:
            fast = fast_link.read()
        finally:
            fast_link.close()
        np.testing.assert_array_equal(fast.positions, slow.positions)
        assert fast.velocities.shape == fast.currents.shape == (20,)
        assert slow.velocities is None and slow.currents is None  # read=position: only what the loop uses


def test_fast_sync_read_by_default_only_where_every_servo_has_it():
    with rig("dynamixel") as r:  # fast=auto: the simulated XM430s run firmware 46
        assert r.link.fast_read
        chain = chain_of(r)
        chain.set_register(9, "firmware_version", FAST_SYNC_READ_FIRMWARE - 1)  # one servo too old
        old = make_link(with_options(r.devices.url, "timeout=0.1"), r.names, r.config)
        old.open()
        try:
            assert not old.fast_read
            np.testing.assert_array_equal(old.read().positions, r.link.read().positions)
        finally:
            old.close()


def test_overload_is_reported_as_hardware_error_of_that_joint():
    with rig("dynamixel", faults="overload=7@0.3s") as r:
        assert r.link.read().hardware_errors == {}
        deadline = time.monotonic() + 3.0
        while not (frame := r.link.read()).hardware_errors and time.monotonic() < deadline:
            pass
        assert frame.hardware_errors == {r.names[6]: OVERLOAD_ERROR}  # servo id 7
        assert not r.plant.torque_on[6] and r.plant.torque_on[[0, 5, 7, 19]].all()  # its Shutdown dropped torque
        assert chain_of(r).fault_counters.overloads == 1


@pytest.mark.parametrize(("fast", "reads"), [(False, 60), (True, 300)])
def test_lost_and_corrupt_replies_are_counted_and_never_read(fast, reads):
    spec = "drop=0.01,corrupt=0.01,seed=4"
    with rig("dynamixel", faults=spec, options=f"timeout=0.1&fast={int(fast)}") as r:
        chain = chain_of(r)
        truth = np.array([s.to_rad(round(s.zero + s.direction * q * 4096 / (2 * np.pi)))
                          for s, q in zip(r.config.servos.values(), start_posture(20), strict=True)])
        failed = recovered = 0
        for _ in range(reads):
            before = chain.fault_counters.dropped + chain.fault_counters.corrupted
            try:
                frame = r.link.read()
            except LinkReadError:
                failed += 1
                assert chain.fault_counters.dropped + chain.fault_counters.corrupted > before
                continue
            # a plain sync read asks the servos whose replies were lost again; a fast one cannot
            recovered += chain.fault_counters.dropped + chain.fault_counters.corrupted > before
            np.testing.assert_array_equal(frame.positions, truth)
        injected = chain.fault_counters
        assert injected.dropped > 0 and injected.corrupted > 0
        assert (recovered > failed) if not fast else (failed > 0 and recovered == 0)
        assert r.link.stats.read_errors == injected.dropped + injected.corrupted
        kinds = r.link.stats.errors_by_kind
        assert kinds.get("no_reply", 0) == injected.dropped and kinds.get("bad_crc", 0) == injected.corrupted


def test_vanished_port_raises_then_reconnect_rearms_the_tripped_watchdog():
    with rig("dynamixel") as r:
        chain = chain_of(r)
        chain.port.vanish()
        with pytest.raises(LinkError):
            r.link.read()
        assert r.link.reconnect() is False
        # the bus watchdog (0.1 s) trips: the servos stop and refuse goals until it is re-armed
        assert wait_until(lambda: chain.register(1, "bus_watchdog") == -1, timeout=2.0)
        chain.port.restore()
        assert r.link.reconnect() is True
        assert r.link.stats.reconnects == 1
        assert chain.register(1, "bus_watchdog") == 5
        assert np.abs(r.link.read().positions - start_posture(20)).max() <= HALF_TICK
        target = start_posture(20) * 0.5
        r.link.write_goals(target)
        read_until(r.link, lambda p: np.abs(p - target).max() <= 2 * HALF_TICK)


def test_bus_watchdog_stops_the_servos_when_the_host_goes_quiet():
    with rig("dynamixel") as r:
        target = start_posture(20) + 1.2
        r.link.write_goals(target)
        chain = chain_of(r)
        # no traffic: the 0.1 s watchdog trips on every servo, and each brakes to a stop short of its goal
        assert wait_until(lambda: all(chain.register(s.id, "bus_watchdog") == -1 for s in r.config.servos.values())
                          and np.abs(plant_now(r).velocity).max() < 1e-3, timeout=3.0)
        position = r.plant.position
        assert np.abs(position - target).min() > 0.3
        assert np.abs(position - start_posture(20)).min() > 0.05


@pytest.mark.parametrize(("ahead", "rearm"), [(False, True), (True, True), (True, False)])
def test_after_a_host_stall_the_tripped_watchdog_is_cleared_before_the_goals(ahead, rearm, monkeypatch):
    """The host stalls after open (here: it waits until the simulated servos report the trip; on a robot a
    memory lock or a page-in) longer than the 0.1 s Bus Watchdog: the servos trip it, and a goal sync write,
    which has no reply, would be ignored without a word. The link saw the silence and clears and re-arms the
    watchdog before its next goals, which the servos then follow; without that (rearm False) they are refused."""
    if not rearm:
        monkeypatch.setattr(DynamixelLink, "_rearm_after_silence", lambda self: None)
    with rig("dynamixel", options="fast=1&timeout=0.1&watchdog=0.1") as r:
        chain, ids = chain_of(r), [s.id for s in r.config.servos.values()]
        before = [chain.register(i, "goal_position") for i in ids]
        assert wait_until(lambda: all(chain.register(i, "bus_watchdog") == -1 for i in ids), timeout=2.0)
        target = r.link.read().positions + 0.2
        if ahead:
            r.link.prepare_goals(target)
            r.link.send_prepared()
        else:
            r.link.write_goals(target)
        r.link.read()  # its instruction follows the goals on the wire: the servos handled them before it
        goals = [chain.register(i, "goal_position") for i in ids]
        if not rearm:
            assert goals == before and "watchdog_rearmed" not in r.link.stats.errors_by_kind
            return
        assert goals == list(r.link.goal_ticks(target)) and chain.register(ids[0], "bus_watchdog") == 5
        assert r.link.stats.errors_by_kind["watchdog_rearmed"] == 1
        read_until(r.link, lambda p: np.abs(p - target).max() <= 2 * HALF_TICK)


def test_goal_beyond_a_servos_position_limits_is_refused():
    with rig("dynamixel") as r:
        goals = start_posture(20)
        goals[2] = 2.5  # servo 3: zero 1620 + 2.5 rad * 652 ticks/rad = 3250 ticks: inside 0..4095
        r.link.write_goals(goals)
        goals[4] = -3.0  # servo 5: 1740 - 1956 < 0; its range is (0 - 1740, 4095 - 1740) * 2 pi / 4096 rad
        with pytest.raises(LinkError, match=r"'r_el' is -3.0 rad, outside its servo's range \[-2.6691, 3.6125\]"):
            r.link.write_goals(goals)


@contextlib.contextmanager
def devices_with(registers: dict):
    """Simulated servos for the test config with ``registers`` written to servo 5; (devices, config), no link."""
    config = servo_config(20)
    with start_devices("dynamixel", ServoPlant(20), config) as devices:
        for name, value in registers.items():
            devices.devices[0].set_register(5, name, value)
        yield devices, config


@pytest.mark.parametrize(("registers", "message"), [
    ({"operating_mode": 1}, r"servo 5 \(r_el\) is in operating mode 1, not a position mode"),
    ({"torque_enable": 1}, r"servo 5 \(r_el\) has Return Delay Time 500 us and torque on"),
])
def test_open_refuses_servos_it_cannot_drive(registers, message):
    with devices_with(registers) as (devices, config):
        link = make_link(with_options(devices.url, TEST_OPTIONS["dynamixel"]), list(config.servos), config)
        with pytest.raises(LinkError, match=message):
            link.open()


def test_open_refuses_servos_that_answer_as_another_model_than_the_config_says():
    """The config says every servo is an XM430-W350 (model 1020); servo 5 answers as an XM540-W270 (1120): open
    refuses in one line naming it, before torque goes on (main: opened and drove it). Servos the config gives no
    model for are not asked; the same servos with the right models open."""
    config = servo_config(20)
    stated = RobotConfig(servos={n: replace(s, model=1020) for n, s in config.servos.items()}, source="test config")
    with start_devices("dynamixel", ServoPlant(20), stated) as devices:
        devices.devices[0].set_register(5, "model_number", 1120)
        devices.devices[0].set_register(9, "model_number", 1120)
        link = make_link(with_options(devices.url, TEST_OPTIONS["dynamixel"]), list(stated.servos), stated)
        with pytest.raises(LinkError, match=r"servo 5 \(r_el\) answers as Dynamixel model 1120, the robot config says "
                                            r"1020 \(2 of 20 servos differ\)"):
            link.open()
        assert not any(devices.devices[0].register(i, "torque_enable") for i in range(1, 21))
        unsaid = RobotConfig(servos={n: replace(s, model=None if s.id in (5, 9) else 1020)
                                     for n, s in stated.servos.items()}, source="test config")
        link = make_link(with_options(devices.url, TEST_OPTIONS["dynamixel"]), list(unsaid.servos), unsaid)
        link.open()
        link.close()


def test_open_names_a_servo_that_does_not_answer():
    config = servo_config(20)
    with DynamixelChain(range(1, 20), ServoPlant(19)) as chain:  # no servo 20
        link = make_link(f"dynamixel:{chain.path}?timeout=0.05", list(config.servos), config)
        with pytest.raises(LinkError, match=r"nothing usable from servo 20 \(head_tilt\).*check power, ids"):
            link.open()


class FrozenPlant:
    """A `JointPlant` that never moves: its state is what the test sets."""

    def __init__(self, n: int) -> None:
        self.position, self.velocity, self.current = np.zeros(n), np.zeros(n), np.zeros(n)

    def set_goal(self, idx: int, position: float) -> None:
        """Ignored."""

    def set_torque(self, idx: int, on: bool) -> None:
        """Ignored."""

    def step(self, dt: float) -> None:
        """Nothing moves."""


def test_a_byte_stuffed_status_packet_is_read_correctly():
    # Present Current -1 (FF FF) then Present Velocity -3 (FD FF FF FF): the servo stuffs FF FF FD into FF FF FD FD
    assert b"\xff\xff\xfd" in struct.pack("<hi", -1, -3)
    config = servo_config(20)
    plant = FrozenPlant(20)
    plant.current[1] = -2.69e-3  # servo 2 turns forwards (direction +1); units of the XM430 e-manual
    plant.velocity[1] = -3 * 0.229 * 2 * np.pi / 60
    with start_devices("dynamixel", plant, config) as devices:
        link = make_link(with_options(devices.url, TEST_OPTIONS["dynamixel"] + "&read=state"), list(config.servos),
                         config)
        link.open()
        try:
            frame = link.read()
        finally:
            link.close()
    assert frame.currents[1] == pytest.approx(-2.69e-3)
    assert frame.velocities[1] == pytest.approx(-3 * 0.229 * 2 * np.pi / 60)
    assert link.stats.read_errors == 0


@pytest.mark.parametrize(("options", "per_cycle"), [
    # Protocol 2.0 (e-manual): Sync Read instruction 14 + 20 ids; a status packet 11 + data each, or one Fast
    # Sync Read reply of 8 + 20 x (4 + data); Sync Write of 20 goals 14 + 20 x 5 = 114
    ("fast=0&read=position", 34 + 20 * 15 + 114),
    ("fast=1&read=position", 34 + 8 + 20 * 8 + 114),
    ("fast=1&read=state", 34 + 8 + 20 * 14 + 114),
])
def test_the_bus_ceiling_counts_the_bytes_a_cycle_moves(options, per_cycle):
    with rig("dynamixel", options=options + "&timeout=0.1") as r:
        for _ in range(5):
            r.link.write_goals(r.link.read().positions)
        (ceiling,) = r.link.bus_ceilings(ADAPTERS["ftdi-fs"])
    assert ceiling.bytes_per_cycle == per_cycle
    assert ceiling.wire_s == pytest.approx(per_cycle * 10 / 1e6)
    assert ceiling.ceiling_hz == pytest.approx(1 / (per_cycle * 10e-6 + 1.5e-3))


@pytest.mark.parametrize("ahead", [False, True])
def test_goals_and_the_next_read_instruction_go_out_in_one_write(ahead):
    """A pipelined loop's cycle: goals with the next read's instruction in one write to the port (one USB
    transfer), built at once or ahead (`prepare_goals`); the goals reach the servos, the next read gets
    its replies, and the bytes a cycle moves are still the packet sizes (Sync Write 114, Fast Sync Read
    instruction 34 and reply 8 + 20 x 8)."""
    with rig("dynamixel", options="fast=1&timeout=0.1") as r:
        writes = []
        ser = r.link._port.ser
        send = ser.write
        ser.write = lambda data: writes.append(bytes(data)) or send(data)
        frame = r.link.read()
        for k in range(5):
            goals = frame.positions + 0.01 * (k + 1)
            if ahead:
                r.link.prepare_goals(goals)
                r.link.send_prepared()
            else:
                r.link.write_goals(goals, request=True)
            frame = r.link.read()
        (ceiling,) = r.link.bus_ceilings(ADAPTERS["ftdi-fs"])
        assert wait_until(lambda: np.array_equal(
            [chain_of(r).register(s.id, "goal_position") for s in r.config.servos.values()],
            r.link.goal_ticks(goals)), 2.0)
    cycle = writes[1:6]  # the first is the read's own instruction
    assert [len(w) for w in cycle] == [114 + 34] * 5
    assert all(w[7] == 0x83 and w[114 + 7] == 0x8A for w in cycle)  # Sync Write, then Fast Sync Read
    assert ceiling.bytes_per_cycle == 114 + 34 + 8 + 20 * 8


def test_reply_loss_is_measured_over_a_sliding_window():
    loss = ReplyLoss(window=100, limit=0.15)
    for _ in range(4):
        loss.add(20, 4)  # 20 % lost, but only 80 replies seen: not yet enough to judge
    assert loss.fraction == pytest.approx(0.2) and not loss.exceeded()
    loss.add(20, 4)
    assert loss.exceeded()
    for _ in range(10):
        loss.add(20, 0)  # the bus recovered: the old losses leave the window
    assert loss.fraction == 0.0 and not loss.exceeded()
    for _ in range(5):
        loss.add(20, 4)
    for _ in range(ReplyLoss.SILENT_RUN):
        loss.add(20, 20)  # unplugged: silence is the watchdog's and reconnect's business, not a noisy bus
    assert loss.fraction == 0.0 and not loss.exceeded()


def test_a_simulated_bus_is_seen_as_a_pty_and_a_usb_adapter_is_not(tmp_path):
    """pty_ports follows the port's path to what it names: the simulated chain's stable symlink leads to
    /dev/pts/N (the loop then lets the kernel carry its bytes, see livezmp.live.loop); a USB adapter's
    path, or a link to one, does not."""
    config = servo_config(2)
    names = list(config.servos)
    with rig("dynamixel") as r:
        assert r.link.pty_ports == 1
        # found when the port opened: the loop asks every cycle, and following the links costs a cycle ~10 us
        with mock.patch("livezmp.links.dynamixel.os.path.realpath", side_effect=AssertionError("path followed")):
            assert r.link.pty_ports == 1
    usb = tmp_path / "robot-bus"
    usb.symlink_to("/dev/ttyUSB0")
    for path in ("/dev/ttyUSB0", str(usb)):
        assert DynamixelLink(path, names, list(config.servos.values())).pty_ports == 0
