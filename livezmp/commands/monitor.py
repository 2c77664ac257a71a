"""`livezmp monitor`, `livezmp replay`, `livezmp recover`: the live capture monitor, the
re-run of a recorded session, and the repair of a recording cut short by a crash."""

from __future__ import annotations

import argparse
import sys
import threading
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from livezmp.balance.pipeline import FrameResult, default_config
from livezmp.checks import check_number, check_output_paths, given_inputs
from livezmp.commands.common import monitor_config, stop_on_signals
from livezmp.errors import InputError
from livezmp.estimate.estimator import EstimatorConfig, EstimatorError
from livezmp.jsonfile import write_json
from livezmp.live.realtime import realtime_priority
from livezmp.model.body_spec import robot_body
from livezmp.model.bvh_body import DEFAULT_MASS, BvhBodyOptions
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.marker_map import load_marker_map
from livezmp.model.markers import MarkerBodyOptions
from livezmp.model.motion_file import trajectory_frames
from livezmp.model.segments import load_mapping
from livezmp.model.urdf_body import UrdfBodyOptions
from livezmp.monitor.alarms import AlarmCommand, AlarmEvent
from livezmp.monitor.dashboard import MAX_CLIENTS, DashboardServer, parse_address
from livezmp.monitor.loop import Monitor, MonitorSummary
from livezmp.monitor.tui import TerminalView
from livezmp.offline.calibrate import Subject, load_subject
from livezmp.recording.reader import damaged_as_input_error, iter_messages
from livezmp.recording.recover import recover
from livezmp.recording.writer import Recorder, stopped_note
from livezmp.sources.factory import SourceOptions, open_source
from livezmp.sources.file_replay import FileReplaySource
from livezmp.sources.interface import Source
from livezmp.sources.mcap_replay import McapReplaySource
from livezmp.sources.mocap_factory import MOCAP_SCHEMES


def _source(args: argparse.Namespace) -> Source:
    urdf = UrdfBodyOptions(config=args.robot_config)
    subject = _subject(args)
    markers = _marker_options(args, subject)
    if args.motion is None:  # the built-in demo, as for `livezmp analyze`
        body, spec = robot_body(demo_robot_path(), urdf)
        traj = demo_trajectory(body.joint_names)
        return FileReplaySource("<demo>", body, spec, traj.t, trajectory_frames(body, traj), args.speed, args.loop)
    bvh = BvhBodyOptions(total_mass=args.mass or DEFAULT_MASS, units=args.units, up_axis=args.up,
                         mapping=load_mapping(args.mapping) if args.mapping else None, sole_width=args.sole_width,
                         hat_fraction=subject.bvh_hat_fraction(args.subject)
                         if subject and (args.skeleton or Path(args.motion or "").suffix.lower() == ".bvh") else None)
    opts = SourceOptions(bvh=bvh, urdf=urdf, robot=args.robot, skeleton=args.skeleton, fps=args.fps,
                         speed=args.speed, loop=args.loop, mass=args.mass, calibration=args.calibration,
                         markers=markers, static=args.static)
    return open_source(args.motion, opts)


def _marker_options(args: argparse.Namespace, subject: Subject | None) -> MarkerBodyOptions:
    """A marker body's options (a C3D replayed, or a capture stream): the marker map (a C3D file's only: a live
    stream's frames are matched by the standard roles' labels), the segment table and the subject file's
    parameters; refused for any other source."""
    opts = MarkerBodyOptions(marker_map=load_marker_map(args.markers) if args.markers else None, bsp=args.bsp,
                             age_years=args.age)
    source = str(args.motion or "")
    c3d = Path(source).suffix.lower() == ".c3d"
    if args.markers and not c3d:
        raise InputError(f"{args.markers}: --markers is for a C3D file replayed (got {source or 'the built-in demo'}; "
                         "a capture stream's labels must be ones the built-in conventions read)")
    if args.static and not c3d:
        raise InputError(f"{args.static}: --static is for a C3D file replayed (got {source or 'the built-in demo'}; "
                         "a capture stream's markers must make a standard set)")
    if not (c3d or source.split("://")[0] in MOCAP_SCHEMES) and (args.bsp != "auto" or args.age is not None):
        raise InputError("--bsp / --age: the segment table is for a C3D file's or a capture stream's markers (got "
                         f"{args.motion or 'the built-in demo'})")
    return subject.marker_options(opts) if subject else opts


