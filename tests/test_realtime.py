"""Real-time scheduling: asked for, reported when refused, and always given back."""

from __future__ import annotations

import os

import pytest

from livezmp.errors import InputError
from livezmp.live.realtime import check_priority, realtime_priority


def test_priority_zero_asks_for_nothing():
    before = os.sched_getscheduler(0)
    with realtime_priority(0) as refused:
        assert refused == "off"
        assert os.sched_getscheduler(0) == before


def test_granted_or_refused_and_restored():
    before = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    with realtime_priority(20) as refused:
        if refused is None:  # root or CAP_SYS_NICE: the thread runs under SCHED_FIFO at 20
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
            assert os.sched_getparam(0).sched_priority == 20
        else:  # refused: nothing changed, and the reason is one line
            assert refused.startswith("refused (") and "\n" not in refused
            assert os.sched_getscheduler(0) == before[0]
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before


def test_restored_after_an_exception():
    before = os.sched_getscheduler(0)
    with pytest.raises(RuntimeError), realtime_priority(10):
        raise RuntimeError("the loop failed")
    assert os.sched_getscheduler(0) == before


@pytest.mark.parametrize("bad", [-1, 100])
def test_out_of_range_priority_is_a_user_error(bad):
    with pytest.raises(InputError, match="must be 1-99"):
        check_priority(bad)
