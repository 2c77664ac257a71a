"""Shared fixtures: the real data (see data_paths.py) and the built-in demo robot."""

from __future__ import annotations

import inspect
import re

import pytest
from data_paths import BANDAI, DATA, DATA_NAMES, HAVE_DATA, OP3_URDF, REQUIRE_DATA


def _data_names(module) -> set[str]:
    """DATA_NAMES plus the module's functions, fixtures and constants that reach them."""
    names = set(DATA_NAMES) | {k for k, v in vars(module).items() if str(v).startswith(str(DATA))}
    sources = {}
    for k, v in vars(module).items():
        f = getattr(v, "__wrapped__", v)
        if inspect.isfunction(f) and f.__module__ == module.__name__:
            sources[k] = inspect.getsource(f)
    while True:
        pattern = re.compile(r"\b(" + "|".join(map(re.escape, names)) + r")\b")
        more = {k for k, src in sources.items() if k not in names and pattern.search(src)}
        if not more:
            return names
        names |= more


def _uses_data(item, cache: dict) -> bool:
    module = item.module
    if "data_paths" not in vars(module) and not any(n in vars(module) for n in DATA_NAMES[:3]):
        return bool(set(item.fixturenames) & set(DATA_NAMES))
    if module not in cache:
        cache[module] = _data_names(module)
    names = cache[module]
    if set(item.fixturenames) & names:
        return True
    src = inspect.getsource(getattr(item.function, "__wrapped__", item.function))
    return re.search(r"\b(" + "|".join(map(re.escape, names)) + r")\b", src) is not None


def pytest_collection_modifyitems(config, items):
    """Without the data (data_paths.py), deselect the tests that read it, saying so in one line."""
    if HAVE_DATA:
        return
    if REQUIRE_DATA:
        raise pytest.UsageError(f"LIVEZMP_REQUIRE_DATA=1 but the data is not at {DATA} (set LIVEZMP_DATA)")
    cache: dict = {}
    keep, drop = [], []
    for item in items:
        (drop if _uses_data(item, cache) else keep).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep
        print(f"\nlivezmp: {len(drop)} tests need the data set, not found at {DATA}: deselected "
              "(get shared/data beside the project, or set LIVEZMP_DATA=/path/to/data)")


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
