"""The live loop's clock, safety rules and cycle logic, on simulated time.

A scripted link stands in for a servo bus here: a first-order servo model on a
simulated clock, with faults scripted by read number, so every count can be compared
with exactly what was injected. The real links over simulated devices are exercised
in test_live_loop_links.py."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from livezmp.correct.online import OnlineCorrector, size_scaled_accel, size_scaled_margin
from livezmp.errors import InputError
from livezmp.histogram import TimingHistogram
from livezmp.links.base import LinkError, LinkFrame, LinkReadError, LinkStats
from livezmp.live.clock import LoopClock
from livezmp.live.config import LoopConfig, SafetyConfig
from livezmp.live.loop import PTY_SEND_PAUSE_S, START_READS, LiveLoop
from livezmp.live.safety import FrameGuard, GoalLimiter, JointLimits, Watchdog, joint_limits
from livezmp.live.scenarios import make_scenario, smooth_step
from livezmp.model.base_placement import BasePlacer
from livezmp.model.demo_robot import demo_robot_path, smooth_ramp

RATE = 500.0
T = 1.0 / RATE


class SimTime:
    """A clock that only moves when advanced (the loop's sleeps) or charged for work; advances
    overshoot by ``overshoot`` s."""

    def __init__(self, overshoot: float = 0.0):
        self.t = 1000.0
        self.overshoot = overshoot

    def now(self) -> float:
        return self.t

    def advance(self, d: float) -> None:
        self.t += max(d, 0.0) + self.overshoot


class ScriptedLink:
    """A Link over first-order servos (time constant 30 ms) on a :class:`SimTime`.

    ``fault(n, t)`` decides read number n's fate: None (good), "error" (LinkReadError),
    "down" (LinkError: port gone), "nan", "jump", "slow" (delivered 30 ms late), "repeat" (the
    previous frame again), "hw" (an overload reported on l_knee). ``reconnect_ok(t)``
    says whether a reconnect at t succeeds. Every call is logged as (name, t)."""

    def __init__(self, time: SimTime, names: list[str], q0: np.ndarray, fault=None, reconnect_ok=None):
        self.time = time
        self.joint_names = names
        self.stats = LinkStats()
        self.q = q0.copy()
        self.goal = q0.copy()
        self.torque = True
        self.fault = fault or (lambda n, t: None)
        self.reconnect_ok = reconnect_ok or (lambda t: True)
        self.calls: list[tuple[str, float]] = []
        self.writes: list[tuple[float, np.ndarray, np.ndarray]] = []  # time, goals, last read positions
        self.last_frame: LinkFrame | None = None
        self._t = time.t

    def _advance(self) -> None:
        dt, self._t = self.time.t - self._t, self.time.t
        if self.torque:
            self.q = self.goal + (self.q - self.goal) * math.exp(-dt / 0.03)

    def read(self) -> LinkFrame:
        self.time.t += 2e-4
        self._advance()
        n = self.stats.reads
        self.stats.reads += 1
        self.calls.append(("read", self.time.t))
        fate = self.fault(n, self.time.t)
        if fate in ("error", "down"):
            self.stats.read_errors += 1
            self.stats.count(fate)
            raise (LinkReadError if fate == "error" else LinkError)(f"scripted {fate} at read {n}")
        if fate == "repeat" and self.last_frame is not None:
            return self.last_frame
        sampled = self.time.t
        if fate == "slow":  # delivered 30 ms after it was sampled
            self.time.t += 0.03
        q = self.q.copy()
        if fate == "nan":
            q[3] = np.nan
        elif fate == "jump":
            q[5] += 0.5
        errors = {"l_knee": 0x20} if fate == "hw" else {}
        self.last_frame = LinkFrame(sampled, q, hardware_errors=errors)
        return self.last_frame

    def write_goals(self, positions: np.ndarray) -> None:
        self.time.t += 1e-4
        self._advance()
        self.calls.append(("write", self.time.t))
        self.writes.append((self.time.t, positions.copy(), self.last_frame.positions.copy()))
        self.stats.writes += 1
        self.goal = positions.copy()

    def hold(self) -> None:
        self.goal = self.q.copy()

    def safe_stop(self, drop_torque: bool = False) -> None:
        self.calls.append(("safe_stop_drop" if drop_torque else "safe_stop", self.time.t))
        self._advance()
        self.goal = self.q.copy()
        self.torque = not drop_torque

    def reconnect(self) -> bool:
        ok = self.reconnect_ok(self.time.t)
        self.calls.append(("reconnect", self.time.t))
        if ok:
            self.stats.reconnects += 1
        return ok

    def close(self) -> None:
        self.safe_stop()


def scripted_loop(body, fault=None, reconnect_ok=None, config: LoopConfig | None = None, command=None,
                  work: float = 0.0):
    """A loop over a ScriptedLink on simulated time; ``work`` (s) is charged per cycle on top of the link's."""
    clock_time = SimTime()
    link = ScriptedLink(clock_time, body.joint_names, np.zeros(len(body.joint_names)), fault, reconnect_ok)

    def now() -> float:
        return clock_time.t

    clock = LoopClock(RATE, now=now, sleep=lambda d: clock_time.advance(d - work))
    events: list[str] = []
    loop = LiveLoop(link, body, config or LoopConfig(rate_hz=RATE), command=command, clock=clock,
                    on_event=events.append)
    return loop, link, clock_time, events


# -- the clock ------------------------------------------------------------------------------------------

def test_clock_keeps_absolute_deadlines_despite_sleep_overshoot():
    """Sleeps that overshoot by 0.3 ms do not accumulate: every cycle wakes 0.3 ms after its own deadline."""
    time = SimTime(overshoot=3e-4)
    clock = LoopClock(RATE, now=time.now, sleep=time.advance)
    start = clock.start().woke
    for _ in range(1000):
        time.t += 5e-4  # the cycle's work
        tick = clock.wait()
    assert tick.index == 1000
    assert tick.woke - start == pytest.approx(1000 * T + 3e-4, abs=1e-9)
    stats = clock.stats()
    assert stats.deadline_misses == 0 and stats.skipped == 0
    assert stats.achieved_hz == pytest.approx(1000 / (1000 * T + 3e-4), rel=1e-9)  # only cycle 1 is late
    assert stats.wake_late.quantile(0.99) == pytest.approx(3e-4, abs=1e-5)
    # slack = period - overshoot - work, to within one 10 us bin
    assert stats.slack.quantile(0.5) == pytest.approx(T - 3e-4 - 5e-4, abs=1e-5)


def test_hybrid_wait_sleeps_short_of_the_deadline_then_spins_to_it():
    """With spin_s, a sleep overshooting by 0.15 ms (< spin_s) no longer makes the cycle late: the
    clock sleeps until spin_s before the deadline and spins on now() (each call 1 us) to it."""
    time = SimTime(overshoot=1.5e-4)
    reads = []

    def now() -> float:
        time.t += 1e-6
        reads.append(time.t)
        return time.t

    sleeps = []
    clock = LoopClock(RATE, now=now, sleep=lambda d: (sleeps.append(d), time.advance(d)), spin_s=2e-4)
    clock.start()
    for _ in range(100):
        time.t += 5e-4  # the cycle's work
        tick = clock.wait()
    assert tick.index == 100
    # each sleep ends spin_s before the deadline: the slack (period - work, less a clock read or two) - spin_s
    assert sleeps == pytest.approx([T - 5e-4 - 2e-4] * 100, abs=3e-6)
    assert clock.stats().wake_late.quantile(0.99) < 3e-6  # woke within a clock read of each deadline
    assert len(reads) > 100 * (2e-4 - 1.5e-4) / 1e-6  # it did spin through the 50 us the sleep left


def test_clock_counts_misses_and_skips_overrun_deadlines():
    time = SimTime()
    clock = LoopClock(RATE, now=time.now, sleep=time.advance)
    clock.start()
    # 2.5 ms of work ends in cycle 2's slot; 7.1 ms from cycle 3's start ends in cycle 6's slot
    work = [1e-3, 2.5e-3, 1e-3, 7.1e-3, 0.5e-3]
    ticks = []
    for w in work:
        time.t += w
        ticks.append(clock.wait())
    assert [t.index for t in ticks] == [1, 2, 3, 6, 7]
    # a late cycle runs at once in its own slot, then the grid resumes
    assert ticks[1].woke - ticks[1].deadline == pytest.approx(0.5e-3)
    assert ticks[3].woke - ticks[3].deadline == pytest.approx(1.1e-3)
    assert ticks[2].woke == pytest.approx(ticks[2].deadline)
    assert ticks[4].woke == pytest.approx(ticks[4].deadline)
    stats = clock.stats()
    assert (stats.deadline_misses, stats.skipped) == (2, 2)


def test_clock_rejects_a_bad_rate():
    with pytest.raises(InputError, match="loop rate 0 Hz"):
        LoopClock(0)


def test_histogram_quantiles_match_numpy_within_a_bin():
    rng = np.random.default_rng(4)
    x = rng.gamma(2.0, 4e-4, 20000)
    h = TimingHistogram()
    for v in x:
        h.add(float(v))
    for q in (0.01, 0.5, 0.9, 0.99):
        assert abs(h.quantile(q) - np.quantile(x, q)) <= h.bin_s
    assert h.mean == pytest.approx(x.mean())
    assert h.max == x.max() and h.quantile(1.0) == x.max() and h.min == x.min()


def test_histogram_keeps_values_beyond_its_span_in_its_end_bins():
    h = TimingHistogram(bin_s=1e-3, span_s=0.01)
    for v in (-0.5, 0.0042, 7.0, 7.0):  # a negative duration counts as 0; longer than the span, in the last bin
        h.add(v)
    assert (h.min, h.max, h.count) == (-0.5, 7.0, 4) and h.mean == pytest.approx(13.5042 / 4)
    assert h.counts[0] == 1 and h.counts[4] == 1 and h.counts[-1] == 2 and sum(h.counts) == 4
    assert h.quantile(0.25) == 1e-3 and h.quantile(0.5) == 5e-3
    assert h.quantile(1.0) == pytest.approx(0.011)  # the last bin's upper edge: beyond the span only "longer"


# -- safety rules ---------------------------------------------------------------------------------------

def test_joint_limits_are_the_urdf_limit_tags(mini):
    root = ET.parse(demo_robot_path()).getroot()
    tags = {j.get("name"): j.find("limit") for j in root.findall("joint") if j.get("type") == "revolute"}
    lim = joint_limits(mini)
    assert sorted(lim.names) == sorted(tags)
    for i, name in enumerate(lim.names):
        assert lim.lower[i] == float(tags[name].get("lower"))
        assert lim.upper[i] == float(tags[name].get("upper"))
        assert lim.velocity[i] == float(tags[name].get("velocity"))


def _limits(n=3):
    return JointLimits([f"j{i}" for i in range(n)], np.full(n, -1.0), np.full(n, 1.0), np.full(n, 5.0))


def test_frame_guard_rules():
    guard = FrameGuard(_limits(), SafetyConfig())
    q = np.array([0.1, 0.2, 0.3])
    assert guard.check(LinkFrame(1.0, q), 1.0002) is None
    cases = [  # frame, time of the check, verdict kind, words of its reason
        (LinkFrame(1.002, np.array([0.1, np.nan, 0.3])), 1.0022, "corrupted", "joint j1: non-finite"),
        (LinkFrame(1.002, np.array([0.1, 0.2])), 1.0022, "corrupted", "2 positions for 3 joints"),
        (LinkFrame(1.002, np.array([0.1, 1.2, 0.3])), 1.0022, "corrupted",
         "joint j1: 1.200 rad is beyond its limits [-1.000, 1.000]"),
        # 2 ms after the last good frame: 5 rad/s x 1.5 x 2 ms + 0.05 = 0.065 rad allowed
        (LinkFrame(1.002, q + [0, 0, 0.07]), 1.0022, "corrupted", "joint j2: jumped 0.070 rad"),
        (LinkFrame(1.0, q), 1.0022, "stale", "not newer than the previous one"),
        (LinkFrame(1.01, q), 1.035, "stale", "frame is 25.0 ms old (> 20.0 ms)"),
        (LinkFrame(1.05, q, device_time=5.0), 1.0502, None, None),
        (LinkFrame(1.052, q, device_time=5.0), 1.0522, "stale", "not newer than the previous one"),
        # 0.06 rad more after 10 ms is plausible
        (LinkFrame(1.06, q + 0.06, device_time=5.01), 1.0602, None, None),
    ]
    for frame, now, kind, reason in cases:
        v = guard.check(frame, now)
        assert (v is None) if kind is None else (v.kind == kind and reason in v.reason), (frame, v)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(st.floats(-3, 3), min_size=3, max_size=3), min_size=1, max_size=40),
       st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3))
