"""`livezmp run`, `livezmp sim` and `livezmp demo` as a user runs them: real processes,
real signals, the summary JSON they write, one-line errors for mistakes."""

from __future__ import annotations

import json
import math
import os
import re
import select
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from humanoid_gen import generate_humanoid

from livezmp.cli import main
from livezmp.live.scenarios import make_scenario
from livezmp.model.demo_robot import demo_robot_path
from livezmp.model.trajectory_csv import JointTrajectory, write_joint_csv
from livezmp.model.urdf_body import body_from_urdf

SUMMARY_KEYS = ("cycles", "achieved_hz", "deadline_misses", "read_errors", "write_errors", "stale_frames",
                "corrections_sent", "inside_fraction", "max_latency_ms", "p99_latency_ms", "fell")


def livezmp(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "livezmp", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})


def line_from(stream, deadline: float, wanted=lambda line: True) -> str:
    """The first line of ``stream`` that ``wanted`` accepts, before ``deadline`` (monotonic s)."""
    while time.monotonic() < deadline:
        ready, _, _ = select.select([stream], [], [], max(0.0, deadline - time.monotonic()))
        if ready:
            line = stream.readline()
            if not line:
                break
            if wanted(line):
                return line
    raise AssertionError("no such line before the deadline")


def stop(proc: subprocess.Popen, sig=signal.SIGTERM, timeout: float = 20.0) -> tuple[int, str, str]:
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        raise
    return proc.returncode, out, err


def test_sim_serves_a_robot_that_run_balances(tmp_path):
    """`livezmp sim` in its own process; `livezmp run` on its URL with a motion CSV."""
    sim = livezmp("sim", "--link", "dynamixel", "--scenario", "stand", "--baud", "2000000", "--adapter", "hs")
    try:
        hello = json.loads(line_from(sim.stdout, time.monotonic() + 30))
        assert hello["link"] == "dynamixel" and os.path.exists(hello["ports"][0])
        assert hello["placeholder_inertias"] == []  # livezmp_mini's inertias are real
        body = body_from_urdf(demo_robot_path())
        stand = make_scenario("stand", body).goals(0.0)
        arm = body.joint_names.index("l_sho_pitch")
        t = np.linspace(0.0, 1.0, 11)
        q = np.tile(stand, (len(t), 1))
        q[:, arm] += 0.3 * t  # raise the left arm 0.3 rad over a second
        motion = tmp_path / "raise.csv"
        write_joint_csv(JointTrajectory(t, q, body.joint_names), motion)
        summary_path = tmp_path / "s.json"
        rc = main(["run", "--robot", str(demo_robot_path()), "--link", hello["url"], "--motion", str(motion),
                   "--rate", "100", "--quiet", "--summary-json", str(summary_path), "--adapter-latency-ms", "0.1875"])
        assert rc == 0
        s = json.loads(summary_path.read_text())
        assert all(k in s for k in SUMMARY_KEYS)
        # the motion's 1 s at 100 Hz (deadlines a loaded machine made the loop skip are counted)
        assert s["stopped_by"] == "duration" and s["cycles"] + s["clock"]["skipped_cycles"] == 100
        assert s["commands_sent"] > 50 and s["fell"] is None  # another process's robot: run cannot know
        assert s["watchdog_trips"] == 0
        # a Fast Sync Read of 20 positions (14 + 20 bytes out, 8 + 20 x 8 back) and a Sync Write of 20 goals
        # (14 + 20 x 5) at 2 Mbit/s, 10 bits a byte, plus the high-speed adapter's 0.1875 ms
        bus = s["bus"]
        assert bus["baud"] == 2_000_000 and bus["read"] == "fast sync read: position"
        assert bus["bytes_per_cycle"] == 34 + 168 + 114 and bus["wire_ms_per_cycle"] == pytest.approx(1.58)
        assert bus["ceiling_hz"] == pytest.approx(1 / (1.58e-3 + 0.1875e-3), abs=0.1)
        assert bus["utilisation"] == pytest.approx(s["achieved_hz"] / bus["ceiling_hz"], rel=1e-3)
    finally:
        rc, _, err = stop(sim)
    assert rc == 0 and "the robot did not fall" in err


