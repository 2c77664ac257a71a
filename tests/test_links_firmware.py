"""The fw: link (firmware_protocol over pyserial) against the simulated firmware board on a pty.

Truth: the plant's joint angles, the providers' sensor readings, the board engine's state, and the
fault injector's counters.
"""

from __future__ import annotations

import contextlib
import time

import numpy as np
import pytest
from sim_support import short_gil_switch, wait_until  # noqa: F401 - short_gil_switch is a fixture
from test_links_support import NAMES, read_until, rig, start_posture

import firmware_protocol as fp
from livezmp.links import make_link
from livezmp.links.base import FootSensors, LinkError, LinkReadError
from livezmp.model.robot_config import RobotConfig
from sim_devices.firmware_board import FirmwareBoard
from sim_devices.servo_plant import ServoPlant

pytestmark = pytest.mark.usefixtures("short_gil_switch")


def board_of(r) -> FirmwareBoard:
    return r.devices.devices[0]


def test_open_connects_configures_the_watchdog_and_streams_and_enables_torque():
    with rig("fw") as r:
        engine = board_of(r).engine
        assert engine.state == fp.BoardState.ACTIVE
        assert (engine.watchdog_timeout, engine.watchdog_action) == (0.2, fp.WatchdogAction.HOLD)
        assert engine.rates == fp.StreamRates(500, 0, 0, 10)  # no feet or IMU on this board
        assert all(engine.torque.values()) and r.plant.torque_on.all()


def test_state_is_the_plants_exactly_with_the_board_clock():
    with rig("fw") as r:
        first = r.link.read()
        for _ in range(20):
            frame = r.link.read()
            np.testing.assert_array_equal(frame.positions, start_posture(20))
            np.testing.assert_array_equal(frame.velocities, 0.0)
            np.testing.assert_array_equal(frame.currents, 0.0)
        host, board = frame.t - first.t, frame.device_time - first.device_time
        assert board > 0 and abs(board - host) < 0.01  # the board clock runs with ours


def test_feet_and_imu_come_from_the_providers():
    feet = FootSensors(forces={"left": np.array([10.0, 12.5, 8.0, 9.5]), "right": np.zeros(4)},
                       cop={"left": np.array([0.011, -0.004]), "right": None})
    imu = {"orientation": np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2]),
           "angular_velocity": np.array([0.1, -0.2, 0.3]), "acceleration": np.array([0.25, -0.5, 9.75])}
    names = NAMES[:4]
    with FirmwareBoard(ServoPlant(4), names, foot_sensors=lambda: feet, imu=lambda: imu) as board:
        link = make_link(f"fw:{board.path}?rate=200&timeout=0.3", names, RobotConfig())
        link.open()
        try:
            assert board.engine.rates == fp.StreamRates(200, 200, 200, 10)
            frame = link.read()
            while frame.feet is None or frame.imu is None:
                frame = link.read()
        finally:
            link.close()
    f32 = np.float32
    np.testing.assert_array_equal(frame.feet.forces["left"], feet.forces["left"].astype(f32))
    np.testing.assert_array_equal(frame.feet.forces["right"], 0.0)
    np.testing.assert_array_equal(frame.feet.cop["left"], feet.cop["left"].astype(f32))
    assert frame.feet.cop["right"] is None  # no load: no centre of pressure
    for key, value in imu.items():
        np.testing.assert_array_equal(frame.imu[key], value.astype(f32))


def test_overload_is_reported_on_its_joint():
    with rig("fw", faults="overload=7@0.3s") as r:
        assert r.link.read().hardware_errors == {}
        deadline = time.monotonic() + 3.0
        while not (frame := r.link.read()).hardware_errors and time.monotonic() < deadline:
            pass
        assert frame.hardware_errors == {r.names[6]: fp.JointError.OVERLOAD | fp.JointError.TORQUE_OFF}
        assert not r.plant.torque_on[6] and r.plant.torque_on[[0, 5, 7, 19]].all()


