"""Real-time scheduling for the live loop (Linux SCHED_FIFO, CPU affinity, locked memory), asked for and given back.

A 500 Hz loop has 2 ms a cycle. Under the default time-sharing scheduler any other
runnable process on the machine can hold the loop's core for a scheduler slice (several
milliseconds) just when the loop should wake or when a servo reply arrives: the deadline
is missed although the loop's own work takes well under a millisecond. Under SCHED_FIFO
the loop runs as soon as it is runnable; it sleeps and waits on the port between cycles,
and the kernel keeps 5 % of each second for everything else (``sched_rt_runtime_us``),
so it cannot lock a machine up. This is what robot control frameworks do on Linux
(ros2_control's controller manager asks for SCHED_FIFO 50 and locks its memory).

A wake-up also waits for its CPU to leave its idle state: a deep C-state on bare metal, a
halted virtual CPU that the host must run again in a VM. Each cycle on a serial bus has
several: the loop's timer, the kernel worker that carries the port's bytes to the reader (a
normal-priority kworker running ``flush_to_ldisc``, for USB-serial adapters and ptys alike)
and the reader it wakes. With ``awake`` the loop holds a CPU latency request of 0 us
(:func:`awake_cpus`, the kernel's PM QoS ``/dev/cpu_dma_latency``, as cyclictest does) while
it runs, so idle CPUs wait in a state they leave at once. Measured on a 2-CPU VM
(benchmarks/bench_tty_worker.py, load 0.5): that worker's wait for a CPU 29-35 -> 6-8 us at
the median.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import re
import struct
from collections.abc import Iterator

from livezmp.errors import InputError

LOOP_PRIORITY = 50  # the loop; a simulator's devices run just below it (LOOP_PRIORITY - 1)
_MCL_CURRENT, _MCL_FUTURE = 1, 2  # <sys/mman.h>
_PR_SET_TIMERSLACK, _PR_GET_TIMERSLACK = 29, 30  # <linux/prctl.h>
FINE_TIMER_SLACK_NS = 1  # the least the kernel takes (0 would restore the thread's default)
CPU_LATENCY_QOS = "/dev/cpu_dma_latency"  # the kernel's PM QoS CPU latency request (us, a native int32)


def check_priority(priority: int) -> None:
    """A SCHED_FIFO priority is 1–99, or 0 for none; anything else is a user error."""
    if not 0 <= priority <= 99:
        raise InputError(f"--realtime-priority {priority}: must be 1-99 (SCHED_FIFO), or 0 for normal scheduling")


def parse_cpus(text: str, option: str = "--cpu") -> frozenset[int]:
    """--cpu (or ``option``): CPU numbers as ``2`` or ``2,3`` or ``0-1``, each one this machine has (InputError
    otherwise)."""
    cpus: set[int] = set()
    for part in text.split(","):
        bounds = re.fullmatch(r"\s*(\d+)(?:-(\d+))?\s*", part)
        if bounds is None:
            cpus = set()
            break
        cpus.update(range(int(bounds[1]), int(bounds[2] or bounds[1]) + 1))
    have = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else set()
    if not cpus or not cpus <= have:
        raise InputError(f"{option} {text}: expected CPU numbers such as 1 or 0,1 among {sorted(have)}")
    return frozenset(cpus)


def _libc_call(name: str, *args: int) -> str | None:
    """Call libc's ``name``; None when it succeeded, else the reason (one line)."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    if getattr(libc, name)(*args) == 0:
        return None
    return os.strerror(ctypes.get_errno())