def test_goal_limiter_never_exceeds_its_limits(offset_seq, command):
    cfg = SafetyConfig(max_correction_rad=0.4, max_correction_rate_rad_s=2.0, limit_margin_rad=0.01)
    lim = _limits()
    limiter = GoalLimiter(lim, cfg, T)
    command = np.array(command)
    prev = np.zeros(3)
    for offsets in offset_seq:
        goals, limited, _ = limiter.apply(command, np.array(offsets))
        sent = limiter.offsets
        assert np.all(np.abs(sent) <= 0.4 + 1e-12)
        assert np.all(np.abs(sent - prev) <= 2.0 * T + 1e-12)
        assert np.all(goals >= -0.99 - 1e-12) and np.all(goals <= 0.99 + 1e-12)
        exact = np.allclose(sent, offsets, atol=0) and np.allclose(goals, command + sent, atol=0)
        assert limited == (not exact)
        prev = sent


def test_goal_limiter_is_the_two_clips_exactly_also_for_non_finite_input():
    """The limiter's goals and kept offsets are, bit for bit, offsets clipped to the correction limit and
    the rate limit, then command + offsets clipped to the joint limits (np.clip, the reference):
    non-finite offsets count as zero, a NaN command stays NaN (the link refuses it)."""
    cfg = SafetyConfig(max_correction_rad=0.4, max_correction_rate_rad_s=2.0, limit_margin_rad=0.01)
    limiter = GoalLimiter(_limits(), cfg, T)
    rng = np.random.default_rng(7)
    for _ in range(300):
        command, offsets = rng.normal(0.0, 0.8, 3), rng.normal(0.0, 0.5, 3)
        offsets[rng.random(3) < 0.2] = rng.choice([np.nan, np.inf, -np.inf])
        command[rng.random(3) < 0.05] = np.nan
        kept = limiter.offsets.copy()
        want = np.where(np.isfinite(offsets), offsets, 0.0)
        sent = np.clip(np.clip(want, -0.4, 0.4), kept - 2.0 * T, kept + 2.0 * T)
        goals = np.clip(command + sent, -0.99, 0.99)
        got, limited, _ = limiter.apply(command, offsets)
        assert np.array_equal(got, goals, equal_nan=True) and np.array_equal(limiter.offsets, sent)
        assert limited == bool(np.any(sent != want) or np.any(goals != command + sent))


