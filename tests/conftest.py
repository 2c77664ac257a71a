"""Shared fixtures: the real data (see data_paths.py) and the built-in demo robot."""

from __future__ import annotations

import pytest
from data_paths import BANDAI, OP3_URDF


@pytest.fixture(scope="session")
def op3_body():
    from livezmp.model.urdf_body import body_from_urdf

    return body_from_urdf(OP3_URDF)


@pytest.fixture(scope="session")
def bandai_walk():
    from livezmp.model.bvh import read_bvh

    return read_bvh(BANDAI / "walk_normal_001.bvh")


@pytest.fixture(scope="session")
def mini():
    """The built-in livezmp_mini robot's body."""
    from livezmp.model.demo_robot import demo_robot_path
    from livezmp.model.urdf_body import body_from_urdf

    return body_from_urdf(demo_robot_path())


@pytest.fixture(scope="session")
def mini_config(mini):
    """The livezmp_mini robot config (servos, feet)."""
    from livezmp.model.demo_robot import demo_robot_path
    from livezmp.model.robot_config import find_robot_config

    return find_robot_config(demo_robot_path(), mini.model.name)
