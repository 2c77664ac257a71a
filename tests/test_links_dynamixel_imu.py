"""An IMU sub-controller on the Dynamixel bus (the OP3's OpenCR at id 200): its registers, the link reading
it in the servos' transaction through dynamixel-sdk, the bytes that costs, and fall detection from it.

Truth: the vendor's register layout and scale factors (cited in livezmp/links/dynamixel_imu.py), the
simulated humanoid's own IMU reading, Protocol 2.0 packet sizes counted by hand, and the simulator's fall."""

from __future__ import annotations

import math
import re
from dataclasses import replace
from importlib import resources

import numpy as np
import pytest
from sim_support import sdk_latency_timer, short_gil_switch  # noqa: F401 - fixtures
from test_fall_detection import against_a_simulator

from livezmp.errors import InputError
from livezmp.links import open_link
from livezmp.links.dynamixel_imu import decode_imu, encode_imu
from livezmp.live.fall_detection import FallDetector
from livezmp.live.scenarios import Poser
from livezmp.model.robot import load_robot
from livezmp.model.robot_config import ImuConfig, load_robot_config
from sim_devices.humanoid import SimHumanoid
from sim_devices.launch import humanoid_imu, start_devices

pytestmark = pytest.mark.usefixtures("short_gil_switch", "sdk_latency_timer")
OP3_AXES = (-1, -1, 1)  # the OP3's board: x and y turned round (the vendor's module negates them)
G = 9.81


def test_registers_hold_the_vendors_units_in_the_boards_axes():
    # 1 g up and 1 rad/s about the robot's x: the board (x, y reversed) reads +16384 on z and -16.4 * 57.3 on x
    raw = np.frombuffer(encode_imu(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, G]), OP3_AXES), dtype="<i2")
    assert list(raw) == [-round(16.4 * math.degrees(1.0)), 0, 0, 0, 0, 16384]
    back = decode_imu(raw.tobytes(), OP3_AXES)
    np.testing.assert_allclose(back["angular_velocity"], [1.0, 0.0, 0.0], atol=math.radians(0.5 / 16.4))
    np.testing.assert_allclose(back["acceleration"], [0.0, 0.0, G], atol=0.5 * G / 16384)
    # beyond +-2 g or +-2000 deg/s the sensor saturates
    raw = np.frombuffer(encode_imu(np.array([0.0, 0.0, 100.0]), np.array([3 * G, 0.0, 0.0]), (1, 1, 1)), "<i2")
    assert raw[2] == 32767 and raw[3] == 32767


def test_the_robot_config_names_the_imu_and_refuses_a_bad_one(tmp_path):
    path = tmp_path / "r.toml"

    def load(imu: str):
        path.write_text('[servos]\na = { id = 1 }\n' + imu)
        return load_robot_config(path)

    assert load("[imu]\nid = 200\naxes = [-1, -1, 1]\n").imu == ImuConfig(200, OP3_AXES)
    assert load("").imu is None
    for bad, said in (("id = 1", "[imu] id: 1 is a servo's id"), ("id = 200\naxes = [1, 2, 1]", "[imu] axes"),
                      ("axes = [1, 1, 1]", "[imu]: missing 'id'"), ("id = 200\nrate = 5", "unknown key 'rate'")):
        with pytest.raises(InputError, match=re.escape(f"{path}: {said}" if said[0] == "[" else said)):
            load("[imu]\n" + bad + "\n")


def sloped(body) -> SimHumanoid:
    return SimHumanoid(body, Poser(body).standing().astype(np.float32).astype(float), slope=math.radians(7))