def test_safety_config_errors_name_the_field():
    with pytest.raises(InputError, match="watchdog_s = -1: must be a positive number"):
        SafetyConfig(watchdog_s=-1)


def test_watchdog_expires_after_its_timeout():
    w = Watchdog(0.1, 5.0)
    assert not w.expired(5.1)
    assert w.expired(5.1001)
    w.feed(5.2)
    assert not w.expired(5.25)


# -- the loop on a scripted link ---------------------------------------------------------------------

def _writes_follow_good_reads(link: ScriptedLink) -> bool:
    """Every write comes right after a read in the same cycle."""
    names = [c for c, _ in link.calls]
    return all(i > 0 and names[i - 1] == "read" for i, c in enumerate(names) if c == "write")


def test_summary_read_errors_agree_with_the_link_block(mini):
    """Errors counted while the link was opened are not the run's: both places say the run's."""
    loop, link, _, _ = scripted_loop(mini, fault=lambda n, t: "error" if n in (20, 30) else None)
    link.stats.read_errors = 5  # e.g. pings that failed while connecting
    s = loop.run(duration=0.2)
    assert s["read_errors"] == s["link"]["read_errors"] == 2 and s["link"]["read_errors_before_run"] == 5


def test_failed_and_rejected_frames_never_drive_a_command(mini):
    # by read number: read 0 is the one at start-up the corrector measures the robot in (LiveLoop.run), read n cycle
    # n - 1's
    script = {51: "error", 52: "error", 91: "nan", 121: "jump", 151: "slow", 201: "repeat", 241: "error"}
    loop, link, _, events = scripted_loop(mini, fault=lambda n, t: script.get(n))
    s = loop.run(duration=0.8)
    # the slow read (30.2 ms) passed 14 deadlines, which were skipped; every other cycle ran
    assert s["cycles"] + s["clock"]["skipped_cycles"] == 0.8 * RATE
    assert s["clock"]["skipped_cycles"] == 14 and s["deadline_misses"] == 1
    assert (s["read_errors"], s["corrupted_frames"], s["stale_frames"]) == (3, 2, 2)
    assert link.stats.reads == s["cycles"] + 1
    assert s["commands_sent"] == s["good_frames"] == s["cycles"] - len(script)
    assert link.stats.writes == s["commands_sent"]
    assert _writes_follow_good_reads(link)
    # each kind is told once a second at most: the second of each within the run is counted, and told at its end
    assert [e for e in events if "frame dropped" in e] == [
        "t=0.180s: corrupted frame dropped: joint l_hip_roll: non-finite position",
        "t=0.300s: stale frame dropped: frame is 30.0 ms old (> 20.0 ms)",
        "t=0.800s: corrupted frame dropped: joint l_knee: jumped 0.500 rad since the last frame "
        "(1 in the 0.6 s before)",
        "t=0.800s: stale frame dropped: frame is not newer than the previous one (1 in the 0.5 s before)"]
    assert link.calls[-1][0] == "safe_stop"
    assert s["stopped_by"] == "duration" and s["watchdog_trips"] == 0


