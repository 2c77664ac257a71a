"""Seeds, mutations and the contract for fuzzing livezmp's inputs.

Contract for a file: the command (run in this process, stdout and both stderr levels
captured; or as a process of its own) exits 2 with exactly one stderr line naming one of its input files, or exits 0
(``replay``: 0 or 1, its verdict) with finite outputs (strict JSON, finite CSV cells);
never an exception escaping ``main``, never longer than :data:`TIME_LIMIT_S`.
Contract for a packet: the UDP source never raises; each packet is either delivered
(finite time and channels, then analysed without error) or counted in its stats.
"""

from __future__ import annotations

import contextlib
import functools
import io
import json
import math
import os
import random
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from unittest import mock

import numpy as np

from livezmp import cli

BURST = 20  # packets in flight at once
TIME_LIMIT_S = 20.0  # one input; the slowest accepted input takes about a second
EXTREMES = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e-300", "0", "-0", "1e9", "-1", "9" * 40,
            "", "x", "1,5", "0x10", "1e-9", "3600", "\x00", "é", "[", "{", "../../x", "𝄞"]
OPS = ("number", "delete_line", "duplicate_line", "swap_lines", "insert_bytes", "truncate", "flip_byte",
       "repeat_block", "bom", "utf16", "extreme_token")


class Hang(Exception):
    pass


@dataclass
class Outcome:
    kind: str  # "clean", "refused" or "failure"
    detail: str = ""


@dataclass
class Tally:
    tried: int = 0
    clean: int = 0
    refused: int = 0
    failures: list[str] = field(default_factory=list)

    def add(self, o: Outcome) -> None:
        self.tried += 1
        if o.kind == "failure":
            self.failures.append(o.detail)
        else:
            setattr(self, o.kind, getattr(self, o.kind) + 1)


# -- mutation -------------------------------------------------------------------------------------------

NUMBER = re.compile(rb"-?\d+(\.\d+)?([eE][-+]?\d+)?")


def mutate(data: bytes, ops: list[tuple[str, int, int]]) -> bytes:
    """Apply ``ops`` (name, position seed, choice seed) to ``data``; deterministic."""
    for name, pos, choice in ops:
        data = _apply(data, name, pos, choice)
    return data


def _apply(data: bytes, name: str, pos: int, choice: int) -> bytes:
    lines = data.split(b"\n")
    n = max(len(lines), 1)
    extreme = EXTREMES[choice % len(EXTREMES)].encode()
    if name == "number":
        found = list(NUMBER.finditer(data))
        if not found:
            return data
        m = found[pos % len(found)]
        return data[: m.start()] + extreme + data[m.end():]
    if name == "extreme_token":
        toks = data.split(b" ")
        toks[pos % len(toks)] = extreme
        return b" ".join(toks)
    if name == "delete_line":
        del lines[pos % n]
    elif name == "duplicate_line":
        i = pos % n
        lines[i:i] = [lines[i]] * (1 + choice % 3)
    elif name == "swap_lines":
        i, j = pos % n, choice % n
        lines[i], lines[j] = lines[j], lines[i]
    elif name == "repeat_block":  # deep or wide structure: a run of lines repeated many times
        i = pos % n
        block = lines[i : i + 1 + choice % 4]
        lines[i:i] = block * (50 + choice % 2000)
    elif name == "insert_bytes":
        i = pos % (len(data) + 1)
        rnd = random.Random(choice)
        return data[:i] + bytes(rnd.randrange(256) for _ in range(1 + choice % 16)) + data[i:]
    elif name == "truncate":
        return data[: pos % (len(data) + 1)]
    elif name == "flip_byte":
        if not data:
            return data
        i = pos % len(data)
        return data[:i] + bytes([data[i] ^ (1 << (choice % 8))]) + data[i + 1:]
    elif name == "bom":
        return b"\xef\xbb\xbf" + data
    elif name == "utf16":
        return data.decode("utf-8", "replace").encode("utf-16")
    return b"\n".join(lines)


def random_ops(rnd: random.Random) -> list[tuple[str, int, int]]:
    weights = [6, 2, 2, 1, 2, 1, 2, 1, 0.2, 0.2, 3]
    return [(rnd.choices(OPS, weights)[0], rnd.randrange(1 << 30), rnd.randrange(1 << 30))
            for _ in range(rnd.choice((1, 1, 2, 3, 5)))]


# -- seeds ---------------------------------------------------------------------------------------------