@contextlib.contextmanager
def realtime_priority(priority: int, cpus: frozenset[int] | None = None, lock_memory: bool = False,
                      required: bool = False, awake: bool = False) -> Iterator[str | None]:
    """Run the calling thread under SCHED_FIFO at ``priority`` (1–99) inside the block, on
    ``cpus`` (None: where it was), with the process's memory locked if ``lock_memory`` and idle
    CPUs kept awake if ``awake`` (:func:`awake_cpus`; both only once SCHED_FIFO was granted).
    Yields None when granted, else one line saying why not (0 asks for nothing: "off"); with
    ``required``, a refusal raises InputError instead. A memory lock or CPU latency request
    refused is not a refusal (the loop still runs first; they are reported by
    :func:`memory_locked` and :func:`cpu_wake_latency_us`). The thread's previous policy,
    priority and CPUs are restored on exit."""
    check_priority(priority)
    with _affinity(cpus), fine_timer_slack():
        if priority == 0:
            yield "off"
            return
        if not hasattr(os, "sched_setscheduler"):
            refused = "not available on this system"
        else:
            before = os.sched_getscheduler(0), os.sched_getparam(0)
            try:
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
                refused = None
            except OSError as e:
                refused = f"refused ({e.strerror}; needs root, CAP_SYS_NICE or an rtprio limit)"
        if refused is not None:
            if required:
                raise InputError(f"--realtime-priority {priority}: SCHED_FIFO {refused}")
            yield refused
            return
        locked = lock_memory and _libc_call("mlockall", _MCL_CURRENT | _MCL_FUTURE) is None
        try:
            with awake_cpus() if awake else contextlib.nullcontext():
                yield None
        finally:
            if locked:
                _libc_call("munlockall")
            os.sched_setscheduler(0, before[0], before[1])


@contextlib.contextmanager
def awake_cpus() -> Iterator[str | None]:
    """Inside the block, hold a CPU latency request of 0 us (PM QoS, ``/dev/cpu_dma_latency``): every
    idle CPU of the machine waits in a state it leaves at once (a polling loop) instead of halting,
    so a wake-up is not delayed by the idle state's exit. It costs the idle CPUs' power (in a VM, the
    host's CPU time) while held; the kernel drops the request when the file is closed, on exit or if
    the process dies. Yields None when held, else why not (one line: it needs root)."""
    try:
        fd = os.open(CPU_LATENCY_QOS, os.O_WRONLY)
    except OSError as e:
        yield f"refused ({e.strerror})"
        return
    try:
        os.write(fd, struct.pack("=i", 0))
        yield None
    finally:
        os.close(fd)


def cpu_wake_latency_us() -> int | None:
    """The CPU latency (us) the kernel keeps its idle CPUs within now, as PM QoS aggregates every
    process's request (0: kept awake, see :func:`awake_cpus`; 2000000000: no request); None where
    it cannot be read."""
    try:
        with open(CPU_LATENCY_QOS, "rb") as f:
            return struct.unpack("=i", f.read(4))[0]
    except (OSError, struct.error):
        return None


@contextlib.contextmanager
def fine_timer_slack() -> Iterator[None]:
    """Inside the block, the calling thread's timed waits (sleep, select's timeout) end when asked rather
    than up to the kernel's timer slack later: 50 us by default for a thread under normal scheduling (none
    under SCHED_FIFO), measured here as the median lateness of a 0.3 ms select: 73 us with it, 23 us at 1 ns.
    The loop's cycle starts and a simulator's replies that would be that much late without real-time
    priority. The previous slack is restored on exit; where prctl is not there, nothing changes."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
    before = libc.prctl(_PR_GET_TIMERSLACK, 0, 0, 0, 0) if hasattr(libc, "prctl") else -1
    if before <= 0:
        yield
        return
    libc.prctl(_PR_SET_TIMERSLACK, FINE_TIMER_SLACK_NS, 0, 0, 0)
    try:
        yield
    finally:
        libc.prctl(_PR_SET_TIMERSLACK, before, 0, 0, 0)


@contextlib.contextmanager
def _affinity(cpus: frozenset[int] | None) -> Iterator[None]:
    if cpus is None:
        yield
        return
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, cpus)
    try:
        yield
    finally:
        os.sched_setaffinity(0, before)


def memory_locked() -> bool:
    """Whether this process has memory locked now (Linux: VmLck in /proc/self/status)."""
    try:
        with open("/proc/self/status") as f:
            return any(line.startswith("VmLck:") and int(line.split()[1]) > 0 for line in f)
    except OSError:
        return False