def test_watchdog_stops_commanding_and_resumes_without_a_velocity_spike(mini):
    """Reads fail from 0.6 s to 0.85 s: within the 100 ms watchdog the loop holds and
    stops writing; when frames return the estimator restarts and the goals ramp from the
    present posture to the command."""
    arm = mini.joint_names.index("l_sho_pitch")

    def command(t):
        q = np.zeros(len(mini.joint_names))
        q[arm] = 0.5 * math.sin(2 * math.pi * t)
        return q

    loop, link, _, events = scripted_loop(mini, command=command,
                                          fault=lambda n, t: "error" if 0.6 <= t - 1000.0 < 0.85 else None)
    speeds = []
    feed = loop._feed

    def spy(t, channels, valid):
        feed(t, channels, valid)
        if loop._fresh:
            speeds.append(abs(loop.result.v[6 + arm]))

    loop._feed = spy
    s = loop.run(duration=1.6)
    writes = [(t - 1000.0, g, q) for t, g, q in link.writes]
    stop = next(t for c, t in link.calls if c == "safe_stop") - 1000.0
    last_good_read = max(t for c, t in link.calls if c == "read" and t - 1000.0 < 0.6) - 1000.0
    assert 0.1 - 1e-9 <= stop - last_good_read <= 0.1 + T
    assert not [t for t, _, _ in writes if 0.6 <= t < 0.85]
    assert s["watchdog_trips"] == 1 and s["resumes"] == 1
    t_back, goals_back, present = next(w for w in writes if w[0] >= 0.85)
    # the first goals after the gap are the present posture, not a jump to the command
    assert np.array_equal(goals_back, present)
    assert abs(command(t_back)[arm] - present[arm]) > 0.1
    assert any("watchdog: no valid frame for 10" in e for e in events)
    # no velocity spike across the gap: the arm moves at most 0.5 * 2 pi rad/s
    assert max(speeds) < 0.5 * 2 * math.pi * 1.2


def test_port_loss_reconnects_when_the_port_returns(mini):
    gone = (0.3, 0.9)

    def fault(n, t):
        return "down" if gone[0] <= t - 1000.0 < gone[1] else None

    loop, link, time, events = scripted_loop(mini, fault=fault, reconnect_ok=lambda t: t - 1000.0 >= gone[1])
    s = loop.run(duration=1.5)
    reconnects = [t - 1000.0 for c, t in link.calls if c == "reconnect"]
    assert reconnects[0] == pytest.approx(gone[0] + T, abs=T)
    assert all(b - a >= 0.25 - 1e-9 for a, b in zip(reconnects, reconnects[1:], strict=False))
    assert reconnects[-1] >= gone[1] and s["reconnects"] == 1
    # while the port is gone the loop does not hammer it with reads
    assert sum(1 for c, t in link.calls if c == "read" and gone[0] < t - 1000.0 < gone[1]) == 1
    assert s["watchdog_trips"] == 1 and s["state"] == "running"
    # commanding resumes on the first cycle after the reconnect
    assert sum(1 for t, _, _ in link.writes if t - 1000.0 > reconnects[-1]) == round((1.5 - reconnects[-1]) / T)


