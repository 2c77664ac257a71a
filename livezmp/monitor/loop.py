"""The monitor loop: source → pipeline → alarms, dashboard → recording, correction, terminal.

One thread runs it, frame by frame, at constant cost per frame: every input frame is
analysed and recorded; each result goes to the alarm tracker, the dashboard and other
listeners (a cheap hand-off), then the recorder, the optional online corrector and the
terminal view (rate limited). Recording comes after the hand-off so that it is not on the
way from a frame to its result on the dashboard; nothing is skipped to make room, and the
input that completed a result is recorded before it (a recording cut anywhere replays). When
the source is idle the loop still closes due recording chunks and records the source's
faults. It stops when the source is finished or ``stop`` is set, then delivers the
pipeline's last frames and closes the recording. Listeners (the dashboard, a replay check) get every result and alarm.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from livezmp.balance.foot_sensors import CopVsZmp
from livezmp.balance.pipeline import FrameResult, Pipeline, PipelineConfig
from livezmp.correct.online import OnlineCorrector
from livezmp.errors import InputError
from livezmp.gait.channels import reference_channel, tag_channels
from livezmp.gait.live import GaitLiveEstimator
from livezmp.histogram import TimingHistogram
from livezmp.monitor.alarms import AlarmCommand, AlarmEvent, AlarmTracker
from livezmp.recording.writer import Recorder
from livezmp.sources.interface import Source

RATE_WINDOW = 1.0  # s over which the input rate is measured
KEPT_EVENTS = 1000  # alarm events kept for the summary (a long session may raise many)


@dataclass
class MonitorSummary:
    """Totals of a finished run: frames in and analysed, frames out of support, alarms
    raised, source counters, wall-clock duration (s), the last alarm events."""

    inputs: int
    results: int
    out_of_support: int
    alarms: int
    source_stats: dict
    duration: float
    events: list[AlarmEvent] = field(default_factory=list)


class Listener(Protocol):
    """Gets every analysed frame (with the plates' measured centre of pressure, internal
    frame, or None) and alarm event, on the monitor thread; must be quick (the dashboard
    only queues them)."""

    def publish(self, r: FrameResult, cop: np.ndarray | None = None) -> None: ...

    def alarm(self, ev: AlarmEvent) -> None: ...


class Monitor:
    """Runs ``source`` through a :class:`Pipeline` with ``config``. Optional sinks:
    ``recorder``, ``listeners`` (e.g. the dashboard), ``view`` (update/alarm/close),
    ``alarm_command``; ``alarm_after`` s out of support raises an alarm; ``correct``
    runs the :class:`OnlineCorrector` and records its output; ``max_inputs`` stops after that many
    input frames (None: when the source is finished or ``stop`` is set)."""

    def __init__(self, source: Source, config: PipelineConfig, *, alarm_after: float = 0.2,
                 recorder: Recorder | None = None, listeners: Sequence[Listener] = (), view=None,
                 alarm_command: AlarmCommand | None = None, correct: bool = False, idle: float = 0.05,
                 max_inputs: int | None = None):
        self.source, self.recorder, self.listeners, self.view = source, recorder, list(listeners), view
        self.alarm_command = alarm_command
        self.pipeline = Pipeline(source.body, config, source.nominal_dt)
        self.alarms = AlarmTracker(alarm_after)
        dt = source.nominal_dt or 0.01
        self.corrector = OnlineCorrector(source.body, dt) if correct else None
        self.idle, self.max_inputs = idle, max_inputs
        self.inputs = self.results = self.out_of_support = 0
        self.last: FrameResult | None = None
        self.events: deque[AlarmEvent] = deque(maxlen=KEPT_EVENTS)
        self._arrivals: deque[float] = deque()
        self._gait: tuple[int, GaitLiveEstimator] | None = None
        self._gait_tried = False
        self.cadence: float | None = None
        # per analysed frame: result ready − arrival of the input that completed it (the
        # work beyond the estimator's lag), and − the source's own stamp where it has one
        self.beyond_lag = TimingHistogram(bin_s=1e-5, span_s=1.0)
        self.from_stamp = TimingHistogram(bin_s=1e-5, span_s=1.0)
        # plates' CoP (internal frame) of the inputs not yet analysed, by input index
        self._cops: deque[tuple[int, np.ndarray]] = deque(maxlen=self.pipeline.lag + 8)
        self.cop_vs_zmp = CopVsZmp()

    # -- status ---------------------------------------------------------------

    def input_fps(self) -> float | None:
        a = self._arrivals
        if len(a) < 2 or a[-1] <= a[0]:
            return None
        return (len(a) - 1) / (a[-1] - a[0])

    def status(self) -> dict:
        """The live status (plain JSON values): source, rates, balance, alarms, drops."""
        r, st = self.last, self.source.stats
        return {
            "source": self.source.name, "inputs": self.inputs, "results": self.results,
            "input_fps": self.input_fps(), "support": r.support if r else None,
            "margin": None if r is None or r.margin is None else float(r.margin),
            "out_of_support": self.out_of_support,
            "out_fraction": self.out_of_support / self.results if self.results else None,
            "alarms": self.alarms.count, "alarm_active": self.alarms.raised,
            "alarm_since": self.alarms.since if self.alarms.raised else None,
            "lag_ms": None if self.source.nominal_dt is None else 1000.0 * self.pipeline.lag * self.source.nominal_dt,
            "cadence": self.cadence, "dropped": st.dropped, "lost": st.lost, "source_stats": st.as_dict(),
            "recording": str(self.recorder.path) if self.recorder else None,
        }

    def summary_json(self) -> dict:
        """What ``--summary-json`` writes: frames in / analysed / dropped per reason, latency
        percentiles (ms), the estimator's settings and lag, source counters."""
        st, est = self.source.stats.as_dict(), self.pipeline.config.estimator
        # bad_markers counts frames kept (their bad markers left out as occluded), resyncs new timelines followed,
        # disconnected reads that found a link's port gone, kernel_drops datagrams that never reached the source:
        # none is a frame received and dropped
        dropped = {k: v for k, v in st.items() if k not in ("delivered", "lost", "reconnects", "bad_markers", "resyncs",
                                                            "disconnected", "kernel_drops")}
        dt, lag = self.source.nominal_dt, self.pipeline.lag
        return {
            "source": self.source.name, "frames_in": self.inputs, "analysed_frames": self.results,
            "dropped": {**dropped, "total": sum(dropped.values())}, "lost": st["lost"],
            "reconnects": st["reconnects"], "disconnected": st["disconnected"], "bad_markers": st["bad_markers"],
            "resyncs": st["resyncs"], "kernel_drops": st["kernel_drops"],
            "out_of_support": self.out_of_support, "alarms": self.alarms.count,
            "latency": {"result_after_input": self.beyond_lag.summary_ms(),
                        "result_after_source_stamp": self.from_stamp.summary_ms() if self.from_stamp.count else None},
            "estimator": {"lag_frames": lag, "lag_ms": None if dt is None else 1e3 * lag * dt,
                          "window_s": est.window_s, "lag_s": est.lag_s, "cutoff_hz": est.cutoff_hz,
                          "kalman_corner_hz": est.kalman_corner_hz, "rate_hz": est.rate_hz},
            "cop_vs_zmp": self.cop_vs_zmp.summary() if self.cop_vs_zmp.readings else None,
            "recording": self.recorder.state() if self.recorder else None,
            **(self.source.details() if hasattr(self.source, "details") else {}),  # e.g. a marker stream's gaps
        }

    # -- per frame ------------------------------------------------------------

    def _track_gait(self, r: FrameResult) -> None:
        """Cadence from the thigh flexion channel, when the body has one."""
        if not self._gait_tried:
            self._gait_tried = True
            try:
                tags = tag_channels(self.source.body, r.q, self.source.name)
                ref = tags[reference_channel(tags, self.source.name)]
                self._gait = (self.source.body.channel_names.index(ref.name), GaitLiveEstimator(1, 0))
            except InputError:
                self._gait = None
        if self._gait is not None:
            channel, est = self._gait
            state = est.update(r.t, np.array([r.q[channel]]))
            self.cadence = None if state is None else state.cadence

    def _alarm(self, ev: AlarmEvent) -> None:
        self.events.append(ev)
        if self.recorder:
            self.recorder.write("/alarm", ev.as_message())
        for li in self.listeners:
            li.alarm(ev)
        if self.view:
            self.view.alarm(ev)
        else:
            print(f"livezmp: {ev.message}", file=sys.stderr, flush=True)
        if self.alarm_command:
            self.alarm_command.run(ev)

    def _result(self, r: FrameResult) -> None:
        self._record(r, *self._publish(r))

    def _publish(self, r: FrameResult) -> tuple[np.ndarray | None, AlarmEvent | None]:
        """Count and hand ``r`` to the listeners (the dashboard); its measured CoP and alarm event."""
        self.results += 1
        self.last = r
        if r.inside is False:
            self.out_of_support += 1
        self._track_gait(r)
        ev = self.alarms.update(r)
        cop = self._measured_cop(r.index)
        if cop is not None:
            cop = None if np.isnan(cop[0]) else cop  # plates present, unloaded
            self.cop_vs_zmp.add(cop, r.zmp, r.clamped)
        for li in self.listeners:
            li.publish(r, cop)
        return cop, ev

    def _record(self, r: FrameResult, cop: np.ndarray | None, ev: AlarmEvent | None) -> None:
        """After the hand-off: record ``r``, raise its alarm, correct, update the terminal view."""
        if self.recorder:
            self.recorder.result(r, cop)
        if ev is not None:
            self._alarm(ev)
        if self.corrector is not None:
            c = self.corrector.step(r, r.q)
            if self.recorder:
                names = self.source.body.channel_names
                self.recorder.write("/correction", {
                    "index": r.index, "t": r.t, "limited": c.limited,
                    "delta": {"x": float(c.delta[0]), "y": float(c.delta[1]), "z": float(c.delta[2])},
                    "offsets": {names[i]: float(c.offsets[i]) for i in np.flatnonzero(c.offsets)}})
        if self.view:
            self.view.update(self.status())

    def _measured_cop(self, index: int) -> np.ndarray | None:
        """The plates' CoP of input ``index`` (internal frame), compared with the ZMP by the
        caller's result; None when the source has no plates."""
        while self._cops and self._cops[0][0] < index:
            self._cops.popleft()
        if not self._cops or self._cops[0][0] != index:
            return None
        return self._cops.popleft()[1]

    def _idle(self) -> None:
        for err in self.source.errors.drain():
            if err.kind == "disconnected" and not self.view:  # the source gone: told as it happens, not only recorded
                times = f" ({err.count} times in {self.source.errors.interval:g} s)" if err.count > 1 else ""
                print(f"livezmp: {err.message}{times}", file=sys.stderr, flush=True)
            if self.recorder:
                self.recorder.write("/device_error", {"wall_time": err.wall, "kind": err.kind,
                                                      "message": err.message, "count": err.count})
        if self.recorder:
            self.recorder.tick()
        if self.view:
            self.view.update(self.status())

    def step(self) -> bool:
        """Read and process one frame (or do the idle work); False once the source is finished."""
        frame = self.source.read(self.idle)
        if frame is None:
            self._idle()
            return not self.source.finished
        k = self.inputs
        self.inputs += 1
        self._arrivals.append(frame.received)
        while self._arrivals[-1] - self._arrivals[0] > RATE_WINDOW:
            self._arrivals.popleft()
        if frame.restart and self.pipeline.frames_in:  # a new timeline: finish the old one, start over
            for r in self.pipeline.restart():
                self._result(r)
            self._gait_tried = False  # the cadence's estimator starts over too: its times may go back
        if frame.cop is not None:
            self._cops.append((k, self.source.body.world_from_input @ frame.cop))
        r = self.pipeline.step(frame.t, frame.channels, frame.contacts, frame.gravity)
        if r is not None:
            published = self._publish(r)
            done = time.monotonic() - frame.received
            self.beyond_lag.add(done)
            if frame.latency is not None:
                self.from_stamp.add(frame.latency + done)
        if self.recorder:  # after the hand-off, and before the result it completed: a recording cut
            self.recorder.input(k, frame.t, frame.channels, frame.contacts, frame.gravity)  # anywhere replays
        if r is not None:
            self._record(r, *published)
        if k % 64 == 0:
            self._idle()
        return True

    def run(self, stop: threading.Event | None = None) -> MonitorSummary:
        """Process frames until the source is finished or ``stop`` is set."""
        start = time.monotonic()
        stop = stop or threading.Event()
        try:
            while not stop.is_set() and self.step():
                if self.max_inputs is not None and self.inputs >= self.max_inputs:
                    break
            for r in self.pipeline.flush():
                self._result(r)
            self._idle()
        finally:
            self.source.close()
            if self.alarm_command:
                self.alarm_command.close()
            if self.recorder:
                self.recorder.close({"source_stats": self.source.stats.as_dict(), "inputs": self.inputs,
                                     "results": self.results, "out_of_support": self.out_of_support,
                                     "alarms": self.alarms.count})
            if self.view:
                self.view.close(self.status())
        return MonitorSummary(self.inputs, self.results, self.out_of_support, self.alarms.count,
                              self.source.stats.as_dict(), time.monotonic() - start, list(self.events))