def test_demo_runs_until_sigterm_then_stops_safely(tmp_path):
    summary_path = tmp_path / "demo.json"
    demo = livezmp("demo", "--duration", "0", "--summary-json", str(summary_path))
    try:
        line_from(demo.stderr, time.monotonic() + 40, lambda line: line.startswith("t "))  # the status line
    finally:
        rc, out, err = stop(demo)
    assert rc == 0, err
    s = json.loads(summary_path.read_text())
    assert all(k in s for k in SUMMARY_KEYS)
    assert s["stopped_by"] == "SIGTERM" and s["fell"] is False and s["scenario"] == "demo"
    assert s["link_url"].startswith("dynamixel:") and s["cycles"] > 0 and s["commands_sent"] > 0
    assert "cycles at" in out and "simulator: did not fall" in out
    # the simulator's process was kept on the last CPU (the loop was not pinned), as bench_live_loop places it
    cpus = sorted(os.sched_getaffinity(0))
    assert s["simulator_cpus"] == (cpus[-1:] if len(cpus) > 1 else cpus)


# `livezmp run` / `demo` in a child process that signals itself at one point of its start-up (names below), the
# link's stop commands and close logged on stderr
SIGNAL_AT = """
import os, signal, sys
import livezmp.cli as cli

sig, where = getattr(signal, sys.argv[1]), sys.argv[2]
kill = lambda: os.kill(os.getpid(), sig)
if where == "import":  # as the command's modules are imported (many seconds on a loaded machine)
    real_import = cli.importlib.import_module
    cli.importlib = type("I", (), {"import_module": staticmethod(lambda m: (kill(), real_import(m))[1])})
    sys.exit(cli.main(sys.argv[3:]))
import livezmp.commands.run as run
from sim_devices.mock_link import MockLink

for name in ("safe_stop", "close"):
    def logged(self, *a, _real=getattr(MockLink, name), _name=name, **k):
        print("link:", _name, *a, *k.values(), file=sys.stderr, flush=True)
        return _real(self, *a, **k)
    setattr(MockLink, name, logged)
if where == "robot":
    real_load = run.load_robot
    run.load_robot = lambda *a: (kill(), real_load(*a))[1]
elif where == "sim":  # while the simulator's process starts (up to a minute)
    import multiprocessing.connection as mc
    import sim_devices.process as sp
    real_poll, real_close = mc.Connection.poll, sp.SimProcess.close
    mc.Connection.poll = lambda self, *a: (kill(), real_poll(self, *a))[1]
    sp.SimProcess.close = lambda self: (print("sim: close", file=sys.stderr, flush=True), real_close(self))[1]
elif where == "open":
    real_open = MockLink.open
    MockLink.open = lambda self: (real_open(self), kill())[0]
else:
    class Signalled(run.LiveLoop):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            kill()
    run.LiveLoop = Signalled
sys.exit(cli.main(sys.argv[3:]))
"""