def _recorded_loop(body, path, fault, reconnect_ok):
    from livezmp.live.recorder import LoopRecorder
    from livezmp.model.body_spec import robot_body

    loop, link, _, events = scripted_loop(body, fault=fault, reconnect_ok=reconnect_ok)
    loop.recorder = LoopRecorder(path, robot_body(demo_robot_path())[1], {"fps": RATE}, body.channel_names,
                                 body.joint_names)
    return loop, link, events


def test_link_faults_are_recorded_with_their_loop_times_and_timed_in_the_summary(mini, tmp_path):
    """Three failed reads, then the port gone from 0.3 to 0.9 s of a 1.5 s run: each fault is on the
    recording's /device_error at its loop time (the failed reads folded, their counts adding up), the
    summary times the outage (until the reconnect that found the port, at 1.05 s), and at 50 % of the run the link
    failed it; every good sample before the
    fault is in the recording."""
    from livezmp.recording.reader import iter_messages

    gone = (0.3, 0.9)

    def fault(n, t):
        # read n is cycle n - 1's (read 0: the start-up read the corrector measures the robot in)
        return "error" if n in (21, 22, 23) else "down" if gone[0] <= t - 1000.0 < gone[1] else None

    path = tmp_path / "run.mcap"
    loop, link, events = _recorded_loop(mini, path, fault, lambda t: t - 1000.0 >= gone[1])
    s = loop.run(duration=1.5)
    totals = loop.recorder.close(s)
    reconnected = [t - 1000.0 for c, t in link.calls if c == "reconnect"][-1]
    records = sorted(iter_messages(path, "/device_error"), key=lambda r: r["t"])
    kinds = [r["kind"] for r in records]
    # the first failed read told at once, the two after it within its second in a record of their own once it passed
    assert kinds == ["read_error", "link_down", "watchdog", "read_error", "reconnected", "resumed"]
    assert [r["count"] for r in records[::3]] == [1, 2] and records[0]["t"] == pytest.approx(20 * T, abs=T)
    assert records[3]["t"] == pytest.approx(1.04, abs=T)
    assert records[3]["message"] == "read failed: scripted error at read 23 (2 in the 1.0 s before)"
    by = {r["kind"]: r for r in records[::-1]}
    assert by["link_down"]["t"] == pytest.approx(gone[0], abs=T) and "scripted down" in by["link_down"]["message"]
    assert by["reconnected"]["t"] == pytest.approx(reconnected, abs=T)
    assert all(r["count"] >= 1 and r["wall_time"] > 1e9 for r in records)
    assert totals["written"]["/device_error"] == 6
    down = s["link_down"]
    assert down["events"] == 1 and not down["at_end"]
    assert down["seconds"] == pytest.approx(by["reconnected"]["t"] - by["link_down"]["t"], abs=1e-9)
    assert down["share"] == pytest.approx(down["seconds"] / 1.5, abs=1e-4) and s["run_s"] == 1.5
    assert s["without_frames"]["events"] == 1 and not s["without_frames"]["at_end"]
    assert s["link_failed"] == "link down 50 % of the run (0.8 s in 1 outage(s)), more than the 10 % allowed"
    # the failed reads are not told on stderr (the status line counts them), the outage is
    assert not [e for e in events if "read failed" in e] and any("link down" in e for e in events)
    inputs = [m["t"] for m in iter_messages(path, "/input")]
    assert len(inputs) == s["good_frames"] and sum(t < gone[0] for t in inputs) == round(gone[0] / T) - 3


@pytest.mark.parametrize("fate", ["down", "error"])
def test_a_link_that_never_comes_back_fails_the_run(mini, tmp_path, fate):
    """The port gone ("down") or every servo silent ("error": each read fails, the adapter still there)
    from 0.5 s to the end of a 1 s run: the summary says it never came back."""
    loop, _, _ = _recorded_loop(mini, tmp_path / "r.mcap", lambda n, t: fate if t - 1000.0 >= 0.5 else None,
                                lambda t: False)
    s = loop.run(duration=1.0)
    loop.recorder.close(s)
    what = "link down" if fate == "down" else "without a valid frame"
    assert s["link_failed"].startswith(f"{what} at the end of the run: it never came back")
    span = s["link_down" if fate == "down" else "without_frames"]
    assert span["at_end"] and span["seconds"] == pytest.approx(0.5 if fate == "down" else 0.4, abs=2 * T)
    assert s["link_down"]["events"] == (fate == "down")


def test_an_outage_under_a_tenth_of_the_run_is_counted_not_failed(mini):
    loop, _, _, _ = scripted_loop(mini, fault=lambda n, t: "down" if 0.3 <= t - 1000.0 < 0.35 else None,
                                  reconnect_ok=lambda t: t - 1000.0 >= 0.35)
    s = loop.run(duration=4.0)
    assert s["link_down"]["events"] == 1 and 0 < s["link_down"]["share"] < 0.1
    assert s["link_failed"] is None and s["reconnects"] == 1


def _measured(monkeypatch, loop: LiveLoop) -> list[tuple[bool, np.ndarray]]:
    """(whether the loop's clock had started, the posture q) of each time its corrector measures the robot's own
    dynamics (`OnlineCorrector.prepare`), filled as ``loop`` runs."""
    calls = []
    prepare = OnlineCorrector.prepare

    def spy(self, q):
        calls.append((loop.clock.cycles > 0, q.copy()))
        prepare(self, q)

    monkeypatch.setattr(OnlineCorrector, "prepare", spy)
    return calls


