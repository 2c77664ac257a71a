"""Shared helpers of the servo-link tests (test_links_*.py); no tests here."""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
from sim_support import wait_until  # also imported from here by the link tests

from livezmp.links import make_link
from livezmp.links.base import Link
from livezmp.model.robot_config import RobotConfig, ServoConfig
from sim_devices.launch import SimDevices, start_devices
from sim_devices.mock_link import MockLink
from sim_devices.servo_plant import ServoPlant

NAMES = ["r_sho_pitch", "l_sho_pitch", "r_sho_roll", "l_sho_roll", "r_el", "l_el", "r_hip_yaw", "l_hip_yaw",
         "r_hip_roll", "l_hip_roll", "r_hip_pitch", "l_hip_pitch", "r_knee", "l_knee", "r_ank_pitch", "l_ank_pitch",
         "r_ank_roll", "l_ank_roll", "head_pan", "head_tilt"]
HALF_TICK = math.pi / 4096  # rad: the rounding of a 4096-tick encoder
# URL options per kind for the tests: replies on a loaded 2-core machine can take tens of ms.
# CAN: 20 nodes at 20 Hz leave python-can's slcan reader headroom on a busy machine.
TEST_OPTIONS = {"dynamixel": "timeout=0.1", "can": "timeout=0.5&rate=20", "fw": "timeout=0.3", "mock": ""}


def servo_config(n: int = 20) -> RobotConfig:
    """Servo ids 1..n with a different zero tick per servo and every third one reversed."""
    return RobotConfig(servos={name: ServoConfig(name, i + 1, zero=1500 + 60 * i, direction=-1 if i % 3 == 0 else 1)
                               for i, name in enumerate(NAMES[:n])}, source="test config")


def start_posture(n: int) -> np.ndarray:
    """Distinct joint angles (rad) that fall between encoder ticks and are float32 numbers, so that a board
    holding them (positions travel as float32) holds them exactly."""
    return (np.linspace(-0.6, 0.6, n) + 1e-4).astype(np.float32).astype(float)


@dataclass
class Rig:
    kind: str
    plant: ServoPlant
    config: RobotConfig
    names: list[str]
    link: Link
    devices: SimDevices | None


def with_options(url: str, options: str) -> str:
    return url + ("&" if "?" in url else "?") + options if options else url


@contextlib.contextmanager
def rig(kind: str, n: int = 20, faults: str = "", options: str | None = None, devices: dict | None = None,
        **plant_options) -> Iterator[Rig]:
    """A plant at `start_posture` (other `ServoPlant` parameters: ``plant_options``), its simulated devices of
    ``kind`` (`start_devices` keyword arguments: ``devices``) and an open link to them (``mock``: none)."""
    plant = ServoPlant(n, position=start_posture(n), **plant_options)
    config = servo_config(n)
    names = list(config.servos)
    if kind == "mock":
        link = MockLink(plant, names)
        link.open()
        yield Rig(kind, plant, config, names, link, None)
        link.close()
        return
    with start_devices(kind, plant, config, faults=faults, **(devices or {})) as sim:
        link = make_link(with_options(sim.url, TEST_OPTIONS[kind] if options is None else options), names, config)
        link.open()
        try:
            yield Rig(kind, plant, config, names, link, sim)
        finally:
            link.close()


def plant_now(r: Rig) -> ServoPlant:
    """The plant, stepped to now: the Dynamixel chain steps it only when a packet needs it (a register read
    does); the boards and CAN nodes step it at every JOINT_STATE they stream; the mock at every read."""
    if r.kind == "dynamixel":
        r.devices.devices[0].register(1, "present_position")
    elif r.kind == "mock":
        r.link.read()
    else:  # two more steps: one that started after this call has run whole
        steps = r.plant.steps
        assert wait_until(lambda: r.plant.steps >= steps + 2, timeout=2.0)
    return r.plant


def read_until(link: Link, done: Callable[[np.ndarray], bool], timeout: float = 3.0) -> np.ndarray:
    """Read until ``done(positions)`` holds; the last positions. AssertionError at the deadline; a read that
    fails (there are no faults where this is used) is an error too."""
    deadline = time.monotonic() + timeout
    positions = None
    while time.monotonic() < deadline:
        positions = link.read().positions
        if done(positions):
            return positions
    raise AssertionError(f"condition not met within {timeout} s; last positions {positions}")


