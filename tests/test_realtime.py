"""Real-time scheduling: asked for, reported when refused, and always given back."""

from __future__ import annotations

import ctypes
import ctypes.util
import os

import pytest

from livezmp.errors import InputError
from livezmp.live import realtime
from livezmp.live.realtime import awake_cpus, check_priority, cpu_wake_latency_us, parse_cpus, realtime_priority


def test_priority_zero_asks_for_nothing():
    before = os.sched_getscheduler(0)
    with realtime_priority(0) as refused:
        assert refused == "off"
        assert os.sched_getscheduler(0) == before


def timer_slack_ns() -> int:
    """The calling thread's timer slack, as the kernel reports it (prctl PR_GET_TIMERSLACK)."""
    return ctypes.CDLL(ctypes.util.find_library("c")).prctl(30, 0, 0, 0, 0)


def test_timer_slack_is_fine_inside_and_given_back():
    before = timer_slack_ns()
    assert before > 1  # the kernel's default for a normal thread (50 us)
    for priority in (0, 20):  # normal scheduling (where the slack applies), and SCHED_FIFO or its refusal
        with realtime_priority(priority):
            assert timer_slack_ns() in (0, 1)  # 0: the kernel's own under SCHED_FIFO
        assert timer_slack_ns() == before


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


def permitted(priority: int) -> bool:
    """Whether this process may ask for SCHED_FIFO ``priority``: root (CAP_SYS_NICE) or an rtprio limit."""
    import resource
    return os.geteuid() == 0 or resource.getrlimit(resource.RLIMIT_RTPRIO)[0] >= priority


def vm_locked_kb() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmLck:"))


def test_affinity_and_locked_memory_given_and_given_back():
    """One CPU, SCHED_FIFO and mlockall inside; the CPUs, the policy and VmLck as before after."""
    cpus = os.sched_getaffinity(0)
    one = frozenset({max(cpus)})
    before = os.sched_getscheduler(0), vm_locked_kb()
    with realtime_priority(20, one, lock_memory=True) as refused:
        assert os.sched_getaffinity(0) == one
        if permitted(20):
            assert refused is None and os.sched_getscheduler(0) == os.SCHED_FIFO
            assert vm_locked_kb() > 10_000  # the whole interpreter, numpy included, is resident and locked
        else:
            assert refused.startswith("refused (")
    assert os.sched_getaffinity(0) == cpus
    assert (os.sched_getscheduler(0), vm_locked_kb()) == before


def test_a_required_priority_refused_is_a_one_line_user_error(monkeypatch):
    def refuse(*_):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with pytest.raises(InputError) as e, realtime_priority(30, required=True):
        pass
    assert str(e.value) == ("--realtime-priority 30: SCHED_FIFO refused (Operation not permitted; needs root, "
                            "CAP_SYS_NICE or an rtprio limit)")
    with realtime_priority(30) as refused:  # not required: the loop runs on and is told why
        assert refused.startswith("refused (Operation not permitted")


@pytest.mark.parametrize(("text", "cpus"), [("0", {0}), ("0-1", {0, 1}), ("1,0", {0, 1})])
def test_cpu_lists(text, cpus):
    assert parse_cpus(text) == cpus


@pytest.mark.parametrize("text", ["", "x", "0-", str(os.cpu_count() + 3)])
def test_bad_cpu_lists_are_user_errors(text):
    with pytest.raises(InputError, match=f"--cpu {text}: expected CPU numbers"):
        parse_cpus(text)


def test_cpus_kept_awake_inside_and_let_sleep_after():
    """awake_cpus holds a 0 us CPU latency request: the kernel's aggregate target reads 0 inside the block
    and what it was before after it (root here; the default, or another process's request)."""
    before = cpu_wake_latency_us()
    assert before is not None and before >= 0
    with awake_cpus() as refused:
        assert refused is None
        assert cpu_wake_latency_us() == 0
    assert cpu_wake_latency_us() == before


def test_awake_only_with_sched_fifo_granted():
    """realtime_priority(..., awake=True) keeps the CPUs awake while SCHED_FIFO is held, not at priority 0."""
    before = cpu_wake_latency_us()
    with realtime_priority(0, awake=True):
        assert cpu_wake_latency_us() == before
    with realtime_priority(20, awake=True) as refused:
        assert refused is None and cpu_wake_latency_us() == 0
    assert cpu_wake_latency_us() == before


def test_a_refused_cpu_latency_request_says_why(monkeypatch, tmp_path):
    monkeypatch.setattr(realtime, "CPU_LATENCY_QOS", str(tmp_path / "no_such_device"))
    with awake_cpus() as refused:
        assert refused == "refused (No such file or directory)"
    assert cpu_wake_latency_us() is None