def test_lost_and_corrupt_frames_are_counted_and_never_read():
    with rig("fw") as r:
        board = board_of(r)
        board.set_faults("drop=0.01,corrupt=0.01,seed=2")  # after the handshake, which resets the sequence count
        for _ in range(600):
            frame = r.link.read()
            np.testing.assert_array_equal(frame.positions, start_posture(20))
            np.testing.assert_array_equal(frame.velocities, 0.0)
        injected = board.set_faults("")
        r.link.read()  # the next frame shows the gap left by a loss just before the faults stopped
        assert injected.dropped > 0 and injected.corrupted > 0
        assert r.link.stats.read_errors == injected.dropped + injected.corrupted
        kinds = r.link.stats.errors_by_kind
        rejected = sum(n for kind, n in kinds.items() if kind not in ("seq_gap", "timeout"))
        assert rejected == injected.corrupted  # each corrupt frame rejected once, by CRC or header checks


def test_state_that_arrives_late_is_refused_until_the_link_catches_up():
    with rig("fw", options="timeout=0.1") as r:
        r.link.read()
        board_of(r).set_faults("delay=1:150ms")  # every frame from now on reaches us 0.15 s late
        errors = []
        end = time.monotonic() + 0.6
        while time.monotonic() < end:
            with pytest.raises(LinkReadError) as info:  # no read may hand out such a state
                r.link.read()
            errors.append(str(info.value))
        assert any("ms late: this host is not keeping up" in e for e in errors)
        assert r.link.stats.errors_by_kind["stale"] > 0
        board_of(r).set_faults("")
        frame, deadline = None, time.monotonic() + 3.0
        while frame is None and time.monotonic() < deadline:
            with contextlib.suppress(LinkReadError):
                frame = r.link.read()
        np.testing.assert_array_equal(frame.positions, start_posture(20))


def test_vanished_port_raises_then_reconnect_brings_the_board_back():
    with rig("fw") as r:
        board = board_of(r)
        board.port.vanish()
        with pytest.raises(LinkError):
            r.link.read()
        assert r.link.reconnect() is False
        # its watchdog: no host for 0.2 s
        assert wait_until(lambda: board.engine.state == fp.BoardState.HOLDING, timeout=3.0)
        board.port.restore()
        assert r.link.reconnect() is True
        assert board.engine.state == fp.BoardState.ACTIVE
        np.testing.assert_array_equal(r.link.read().positions, start_posture(20))
        target = start_posture(20) * 0.5
        r.link.write_goals(target)
        read_until(r.link, lambda p: np.abs(p - target).max() < 1e-6)


def test_board_watchdog_holds_when_the_loop_stops_polling():
    with rig("fw") as r:
        target = start_posture(20) + 2.0
        r.link.write_goals(target)
        engine = board_of(r).engine
        # no reads, so no heartbeats: the 0.2 s watchdog holds every joint where it is
        assert wait_until(lambda: engine.state == fp.BoardState.HOLDING, timeout=3.0)
        position, deadline = None, time.monotonic() + 3.0
        while position is None and time.monotonic() < deadline:  # the first reads may find the board's backlog
            try:
                position = r.link.read().positions
            except LinkReadError as err:
                assert "ms late: this host is not keeping up" in str(err)
        assert np.abs(position - target).min() > 0.6  # 4.8 rad/s for 0.2 s at most
        r.link.write_goals(position)  # a valid command resumes
        read_until(r.link, lambda _: engine.state == fp.BoardState.ACTIVE)


def test_open_names_the_joints_the_board_does_not_have():
    with FirmwareBoard(ServoPlant(3), NAMES[:3]) as board:
        link = make_link(f"fw:{board.path}", NAMES[:5], RobotConfig())
        with pytest.raises(LinkError, match="no board has joint\\(s\\) l_sho_roll, r_el"):
            link.open()
