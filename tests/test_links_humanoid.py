"""A simulated humanoid behind the simulated devices: its joints, foot force cells and IMU reach the host
through the fw: and can: links. Truth: the humanoid's posture, its weight and gravity."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sim_support import short_gil_switch  # noqa: F401 - fixture
from test_links_support import with_options

import livezmp
from livezmp.links import open_link
from livezmp.live.scenarios import Poser
from livezmp.model.robot_config import find_robot_config
from livezmp.model.urdf_body import body_from_urdf
from sim_devices.humanoid import SimHumanoid
from sim_devices.launch import humanoid_sensors, start_devices

pytestmark = pytest.mark.usefixtures("short_gil_switch")
MINI_URDF = Path(livezmp.__file__).parent / "data" / "robots" / "livezmp_mini.urdf"
G = 9.81


@pytest.fixture(scope="module")
def body():
    return body_from_urdf(MINI_URDF)


# what is checked is what arrives; the staleness rule has its own tests (test_links_firmware.py). A loaded 2-CPU host's
# slcan reader, one byte a system call, fell 977 ms behind 20 nodes' streams once in a whole-suite run
@pytest.mark.parametrize(("kind", "options"), [("fw", "rate=100&timeout=0.3"), ("can", "rate=20&timeout=2")])
def test_humanoid_posture_feet_and_imu_reach_the_host(body, kind, options):
    posture = Poser(body).standing().astype(np.float32).astype(float)
    humanoid = SimHumanoid(body, posture)
    config = find_robot_config(MINI_URDF, "livezmp_mini")
    names = body.joint_names
    feet, imu = humanoid_sensors(humanoid)
    with start_devices(kind, humanoid, config, joint_names=names, foot_sensors=feet, imu=imu) as devices:
        link = open_link(with_options(devices.url, options), names, config)
        try:
            frame = link.read()
            while frame.feet is None or frame.imu is None:
                frame = link.read()
        finally:
            link.close()
    np.testing.assert_array_equal(frame.positions, posture)
    weight = body.total_mass * G
    total = sum(f.sum() for f in frame.feet.forces.values())
    assert total == pytest.approx(weight, rel=1e-5)  # standing still: the cells carry the weight
    cells = humanoid.foot_forces()  # standing still: what the devices sampled
    for side in ("left", "right"):
        forces, cop = frame.feet.forces[side], frame.feet.cop[side]
        assert np.all(forces > 0)  # double support
        # livezmp_mini's soles list their corners rear-right, front-right, front-left, rear-left
        truth = getattr(cells, side)
        np.testing.assert_allclose(forces, truth[[2, 1, 3, 0]], rtol=1e-6)  # front-left, front-right, rear-...
        sole = body.feet[side].sole_local[:, :2]
        np.testing.assert_allclose(cop, truth @ (sole - sole.mean(axis=0)) / truth.sum(), atol=1e-6)
        assert abs(cop[0]) < 0.06 and abs(cop[1]) < 0.033  # inside the 0.12 x 0.066 m sole
    np.testing.assert_allclose(frame.imu["orientation"], [1.0, 0.0, 0.0, 0.0], atol=1e-6)  # upright
    np.testing.assert_allclose(frame.imu["acceleration"], [0.0, 0.0, G], atol=1e-5)  # at rest: specific force
    np.testing.assert_allclose(frame.imu["angular_velocity"], 0.0, atol=1e-6)
