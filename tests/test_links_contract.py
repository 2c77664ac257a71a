"""The Link contract, the same tests on every backend: the real clients (dynamixel-sdk, python-can slcan,
pyserial) against the simulated devices on ptys, and the in-process mock.

Truth is the simulated plant: its joint angles, and where it moves to.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from sim_support import short_gil_switch  # noqa: F401 - fixture
from test_links_support import HALF_TICK, plant_now, read_until, rig, start_posture, wait_until

from livezmp.links.base import LinkError

pytestmark = pytest.mark.usefixtures("short_gil_switch")
KINDS = ["dynamixel", "can", "fw", "mock"]
N = {"dynamixel": 20, "can": 20, "fw": 20, "mock": 20}


def tolerance(kind: str) -> float:
    """How close a read position must be to the plant's: half an encoder tick, or float32 rounding."""
    return HALF_TICK if kind == "dynamixel" else 1e-6


@pytest.mark.parametrize("kind", KINDS)
def test_read_gives_the_plant_positions_in_joint_order(kind):
    with rig(kind, N[kind]) as r:
        frame = r.link.read()
        assert frame.positions.shape == (N[kind],)
        assert np.abs(frame.positions - start_posture(N[kind])).max() <= tolerance(kind)
        if frame.velocities is not None:  # the dynamixel: link reads only positions by default
            assert np.abs(frame.velocities).max() < 0.05  # holding still
        later = r.link.read()
        assert later.t > frame.t
        assert r.link.stats.read_errors == 0


@pytest.mark.parametrize("kind", KINDS)
def test_goals_move_the_plant_to_them(kind):
    with rig(kind, N[kind]) as r:
        target = start_posture(N[kind])[::-1] * 0.5
        r.link.write_goals(target)
        read_until(r.link, lambda p: np.abs(p - target).max() <= 2 * tolerance(kind) + 1e-9)
        assert np.abs(plant_now(r).position - target).max() <= 2 * tolerance(kind) + 1e-9


@pytest.mark.parametrize("kind", KINDS)
def test_safe_stop_holds_where_the_robot_is_then_drops_torque(kind):
    with rig(kind, N[kind], max_velocity=0.5) as r:  # slow joints: the test does not race the link's latency
        start = start_posture(N[kind])
        target = start + 1.2
        r.link.write_goals(target)
        read_until(r.link, lambda p: np.abs(p - start).min() > 0.05)  # every joint on its way
        r.link.safe_stop()
        stopped_near = plant_now(r).position.copy()
        end = time.monotonic() + 0.3  # without the hold it would go on by 0.15 rad
        while time.monotonic() < end:
            r.link.read()  # bus traffic: a Dynamixel bus watchdog would stop the servos, and hide a missing hold
        final = plant_now(r).position.copy()
        assert np.abs(final - stopped_near).max() < 0.05  # 0.1 s of motion: how old a CAN read at 20 Hz can be
        assert np.abs(final - target).min() > 0.6
        assert np.abs(r.plant.velocity).max() < 1e-3
        r.link.safe_stop()  # idempotent
        r.link.safe_stop(drop_torque=True)
        assert wait_until(lambda: not r.plant.torque_on.any(), timeout=2.0)


@pytest.mark.parametrize("kind", KINDS)
def test_non_finite_goals_are_refused_and_nothing_is_sent(kind):
    with rig(kind, N[kind]) as r:
        goals = start_posture(N[kind]) + 0.3
        goals[4] = np.nan
        with pytest.raises(LinkError, match=f"'{r.names[4]}'"):
            r.link.write_goals(goals)
        # nothing reaches the servos in the next 0.1 s
        assert not wait_until(lambda: np.abs(r.plant.goal - start_posture(N[kind])).max() > tolerance(kind),
                              timeout=0.1)
        with pytest.raises(LinkError, match="positions"):
            r.link.write_goals(np.zeros(3))


@pytest.mark.parametrize("kind", ["dynamixel", "can", "fw"])
def test_port_that_vanishes_and_returns_by_fault_spec_is_reconnected(kind):
    with rig(kind, 4, faults="vanish=1s+0.3s") as r:
        port = r.devices.ports[0]
        deadline = time.monotonic() + 3.0
        with pytest.raises(LinkError):  # some read fails once the port is gone...
            while time.monotonic() < deadline:
                r.link.read()
        assert wait_until(lambda: r.devices.fault_counters.vanishes == 1)
        # ...and the link is back with it
        wait_until(r.link.reconnect, timeout=max(deadline + 1.0 - time.monotonic(), 0.0), interval=0.05)
        assert port.present and r.link.stats.reconnects == 1
        assert np.abs(r.link.read().positions - start_posture(4)).max() <= tolerance(kind)
