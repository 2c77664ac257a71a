"""Shared helpers for the simulated-device tests (test_sim_*.py)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import pytest


def wait_until(condition: Callable[[], bool], timeout: float = 3.0, interval: float = 0.005) -> bool:
    """Poll ``condition`` until it holds or ``timeout`` seconds pass; its final value."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(interval)
    return condition()


@pytest.fixture
def short_gil_switch():
    """Hand the GIL over within 0.5 ms instead of 5 ms while the test runs.

    The simulated device serves from a thread of the test process, and
    dynamixel-sdk busy-polls its port: with the default switch interval each
    hand-over to the device thread can take 5 ms, and a loaded machine can then
    push a reply past the client's 34 ms timeout.
    """
    previous = sys.getswitchinterval()
    sys.setswitchinterval(5e-4)
    yield
    sys.setswitchinterval(previous)


@pytest.fixture
def sdk_latency_timer(monkeypatch):
    """Give dynamixel-sdk a 50 ms latency timer (reply timeout 2 x 50 + 2 ms) instead of 16 ms.

    dynamixel-sdk sizes every reply timeout from its module-level LATENCY_TIMER,
    meant to match a USB adapter's latency timer; on a pty the latency is the
    scheduling delay of the device thread, which a loaded machine stretches.
    """
    monkeypatch.setattr("dynamixel_sdk.port_handler.LATENCY_TIMER", 50)
