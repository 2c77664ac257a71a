"""SIGINT, SIGTERM and SIGHUP during ``livezmp run`` / ``demo``'s start-up, told truthfully.

From the command line's parsing (:func:`livezmp.cli.main` installs the handler before it imports the
command: on a loaded 2-CPU machine importing livezmp's modules took 25 s at load 19) to the loop's first
cycle the command imports its modules, checks its options, loads the robot, starts a
simulator (``demo``), opens the link (ports opened, servos checked and configured, torque on and
holding the posture read, a Dynamixel bus's watchdog armed: the servos hold on their own once the
bus is silent for its time) and makes the estimator and the recording. A signal there ends the
start-up where it is: :class:`Interrupted` (a BaseException, as KeyboardInterrupt is, so no
``except Exception`` on the way swallows it) unwinds through the ``finally`` blocks any error
takes, so a link opened or being opened gets the shutdown path's stop commands (``close``: hold
the present posture) and is released, a simulator is stopped and a recording already made is
finished. The command then writes a summary saying in which stage it stopped and exits with
128 + the signal's number (130, 143, 129), as a shell reports a process a signal ended.

Once the loop runs, a signal asks it to stop after its cycle (a normal end: exit 0 and
``stopped_by``); after it, and once an interruption is on its way, a signal is noted and the
shutdown finishes.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
from collections.abc import Callable, Iterator

from livezmp.checks import check_output_path
from livezmp.errors import InputError
from livezmp.jsonfile import write_json
from livezmp.links.base import Link

# The signals that stop a command cleanly (the stop commands first, the summary and recording written):
# Ctrl-C, a service manager's stop, and the terminal or SSH session closing, whose SIGHUP would otherwise end
# the process where it stands (no stop commands, no summary, the recording unfinished).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextlib.contextmanager
def handling_stop_signals(handler: Callable[[int, object], None]) -> Iterator[None]:
    """``handler`` for the :data:`STOP_SIGNALS` inside the block, the previous handlers back after it. A SIGHUP
    the process was started ignoring stays ignored: `nohup` asks for a command that outlives its terminal."""
    old = {s: signal.signal(s, handler) for s in STOP_SIGNALS
           if not (s == signal.SIGHUP and signal.getsignal(s) is signal.SIG_IGN)}
    try:
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)


LOOP_STAGE = "the loop"
STOPPING_STAGE = "stopping"


class Interrupted(BaseException):
    """A signal (``name``, ``number``) ended the start-up in ``stage``."""

    def __init__(self, name: str, number: int, stage: str):
        super().__init__(f"{name} during start-up ({stage})")
        self.name, self.number, self.stage = name, number, stage


class Startup:
    """Where a command's start-up is (``stage``, one line), whether its link's ``open`` returned
    (``link_opened``) and ``close`` ran (``link_closed``); what a signal does there (module docstring)."""

    def __init__(self) -> None:
        self.stage = "loading livezmp"
        self.link_opened = False
        self.link_closed = False
        self.recording: dict | None = None  # what a recording finished by the interruption holds
        self.signal: str | None = None  # the signal that interrupted the start-up
        self._stop: Callable[[str], None] | None = None

    def enter(self, stage: str) -> None:
        self.stage = stage

    @contextlib.contextmanager
    def running(self, stop: Callable[[str], None]) -> Iterator[None]:
        """Inside the block (the loop) a signal calls ``stop(signal name)``; after it, signals are noted only."""
        self._stop = stop  # one assignment: no moment where a signal is neither raised nor passed on
        self.stage = LOOP_STAGE
        try:
            yield
        finally:
            self.stage = STOPPING_STAGE
            self._stop = None

    def handle(self, signum: int, _frame) -> None:
        """The signal handler: before the loop raise Interrupted (once), in it ask it to stop, after it nothing."""
        name = signal.Signals(signum).name
        if self._stop is not None:
            self._stop(name)
            return
        if self.stage == STOPPING_STAGE or self.signal is not None:
            return
        self.signal = name
        raise Interrupted(name, signum, self.stage)


@contextlib.contextmanager
def startup_signals() -> Iterator[Startup]:
    """Inside the block the :data:`STOP_SIGNALS` go to a :class:`Startup`'s handler; the previous handlers
    come back on exit."""
    startup = Startup()
    with handling_stop_signals(startup.handle):
        yield startup


@contextlib.contextmanager
def closing_link(link: Link, startup: Startup) -> Iterator[Link]:
    """``link`` opened, and closed (its stop commands, then the port released) on every way out: also when
    its ``open`` fails or a signal interrupts it half way (the stop commands go to what it had configured)."""
    startup.enter("opening the link")
    try:
        link.open()
        startup.link_opened = True
        yield link
    finally:
        link.close()
        startup.link_closed = True


def interrupted_summary(e: Interrupted, startup: Startup) -> dict:
    """The summary of a start-up a signal ended: no cycle run; what was done with the link; the recording."""
    return {"stopped_by": e.name, "stopped_during": f"start-up: {e.stage}", "cycles": 0,
            "link": {"opened": startup.link_opened, "closed": startup.link_closed},
            "recording": startup.recording}


def finish_interrupted(e: Interrupted, startup: Startup, args: argparse.Namespace) -> int:
    """Write (``--summary-json``) and print the summary of a start-up a signal ended; the exit code, 128 + the
    signal's number. The options may not have been checked yet: a summary path that cannot be written is told
    in one line, the exit code the same."""
    summary = interrupted_summary(e, startup)
    path = getattr(args, "summary_json", None)
    try:
        if path:
            check_output_path(path, "--summary-json")
            write_json(summary, path)
    except InputError as err:
        print(f"livezmp: error: {err}", file=sys.stderr)
    print(interrupted_line(summary), flush=True)
    return 128 + e.number


def interrupted_line(summary: dict) -> str:
    """One line for the operator of an :func:`interrupted_summary`."""
    link = summary["link"]
    what = ("the link, open (torque on, holding), was sent its stop commands and closed" if link["opened"] else
            "the link, being opened, was sent its stop commands and closed" if link["closed"] else
            "no link was opened")
    return f"stopped by {summary['stopped_by']} during {summary['stopped_during']}: no cycle run; {what}"