def _subject(args: argparse.Namespace) -> Subject | None:
    """The --subject file, for a person's body: a BVH (file or a stream's --skeleton), a C3D, or a capture
    stream's marker body."""
    if not args.subject:
        return None
    person = (args.skeleton or Path(args.motion or "").suffix.lower() in (".bvh", ".c3d")
              or str(args.motion).split("://")[0] in MOCAP_SCHEMES)
    if args.robot or not person:
        raise InputError(f"{args.subject}: a subject file describes a person: it goes with a BVH or C3D file or a "
                         "stream's --skeleton (a recording carries its own body; a robot has its URDF)")
    return load_subject(args.subject)


def _print_summary(s: MonitorSummary) -> None:
    st = s.source_stats
    drops = ", ".join(f"{k} {v}" for k, v in st.items() if v and k != "delivered") or "none"
    print(f"monitor: {s.inputs} frames in, {s.results} analysed, {s.out_of_support} out of support, "
          f"{s.alarms} alarm(s) in {s.duration:.1f} s; source faults: {drops}", flush=True)


def _run(source: Source, cfg, args: argparse.Namespace, session: dict, listeners: list) -> MonitorSummary:
    """Wire the sinks the options ask for, run the monitor until done or stopped."""
    recorder = dashboard = view = command = None
    try:
        if args.alarm_command:
            command = AlarmCommand(args.alarm_command)
        if args.record:
            recorder = Recorder(args.record, source.body_spec, session, source.body.channel_names)
            print(f"recording: {args.record}", flush=True)
        view = TerminalView() if args.tui else None
        monitor = Monitor(source, cfg, alarm_after=session["alarm_after"], recorder=recorder, listeners=listeners,
                          view=view, alarm_command=command, correct=session["correct"],
                          max_inputs=getattr(args, "frames", None))
        if args.dashboard:
            host, port = parse_address(args.dashboard)
            hello = {"source": source.name, "body": f"{source.body.kind} body, {source.body.nq} channels",
                     "alarm_after": session["alarm_after"]}
            dashboard = DashboardServer(host, port, monitor.status, hello, allow_remote=args.allow_remote,
                                        token=args.token)
            print(f"dashboard: {dashboard.start()}", flush=True)
            monitor.listeners.append(dashboard)
        print(f"source: {source.name}", flush=True)
        stop = threading.Event()
        with stop_on_signals(lambda _name: stop.set()):
            summary = monitor.run(stop)
    except BaseException:
        source.close()
        if recorder:
            recorder.close()
        raise
    finally:
        if dashboard:
            dashboard.stop()
    _print_summary(summary)
    if dashboard and dashboard.refused:
        print(f"dashboard: {dashboard.refused} client(s) refused: at most {MAX_CLIENTS} at once", flush=True)
    if recorder and recorder.error:
        print(f"livezmp: recording {args.record} failed ({recorder.error}); {recorder.unwritten} messages not "
              f"written{stopped_note(args.record)}", file=sys.stderr, flush=True)
    if getattr(args, "summary_json", None):
        write_json({**monitor.summary_json(),
                    "dashboard_refused": None if dashboard is None else dashboard.refused}, args.summary_json)
    return summary


MAX_WINDOW_S = 10.0  # s: the estimator's window and lag (its memory grows with the window)


def check_outputs(args: argparse.Namespace) -> None:
    """--record and --summary-json before the source opens: their directories, neither a device, not one file
    (the summary, written last, would replace the session's recording)."""
    check_output_paths((args.record, "--record"), (args.summary_json, "--summary-json"), inputs=given_inputs(args))


def cmd_monitor(args: argparse.Namespace) -> int:
    if not args.alarm_after >= 0:
        raise InputError(f"--alarm-after must be ≥ 0 ms, got {args.alarm_after}")
    if args.frames is not None and args.frames < 1:
        raise InputError(f"--frames must be a positive number of frames, got {args.frames}")
    check_number(args.window_s, "--window-s (s)", 0.0, MAX_WINDOW_S, lo_open=True)
    check_number(args.lag_s, "--lag-s (s)", 0.0, MAX_WINDOW_S)
    check_outputs(args)
    # set before the source and the dashboard start their threads: they inherit the policy
    with realtime_priority(args.realtime_priority) as refused:
        if refused not in (None, "off"):
            print(f"realtime priority {refused}: running at normal priority", flush=True)
        _monitor(args)
    return 0