def test_the_corrector_measures_the_robot_before_the_clock_starts_and_keeps_it_across_a_resume(mini, monkeypatch):
    """Its measure (4.5-10 ms of CPU, which in the first corrected cycle overran a 200 Hz period) is made once, before
    the clock's first deadline, in the posture of a frame read at start-up; the watchdog's stop and resume (reads
    failing from 0.3 to 0.5 s) restart the estimator and reset the corrector without measuring again. On main: in
    the first analysed frame, on the clock, and again after the resume."""
    stand = make_scenario("stand", mini).goals(0.0)
    time = SimTime()
    link = ScriptedLink(time, mini.joint_names, stand, lambda n, t: "error" if 0.3 <= t - 1000.0 < 0.5 else None)
    loop = LiveLoop(link, mini, LoopConfig(rate_hz=RATE), clock=LoopClock(RATE, now=time.now, sleep=time.advance))
    calls = _measured(monkeypatch, loop)
    s = loop.run(duration=1.0)
    assert s["watchdog_trips"] == s["resumes"] == 1 and s["analysed_frames"] > 0.5 * RATE
    assert [started for started, _ in calls] == [False]
    q = calls[0][1]  # the standing posture read, its base placed by its feet as the loop's first sample's
    assert np.array_equal(q[loop.nb:], stand)
    assert np.array_equal(q[:loop.nb], BasePlacer(mini).update(stand))
    assert link.stats.reads == s["cycles"] + 1 and s["link"]["read_errors_before_run"] == 0


def test_a_failed_start_up_read_is_tried_again_before_the_clock_starts(mini, monkeypatch):
    """The start-up read fails, or its frame is rejected, once or twice: the read is tried again and the corrector
    still measures the robot before the clock starts, in the standing posture of the first good frame; the failed
    reads are the run's, as a cycle's are (main: one read, then the measure inside the first analysed cycle)."""
    stand = make_scenario("stand", mini).goals(0.0)
    for fate in ("error", "nan"):
        for bad in (1, 2):
            time = SimTime()
            link = ScriptedLink(time, mini.joint_names, stand, lambda n, t, f=fate, k=bad: f if n < k else None)
            loop = LiveLoop(link, mini, LoopConfig(rate_hz=RATE),
                            clock=LoopClock(RATE, now=time.now, sleep=time.advance))
            calls = _measured(monkeypatch, loop)
            s = loop.run(duration=0.3)
            assert [started for started, _ in calls] == [False], (fate, bad)
            assert np.array_equal(calls[0][1][loop.nb:], stand)
            assert s["startup_reads"] == {"reads": bad + 1, "measured_before_clock": True}
            assert s["good_frames"] == s["cycles"] and s["corrupted_frames"] == 0
            assert s["read_errors"] == s["failed_reads"] == (bad if fate == "error" else 0)
            assert link.stats.reads == s["cycles"] + bad + 1


def test_without_a_frame_at_start_up_the_corrector_measures_in_its_first_analysed_frame(mini, monkeypatch):
    """Every one of the START_READS start-up reads fails (or its frame is rejected), or the port is gone at the
    first: the corrector measures the robot in its first analysed frame, inside that cycle, as before; the failed
    reads are the run's, as a cycle's are."""
    stand = make_scenario("stand", mini).goals(0.0)
    for fate, tried in (("error", START_READS), ("nan", START_READS), ("down", 1)):
        time = SimTime()
        link = ScriptedLink(time, mini.joint_names, stand, lambda n, t, f=fate, k=tried: f if n < k else None)
        loop = LiveLoop(link, mini, LoopConfig(rate_hz=RATE), clock=LoopClock(RATE, now=time.now, sleep=time.advance))
        calls = _measured(monkeypatch, loop)
        s = loop.run(duration=0.3)
        assert [started for started, _ in calls] == [True], fate
        assert s["startup_reads"] == {"reads": tried, "measured_before_clock": False}
        assert s["corrupted_frames"] == 0 and s["link"]["read_errors_before_run"] == 0
        assert s["failed_reads"] == (0 if fate == "nan" else tried), fate


def test_watchdog_can_drop_torque_and_then_only_monitors(mini):
    cfg = LoopConfig(rate_hz=RATE, safety=SafetyConfig(drop_torque=True))
    loop, link, _, _ = scripted_loop(mini, fault=lambda n, t: "error" if 0.3 <= t - 1000.0 < 0.5 else None,
                                     config=cfg)
    s = loop.run(duration=0.8)
    assert ("safe_stop_drop" in [c for c, _ in link.calls])
    assert not [t for t, _, _ in link.writes if t - 1000.0 >= 0.3]
    assert s["state"] == "halted" and s["good_frames"] > 0.8 * RATE * 0.5
    assert link.calls[-1][0] == "safe_stop_drop"  # the exit keeps torque off


def test_hardware_error_latches_a_safe_stop(mini):
    # read n is cycle n - 1's (read 0: the start-up read the corrector measures the robot in)
    loop, link, _, events = scripted_loop(mini, fault=lambda n, t: "hw" if n == 101 else None)
    s = loop.run(duration=0.5)
    assert s["hardware_errors"] == {"l_knee": 0x20}
    assert s["halted"] == "hardware error on l_knee"
    assert s["commands_sent"] == 100
    assert any("servo l_knee: hardware error 0x20" in e for e in events)


