"""Out-of-support alarms: the ZMP outside the support polygon for longer than a threshold.

A frame is out of support when its ZMP lies outside the polygon (``inside`` is False);
frames in flight or without support have no verdict and end a run like frames inside.
Durations use the frames' own clock, so a replay raises the same alarms as the live
session. An alarm is raised once per run, when the run reaches ``threshold`` s, and
cleared at the first frame back inside (or without a verdict).
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
from dataclasses import asdict, dataclass

from livezmp.balance.pipeline import FrameResult
from livezmp.errors import InputError


@dataclass(frozen=True)
class AlarmEvent:
    """``event`` "raised" or "cleared" at frame ``index``, time ``t`` s; the run began at
    ``since`` s, has lasted ``duration`` s, with margin at worst ``worst_margin`` m (< 0)."""

    event: str
    index: int
    t: float
    since: float
    duration: float
    worst_margin: float

    @property
    def message(self) -> str:
        if self.event == "raised":
            return (f"ALARM: ZMP out of support for {1000 * self.duration:.0f} ms since t={self.since:.3f} s "
                    f"(worst {1000 * -self.worst_margin:.0f} mm outside)")
        return (f"cleared: ZMP back in support at t={self.t:.3f} s after {1000 * self.duration:.0f} ms out "
                f"(worst {1000 * -self.worst_margin:.0f} mm outside)")

    def as_message(self) -> dict:
        return {**asdict(self), "message": self.message}


class AlarmTracker:
    """Feed every analysed frame to :meth:`update`; it returns the event the frame causes."""

    def __init__(self, threshold: float):
        if not threshold >= 0:
            raise InputError(f"alarm threshold must be ≥ 0 s, got {threshold}")
        self.threshold = threshold
        self.since: float | None = None  # start of the current out-of-support run
        self.worst = 0.0
        self.raised = False
        self.count = 0

    def update(self, r: FrameResult) -> AlarmEvent | None:
        if r.inside is False:
            if self.since is None:
                self.since, self.worst, self.raised = r.t, 0.0, False
            elif r.t < self.since:  # a stream that started over on an earlier clock: the run is timed from here
                self.since = r.t
            self.worst = min(self.worst, r.margin)
            if not self.raised and r.t - self.since >= self.threshold:
                self.raised = True
                self.count += 1
                return AlarmEvent("raised", r.index, r.t, self.since, r.t - self.since, self.worst)
            return None
        if self.since is None:
            return None
        event = AlarmEvent("cleared", r.index, r.t, self.since, r.t - self.since, self.worst) if self.raised else None
        self.since, self.raised = None, False
        return event


class AlarmCommand:
    """Runs a user command on every alarm event, without waiting for it. The event goes
    in the environment: ``LIVEZMP_ALARM`` (raised/cleared), ``LIVEZMP_ALARM_T``,
    ``LIVEZMP_ALARM_DURATION`` (s), ``LIVEZMP_ALARM_MARGIN`` (m), ``LIVEZMP_ALARM_JSON``.
    While the previous run is still going, new events are counted in ``skipped``, so a
    slow command never piles up processes."""

    def __init__(self, command: str):
        self.argv = shlex.split(command)
        if not self.argv:
            raise InputError("--alarm-command: empty command")
        if shutil.which(self.argv[0]) is None:
            raise InputError(f"--alarm-command: {self.argv[0]!r}: command not found")
        self._proc: subprocess.Popen | None = None
        self.started = 0
        self.skipped = 0

    def run(self, ev: AlarmEvent) -> None:
        if self._proc is not None and self._proc.poll() is None:
            self.skipped += 1
            return
        env = {**os.environ, "LIVEZMP_ALARM": ev.event, "LIVEZMP_ALARM_T": repr(ev.t),
               "LIVEZMP_ALARM_DURATION": repr(ev.duration), "LIVEZMP_ALARM_MARGIN": repr(ev.worst_margin),
               "LIVEZMP_ALARM_JSON": json.dumps(ev.as_message())}
        self._proc = subprocess.Popen(self.argv, env=env, stdin=subprocess.DEVNULL)
        self.started += 1

    def close(self, timeout: float = 5.0) -> None:
        """Wait (bounded) for the last run, so it is not left a zombie."""
        if self._proc is not None:
            try:
                self._proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