def _monitor(args: argparse.Namespace) -> None:
    source = _source(args)
    fps = 1.0 / source.nominal_dt
    cfg = monitor_config(args, SimpleNamespace(body=source.body, fps=fps),  # it needs only the body and rate
                         isinstance(source, FileReplaySource))
    if args.ground is None and getattr(source, "ground_z", None) is not None:  # a capture stream's plates
        cfg = replace(cfg, ground_z=source.ground_z)
    settings = {k: v for k, v in (("window_s", args.window_s), ("lag_s", args.lag_s)) if v is not None}
    if settings:
        try:
            cfg = replace(cfg, estimator=replace(cfg.estimator, rate_hz=fps, **settings))
        except EstimatorError as e:
            raise InputError(f"--window-s / --lag-s: {e}") from None
    session = {"source": source.name, "fps": fps, "mode": cfg.mode, "ground_z": cfg.ground_z,
               "cutoff_hz": cfg.estimator.cutoff_hz,
               "alarm_after": args.alarm_after / 1000.0, "correct": args.correct}
    if settings:  # replay re-runs with them
        session["estimator"] = settings
    _run(source, cfg, args, session, [])


class ReplayCheck:
    """Compares re-run results with the recording's ``/result`` messages, frame by frame."""

    def __init__(self, path: str):
        self._recorded = iter_messages(path, "/result")
        self._next = next(self._recorded, None)
        self.compared = self.support_diff = self.raised = 0
        self.max_zmp_diff = 0.0

    def publish(self, r: FrameResult, cop=None) -> None:
        while self._next is not None and self._next["index"] < r.index:
            self._next = next(self._recorded, None)
        if self._next is None or self._next["index"] != r.index:
            return
        m = self._next
        self.compared += 1
        self.support_diff += m["support"] != r.support
        if (m["zmp"] is None) != (r.zmp is None):
            self.max_zmp_diff = float("inf")
        elif r.zmp is not None:
            z = m["zmp"]
            self.max_zmp_diff = max(self.max_zmp_diff, float(np.max(np.abs(r.zmp - [z["x"], z["y"], z["z"]]))))

    def alarm(self, ev: AlarmEvent) -> None:
        self.raised += ev.event == "raised"


def cmd_replay(args: argparse.Namespace) -> int:
    with damaged_as_input_error(Path(args.recording)):  # a damaged session or /result message: one line
        return _replay(args)


def _replay(args: argparse.Namespace) -> int:
    check_outputs(args)
    source = McapReplaySource(args.recording, args.speed)
    s = {"mode": "full", "ground_z": None, "alarm_after": 0.2, "correct": False, **source.recording.session}
    # sessions recorded before the per-rate defaults (issue 12) carry no cutoff: they ran at 6 Hz
    cfg = default_config(source.body, s["fps"], s["mode"], s["ground_z"], s.get("cutoff_hz", 6.0))
    if "live_loop" in s:  # recorded by `livezmp run/demo --record`: the loop's own estimator settings
        cfg = replace(cfg, estimator=EstimatorConfig(rate_hz=s["fps"], **s["live_loop"]["estimator"]))
    elif "estimator" in s:  # a monitor session with --window-s / --lag-s
        cfg = replace(cfg, estimator=replace(cfg.estimator, rate_hz=s["fps"], **s["estimator"]))
    check = ReplayCheck(args.recording)
    recorded_alarms = sum(1 for m in iter_messages(args.recording, "/alarm") if m["event"] == "raised")
    _run(source, cfg, args, {**s, "source": f"replay of {args.recording}"}, [check])
    same = check.support_diff == 0 and check.max_zmp_diff <= 1e-9 and check.raised == recorded_alarms
    print(f"replay: {check.compared} results compared with the recording: max ZMP difference "
          f"{1000 * check.max_zmp_diff:.6f} mm, {check.support_diff} support differences, "
          f"{recorded_alarms} alarm(s) recorded; {'same analysis' if same else 'DIFFERENT analysis'}", flush=True)
    if source.recording.dropped:
        print(f"replay: the recording dropped {source.recording.dropped} messages while it was made (its writer's "
              "queue was full): the replay sees only the inputs that were kept", flush=True)
    return 0 if same else 1


def cmd_recover(args: argparse.Namespace) -> int:
    rep = recover(args.broken, args.out)
    state = "complete file, nothing lost" if rep.complete else f"stopped: {rep.stopped or 'end of file'}"
    print(f"{args.out}: {rep.messages} messages in {rep.chunks} chunks, {rep.attachments} attachments, "
          f"{rep.metadata} metadata records recovered ({state})", flush=True)
    return 0
