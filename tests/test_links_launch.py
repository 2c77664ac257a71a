"""start_devices: the simulated devices `livezmp sim --link KIND` starts, and its one-line errors."""

from __future__ import annotations

import contextlib
import os

import can
import pytest
from test_links_support import NAMES, servo_config, wait_until

from livezmp.errors import InputError
from livezmp.links import parse_link_url
from livezmp.model.robot_config import RobotConfig, ServoConfig
from sim_devices.launch import start_devices
from sim_devices.servo_plant import ServoPlant


@pytest.mark.parametrize(("kind", "scheme"), [("dynamixel", "dynamixel"), ("can", "can"), ("fw", "fw")])
def test_each_kind_serves_a_link_url_on_a_pty_and_counts_its_faults(kind, scheme):
    config = servo_config(4)
    with start_devices(kind, ServoPlant(4), config, faults="overload=3@0.05s") as devices, contextlib.ExitStack() as up:
        assert parse_link_url(devices.url)[0] == scheme
        assert len(devices.ports) == 1 and os.path.exists(devices.ports[0].path)
        if kind == "can":  # the adapter runs its nodes while its channel is open
            up.enter_context(can.Bus(interface="slcan", channel=devices.ports[0].path, bitrate=1_000_000,
                                     sleep_after_open=0))
        assert wait_until(lambda: devices.fault_counters.overloads == 1, timeout=2.0)
        path = devices.ports[0].path
    assert not os.path.exists(path)  # closed: the device path is gone


@pytest.mark.parametrize(("kind", "config", "names", "faults", "message"), [
    ("serial", servo_config(2), None, "", "simulated link kind 'serial': expected one of dynamixel, can, fw"),
    ("fw", servo_config(2), [NAMES[0], "nose"], "", "test config: no [servos.nose] entry for joint 'nose'"),
    ("fw", RobotConfig(source="empty.toml"), None, "", "empty.toml: no [servos] entries: nothing to simulate"),
    ("dynamixel", RobotConfig(servos={"a": ServoConfig("a", 1, ticks_per_rev=1024)}, source="ax.toml"), None, "",
     "ax.toml: [servos.a] ticks_per_rev 1024: the simulated XM430 has 4096"),
    ("can", RobotConfig(servos={"a": ServoConfig("a", 200)}), None, "",
     "CanServoBus: need one distinct node id in 1..127 per joint name, got [200]"),
    ("fw", RobotConfig(servos={"a_very_long_joint_name": ServoConfig("a_very_long_joint_name", 1)}), None, "",
     "joint 'a_very_long_joint_name': a firmware_protocol joint name is 1-16 printable ASCII characters"),
    ("dynamixel", servo_config(2), None, "drop=2", "fault spec field 'drop': expected a probability in [0, 1]"),
    ("dynamixel", servo_config(2), None, "busoff=1s+1s", "field 'busoff' does not apply to the Dynamixel chain"),
    ("fw", servo_config(2), None, "overload=9@1s", "fault spec field 'overload': no joint with id 9 on this board"),
    ("can", servo_config(2), None, "overload=9@1s", "fault spec field 'overload': no CAN node 9"),
])
def test_mistakes_are_one_line_input_errors(kind, config, names, faults, message):
    with pytest.raises(InputError) as info:
        start_devices(kind, ServoPlant(2), config, joint_names=names, faults=faults)
    assert message in str(info.value)
    assert "\n" not in str(info.value)
