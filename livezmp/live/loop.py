"""The live balance loop: read → estimate → correct → write, at a fixed rate.

Before the clock starts, one frame is read and the corrector measures the robot's own dynamics in
that standing posture (`LiveLoop._prepare_corrector`: milliseconds of CPU, more than a fast cycle has).
Every cycle of a :class:`~livezmp.live.clock.LoopClock` (absolute deadlines):

1. read one verified frame from the link; the :class:`~livezmp.live.safety.FrameGuard`
   rejects stale and corrupted ones;
2. estimate: the base pose comes from the joint angles with the stance foot flat
   (:class:`~livezmp.model.base_placement.BasePlacer`); where the link reads an IMU,
   gravity's direction in that foot's frame comes from it, fused with the legs
   (:class:`~livezmp.estimate.ground_tilt.GroundTilt`), so a slope does not bend the ZMP;
   base + joints go through the per-frame :class:`~livezmp.balance.pipeline.Pipeline`
   (results lag by the estimator's lag). Where the link reads foot sensors
   (``LoopConfig.contacts``), they say which feet are down instead of the kinematic
   detection; and each analysed sample is paired with the sensor reading of the same
   sample, whose centre of pressure, placed on the result's soles, is compared with the
   computed ZMP (:mod:`livezmp.balance.foot_sensors`; summary ``cop_vs_zmp``);
3. correct: at ``correct_hz`` (every few cycles) the
   :class:`~livezmp.correct.online.OnlineCorrector` turns the newest result (with the
   measured CoP of its sample, where there are foot sensors: it sees pushes) into
   leg-joint offsets for the posture about to be sent (held in between: its IK costs
   more than one 500 Hz period allows on every cycle). Where it steps every second cycle or
   less often, its step is split over two cycles: the root rotation from the result in one,
   the legs' IK (the costlier part) for that cycle's command in the next, whose offsets then
   reach the goals a cycle later, so no one cycle carries both on top of its estimate (at
   1 kHz on two buses a cycle with both ran past its deadline one time in five);
4. write: goals = command + offsets, through the
   :class:`~livezmp.live.safety.GoalLimiter` (correction and joint limits; each goal at most its joint's
   URDF speed from the last one sent: counted, told and recorded as ``goal_speed``).

On a link that sends its next read ahead (a Dynamixel bus) the cycle is pipelined: read, write
the goals built the cycle before with the next read's instruction, then estimate and correct
while that read travels; on pseudo-terminals the loop first sleeps `PTY_SEND_PAUSE_S` for each port it
wrote, so the kernel worker that carries the bytes runs before the loop's work.

The command comes from a scenario or motion (``command(t)``: joint goals, rad, at loop
time t in s) or, without one, is the posture of the first frame (hold and balance). At
the start, and when commanding resumes after a stop, the goals blend from the present
posture to the command over ``ramp_s``.

A cycle whose read fails, or whose frame the guard rejects, writes nothing; the
estimator is told the sample is missing (so its time grid stays uniform and short gaps
are bridged by its Kalman prediction). Deadlines the clock skipped are not filled in:
the estimator fits the uneven times instead, a bounded ~0.1 ms more a frame for one
window (a lone gap seen before costs nothing: its windows' weights are kept), where
analysing a missing sample per skipped deadline would add work exactly when the loop is
already late. With no valid frame for the watchdog time the loop stops commanding (hold,
or drop torque); while the link reports its port gone
(:class:`~livezmp.links.base.LinkError`) it stops reading and tries ``reconnect`` every
``reconnect_every_s`` instead; a link that says it is unusable
(:class:`~livezmp.links.base.LinkUnusable`: e.g. it loses too many replies) stops the
run. The first valid frame after a gap longer than the watchdog time restarts the
estimator and resets the corrector (a gap must not produce a velocity spike) and ramps back to the
command. After dropping torque, or a servo's hardware error, the loop only monitors. On every way out
— the end, a stop request (Ctrl-C / SIGTERM), an exception — ``safe_stop`` is the
first call to the link.

With a ``recorder`` (:class:`~livezmp.live.recorder.LoopRecorder`) every good sample,
analysed result, foot-sensor reading and command's correction is queued for its
background writer: the loop only appends objects to a bounded queue.

Memory is bounded (histograms, a short event list) and each cycle costs the same
whatever the length of the run.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from livezmp.balance.foot_sensors import CopLocator, CopVsZmp, contact_force, sensor_contacts
from livezmp.balance.pipeline import FrameResult, Pipeline, default_config
from livezmp.correct.online import OnlineCorrector, size_scaled_accel, size_scaled_margin
from livezmp.errors import InputError
from livezmp.estimate.ground_tilt import GroundTilt
from livezmp.histogram import TimingHistogram
from livezmp.links.base import FootSensors, Link, LinkError, LinkFrame, LinkReadError, LinkUnusable
from livezmp.live.clock import LoopClock, Tick
from livezmp.live.config import CONTACT_MODES, LoopConfig
from livezmp.live.fall_detection import FallDetector
from livezmp.live.link_faults import LinkFaults
from livezmp.live.recorder import LoopRecorder
from livezmp.live.safety import FrameGuard, GoalLimiter, Slowed, Watchdog, joint_limits
from livezmp.model.base_placement import BasePlacer
from livezmp.model.body import BodyModel
from livezmp.model.demo_robot import smooth_ramp
from livezmp.model.mimic import follow

STAGES = ("read", "estimate", "correct", "write")
FELL_CHECK_S = 0.05  # how often the simulator's fall flag is polled (it takes its lock)
# After sending on a pseudo-terminal (a simulated bus) a pipelined cycle sleeps this long before its work. The
# pty's bytes wait for a kernel worker of normal priority; when the other CPUs are busy the scheduler puts it on the
# loop's own CPU (the loop's real-time load does not count in its placement), where under SCHED_FIFO the loop's
# estimate and correction hold it off. Measured on 2 CPUs at load 2-3 (ftrace): it went on the loop's CPU after
# 34-91 % of the loop's writes (OP3, 2 Mbps); livezmp_mini at 4 Mbps, 6 alternated pairs: it waited over 0.2 ms
# after 6-37 % of the writes, with the pause 1-8 %, and missed deadlines went 4-28 % -> 1.6-5.4 %. A 1 us sleep was
# too short. A USB-serial adapter's bytes leave in the write itself. Per port written: on two buses at 1 kHz
# (livezmp_mini, hs adapters, load 0.6-1.5, 7 alternated pairs) 20 us for both missed 0.94-2.75 % of deadlines
# (median 1.16), 40 us 0.62-1.32 % (median 0.90).
PTY_SEND_PAUSE_S = 2e-5
EVENT_REPEAT_S = 1.0  # an event of a repeating kind is told at most once a second; the rest are counted
REPEATING_KINDS = frozenset({"read_error", "stale", "corrupted", "write_error", "no_sensors", "goal_speed"})
# recorded (/device_error) and counted, not told: a bus losing 1 % of its replies would print a line a second; the
# status line counts them
QUIET_KINDS = frozenset({"read_error"})
NOT_RECORDED_KINDS = frozenset({"fell"})  # the robot's state, not a fault of its devices or link
# Reads tried before the clock starts for the corrector's measure of the robot (`LiveLoop._prepare_corrector`): a
# bus losing 5 % of its replies fails all of them one time in 3 million; each failed try costs the link's own
# timeout (a Dynamixel read's few ms), and the robot is holding its posture meanwhile
START_READS = 5
# The goals' speed limit counts the loop time since the goals before (skipped deadlines, cycles without a write) up to
# this many periods: past it (a gap the watchdog is about to end) the goals resume at this pace, not in one jump
MAX_PACE_PERIODS = 3

@dataclass
class LoopCounters:
    """Per-run counts; ``analysed``: results of real samples; ``judged``/``inside``: those
    with a support polygon and those whose estimated ZMP was inside it."""

    cycles: int = 0
    failed_reads: int = 0
    write_errors: int = 0
    stale_frames: int = 0
    corrupted_frames: int = 0
    good_frames: int = 0
    commands_sent: int = 0
    corrections_sent: int = 0
    corrections_limited: int = 0
    goals_slowed: int = 0  # commands sent with a goal the joint speed limit cut
    slowed_joints: dict[str, int] = field(default_factory=dict)  # ... and how often each joint's
    analysed: int = 0
    judged: int = 0
    inside: int = 0
    watchdog_trips: int = 0
    reconnects: int = 0
    resumes: int = 0
    sensor_contacts: int = 0  # good frames whose contacts came from the foot sensors
    no_sensor_frames: int = 0  # good frames without a foot-sensor reading, with contacts="sensors"
    hardware_errors: dict[str, int] = field(default_factory=dict)


class LiveLoop:
    """The loop over one open ``link`` (joints in ``body.joint_names`` order).

    ``command(t)``: joint goals (rad) at loop time t (s), or None to hold the first
    frame's posture. ``clock``: a :class:`LoopClock` (default: real time at
    ``config.rate_hz``). ``fell()``: the simulator's fall flag, when there is one; without
    it, a link with an IMU tells the fall (:mod:`livezmp.live.fall_detection`: the trunk tilted
    past 45 degrees, or free fall), which stops the run as the simulator's flag does.
    ``on_event(msg)`` gets one-line notes of state changes; ``on_status(dict)`` a status
    every ``config.status_every_s``. ``recorder``: where to record the run (it is not
    closed here)."""

    def __init__(self, link: Link, body: BodyModel, config: LoopConfig | None = None,
                 command: Callable[[float], np.ndarray] | None = None, clock: LoopClock | None = None,
                 fell: Callable[[], bool] | None = None, on_event: Callable[[str], None] | None = None,
                 on_status: Callable[[dict], None] | None = None, recorder: LoopRecorder | None = None):
        self.link = link
        self.body = body
        self.config = config or LoopConfig()
        cfg = self.config
        if not (math.isfinite(cfg.correct_hz) and cfg.correct_hz > 0):
            raise InputError(f"corrector rate {cfg.correct_hz!r} Hz: must be a positive number")
        if cfg.contacts not in CONTACT_MODES:
            raise InputError(f"contacts {cfg.contacts!r}: expected one of {', '.join(CONTACT_MODES)}")
        self.clock = clock or LoopClock(cfg.rate_hz)
        self.dt = self.clock.period
        self.correct_every = max(1, round(1.0 / (self.dt * cfg.correct_hz)))
        self.command = command
        self.fell = fell
        # a link that can send its next read's instruction ahead (Dynamixel) lets the cycle's work overlap the
        # bus: read, write, request the next read, then estimate and correct while it travels
        self.pipelined = hasattr(link, "request")
        # ... and one that builds its packets ahead (`prepare_goals`) gets the next cycle's goals then
        self.prepares = self.pipelined and hasattr(link, "prepare_goals")
        self.fall_detector = FallDetector()
        self._imu_seen = False
        self.on_event = on_event
        self.on_status = on_status
        self.recorder = recorder
        self.min_force = contact_force(body, cfg.contact_fraction)
        self.cop_locator = CopLocator(body, self.min_force)
        self.cop_vs_zmp = CopVsZmp()
        self.limits = joint_limits(body)
        self.guard = FrameGuard(self.limits, cfg.safety)
        self.limiter = GoalLimiter(self.limits, cfg.safety, self.dt, body.mimics)
        self.pipeline_config = replace(default_config(body, 1.0 / self.dt),
                                       estimator=cfg.estimator_config(1.0 / self.dt))
        self.counters = LoopCounters()
        self.times = {s: TimingHistogram() for s in STAGES}
        self.latency = TimingHistogram()
        self.events: deque[str] = deque(maxlen=100)
        # event kind -> (last told at, untold since, the latest untold's message)
        self._told: dict[str, tuple[float, int, str]] = {}
        self._untold = 0  # events folded and not noted yet, all kinds
        self.nb = len(body.base_channels)
        self._nan = np.full(body.nq, np.nan)
        self._stop_reason: str | None = None
        self._link_errors0 = link.stats.read_errors
        self._hold: np.ndarray | None = None
        self.halted: str | None = None
        self.torque_dropped = False
        self.stopped = False  # the watchdog stopped commanding
        self.link_down = False
        self.faults = LinkFaults()
        self._t = 0.0  # loop time of the cycle running (s): where the run ended, once it has
        self._samples = 0  # samples given to the estimators over the whole run
        self._startup_reads = 0  # reads tried before the clock for the corrector's measure
        self._measured_before_clock = False
        self._reading: tuple[tuple[bool, bool] | None, FootSensors | None] = (None, None)  # the sample's sensors
        self.corrector = OnlineCorrector(body, self.correct_every * self.dt, cfg.correction_limits,
                                         max_accel_deg_s2=size_scaled_accel(body, cfg.trunk_accel_deg_s2),
                                         margin_m=size_scaled_margin(body) if cfg.margin_m is None
                                         else cfg.margin_m) if cfg.correct else None
        self._restart_estimation()

    # -- state ---------------------------------------------------------------------------------

    def _restart_estimation(self) -> None:
        """A fresh estimator, base placement and offsets, the corrector reset (start, or after a gap)."""
        self.pipe = Pipeline(self.body, self.pipeline_config, nominal_dt=self.dt)
        self.placer = BasePlacer(self.body)
        self.tilt = GroundTilt()
        self._gravity: np.ndarray | None = None  # gravity in the placer's frame at the sample (from the IMU)
        self.command_placer = BasePlacer(self.body)
        if self.corrector is not None:  # its measure of the robot's own dynamics is kept (`_prepare_corrector`)
            self.corrector.reset()
        self.limiter.reset()
        self.guard.reset()
        self.offsets = np.zeros(len(self.limits.names))
        self.result: FrameResult | None = None
        self._cop: np.ndarray | None = None  # the measured CoP of the result's sample (foot sensors)
        self._fresh = False  # a new result arrived this cycle
        self._started = False  # the estimator has had a real sample
        self._fed = 0  # samples given to this pipeline
        self._index0 = self._samples  # run-wide number of this pipeline's first sample
        self._valid = np.zeros(self.pipe.lag + 1, dtype=bool)  # were the last lag + 1 samples real?
        self._feet: list[FootSensors | None] = [None] * (self.pipe.lag + 1)  # ... and their foot sensors
        self._delta = np.zeros(3)  # the corrector's latest root rotation (rad)
        self._next_correction = -math.inf  # loop time of the next corrector step (s)
        # the posture (base + joints) the corrector's updated root rotation awaits its offsets for
        self._offsets_for: np.ndarray | None = None
        self._goals_t = 0.0  # loop time of the goals the limiter kept last (s)
        self._ramp_from: np.ndarray | None = None
        self._ramp_t0 = 0.0
        # (cycle, limited, offsets, command, goals, what the speed limit cut) of the goals built ahead
        self._prepared: tuple[int, bool, np.ndarray, np.ndarray, np.ndarray, Slowed | None] | None = None

    def request_stop(self, reason: str) -> None:
        """Ask the loop to end after the current cycle (safe from a signal handler)."""
        if self._stop_reason is None:
            self._stop_reason = reason

    def _event(self, t: float, kind: str, msg: str) -> None:
        """Note an event of ``kind`` at loop time ``t`` (s): told (``on_event``, the summary's events) and
        recorded (``/device_error``). Those of a kind in `REPEATING_KINDS` (rejected frames, failed reads and
        writes) at most once every EVENT_REPEAT_S: the others in that time are counted, and noted together
        once it has passed (`_flush_events`)."""
        if kind in REPEATING_KINDS:
            last, untold, _ = self._told.get(kind, (-math.inf, 0, ""))
            if t - last < EVENT_REPEAT_S:
                self._told[kind] = (last, untold + 1, msg)
                self._untold += 1
                return
            self._flush_events(t, end=True, kinds=(kind,))  # those before it first: none is lost
            self._told[kind] = (t, 0, msg)
        self._note(t, kind, msg, 1)

    def _note(self, t: float, kind: str, msg: str, count: int) -> None:
        if self.recorder is not None and kind not in NOT_RECORDED_KINDS:
            self.recorder.fault(t, kind, msg, count)
        if kind in QUIET_KINDS:
            return
        line = f"t={t:.3f}s: {msg}"
        self.events.append(line)
        if self.on_event is not None:
            self.on_event(line)

    def _flush_events(self, t: float, end: bool = False, kinds: tuple[str, ...] | None = None) -> None:
        """The repeats of each kind (of ``kinds``; None: all) not noted yet whose EVENT_REPEAT_S has passed (all
        of them at the run's ``end``), in one note a kind at loop time ``t`` (s): the latest one's message and
        their count, so the recording's counts add up to the summary's (a flood of one kind so gives one line a
        second)."""
        for kind in self._told if kinds is None else kinds:
            last, untold, msg = self._told.get(kind, (-math.inf, 0, ""))
            if untold and (end or t - last >= EVENT_REPEAT_S):
                self._told[kind] = (t, 0, msg)
                self._untold -= untold
                self._note(t, kind, f"{msg} ({untold} in the {t - last:.1f} s before)", untold)

    # -- the loop ------------------------------------------------------------------------------

    def run(self, duration: float | None = None) -> dict:
        """Run until ``duration`` seconds of loop time (None: until :meth:`request_stop`);
        return the summary (see :meth:`summary`)."""
        self._last_reconnect = -math.inf
        self._next_fell_check = 0.0
        self._next_status = self.config.status_every_s
        self._link_errors0 = self.link.stats.read_errors
        self._prepare_corrector()
        tick = self.clock.start()
        if self.recorder is not None:
            self.recorder.start()
        # a watchdog shorter than a few periods would trip on one late frame of a slow stream
        self.watchdog = Watchdog(max(self.config.safety.watchdog_s, 3 * self.dt), tick.woke)
        try:
            while True:
                t = self._t = tick.index * self.dt
                if duration is not None and t >= duration:
                    self.request_stop("duration")
                self._poll(t)
                if self._stop_reason is not None:
                    break
                self._cycle(tick, t)
                if self.recorder is not None:  # the recording's writer works while the loop sleeps
                    self.recorder.idle(self.clock.deadline(tick.index + 1) - self.clock.now())
                tick = self.clock.wait()
        except BaseException as e:
            self.request_stop(f"error: {type(e).__name__}: {e}")
            raise
        finally:
            # stop commands go out first, whatever happened
            self.link.safe_stop(drop_torque=self.torque_dropped)
            self._flush_events(self._t, end=True)
        return self.summary()

    def _prepare_corrector(self) -> None:
        """The corrector's measure of the robot's own dynamics (`OnlineCorrector.prepare`: 4.5-10 ms of CPU for
        livezmp_mini, which in the first corrected cycle overran a 200 Hz period) made before the clock starts, in
        the posture of one frame read now (the robot standing as the link opened it), verified as the loop's are,
        its base placed by its feet as the loop's first sample's is. Kept across the estimator's restarts (a
        reconnect, the watchdog's resume): a frame after a gap may find the robot anywhere, and measuring again
        would cost that cycle as much. A read that fails, or whose frame the guard rejects, is tried again, up to
        `START_READS` reads in all; a port gone or a link unusable ends the tries at once (the loop's first cycle
        finds it). Without a good frame the corrector measures in its first analysed frame, inside that cycle (it
        may overrun it); a read that fails here is the run's as the cycles' are (``failed_reads``,
        ``read_errors``), and the summary's ``startup_reads`` says how many were tried and whether the measure
        was made before the clock."""
        if self.corrector is None or self.corrector.reaction is not None:
            return
        for _ in range(START_READS):
            self._startup_reads += 1
            try:
                frame = self.link.read()
            except LinkReadError:
                self.counters.failed_reads += 1
                continue
            except LinkError:  # the port gone, the link unusable: another read now would not mend it
                self.counters.failed_reads += 1
                return
            verdict = self.guard.check(frame, self.clock.now())
            self.guard.reset()  # the loop's first frame is judged on its own: it may carry this one's time stamp
            if verdict is None:
                q = follow(frame.positions, self.body.mimics)
                self.corrector.prepare(np.concatenate([BasePlacer(self.body).update(q), q]))
                self._measured_before_clock = True
                return

    def _poll(self, t: float) -> None:
        """Every so often: the simulator's fall flag, the repeated events and the status callback."""
        if self._untold:
            self._flush_events(t)
        t += 0.5 * self.dt  # grid times: do not let rounding push a check to the next cycle
        if self.fell is not None and t >= self._next_fell_check:
            self._next_fell_check = t + FELL_CHECK_S
            if self.fell():
                self.request_stop("fell")
        if self.on_status is not None and t >= self._next_status:
            self._next_status += self.config.status_every_s
            self.on_status(self.status(t - 0.5 * self.dt))

    def _cycle(self, tick: Tick, t: float) -> None:
        now = self.clock.now
        self.counters.cycles += 1
        self._fresh = False
        if self.link_down:
            self._try_reconnect(t, tick.woke)
            if self.link_down:
                self._check_watchdog(t, now())
                return
        t0 = now()
        frame = self._read(t)
        t1 = now()
        self.times["read"].add(t1 - t0)
        if frame is not None:
            verdict = self.guard.check(frame, t1)
            if verdict is not None:
                if verdict.kind == "stale":
                    self.counters.stale_frames += 1
                else:
                    self.counters.corrupted_frames += 1
                self._event(t, verdict.kind, f"{verdict.kind} frame dropped: {verdict.reason}")
                frame = None
        if frame is None:
            self._request()
            self._missing_sample(t)
            self._check_watchdog(t, t1)
            return
        self.counters.good_frames += 1
        if t1 - self.watchdog.last > self.watchdog.timeout_s or self.stopped:
            self._resume(t)
        self.watchdog.feed(t1)
        if frame.hardware_errors:
            self._hardware_errors(t, frame)
        if frame.imu is not None:
            self._watch_imu(t, frame)
        if self.pipelined:
            # write first, with the offsets the previous cycle's work computed (built then, when this cycle's
            # goals are known ahead), then ask for the next read and do this cycle's work while its bytes are
            # on the wire
            command = self._send_prepared(tick.index, t, t0)
            if command is None and self.halted is None:
                command = self._command(t, frame.positions)
                self._write(t, t0, command)
            self._request()  # when the write failed or was not sent
            ports = getattr(self.link, "pty_ports", 0)
            if ports:
                self.clock.pause(ports * PTY_SEND_PAUSE_S)
            t2 = now()
            self._estimate(t, frame)
            t3 = now()
            self.times["estimate"].add(t3 - t2)
            if command is not None:
                self._correct(t, command)
                self.times["correct"].add(now() - t3)
                self._prepare(tick.index + 1)
            return
        self._estimate(t, frame)
        t2 = now()
        self.times["estimate"].add(t2 - t1)
        if self.halted is not None:
            return
        command = self._command(t, frame.positions)
        self._correct(t, command)
        self.times["correct"].add(now() - t2)
        self._write(t, t0, command)

    def _write(self, t: float, t0: float, command: np.ndarray) -> None:
        """Goals = command + offsets, limited, to the link (``t0``: when the cycle's read started)."""
        t3 = self.clock.now()
        goals, limited, slowed = self.limiter.apply(command, self.offsets, self._periods_since_goals(t))
        self._goals_t = t  # kept by the limiter, sent or not
        try:
            if self.pipelined:  # the next read's instruction in the same transfer as the goals
                self.link.write_goals(goals, request=not self.link_down)
            else:
                self.link.write_goals(goals)
        except LinkError as e:
            self.counters.write_errors += 1
            self._event(t, "write_error", f"write failed: {e}")
            return
        self._written(t, t0, t3, limited, slowed)

    def _prepare(self, index: int) -> None:
        """Cycle ``index``'s goals (its command + the offsets computed now, limited) built into the
        link's packets ahead, while the loop would sleep: when that cycle's read verifies, sending
        is all that is left between the read and the write. Not before commanding has started (its
        ramp starts from the posture read then)."""
        self._prepared = None
        if not self.prepares or self._ramp_from is None or self.halted is not None or self.stopped or \
                self.link_down:
            return
        t = index * self.dt
        command = self._command(t, self._ramp_from)
        goals, limited, offsets, slowed = self.limiter.propose(command, self.offsets)
        try:
            self.link.prepare_goals(goals)
        except LinkError:
            return  # the cycle builds and sends them itself, and says what failed
        self._prepared = (index, limited, offsets, command, goals, slowed)

    def _send_prepared(self, index: int, t: float, t0: float) -> np.ndarray | None:
        """Send the goals `_prepare` built for cycle ``index``, if it did and nothing changed since, and
        return that cycle's command they were built from (the same `_command` would give now: a restart
        drops what was prepared); None when there was nothing to send."""
        prepared, self._prepared = self._prepared, None
        if prepared is None or prepared[0] != index or self.halted is not None or self.stopped:
            return None
        t3 = self.clock.now()
        try:
            self.link.send_prepared()
        except LinkError as e:
            self.counters.write_errors += 1
            self._event(t, "write_error", f"write failed: {e}")
            return prepared[3]
        self.limiter.keep(prepared[4], prepared[2])
        self._goals_t = t
        self._written(t, t0, t3, prepared[1], prepared[5])
        return prepared[3]

    def _written(self, t: float, t0: float, t3: float, limited: bool, slowed: Slowed | None) -> None:
        """Bookkeeping of goals sent at ``t3`` (s) in the cycle whose read started at ``t0``; ``slowed``: what the
        joints' speed limits cut in them."""
        t4 = self.clock.now()
        self.times["write"].add(t4 - t3)
        self.latency.add(t4 - t0)
        self.counters.commands_sent += 1
        if np.logical_or.reduce(self.limiter.offsets):  # any(), without its Python wrapper
            self.counters.corrections_sent += 1
        self.counters.corrections_limited += limited
        if slowed is not None:
            self._slowed(t, slowed)
        if self.recorder is not None and self.corrector is not None:
            self.recorder.correction(self._index0 + self._fed - 1, t, self._delta, limited, self.limiter.offsets)

    def _periods_since_goals(self, t: float) -> float:
        """Loop periods from the goals sent last to loop time ``t`` (s), for their speed limit: 1 on time, more
        after skipped deadlines or cycles that wrote nothing (the command moved on meanwhile: a servo at the
        joint's top speed would have too), at most `MAX_PACE_PERIODS`."""
        return min(max(round((t - self._goals_t) / self.dt), 1), MAX_PACE_PERIODS)

    def _slowed(self, t: float, slowed: Slowed) -> None:
        """Goals the joints' speed limits cut: counted (per joint too), told and recorded as `goal_speed`."""
        self.counters.goals_slowed += 1
        names, counts = self.limits.names, self.counters.slowed_joints
        for j in np.flatnonzero(slowed.mask):
            counts[names[j]] = counts.get(names[j], 0) + 1
        self._event(t, "goal_speed", f"goal of {names[slowed.joint]} slowed to its speed limit: "
                                     f"{slowed.asked:+.3f} rad asked from the goal before, {slowed.allowed:.3f} "
                                     f"allowed at {slowed.speed:.2f} rad/s")

    def _request(self) -> None:
        """With a pipelined link, its next read's instruction goes out now."""
        if self.pipelined and not self.link_down:
            try:
                self.link.request()
            except LinkError:
                pass  # the next read finds the port down and says so

    def _read(self, t: float) -> LinkFrame | None:
        try:
            return self.link.read()
        except LinkReadError as e:
            self.counters.failed_reads += 1
            self._event(t, "read_error", f"read failed: {e}")
        except LinkUnusable as e:  # e.g. a bus that loses too many replies: no reconnect mends it
            self.counters.failed_reads += 1
            self.faults.unusable = str(e)
            self._event(t, "link_unusable", f"link unusable: {e}")
            self.request_stop(f"link unusable: {e}")
        except LinkError as e:
            self.counters.failed_reads += 1
            self.link_down = True
            self.faults.down.begin(t)
            self._event(t, "link_down", f"link down: {e}")
        return None

    def _watch_imu(self, t: float, frame: LinkFrame) -> None:
        self._imu_seen = True
        if self.fall_detector.fell is None and self.fall_detector.update(frame.t, frame.imu):
            self._event(t, "fell", f"fell: {self.fall_detector.fell}")
            if self.fell is None:
                self.request_stop("fell")

    def _missing_sample(self, t: float) -> None:
        if self._started:
            self._feed(t, self._nan, valid=False)

    def _estimate(self, t: float, frame: LinkFrame) -> None:
        q = follow(frame.positions, self.body.mimics)  # the kinematics: a mimic joint where its parent puts it
        self._reading = (self._contacts(t, frame.feet), frame.feet)
        base = self.placer.update(q)
        if self.config.imu_tilt and frame.imu is not None:
            self._gravity = self.tilt.update(frame.t, base, frame.imu)
        self._feed(t, np.concatenate([base, q]), valid=True)
        self._started = True

    def _contacts(self, t: float, feet: FootSensors | None) -> tuple[bool, bool] | None:
        """(left, right) from the foot sensors, or None for kinematic detection (see LoopConfig.contacts)."""
        mode = self.config.contacts
        if mode == "kinematics":
            return None
        contacts = sensor_contacts(feet, self.min_force)
        if contacts is not None:
            self.counters.sensor_contacts += 1
        elif mode == "sensors":
            self.counters.no_sensor_frames += 1
            self._event(t, "no_sensors", "no foot-sensor reading of both feet: contacts detected from the kinematics")
        return contacts

    def _feed(self, t: float, channels: np.ndarray, valid: bool) -> None:
        """One sample into the pipeline, with the contacts and foot sensors of a real one
        (``_reading``); keep its result only when it is the analysis of a real sample, not
        of the estimator's prediction across a gap."""
        contacts, feet = self._reading if valid else (None, None)
        gravity = self._gravity if valid else None
        ring = self._valid
        slot = self._fed % len(ring)
        ring[slot] = valid
        self._feet[slot] = feet
        if valid and self.recorder is not None:
            self.recorder.input(self._index0 + self._fed, t, channels, contacts, gravity)
        self._fed += 1
        self._samples += 1
        result = self.pipe.step(t, channels, contacts, gravity)
        if result is None or not ring[result.index % len(ring)]:
            return
        self.result = result
        self._fresh = True
        self.counters.analysed += 1
        if result.inside is not None:
            self.counters.judged += 1
            self.counters.inside += bool(result.inside)
        self._compare_sensors(result)

    def _compare_sensors(self, result: FrameResult) -> None:
        """The foot sensors read with ``result``'s sample against its ZMP; both recorded."""
        feet = self._feet[result.index % len(self._feet)]
        self._cop = None
        if feet is not None:
            cop = self._cop = self.cop_locator.locate(feet, result.soles)
            distance = self.cop_vs_zmp.add(cop, result.zmp, result.clamped)
        if self.recorder is not None:
            index = self._index0 + result.index
            self.recorder.result(index, result)
            if feet is not None:
                self.recorder.feet(index, result.t, feet, cop, distance)

    def _command(self, t: float, present: np.ndarray) -> np.ndarray:
        """The command at t, blended in from the posture where commanding (re)started."""
        if self._ramp_from is None:
            self._ramp_from, self._ramp_t0 = present.copy(), t
            self.limiter.start_from(present)  # the goals' speed limit counts from where the servos stand
            self._goals_t = t
            if self._hold is None:
                self._hold = present.copy()
        target = self._hold if self.command is None else np.asarray(self.command(t), dtype=float)
        s = float(smooth_ramp(t, self._ramp_t0, self._ramp_t0 + self.config.ramp_s))
        return target if s >= 1.0 else self._ramp_from + s * (target - self._ramp_from)

    def _correct(self, t: float, command: np.ndarray) -> None:
        if self.corrector is None:
            return
        if self._offsets_for is not None:  # the second part of a corrector step split over two cycles
            self._correction_offsets()
            return
        # by loop time, not by counting cycles: when the loop falls behind and skips
        # deadlines, the corrector still steps at the dt it was built for
        if not self._fresh or t < self._next_correction - 0.5 * self.dt:
            return
        self._next_correction = t + self.correct_every * self.dt
        self.corrector.update(self.result, self._cop)
        self._offsets_for = np.concatenate([self.command_placer.update(command), command])
        if self.correct_every == 1:
            self._correction_offsets()

    def _correction_offsets(self) -> None:
        """The offsets of the corrector's root rotation for the command of the cycle that updated it."""
        q_command, self._offsets_for = self._offsets_for, None
        self.offsets = self.corrector.offsets(q_command)[self.nb:]
        self._delta = self.corrector.delta.copy()

    # -- faults --------------------------------------------------------------------------------

    def _check_watchdog(self, t: float, now: float) -> None:
        if self.stopped or not self.watchdog.expired(now):
            return
        self.stopped = True
        self.faults.without_frames.begin(t)
        self._started = False  # no more predicted samples: the estimator restarts on resume
        self.counters.watchdog_trips += 1
        drop = self.config.safety.drop_torque
        self.link.safe_stop(drop_torque=drop)
        if drop:
            self.torque_dropped = True
            self.halted = "torque dropped by the watchdog"
        self._event(t, "watchdog", f"watchdog: no valid frame for {1e3 * (now - self.watchdog.last):.0f} ms; "
                       f"{'torque dropped' if drop else 'holding'}" + ("; reconnecting" if self.link_down else ""))

    def _try_reconnect(self, t: float, now: float) -> None:
        if now - self._last_reconnect < self.config.safety.reconnect_every_s:
            return
        self._last_reconnect = now
        if self.link.reconnect():
            self.counters.reconnects += 1
            self.link_down = False
            self.faults.down.end(t)
            if self.torque_dropped:  # reopening a link switches torque on: a limp robot stays limp
                self.link.safe_stop(drop_torque=True)
            self._event(t, "reconnected", "link reconnected")

    def _resume(self, t: float) -> None:
        gap = self.clock.now() - self.watchdog.last
        self._restart_estimation()
        self.stopped = False
        self.faults.without_frames.end(t)
        self.counters.resumes += 1
        self._event(t, "resumed", f"valid frames again after {1e3 * gap:.0f} ms; estimator restarted"
                       + ("" if self.halted else ", ramping back to the command"))

    def _hardware_errors(self, t: float, frame: LinkFrame) -> None:
        for joint, bits in frame.hardware_errors.items():
            if self.counters.hardware_errors.get(joint) != bits:
                self.counters.hardware_errors[joint] = bits
                self._event(t, "hardware_error", f"servo {joint}: hardware error 0x{bits:02x}")
        if self.config.safety.stop_on_hardware_error and self.halted is None:
            self.halted = f"hardware error on {', '.join(sorted(frame.hardware_errors))}"
            self.link.safe_stop(drop_torque=False)
            self._event(t, "safe_stop", f"safe stop: {self.halted}; monitoring only")

    # -- reports -------------------------------------------------------------------------------

    def status(self, t: float) -> dict:
        """A short live status: loop time, rate, balance, errors, state."""
        c = self.counters
        r = self.result
        return {"t": t, "hz": self.clock.stats().achieved_hz, "support": None if r is None else r.support,
                "margin_mm": None if r is None or r.margin is None else 1e3 * r.margin,
                "inside_fraction": c.inside / c.judged if c.judged else None,
                "misses": self.clock.misses, "read_errors": self.link.stats.read_errors - self._link_errors0,
                "corrections": c.corrections_sent,
                "state": self.state}

    @property
    def state(self) -> str:
        if self.halted is not None:
            return "halted"
        return "stopped" if self.stopped or self.link_down else "running"

    def summary(self) -> dict:
        """Counters, timing and rates of the run (JSON-ready; times in ms). ``read_errors``:
        what the link counted during the run, in its own unit (lost or rejected replies
        or messages: what a simulated device injects); ``failed_reads``: reads that failed (the
        cycles', and the corrector's at start-up); ``stale_frames``/``corrupted_frames``: frames the guard rejected;
        ``cycles``: cycles run (``clock.skipped_cycles`` were passed over)."""
        c = self.counters
        clock = self.clock.stats()
        stats = self.link.stats
        return {
            "cycles": c.cycles,
            "achieved_hz": clock.achieved_hz,
            "deadline_misses": clock.deadline_misses,
            "read_errors": stats.read_errors - self._link_errors0,
            "write_errors": c.write_errors,
            "stale_frames": c.stale_frames,
            "corrupted_frames": c.corrupted_frames,
            "corrections_sent": c.corrections_sent,
            "inside_fraction": c.inside / c.judged if c.judged else None,
            "max_latency_ms": 1e3 * self.latency.max if self.latency.count else None,
            "p99_latency_ms": 1e3 * self.latency.quantile(0.99) if self.latency.count else None,
            "p50_latency_ms": 1e3 * self.latency.quantile(0.5) if self.latency.count else None,
            "fell": bool(self.fell()) if self.fell is not None else (
                self.fall_detector.fell is not None if self._imu_seen else None),
            "imu_fall": self.fall_detector.fell,
            "imu_max_tilt_deg": round(math.degrees(self.fall_detector.max_tilt), 2) if self._imu_seen else None,
            "ground_slope_deg": None if self.tilt.slope_rad is None else round(math.degrees(self.tilt.slope_rad), 2),
            "rate_hz": 1.0 / self.dt,
            "correct": self.config.correct,
            "correct_every": self.correct_every,
            "stopped_by": self._stop_reason,
            "state": self.state,
            "halted": self.halted,
            "failed_reads": c.failed_reads,
            "good_frames": c.good_frames,
            "commands_sent": c.commands_sent,
            "corrections_limited": c.corrections_limited,
            "startup_reads": None if self.corrector is None else {
                "reads": self._startup_reads, "measured_before_clock": self._measured_before_clock},
            "goals_slowed": {"commands": c.goals_slowed, "joints": dict(c.slowed_joints)},
            "analysed_frames": c.analysed,
            "judged_frames": c.judged,
            "watchdog_trips": c.watchdog_trips,
            "reconnects": c.reconnects,
            "resumes": c.resumes,
            "hardware_errors": dict(c.hardware_errors),
            "contacts": {"mode": self.config.contacts, "from_sensors": c.sensor_contacts,
                         "frames_without_sensors": c.no_sensor_frames},
            "cop_vs_zmp": self.cop_vs_zmp.summary() if self.cop_vs_zmp.readings else None,
            "clock": clock.as_dict(),
            "timing": {s: h.summary_ms() for s, h in self.times.items()},
            # the run's read errors, as the top-level count; those from opening the link apart
            "link": {"reads": stats.reads, "read_errors": stats.read_errors - self._link_errors0,
                     "read_errors_before_run": self._link_errors0, "writes": stats.writes,
                     "write_errors": stats.write_errors, "reconnects": stats.reconnects,
                     "errors_by_kind": dict(stats.errors_by_kind)},
            "events": list(self.events),
            **self.faults.summary(self._t),
        }
