"""Shared fixtures over the real data (see data_paths.py)."""

from __future__ import annotations

import pytest
from data_paths import BANDAI, OP3_URDF


@pytest.fixture(scope="session")
def op3_body():
    from livezmp.body_urdf import body_from_urdf

    return body_from_urdf(OP3_URDF)


@pytest.fixture(scope="session")
def bandai_walk():
    from livezmp.bvh import read_bvh

    return read_bvh(BANDAI / "walk_normal_001.bvh")
