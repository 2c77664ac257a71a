"""Real-time scheduling for the live loop (Linux SCHED_FIFO), asked for and given back.

A 500 Hz loop has 2 ms a cycle. Under the default time-sharing scheduler any other
runnable process on the machine can hold the loop's core for a scheduler slice (several
milliseconds) just when the loop should wake or when a servo reply arrives: the deadline
is missed although the loop's own work takes well under a millisecond. Under SCHED_FIFO
the loop runs as soon as it is runnable; it sleeps and waits on the port between cycles,
and the kernel keeps 5 % of each second for everything else (``sched_rt_runtime_us``),
so it cannot lock a machine up. This is what robot control frameworks do on Linux.

The policy is per thread: :func:`realtime_priority` sets it for the calling thread (and
threads it starts afterwards inherit it) and restores the previous policy on exit. Asking
needs root or CAP_SYS_NICE (or an ``rtprio`` limit); when refused the loop runs on at
normal priority and the reason is reported.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

from livezmp.errors import InputError

LOOP_PRIORITY = 50  # the loop; a simulator's devices run just below it (LOOP_PRIORITY - 1)


def check_priority(priority: int) -> None:
    """A SCHED_FIFO priority is 1–99, or 0 for none; anything else is a user error."""
    if not 0 <= priority <= 99:
        raise InputError(f"--realtime-priority {priority}: must be 1-99 (SCHED_FIFO), or 0 for normal scheduling")


@contextlib.contextmanager
def realtime_priority(priority: int) -> Iterator[str | None]:
    """Run the calling thread under SCHED_FIFO at ``priority`` (1–99) inside the block;
    yields None when granted, else one line saying why not (0 asks for nothing: "off").
    The thread's previous policy and priority are restored on exit."""
    check_priority(priority)
    if priority == 0:
        yield "off"
        return
    if not hasattr(os, "sched_setscheduler"):
        yield "not available on this system"
        return
    before = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as e:
        yield f"refused ({e.strerror}; needs root, CAP_SYS_NICE or an rtprio limit)"
        return
    try:
        yield None
    finally:
        os.sched_setscheduler(0, before[0], before[1])
