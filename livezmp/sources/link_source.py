"""A servo link (``dynamixel:``, ``can:``, ``fw:``) as a monitor source: watch a robot's
balance without commanding it.

Each :meth:`LinkSource.read` waits for the next period, reads one verified frame from
the link, places the base from the joint angles (stance foot flat, as the live loop
does) and hands out ``[base x, y, z, yaw, pitch, roll, joints]``. Foot sensors, when the
device has them, give the contacts: a foot bears weight when its cells carry more than
``contact_fraction`` of the body's weight (:func:`livezmp.balance.foot_sensors.sensor_contacts`).
A failed read is counted as malformed and reported; a lost port is reported as
"disconnected" and retried with ``reconnect``.
The monitor never writes goals: the link holds the posture it found at open.
"""

from __future__ import annotations

import time

import numpy as np

from livezmp.balance.foot_sensors import CONTACT_FRACTION, contact_force, sensor_contacts
from livezmp.links import open_link
from livezmp.links.base import Link, LinkError, LinkReadError
from livezmp.model.base_placement import BasePlacer
from livezmp.model.body import BodyModel
from livezmp.model.body_spec import BodySpec
from livezmp.model.mimic import follow
from livezmp.model.robot_config import RobotConfig
from livezmp.sources.interface import ErrorLog, SourceFrame, SourceStats


class LinkSource:
    """Frames read from a servo link (see module docstring); ``rate_hz`` the polling rate."""

    def __init__(self, url: str, body: BodyModel, body_spec: BodySpec, robot_config: RobotConfig,
                 rate_hz: float = 100.0, contact_fraction: float = CONTACT_FRACTION, link: Link | None = None):
        self.name = url
        self.body = body
        self.body_spec = body_spec
        self.nominal_dt = 1.0 / rate_hz
        self.stats = SourceStats()
        self.errors = ErrorLog()
        self.link = link or open_link(url, body.joint_names, robot_config)
        self._placer = BasePlacer(body)
        self._min_force = contact_force(body, contact_fraction)
        self._next = time.monotonic()
        self._t_last = -np.inf

    @property
    def finished(self) -> bool:
        return False

    def read(self, timeout: float) -> SourceFrame | None:
        now = time.monotonic()
        wait = self._next - now
        if wait > timeout:
            time.sleep(timeout)
            return None
        if wait > 0:
            time.sleep(wait)
        self._next = max(self._next + self.nominal_dt, time.monotonic())
        try:
            frame = self.link.read()
        except LinkReadError as e:
            self.stats.malformed += 1
            self.errors.report("malformed", f"{self.name}: {e}")
            return None
        except LinkError as e:
            self.stats.disconnected += 1
            self.errors.report("disconnected", f"{self.name}: {e}")
            if self.link.reconnect():
                self.stats.reconnects += 1
            return None
        if not frame.t > self._t_last:
            self.stats.malformed += 1
            return None
        self._t_last = frame.t
        joints = follow(np.asarray(frame.positions, dtype=float), self.body.mimics)  # mimic joints: their parents'
        contacts = sensor_contacts(frame.feet, self._min_force)
        self.stats.delivered += 1
        return SourceFrame(frame.t, np.concatenate([self._placer.update(joints), joints]), contacts,
                           time.monotonic())

    def close(self) -> None:
        self.link.close()
