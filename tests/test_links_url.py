"""Link URLs: the forms open_link accepts, and a one-line InputError naming the problem for every bad one."""

from __future__ import annotations

import pytest
from test_links_support import NAMES, servo_config

from livezmp.errors import InputError
from livezmp.links import make_link, parse_link_url
from livezmp.links.dynamixel import DynamixelLink
from livezmp.links.firmware import FirmwareLink
from livezmp.model.robot_config import RobotConfig, ServoConfig
from sim_devices.mock_link import MockLink


@pytest.mark.parametrize(("url", "parsed"), [
    ("dynamixel:/dev/ttyUSB0", ("dynamixel", "/dev/ttyUSB0", {})),
    ("dynamixel:/dev/ttyUSB0?baud=57600&fast=1", ("dynamixel", "/dev/ttyUSB0", {"baud": "57600", "fast": "1"})),
    ("can:slcan:/dev/ttyACM0@115200?bitrate=500000", ("can", "slcan:/dev/ttyACM0@115200", {"bitrate": "500000"})),
    ("fw:socket://127.0.0.1:5000?logging=debug?rate=200",
     ("fw", "socket://127.0.0.1:5000?logging=debug", {"rate": "200"})),
    ("fw:spy:///dev/ttyACM0?file=log.txt?", ("fw", "spy:///dev/ttyACM0?file=log.txt", {})),
    ("mock:", ("mock", "", {})),
])
def test_url_forms(url, parsed):
    assert parse_link_url(url) == parsed


def test_options_reach_the_backends():
    config = servo_config(4)
    link = make_link("dynamixel:/dev/ttyUSB0?baud=57600&fast=true&watchdog=0.5&timeout=0.02", NAMES[:4], config)
    assert isinstance(link, DynamixelLink)
    assert (link.path, link.baud, link.fast, link.watchdog, link.timeout) == ("/dev/ttyUSB0", 57600, True, 0.5, 0.02)
    assert link.ids == [1, 2, 3, 4]
    fw = make_link("fw:/dev/ttyACM0?rate=200&watchdog=0&timeout=0.05", NAMES[:4], RobotConfig())
    assert isinstance(fw, FirmwareLink) and (fw.rate, fw.watchdog, fw.timeout) == (200, 0.0, 0.05)
    can = make_link("can:slcan:/dev/ttyACM0?bitrate=1000000&sleep_after_open=0", NAMES[:4], config)
    assert isinstance(can, FirmwareLink) and (can.rate, can.watchdog) == (30, 0.2)
    assert isinstance(make_link("mock:", NAMES[:4], RobotConfig()), MockLink)


@pytest.mark.parametrize(("url", "message"), [
    ("serial:/dev/ttyUSB0", "link URL 'serial:/dev/ttyUSB0': expected dynamixel:PATH, can:INTERFACE:CHANNEL, fw:URL"),
    ("/dev/ttyUSB0", "link URL '/dev/ttyUSB0': expected dynamixel:PATH"),
    ("dynamixel:", "link URL 'dynamixel:': dynamixel: needs a device"),
    ("dynamixel:?baud=57600", "dynamixel: needs a device"),
    ("can:slcan", "expected can:INTERFACE:CHANNEL, e.g. can:slcan:/dev/ttyACM0"),
    ("mock:/dev/ttyUSB0", "mock: takes no device"),
    ("dynamixel:/dev/x?buad=57600",
     "unknown option 'buad' for dynamixel: (options: baud, fast, read, return_delay, watchdog, timeout)"),
    ("fw:/dev/x?fast=1", "unknown option 'fast' for fw: (options: baud, rate, watchdog, timeout)"),
    ("mock:?rate=3", "unknown option 'rate' for mock: (options: none)"),
    ("dynamixel:/dev/x?baud=fast", "option 'baud' must be a positive integer, got 'fast'"),
    ("dynamixel:/dev/x?fast=2", "option 'fast' must be 0, 1 or auto, got '2'"),
    ("fw:/dev/x?timeout=0", "option 'timeout' must be seconds > 0, got '0'"),
    ("fw:/dev/x?watchdog=-1", "option 'watchdog' must be seconds >= 0, got '-1'"),
    ("fw:/dev/x?watchdog=70", "option 'watchdog' must be at most 65.535 s, got 70.0"),
    ("dynamixel:/dev/x?watchdog=3", "option 'watchdog' must be 0 (off) or 0.02..2.54 s, got 3"),
    ("dynamixel:/dev/x?baud=1&baud=2", "option 'baud' given twice"),
    ("dynamixel:/dev/x?baud", "option 'baud' is not NAME=VALUE"),
    # the daemon's host given as the channel: python-can said only "missing 2 required positional arguments"
    ("can:socketcand:127.0.0.1", "link URL 'can:socketcand:127.0.0.1': socketcand needs option(s) host, port: "
                                 "can:socketcand:CHANNEL?host=HOST&port=PORT (CHANNEL: the daemon's CAN interface"),
    ("can:socketcand:can0?host=127.0.0.1&protocol=mit", "socketcand needs option(s) port: can:socketcand:"),
])
def test_bad_urls_are_one_line_input_errors(url, message):
    with pytest.raises(InputError) as info:
        make_link(url, NAMES[:4], servo_config(4))
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_a_joint_without_a_servo_entry_is_named():
    with pytest.raises(InputError, match=r"^test config: no \[servos.head_pan\] entry: the dynamixel: link needs"):
        make_link("dynamixel:/dev/x", [*NAMES[:3], "head_pan"], servo_config(3))
    make_link("fw:/dev/x", ["head_pan"], RobotConfig())  # a board names its joints itself


def test_can_node_ids_must_fit_seven_bits():
    config = RobotConfig(servos={"j": ServoConfig("j", 200)}, source="big.toml")
    with pytest.raises(InputError, match="big.toml: servo id 200 cannot be a CAN node id"):
        make_link("can:virtual:x", ["j"], config)