@pytest.mark.parametrize("fast", [0, 1])
def test_the_link_reads_the_imu_in_the_servos_transaction_and_counts_its_bytes(mini, mini_config, fast):
    humanoid = sloped(mini)
    config = replace(mini_config, imu=ImuConfig(200, OP3_AXES))
    imu = humanoid_imu(humanoid)
    names = mini.joint_names
    counted = {}
    for cfg in (mini_config, config):
        with start_devices("dynamixel", humanoid, cfg, joint_names=names, imu=imu) as devices:
            link = open_link(f"{devices.url}&fast={fast}", names, cfg)
            try:
                for _ in range(5):
                    frame = link.read()
                    link.write_goals(frame.positions)
                counted[cfg.imu is not None] = link.bus_ceilings(devices_adapter())[0].bytes_per_cycle
                label = link.read_label
            finally:
                link.close()
    truth = humanoid.imu()
    assert frame.imu is not None and label == f"{'fast ' if fast else ''}bulk read: position + imu"
    np.testing.assert_allclose(frame.imu["acceleration"], truth.specific_force, atol=G / 16384)
    np.testing.assert_allclose(frame.imu["angular_velocity"], truth.angular_velocity, atol=math.radians(1 / 16.4))
    # standing, the pelvis parallel to the soles on a ground rising 7 degrees: 1 g up, tilted back in its axes (to
    # within the legs' goals held in servo ticks, 0.09 degrees each)
    np.testing.assert_allclose(frame.imu["acceleration"], G * np.array([math.sin(math.radians(7)), 0.0,
                                                                           math.cos(math.radians(7))]), atol=0.03)
    # Protocol 2.0 by hand, 20 servos' positions (4 bytes) and the IMU's 12: instruction = header 4, id, length 2,
    # instruction, CRC 2 (10) + parameters; a status = 11 + data; a Fast read's one status = 8 + (4 + data) each
    write = 10 + 4 + 20 * (1 + 4)
    sync = (10 + 4 + 20) + (8 + 20 * 8 if fast else 20 * (11 + 4))
    bulk = (10 + 5 * 21) + (8 + 20 * 8 + (4 + 12) if fast else 20 * (11 + 4) + 11 + 12)
    assert counted == {False: sync + write, True: bulk + write}


def devices_adapter():
    from livezmp.links.bus_timing import ADAPTERS, DEFAULT_ADAPTER

    return ADAPTERS[DEFAULT_ADAPTER]


def test_fall_detection_tracks_the_tilt_from_gyro_and_accelerometer_alone():
    # no orientation: a body turning at 2 rad/s about y for 0.4 s (0.8 rad = 46 degrees), its accelerometer reading
    # gravity in its turned axes: the tracked tilt follows the true angle, and a fall is told past 45 degrees
    detector = FallDetector()
    fell_at = None
    for k in range(300):
        t = 0.002 * k
        angle = min(2.0 * t, 1.0)
        reading = {"acceleration": G * np.array([-math.sin(angle), 0.0, math.cos(angle)]),
                   "angular_velocity": np.array([0.0, 2.0 if 2.0 * t < 1.0 else 0.0, 0.0])}
        if detector.update(t, reading) and fell_at is None:
            fell_at = t
        if k % 20 == 0 and fell_at is None:  # (a detector that told a fall stops watching)
            assert abs(detector.max_tilt - angle) < 0.02
    assert "tilted" in detector.fell and math.radians(45) / 2.0 + 0.05 <= fell_at < math.radians(45) / 2.0 + 0.07


def test_over_dynamixel_the_host_tells_the_fall_from_the_sub_controllers_imu(mini, tmp_path):
    """The simulator in another process with the mini's config plus an [imu]: the loop has no fall flag, only
    the bus. Leaning past the toes uncorrected, the robot falls, and its IMU sub-controller's gyro and
    accelerometer tell the loop, which stops."""
    config = tmp_path / "mini_imu.toml"
    config.write_text((resources.files("livezmp") / "data" / "robots" / "livezmp_mini.toml").read_text()
                      + "\n[imu]\nid = 200\naxes = [-1, -1, 1]\n")
    robot = load_robot(None, str(config))
    s, truth = against_a_simulator("dynamixel", mini, robot.config, False, ("lean", {"hold_s": 1.0}),
                                   config_path=str(config))
    print(truth["fall"], s["imu_fall"], s["stopped_by"], s["imu_max_tilt_deg"])
    assert truth["fell"] is True
    assert s["fell"] is True and s["stopped_by"] == "fell" and "tilted" in s["imu_fall"]
