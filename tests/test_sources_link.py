"""A servo link as a monitor source: the robot's joints, read through the real client
(dynamixel-sdk, pyserial for fw) from simulated devices, become the monitor's frames."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from livezmp.balance.pipeline import default_config
from livezmp.errors import InputError
from livezmp.model.demo_robot import demo_robot_path
from livezmp.model.robot_config import find_robot_config
from livezmp.monitor.loop import Monitor
from livezmp.sources.factory import SourceOptions, open_source
from sim_devices.launch import start_devices
from sim_devices.servo_plant import ServoPlant

URDF = str(demo_robot_path())


def bent_knees(names: list[str]) -> np.ndarray:
    q = np.zeros(len(names))
    for side in ("l", "r"):  # livezmp_mini: every pitch axis is +y
        q[names.index(f"{side}_hip_pitch")] = -0.3
        q[names.index(f"{side}_knee")] = 0.6
        q[names.index(f"{side}_ank_pitch")] = -0.3
    return q


@pytest.mark.parametrize("kind", ["dynamixel", "fw"])
def test_monitor_watches_a_robot_through_its_link(kind):
    from livezmp.model.urdf_body import body_from_urdf

    body = body_from_urdf(URDF)
    names = body.joint_names
    config = find_robot_config(URDF, "livezmp_mini")
    pose = bent_knees(names)
    plant = ServoPlant(len(names), position=pose)
    with start_devices(kind, plant, config, joint_names=names) as devices:
        src = open_source(devices.url, SourceOptions(robot=URDF, fps=100.0))
        try:
            frame = None
            for _ in range(50):
                frame = src.read(timeout=0.5)
                if frame is not None:
                    break
            assert frame is not None
            # the joints as the plant holds them (to a tick), behind the placed base
            np.testing.assert_allclose(frame.channels[6:], pose, atol=2 * np.pi / 4096)
            assert frame.channels[2] > 0.2  # base above the ground: the stance foot is flat at z = 0
            mon = Monitor(src, default_config(body, 100.0))
            stop = threading.Event()
            timer = threading.Timer(1.5, stop.set)
            timer.start()
            summary = mon.run(stop)
            timer.cancel()
        finally:
            src.close()
    assert mon.results > 50 and mon.out_of_support == 0  # standing still on bent knees: balanced
    assert summary is not None


def test_a_link_source_needs_its_robot():
    with pytest.raises(InputError, match="needs the robot it drives: --robot"):
        open_source("dynamixel:/dev/null", SourceOptions())


def test_a_monitored_link_whose_port_goes_is_told_and_counted(capsys):
    """The device's port gone for 1 s: main told it only on the recording's /device_error (console and summary
    said "source faults: malformed 1"); now one console line a second, and the summary's own ``disconnected``."""
    from livezmp.model.urdf_body import body_from_urdf

    body = body_from_urdf(URDF)
    config = find_robot_config(URDF, "livezmp_mini")
    plant = ServoPlant(len(body.joint_names), position=bent_knees(body.joint_names))
    with start_devices("dynamixel", plant, config, joint_names=body.joint_names) as devices:
        src = open_source(devices.url, SourceOptions(robot=URDF, fps=100.0))
        mon = Monitor(src, default_config(body, 100.0))
        port = devices.ports[0]
        threading.Timer(0.5, port.vanish).start()
        threading.Timer(1.5, port.restore).start()
        stop = threading.Event()
        threading.Timer(3.0, stop.set).start()
        mon.run(stop)
    summary = mon.summary_json()
    assert summary["disconnected"] > 0 and "disconnected" not in summary["dropped"]
    assert summary["reconnects"] == 1 and summary["analysed_frames"] > 50
    assert "livezmp: " + devices.url in capsys.readouterr().err  # told on the console as it happened