def _bvh_seed(d: Path) -> bytes:
    from livezmp.gait.sinewalk import sine_bvh, walk_spec
    from livezmp.model.bvh import write_bvh

    write_bvh(sine_bvh(walk_spec(), 1.0, 100.0, 0.5), d / "seed.bvh")
    return (d / "seed.bvh").read_bytes()


def _robot_seeds(d: Path) -> tuple[bytes, bytes, bytes]:
    """URDF, joint CSV (0.3 s) and robot config of the built-in demo robot."""
    from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
    from livezmp.model.trajectory_csv import write_joint_csv
    from livezmp.model.urdf_body import body_from_urdf

    urdf = demo_robot_path()
    body = body_from_urdf(urdf)
    write_joint_csv(demo_trajectory(body.joint_names, duration=0.3), d / "seed.csv")
    return urdf.read_bytes(), (d / "seed.csv").read_bytes(), urdf.with_suffix(".toml").read_bytes()


def _mcap_seed(d: Path) -> bytes:
    from livezmp.balance.pipeline import default_config
    from livezmp.model.body_spec import robot_body
    from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
    from livezmp.model.motion_file import trajectory_frames
    from livezmp.monitor.loop import Monitor
    from livezmp.recording.writer import Recorder
    from livezmp.sources.file_replay import FileReplaySource

    body, spec = robot_body(demo_robot_path())
    traj = demo_trajectory(body.joint_names, duration=0.3)
    rec = Recorder(d / "seed.mcap", spec, {"fps": 100.0}, body.channel_names)
    src = FileReplaySource("<demo>", body, spec, traj.t, trajectory_frames(body, traj), speed=0)
    Monitor(src, default_config(body, 100.0), recorder=rec).run()
    return (d / "seed.mcap").read_bytes()


C3D_FRAMES = slice(130, 330)  # the data set's CGM2.4 walk: two seconds around its force-plate step


def c3d_seed(d: Path, take: Path) -> bytes:
    """A small C3D cut from ``take``: only the markers the marker body uses, frames :data:`C3D_FRAMES`
    and their analog samples (a fifth of the whole take's read time; mutations reach its header and
    parameters more often)."""
    import ezc3d

    from livezmp.model.c3d import read_c3d, strip_prefix
    from livezmp.model.markers import marker_labels

    keep = marker_labels(read_c3d(take))
    c = ezc3d.c3d(str(take))
    point = c["parameters"]["POINT"]
    labels = [strip_prefix(s) for s in point["LABELS"]["value"]]
    idx = [labels.index(k) for k in keep]
    for name in ("LABELS", "DESCRIPTIONS"):
        if name in point:
            point[name]["value"] = [point[name]["value"][i] for i in idx]
    per_frame = round(c["header"]["analogs"]["frame_rate"] / c["header"]["points"]["frame_rate"])
    f = C3D_FRAMES
    c["data"]["points"] = c["data"]["points"][:, idx, f]
    c["data"]["analogs"] = c["data"]["analogs"][:, :, f.start * per_frame : f.stop * per_frame]
    del c["data"]["meta_points"]
    c.write(str(d / "seed.c3d"))
    return (d / "seed.c3d").read_bytes()


@dataclass
class Seeds:
    """Valid inputs of every format, and the files the commands need beside them."""

    dir: Path
    files: dict[str, bytes]


def make_seeds(d: Path, c3d: Path | None = None) -> Seeds:
    """Seeds of every format; ``c3d`` a real C3D take to cut the C3D seed from (the data set's), if given."""
    d.mkdir(parents=True, exist_ok=True)
    urdf, csv, toml = _robot_seeds(d)
    (d / "robot.urdf").write_bytes(urdf)
    (d / "robot.csv").write_bytes(csv)
    files = {"bvh": _bvh_seed(d), "csv": csv, "urdf": urdf, "toml": toml, "mcap": _mcap_seed(d)}
    if c3d is not None and c3d.is_file():
        files["c3d"] = c3d_seed(d, c3d)
    return Seeds(d, files)


# -- running a command under the contract ----------------------------------------------------------------