def test_stop_commands_go_out_first_on_an_exception(mini):
    def command(t):
        if t > 0.2:
            raise RuntimeError("motion source failed")
        return np.zeros(len(mini.joint_names))

    loop, link, _, _ = scripted_loop(mini, command=command)
    with pytest.raises(RuntimeError, match="motion source failed"):
        loop.run(duration=1.0)
    assert link.calls[-1][0] == "safe_stop" and link.calls[-2][0] == "read"


def test_stop_request_ends_the_loop_with_a_safe_stop(mini):
    loop, link, _, _ = scripted_loop(mini, config=LoopConfig(rate_hz=RATE, status_every_s=0.1))
    loop.on_status = lambda status: loop.request_stop("SIGTERM") if status["t"] >= 0.3 else None
    s = loop.run()
    assert s["stopped_by"] == "SIGTERM" and s["cycles"] == 0.3 * RATE
    assert link.calls[-1][0] == "safe_stop"


class PipelinedLink(ScriptedLink):
    """A ScriptedLink whose goals go out with the next read's request (as on a Dynamixel bus), and,
    with ``prepares``, can have them built ahead (`prepare_goals`, then `send_prepared`)."""

    def request(self) -> None:
        self.calls.append(("request", self.time.t))

    def write_goals(self, positions: np.ndarray, request: bool = False) -> None:
        super().write_goals(positions)

    def prepare(self, positions: np.ndarray) -> None:
        self.prepared = positions.copy()

    def send_prepared(self) -> None:
        self.sent_prepared += 1
        super().write_goals(self.prepared)


def pipelined_loop(body, prepares: bool, fault, command, config):
    loop, link, _, _ = scripted_loop(body, fault=fault, command=command, config=config)
    piped = PipelinedLink(link.time, body.joint_names, np.zeros(len(body.joint_names)), fault)
    piped.sent_prepared = 0
    if prepares:
        piped.prepare_goals = piped.prepare
    loop = LiveLoop(piped, body, config, command=command, clock=loop.clock)
    return loop, piped


def test_goals_built_ahead_are_the_goals_the_cycle_would_send(mini):
    """The pipelined loop builds cycle k+1's goals at the end of cycle k. Sent or not (a read fails,
    a frame is rejected, the watchdog stops and the loop resumes), every goal written is the one
    the cycle would have computed itself: the limiter keeps its state until they are sent. The command
    a cycle's goals were built from is not asked for again when they are sent (once a cycle is its cost)."""
    cfg = LoopConfig(rate_hz=RATE, ramp_s=0.05, safety=SafetyConfig(max_correction_rate_rad_s=0.05))
    ankles = [mini.joint_names.index(n) for n in ("l_ank_pitch", "r_ank_pitch")]
    asked: list[float] = []

    def command(t):
        asked.append(t)
        q = np.zeros(len(mini.joint_names))
        q[ankles] = -0.3 * min(t / 0.5, 1.0)
        return q

    # the corrector's offsets move at the limiter's rate from about read 190; then faults
    script = {250: "error", 251: "nan", 300: "error", 350: "jump", **{n: "error" for n in range(400, 460)}}
    runs = {}
    repeats = {}
    for prepares in (False, True):
        asked.clear()
        loop, link = pipelined_loop(mini, prepares, lambda n, t: script.get(n), command, cfg)
        runs[prepares] = (loop.run(duration=1.0), link)
        repeats[prepares] = len(asked) - len(set(asked))
    (plain, plain_link), (ahead, ahead_link) = runs[False], runs[True]
    assert plain["commands_sent"] == ahead["commands_sent"]
    assert ahead["corrections_limited"] > 0 and ahead["resumes"] == 1  # the limiter and a restart are exercised
    goals = [np.array([g for _, g, _ in link.writes]) for link in (plain_link, ahead_link)]
    assert goals[0].shape == goals[1].shape and np.array_equal(goals[0], goals[1])
    # all but the first write of each stretch of good frames went out as built ahead
    stretches = 1 + 3 + 1  # the start; after reads 250-251, 300 and 350 (failed or rejected); the watchdog's resume
    assert ahead_link.sent_prepared == ahead["commands_sent"] - stretches and plain_link.sent_prepared == 0
    assert repeats == {False: 0, True: 0}  # each cycle's command asked for once, built ahead or not


@pytest.mark.parametrize("ptys", [0, 1, 2])
def test_a_pipelined_cycle_on_a_pty_pauses_after_sending_and_before_its_work(mini, ptys):
    """On pseudo-terminals (the link's `pty_ports`: two simulated buses, two) each pipelined cycle sleeps
    PTY_SEND_PAUSE_S for each port between sending (goals + next read) and estimating, so the kernel worker that
    carries the bytes gets the CPU; on other ports (USB-serial adapters) it goes straight on to its work."""
    time = SimTime()
    link = PipelinedLink(time, mini.joint_names, np.zeros(len(mini.joint_names)))
    link.sent_prepared, link.prepare_goals, link.pty_ports = 0, link.prepare, ptys

    def sleep(d: float) -> None:
        link.calls.append(("sleep", d))
        time.advance(d)

    loop = LiveLoop(link, mini, LoopConfig(rate_hz=RATE), clock=LoopClock(RATE, now=time.now, sleep=sleep))
    estimate = loop._estimate

    def logged_estimate(t, frame):
        link.calls.append(("estimate", t))
        estimate(t, frame)

    loop._estimate = logged_estimate
    s = loop.run(duration=0.1)
    calls = [name if name != "sleep" else ("pause" if t == ptys * PTY_SEND_PAUSE_S else "sleep")
             for name, t in link.calls]
    cycles = [c for c in " ".join(calls).split("read") if "estimate" in c]
    assert len(cycles) == s["good_frames"] == 0.1 * RATE
    sent = [c.split("estimate")[0].split() for c in cycles]  # what each cycle did between its read and its work
    assert all(c[-1] == ("pause" if ptys else "request") and "write" in c for c in sent)
    assert calls.count("pause") == (len(cycles) if ptys else 0)


