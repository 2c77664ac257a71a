"""kill -9 of a recording monitor at random moments: every file is recovered into one
the mcap reader opens, holding every frame from 0 up to at most the last chunk, and
the frames lost at the end were received less than a second before the kill."""

from __future__ import annotations

import io
import json
import os
import random
import signal
import struct
import subprocess
import sys
import time
from pathlib import Path

from data_paths import ROOT
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader
from sim_support import wait_until

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.model.body_spec import robot_body
from livezmp.model.demo_robot import demo_robot_path
from livezmp.recording.reader import open_recording
from livezmp.recording.recover import recover
from livezmp.recording.writer import CHUNK_SECONDS

RUNS = 5


def messages_before_the_cut(data: bytes) -> int:
    """Messages the mcap stream reader gets from a file cut short, before its error (a cut
    inside a record's length field comes out of the reader as struct.error)."""
    n = 0
    try:
        for r in StreamReader(io.BytesIO(data), validate_crcs=True).records:
            n += isinstance(r, Message)
    except (McapError, struct.error):
        pass
    return n


# One process imports livezmp once and forks a `livezmp monitor` per run: five cold
# start-ups on a busy 2-core machine would cost more than the whole rest of the suite.
FORKER = """
import os, sys
from livezmp.cli import main
for path in sys.argv[1:]:
    pid = os.fork()
    if pid == 0:
        sys.stdout = open(os.devnull, "w")  # this pipe carries the parent's pid lines only
        os._exit(main(["monitor", "--loop", "--speed", "2", "--record", path]))
    print(pid, path, flush=True)
for _ in sys.argv[1:]:
    os.wait()
"""


def test_kill_9_while_recording(tmp_path):
    rng = random.Random(6)
    paths = [tmp_path / f"broken{i}.mcap" for i in range(RUNS)]
    forker = subprocess.Popen([sys.executable, "-c", FORKER, *map(str, paths)], cwd=ROOT, text=True,
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                              env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    pids = {}
    for _ in range(RUNS):
        pid, path = forker.stdout.readline().split()
        pids[Path(path)] = int(pid)
    kills = {}
    due = {}

    def kill_those_due() -> bool:
        """Kill each recorder at a random moment after its first chunk; True once all are killed."""
        for path, pid in pids.items():
            if path in kills:
                continue
            if path not in due and path.exists() and messages_before_the_cut(path.read_bytes()):
                due[path] = time.monotonic() + rng.uniform(0.0, 1.5)
            elif path in due and time.monotonic() >= due[path]:
                kills[path] = time.time_ns()
                os.kill(pid, signal.SIGKILL)
        return len(kills) == RUNS

    try:
        wait_until(kill_those_due, timeout=60.0)
    finally:
        for path, pid in pids.items():
            if path not in kills:
                os.kill(pid, signal.SIGKILL)
        forker.wait(10)
    assert len(kills) == RUNS
    body, _ = robot_body(demo_robot_path())
    # results trail inputs by the estimator's lag, and by one more frame when a chunk closed
    # between an input and its step's result
    lag = Pipeline(body, default_config(body, 100.0), 0.01).lag + 1
    for path in paths:
        fixed = path.with_name(path.stem + "_fixed.mcap")
        rep = recover(path, fixed)
        assert not rep.complete  # no footer after kill -9
        assert rep.messages == messages_before_the_cut(path.read_bytes()) > 0
        with open(fixed, "rb") as f:  # a complete file for the mcap reader
            msgs = [(ch.topic, m) for _, ch, m in make_reader(f, validate_crcs=True).iter_messages()]
        inputs = [json.loads(m.data) for topic, m in msgs if topic == "/input"]
        results = [json.loads(m.data)["index"] for topic, m in msgs if topic == "/result"]
        assert [m["index"] for m in inputs] == list(range(len(inputs))) and inputs
        assert results == list(range(len(results))) and len(inputs) - lag <= len(results) <= len(inputs)
        last_input = max(m.log_time for topic, m in msgs if topic == "/input")
        lost = (kills[path] - last_input) / 1e9
        assert 0 <= lost < 2 * CHUNK_SECONDS, (path, lost)  # at most the open chunk was lost
        assert open_recording(fixed).body_spec.kind == "urdf"