@pytest.mark.parametrize(("sig", "where", "command", "stage", "link"), [
    ("SIGTERM", "loop", "run", "preparing the loop", "the link, open (torque on, holding), was sent its stop commands"),
    ("SIGINT", "open", "run", "opening the link", "the link, being opened, was sent its stop commands and closed"),
    ("SIGTERM", "robot", "run", "loading the robot", "no link was opened"),
    ("SIGTERM", "import", "run", "loading livezmp", "no link was opened"),
    ("SIGTERM", "sim", "demo", "starting the simulator", "no link was opened"),
    ("SIGINT", "loop", "demo", "preparing the loop", "the link, open (torque on, holding), was sent its stop"),
    ("SIGHUP", "open", "run", "opening the link", "the link, being opened, was sent its stop commands and closed"),
])
def test_a_signal_during_start_up_stops_it_safely_with_a_summary(tmp_path, sig, where, command, stage, link):
    """SIGINT / SIGTERM before the loop's first cycle: the link (if opened, or being opened) gets the stop
    commands of the shutdown path and is closed, a recording already made is finished, and the summary
    says in which stage it stopped; exit 128 + the signal's number, no traceback."""
    summary, rec = tmp_path / "s.json", tmp_path / "r.mcap"
    argv = (["--link", "mock:", "--robot", str(demo_robot_path())] if command == "run" else
            ["--link", "dynamixel" if where == "sim" else "mock"])
    proc = subprocess.run([sys.executable, "-c", SIGNAL_AT, sig, where, command, *argv, "--duration", "1", "--quiet",
                           "--realtime-priority", "0", "--summary-json", str(summary), "--record", str(rec)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 128 + getattr(signal, sig), proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stdout.startswith(f"stopped by {sig} during start-up: {stage}: no cycle run; {link}")
    assert proc.stdout.count("\n") == 1
    s = json.loads(summary.read_text())
    assert s["stopped_by"] == sig and s["stopped_during"] == f"start-up: {stage}" and s["cycles"] == 0
    opened = where == "loop"
    assert s["link"] == {"opened": opened, "closed": where in ("open", "loop")}
    # the stop commands of the shutdown path (close: hold) went out once, after the link had been opened
    assert proc.stderr.count("link: close") == proc.stderr.count("link: safe_stop") == (where in ("open", "loop"))
    assert ("sim: close" in proc.stderr) == (where == "sim")  # the simulator's process stopped
    if opened:  # the recording was made: finished, saying why it ended
        from livezmp.recording.reader import open_recording

        assert s["recording"]["path"] == str(rec) and open_recording(rec).counts["/input"] == 0
    else:
        assert s["recording"] is None and not rec.exists()


@pytest.mark.parametrize("nohup", [False, True])
def test_sighup_stops_a_running_loop_as_sigterm_does_unless_it_is_ignored(tmp_path, nohup):
    """The terminal or SSH session closing (SIGHUP) stops the loop through its safe stop, its summary and recording
    written (main: the process died where it stood, exit -1, no summary, the recording unfinished); started under
    nohup (SIGHUP ignored), the run goes on to its end."""
    summary, rec = tmp_path / "s.json", tmp_path / "r.mcap"
    ignore = (lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN)) if nohup else None
    proc = subprocess.Popen([sys.executable, "-m", "livezmp", "run", "--link", "mock:",
                             "--robot", str(demo_robot_path()), "--duration", "4" if nohup else "0",
                             "--realtime-priority", "0",
                             "--summary-json", str(summary), "--record", str(rec)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=ignore,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        line_from(proc.stderr, time.monotonic() + 60, lambda line: line.startswith("t "))  # the loop runs
    finally:
        rc, _, err = stop(proc, signal.SIGHUP, timeout=60)
    assert rc == 0 and "Traceback" not in err, err
    s = json.loads(summary.read_text())
    assert s["stopped_by"] == ("duration" if nohup else "SIGHUP") and s["cycles"] > 0
    from livezmp.recording.reader import open_recording

    assert open_recording(rec).counts["/input"] > 0  # finished: readable as a whole


def test_a_run_whose_terminal_closes_stops_safely_with_its_summary(tmp_path):
    """An SSH session dropping: the run's controlling terminal closes (SIGHUP, then every write to it fails with
    EIO). The loop stops through its safe stop and writes its summary and recording; main: the status line's write
    raised in the loop (exit 1, no summary)."""
    import pty

    summary, rec = tmp_path / "s.json", tmp_path / "r.mcap"
    pid, fd = pty.fork()
    if pid == 0:  # the child: on the terminal as its controlling terminal, as a login shell's command is
        os.execv(sys.executable, [sys.executable, "-m", "livezmp", "run", "--link", "mock:", "--robot",
                                  str(demo_robot_path()), "--duration", "0", "--realtime-priority", "0",
                                  "--summary-json", str(summary), "--record", str(rec)])
    seen, deadline = b"", time.monotonic() + 60
    while b"running" not in seen and time.monotonic() < deadline:  # its status line: the loop runs
        if select.select([fd], [], [], 1.0)[0]:
            seen += os.read(fd, 4096)
    os.close(fd)  # the terminal goes away
    _, status = os.waitpid(pid, 0)
    assert os.waitstatus_to_exitcode(status) == 0, seen.decode(errors="replace")[-500:]
    s = json.loads(summary.read_text())
    assert s["stopped_by"] == "SIGHUP" and s["cycles"] > 0
    from livezmp.recording.reader import open_recording

    assert open_recording(rec).counts["/input"] > 0


def test_a_console_whose_reader_is_gone_is_discarded_not_raised():
    from livezmp.commands.console import OutlivingStream

    read, write = os.pipe()
    os.close(read)
    stream = OutlivingStream(os.fdopen(write, "w", buffering=1))
    assert stream.write("status\n") == 7 and stream.gone  # EPIPE: the rest goes to /dev/null
    stream.write("summary\n")
    stream.flush()
    stream.close()


def test_demo_runs_any_humanoid_and_without_corrections_it_falls(tmp_path):
    """A humanoid never seen (other joint names and order, 0.8x the mini's size), no robot config: servo ids
    in joint order on the simulated Dynamixel bus; the scenario finds its limbs; uncorrected, it falls."""
    urdf = generate_humanoid(tmp_path / "other.urdf", 0.8, 0.9, 3)
    summary_path = tmp_path / "s.json"
    # run past the scenario's end (the last goals held): a fall near its end still stops the loop, on a busy
    # machine too, where the simulator's fall flag can reach the loop after the scenario's last cycle
    assert main(["demo", "--robot", str(urdf), "--scenario", "arm_swing", "--no-correct", "--quiet",
                 "--duration", "10", "--summary-json", str(summary_path)]) == 0
    s = json.loads(summary_path.read_text())
    assert s["fell"] is True and s["stopped_by"] == "fell" and s["corrections_sent"] == 0
    assert s["bus"]["ceiling_hz"] == pytest.approx(1 / ((34 + 168 + 114) * 10e-6 + 1.5e-3), abs=0.1)
    assert s["rate_hz"] == math.floor(0.85 * s["bus"]["ceiling_hz"])  # the default rate: what the wire allows


def test_run_with_the_mock_link_holds_the_first_posture(tmp_path):
    path = tmp_path / "s.json"
    # 200 Hz: the corrector measures the robot's own dynamics (4.5-10 ms) before the loop's clock starts; made in the
    # first corrected cycle, it overran a 200 Hz period and skipped a deadline (99 cycles) in 2-5 of 8 runs
    assert main(["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--duration", "0.5", "--rate", "200",
                 "--quiet", "--summary-json", str(path)]) == 0
    s = json.loads(path.read_text())
    assert s["cycles"] == 100 and s["good_frames"] == 100 and s["commands_sent"] == 100
    assert s["inside_fraction"] == 1.0 and s["state"] == "running"
    # the loop asked for SCHED_FIFO by default; granted or not, the summary says which
    assert s["realtime_priority"] in (0, 50)


def test_a_run_whose_link_never_came_back_is_recorded_and_exits_3(tmp_path, monkeypatch, capsys):
    """The mock link's port gone after 41 reads of a 100-cycle run (the start-up read the corrector measures the
    robot in, and 40 cycles'), for good: the run ends as asked,
    its summary and recording written (the 40 samples before the fault in it, the outage on
    /device_error), and exits 3 (EXIT_LINK_FAILED) with one line saying why."""
    from livezmp.links.base import LinkError
    from livezmp.recording.reader import iter_messages
    from sim_devices.mock_link import MockLink

    read = MockLink.read

    def vanishing(self):
        if self.stats.reads >= 41:
            raise LinkError("mock: port gone")
        return read(self)

    monkeypatch.setattr(MockLink, "read", vanishing)
    monkeypatch.setattr(MockLink, "hold", lambda self: None)  # its hold reads first
    monkeypatch.setattr(MockLink, "reconnect", lambda self: False)
    path, rec = tmp_path / "s.json", tmp_path / "r.mcap"
    assert main(["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--duration", "0.5", "--rate", "200",
                 "--quiet", "--realtime-priority", "0", "--summary-json", str(path), "--record", str(rec)]) == 3
    out, err = capsys.readouterr()
    assert re.fullmatch(r"livezmp: the link failed the run: link down at the end of the run: it never came back "
                        r"\(0\.\d s in all\)\n", err.splitlines(keepends=True)[-1])
    assert re.search(r"; link down 0\.\d s in 1 outage\(s\), still down at the end", out)
    s = json.loads(path.read_text())
    assert s["stopped_by"] == "duration" and s["good_frames"] == 40 and s["link_down"]["at_end"]
    assert s["recording"]["written"]["/input"] == 40 and s["run_s"] == 0.5
    # cycle 40 on an unloaded machine, later when the clock skipped deadlines
    (first, t), *_ = [(r["kind"], r["t"]) for r in iter_messages(rec, "/device_error")]
    assert first == "link_down" and 0.2 <= t < 0.5 and s["link_down"]["seconds"] == pytest.approx(0.5 - t)


def test_a_summary_that_cannot_be_written_after_a_failed_link_still_exits_3(tmp_path, monkeypatch, capsys):
    """The link gone for good after 41 reads, and the summary's directory removed meanwhile: the summary line,
    the file's one-line error, then the link's failure; exit 3, the run's own failure (main: exit 2, the
    summary file's, and the link's failure never told)."""
    import shutil

    from livezmp.links.base import LinkError
    from sim_devices.mock_link import MockLink

    read = MockLink.read
    out_dir = tmp_path / "out"
    out_dir.mkdir()

    def vanishing(self):
        if self.stats.reads >= 41:
            shutil.rmtree(out_dir, ignore_errors=True)
            raise LinkError("mock: port gone")
        return read(self)

    monkeypatch.setattr(MockLink, "read", vanishing)
    monkeypatch.setattr(MockLink, "hold", lambda self: None)  # its hold reads first
    monkeypatch.setattr(MockLink, "reconnect", lambda self: False)
    assert main(["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--duration", "0.5", "--rate", "200",
                 "--quiet", "--realtime-priority", "0", "--summary-json", str(out_dir / "s.json")]) == 3
    out, err = capsys.readouterr()
    assert "stopped by duration; link down" in out
    lines = err.splitlines()
    assert re.fullmatch(r"livezmp: error: .*s\.json: cannot write: No such file or directory", lines[-2])
    assert lines[-1].startswith("livezmp: the link failed the run: link down at the end of the run")


def test_run_under_a_required_realtime_priority_on_one_cpu(tmp_path, monkeypatch):
    """--realtime-priority 30 --cpu N: the loop runs under SCHED_FIFO 30 on CPU N with its memory
    locked, waking by sleep then spin (seen from inside the loop), and the thread gets its policy
    and CPUs back afterwards."""
    import livezmp.commands.run as run_command
    seen = []

    class Watched(run_command.LiveLoop):
        def run(self, duration=None):
            seen.append((os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, os.sched_getaffinity(0),
                         self.clock.spin_s))
            return super().run(duration)

    monkeypatch.setattr(run_command, "LiveLoop", Watched)
    cpu = max(os.sched_getaffinity(0))
    before = os.sched_getscheduler(0), os.sched_getaffinity(0)
    path = tmp_path / "s.json"
    assert main(["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--duration", "0.1", "--quiet",
                 "--realtime-priority", "30", "--cpu", str(cpu), "--summary-json", str(path)]) == 0
    s = json.loads(path.read_text())
    assert seen == [(os.SCHED_FIFO, 30, {cpu}, 2e-4)]  # on its own CPU it spins the last 0.2 ms to each deadline
    assert s["realtime_priority"] == 30 and s["memory_locked"] is True
    assert s["cpu_wake_latency_us"] == 0  # the CPUs were kept awake while the loop ran (awake_cpus)
    assert (os.sched_getscheduler(0), os.sched_getaffinity(0)) == before


def test_a_required_realtime_priority_refused_stops_before_the_link_opens(monkeypatch, capsys):
    def refuse(*_):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    argv = ["run", "--robot", str(demo_robot_path()), "--link", "dynamixel:/nonexistent", "--realtime-priority", "50"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == ("livezmp: error: --realtime-priority 50: SCHED_FIFO refused (Operation not permitted; needs root, "
                   "CAP_SYS_NICE or an rtprio limit)\n")
    # not given, the same refusal only makes the loop run at normal priority (and say so)
    assert main(["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--duration", "0.05", "--quiet"]) == 0
    out = capsys.readouterr()
    assert "real-time priority refused (Operation not permitted" in out.err + out.out


@pytest.mark.parametrize(("argv", "message"), [
    (["run", "--robot", "nope.urdf", "--link", "mock:"], "nope.urdf: no such file"),
    (["run", "--robot", str(demo_robot_path()), "--link", "serial:/dev/x"], "link URL 'serial:/dev/x': expected"),
    (["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--scenario", "dance"], "unknown scenario 'dance'"),
    (["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--rate", "0"], "--rate 0: must be"),
    # below the estimator's slowest input it had been refused as "EstimatorConfig.window_s = 0.2 s is 0 samples"
    (["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--rate", "0.001"],
     "--rate 0.001: must be a number of Hz in [10, 2000]"),
    # in range but too slow for the loop's estimator (its 8 Hz cutoff): main named EstimatorConfig, not --rate
    (["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--rate", "13"],
     "--rate 13: too slow for the live loop's estimator: EstimatorConfig.cutoff_hz"),
    (["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--watchdog-ms", "-5"], "--watchdog-ms -5.0"),
    (["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--motion", "m.csv", "--scenario", "lean"],
     "give --motion or --scenario, not both"),
    (["demo", "--link", "mock", "--fault", "drop=0.1"], "the mock link has no devices"),
    (["demo", "--fault", "drop=2"], "fault spec field 'drop': expected a probability in [0, 1], got '2'"),
    (["demo", "--realtime-priority", "120"], "--realtime-priority 120: must be 1-99"),
    (["sim", "--link", "dynamixel", "--realtime-priority", "-1"], "--realtime-priority -1: must be 1-99"),
    (["demo", "--adapter", "usb3"], "--adapter: USB adapter 'usb3': expected ftdi-fs, hs, none or a latency in ms"),
    (["demo", "--link", "fw", "--buses", "2"], "--buses: only the dynamixel link and MIT-mode CAN motors have"),
    (["demo", "--link", "fw", "--can-protocol", "mit"], "--can-protocol: only the can link has a protocol"),
    (["demo", "--baud", "0"], "--baud 0: must be a positive number of bit/s"),
    (["demo", "--sim-cpu", "x"], "--sim-cpu x: expected CPU numbers such as 1 or 0,1 among"),
    (["demo", "--link", "mock", "--sim-cpu", "0"], "--sim-cpu: the mock link's humanoid steps in the loop's own"),
    (["run", "--robot", str(demo_robot_path()), "--link", "mock:", "--adapter-latency-ms", "-1"],
     "--adapter-latency-ms -1.0: must be milliseconds >= 0"),
    # a device that is not there: exit 2 from run as from monitor, naming the link
    (["run", "--robot", str(demo_robot_path()), "--link", "dynamixel:/dev/livezmp-none"],
     "dynamixel:/dev/livezmp-none: cannot open the link"),
    (["monitor", "dynamixel:/dev/livezmp-none", "--robot", str(demo_robot_path())],
     "dynamixel:/dev/livezmp-none: cannot open the link"),
    (["replay", str(demo_robot_path())], "livezmp_mini.urdf: not an MCAP file"),
    (["demo", "--summary-json", "/nonexistent-dir/s.json"], "--summary-json /nonexistent-dir/s.json: directory"),
    (["demo", "--record", "/nonexistent-dir/r.mcap"], "--record /nonexistent-dir/r.mcap: directory"),
    (["recover", str(demo_robot_path()), "-o", "/nonexistent-dir/x.mcap"], "-o /nonexistent-dir/x.mcap: directory"),
])
def test_mistakes_are_one_line_errors(capsys, argv, message):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1 and "Traceback" not in err