@contextlib.contextmanager
def _captured():
    """stdout/stderr of Python and of C code (file descriptors 1 and 2) into buffers."""
    out, err = io.StringIO(), io.StringIO()
    saved = os.dup(2), os.dup(1)
    with tempfile.TemporaryFile() as raw_err, tempfile.TemporaryFile() as raw_out:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(raw_err.fileno(), 2)
        os.dup2(raw_out.fileno(), 1)
        box = {}
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                yield box
        finally:
            os.dup2(saved[0], 2)
            os.dup2(saved[1], 1)
            os.close(saved[0])
            os.close(saved[1])
            raw_err.seek(0)
            box["err"] = err.getvalue() + raw_err.read().decode("utf-8", "replace")
            box["out"] = out.getvalue()


def _on_alarm(signum, frame):
    raise Hang()


@functools.cache
def _grammar(build=cli.build_parser):
    return build()


def run_cli(argv: list[str], inputs: list[Path], outputs: list[Path], ok_codes=(0,)) -> Outcome:
    """Run ``livezmp argv`` here and judge it by the contract (module docstring). The grammar is
    built once per process (building it costs more than refusing most inputs; it is not what is fuzzed)."""
    for p in outputs:
        p.unlink(missing_ok=True)
    old = signal.signal(signal.SIGALRM, _on_alarm)
    signal.setitimer(signal.ITIMER_REAL, TIME_LIMIT_S)
    rc, escaped = None, None
    try:
        with _captured() as box:
            try:
                with mock.patch.object(cli, "build_parser", _grammar):
                    rc = cli.main([str(a) for a in argv])
            except SystemExit as e:
                rc = e.code
            except Hang:
                escaped = f"hang: more than {TIME_LIMIT_S} s"
            except BaseException as e:  # the contract: nothing escapes main
                escaped = f"{type(e).__name__}: {str(e)[:200]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    if escaped:
        return Outcome("failure", escaped)
    return _judge(rc, box["err"], inputs, outputs, ok_codes)


def run_process(argv: list[str], inputs: list[Path], outputs: list[Path], ok_codes=(0,)) -> Outcome:
    """Run ``python -m livezmp argv`` as a process of its own and judge it by the same contract: what
    the in-process run cannot show (the real exit code, every line the process writes to stderr)."""
    for p in outputs:
        p.unlink(missing_ok=True)
    try:
        r = subprocess.run([sys.executable, "-m", "livezmp", *map(str, argv)], capture_output=True, text=True,
                           errors="replace", timeout=TIME_LIMIT_S + 10)
    except subprocess.TimeoutExpired:
        return Outcome("failure", f"hang: more than {TIME_LIMIT_S + 10} s")
    if "Traceback (most recent call last)" in r.stderr:  # replay's exit 1 is also a verdict
        return Outcome("failure", f"exit {r.returncode} with a traceback: {r.stderr[-300:]!r}")
    return _judge(r.returncode, r.stderr, inputs, outputs, ok_codes)


def _judge(rc, err: str, inputs: list[Path], outputs: list[Path], ok_codes) -> Outcome:
    lines = err.splitlines()
    if rc == 2:
        names = [p.name for p in inputs]
        if len(lines) != 1:
            return Outcome("failure", f"exit 2 with {len(lines)} stderr lines: {err[:300]!r}")
        if not any(n in lines[0] for n in names):
            return Outcome("failure", f"exit 2 naming none of {names}: {lines[0][:200]}")
        return Outcome("refused", lines[0])
    if rc in ok_codes:
        bad = _non_finite_outputs(outputs)
        return Outcome("failure", f"exit {rc} with {bad}") if bad else Outcome("clean")
    return Outcome("failure", f"exit {rc}: {err[-300:]!r}")