def test_corrections_are_bounded_and_rate_limited(mini):
    """A command that leans the robot forward at the ankles far beyond its toes: the
    corrector pushes back (at 125 Hz, every 4th cycle), within the safety limits."""
    cfg = LoopConfig(rate_hz=RATE, ramp_s=1e-9,
                     safety=SafetyConfig(max_correction_rad=0.1, max_correction_rate_rad_s=1.0))
    ankles = [mini.joint_names.index(n) for n in ("l_ank_pitch", "r_ank_pitch")]

    def command(t):
        q = np.zeros(len(mini.joint_names))
        q[ankles] = -0.3 * min(t / 0.5, 1.0)
        return q

    loop, link, _, _ = scripted_loop(mini, command=command, config=cfg)
    s = loop.run(duration=1.2)
    assert s["corrections_sent"] > 0 and s["corrections_limited"] > 0
    goals = np.array([g for _, g, _ in link.writes])
    offsets = goals - np.array([command(i * T) for i in range(len(goals))])
    assert np.abs(offsets).max() <= 0.1 + 1e-9
    assert np.abs(np.diff(offsets, axis=0)).max() <= 1.0 * T + 1e-9


@pytest.mark.parametrize("correct_hz", [125.0, RATE])
def test_a_corrector_step_is_split_over_two_cycles_when_it_steps_every_second_or_less(mini, monkeypatch, correct_hz):
    """At 125 Hz in a 500 Hz loop the corrector steps every 4th cycle: the root rotation from the newest result in
    one cycle, the legs' IK (its costly part) for that cycle's command in the next, so no cycle carries both; the
    offsets are what a whole step gives from that result and command (a twin corrector's). Stepping every cycle
    (500 Hz), the step stays whole."""
    cfg = LoopConfig(rate_hz=RATE, ramp_s=1e-9, correct_hz=correct_hz)
    ankles = [mini.joint_names.index(n) for n in ("l_ank_pitch", "r_ank_pitch")]

    commanded = []

    def command(t):  # leans past the toes: the corrector acts
        q = np.zeros(len(mini.joint_names))
        q[ankles] = -0.3 * min(t / 0.5, 1.0)
        commanded.append(q)
        return q

    loop, _, _, _ = scripted_loop(mini, command=command, config=cfg)
    twin = OnlineCorrector(mini, loop.correct_every * T, cfg.correction_limits,
                           max_accel_deg_s2=size_scaled_accel(mini, cfg.trunk_accel_deg_s2),
                           margin_m=size_scaled_margin(mini))
    log, asked, same = [], [], []
    update, offsets = OnlineCorrector.update, OnlineCorrector.offsets

    def logged_update(self, result, cop=None):
        if self is not twin:
            log.append((loop.counters.cycles, "update"))
            asked.append((result, cop, commanded[-1]))  # the command of this cycle, asked for before its correction
        return update(self, result, cop)

    def logged_offsets(self, q_command):
        out = offsets(self, q_command)
        if self is not twin:
            log.append((loop.counters.cycles, "offsets"))
            result, cop, joints = asked[-1]
            same.append(np.array_equal(q_command[loop.nb:], joints)
                        and np.array_equal(out, twin.step(result, q_command, cop).offsets))
        return out

    monkeypatch.setattr(OnlineCorrector, "update", logged_update)
    monkeypatch.setattr(OnlineCorrector, "offsets", logged_offsets)
    s = loop.run(duration=1.2)
    steps = [c for c, kind in log if kind == "update"]
    assert s["corrections_sent"] > 0 and len(steps) > correct_hz  # over 1 s of the 1.2 s run
    after = 0 if correct_hz == RATE else 1  # the cycle the offsets come in, after the update's
    whole = [(c + k, kind) for c in steps for k, kind in ((0, "update"), (after, "offsets"))]
    assert log in (whole, whole[:-1])  # (the run may end between the two)
    assert len(same) >= len(steps) - 1 and all(same)


def test_ramps_at_one_time_match_their_closed_forms_and_the_array_evaluation():
    # the loop evaluates them at one float time each cycle (a path of their own): the same values,
    # clamped outside the ramp, as over an array
    times = [-0.5, 0.0, 0.1, 0.37, 0.5, 0.9, 1.0, 2.0]
    for x in times:
        c = min(max(x, 0.0), 1.0)
        assert smooth_step(x) == pytest.approx(0.5 - 0.5 * math.cos(math.pi * c), abs=1e-15)
        assert smooth_ramp(2.0 + 3.0 * x, 2.0, 5.0) == pytest.approx(c**3 * (10 - 15 * c + 6 * c * c), abs=1e-14)
    np.testing.assert_allclose(smooth_step(np.array(times)), [smooth_step(x) for x in times], atol=1e-15)
    np.testing.assert_allclose(smooth_ramp(2.0 + 3.0 * np.array(times), 2.0, 5.0),
                               [smooth_ramp(2.0 + 3.0 * x, 2.0, 5.0) for x in times], atol=1e-14)