def _non_finite_outputs(outputs: list[Path]) -> str | None:
    for p in outputs:
        if not p.exists() or p.suffix not in (".json", ".csv"):
            continue
        text = p.read_text(encoding="utf-8")
        if p.suffix == ".json":
            try:
                json.loads(text, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
            except ValueError as e:
                return f"{p.name}: not strict JSON ({e})"
        elif p.suffix == ".csv":
            for cell in re.split(r"[,\r\n]+", text):
                try:
                    if not math.isfinite(float(cell)):
                        return f"{p.name}: cell {cell}"
                except ValueError:
                    continue
    return None


# -- targets -----------------------------------------------------------------------------------------


def commands(fmt: str, path: Path, seeds: Seeds, work: Path) -> list[tuple[list, list[Path], list[Path], tuple]]:
    """The commands that read ``path`` as an input of ``fmt``: (argv, inputs to name, outputs, exit codes
    meaning success)."""
    d = seeds.dir
    summary, table = work / "s.json", work / "zmp.csv"
    outs = [summary, table]
    tail = ["--summary-json", summary, "--out", table]
    if fmt in ("bvh", "c3d"):
        return [(["analyze", path, *tail], [path], outs, (0,))]
    if fmt == "csv":
        return [(["analyze", path, "--robot", d / "robot.urdf", *tail], [path, d / "robot.urdf"], outs, (0,))]
    if fmt == "urdf":
        return [(["analyze", d / "robot.csv", "--robot", path, *tail], [path, d / "robot.csv"], outs, (0,))]
    if fmt == "toml":
        return [(["analyze", d / "robot.csv", "--robot", d / "robot.urdf", "--robot-config", path, *tail],
                 [path, d / "robot.csv", d / "robot.urdf"], outs, (0,))]
    if fmt == "mcap":
        return [(["replay", path], [path], [], (0, 1)), (["recover", path, "-o", work / "fixed.mcap"], [path],
                                                         [work / "fixed.mcap"], (0,))]
    raise ValueError(fmt)


def check_file(fmt: str, data: bytes, seeds: Seeds, work: Path, run=run_cli) -> Outcome:
    """Write ``data`` as an input of ``fmt`` and run the commands that read it (``run``: here, or
    :func:`run_process`); the first one's outcome unless a later one fails."""
    path = work / f"input.{fmt}"
    path.write_bytes(data)
    first = None
    for argv, inputs, outputs, ok in commands(fmt, path, seeds, work):
        o = run(argv, inputs, outputs, ok)
        if o.kind == "failure":
            return Outcome("failure", f"{argv[0]}: {o.detail}" if fmt == "mcap" else o.detail)
        first = first or o
    return first


class PacketTarget:
    """A UDP source on loopback and a pipeline behind it, for the packet contract."""

    def __init__(self):
        from livezmp.balance.pipeline import Pipeline, default_config
        from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
        from livezmp.model.motion_file import trajectory_frames
        from livezmp.sources.factory import SourceOptions, open_source

        self.src = open_source("udp://127.0.0.1:0", SourceOptions(robot=str(demo_robot_path()), fps=100.0))
        self.pipeline = Pipeline(self.src.body, default_config(self.src.body, 100.0), 0.01)
        self.frames = trajectory_frames(self.src.body, demo_trajectory(self.src.body.joint_names, duration=1.0))
        self.tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.seq = 0

    def seed(self, binary: bool) -> bytes:
        from livezmp.sources.frame_format import WireFrame, encode_binary, encode_json

        k = self.seq % len(self.frames)
        f = WireFrame(self.seq, 0.01 * self.seq, self.frames[k], (True, False) if k % 2 else None)
        self.seq += 1
        return encode_binary(f) if binary else encode_json(f)

    def counted(self) -> int:
        st = self.src.stats
        return st.delivered + st.dropped

    def send(self, packets: list[bytes]) -> Outcome:
        """Send ``packets`` (a few at a time: the kernel drops datagrams beyond its receive
        buffer); every one must be delivered (and analysed) or counted."""
        for lo in range(0, len(packets), BURST):
            o = self._send(packets[lo : lo + BURST])
            if o.kind == "failure":
                return o
        return Outcome("clean")

    def _send(self, packets: list[bytes]) -> Outcome:
        start = self.counted()
        for p in packets:
            self.tx.sendto(p[:65000], ("127.0.0.1", self.src.port))
        deadline = time.monotonic() + 1.0
        try:
            while self.counted() < start + len(packets):
                # short reads: read() returns only with a delivered frame, so a burst ending in dropped
                # packets would otherwise wait out the whole timeout
                f = self.src.read(0.01)
                if f is None and time.monotonic() > deadline:
                    return Outcome("failure", f"packet counter {self.counted() - start} of {len(packets)}: "
                                              "packets neither delivered nor counted")
                if f is None:
                    continue
                if not (math.isfinite(f.t) and np.all(np.isfinite(f.channels))):
                    return Outcome("failure", f"delivered a non-finite frame at t {f.t}")
                if f.restart:
                    self.pipeline.restart()
                self.pipeline.step(f.t, f.channels, f.contacts)
        except Exception as e:  # the contract: a packet never raises
            return Outcome("failure", f"packet counter {self.counted()}: {type(e).__name__}: {str(e)[:200]}")
        return Outcome("clean")

    def close(self) -> None:
        self.tx.close()
        self.src.close()
