"""The CI part of the fuzz suite (under a minute): hypothesis draws mutations of each
format's seed (C3D: cut from the data set's walk), every corpus file is replayed, a few thousand
mutated UDP packets are sent, and a sample runs as real processes; each input must meet
the contract of :mod:`tests.fuzz.harness`. The longer run is ``python -m tests.fuzz``."""

from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from livezmp.model.c3d import _PROBE
from tests.data_paths import DATA
from tests.fuzz.harness import (
    EXTREMES,
    OPS,
    PacketTarget,
    Seeds,
    c3d_seed,
    check_file,
    commands,
    make_seeds,
    mutate,
    run_process,
)

CORPUS = Path(__file__).parent / "corpus"
C3D_TAKE = DATA / "c3d" / "cgm24_walking01_forceplate.c3d"
FILE_FORMATS = ("bvh", "csv", "urdf", "toml", "mcap")
EXAMPLES = {"bvh": 100, "csv": 100, "urdf": 100, "toml": 100, "mcap": 100}

op = st.tuples(st.sampled_from(OPS), st.integers(0, 1 << 20), st.integers(0, 4 * len(EXTREMES)))


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    return make_seeds(tmp_path_factory.mktemp("seeds"))


def contract(fmt: str, data: bytes, seeds, work: Path) -> None:
    o = check_file(fmt, data, seeds, work)
    assert o.kind != "failure", o.detail


@pytest.mark.parametrize("fmt", FILE_FORMATS)
def test_seed_is_accepted(fmt, seeds, tmp_path):
    assert check_file(fmt, seeds.files[fmt], seeds, tmp_path).kind == "clean"


@pytest.mark.parametrize("fmt", FILE_FORMATS)
def test_mutated_inputs_meet_the_contract(fmt, seeds, tmp_path):
    @settings(max_examples=EXAMPLES[fmt], deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.lists(op, min_size=1, max_size=4))
    def check(ops):
        contract(fmt, mutate(seeds.files[fmt], ops), seeds, tmp_path)

    check()


@pytest.fixture(scope="module")
def c3d_seeds(seeds):
    return Seeds(seeds.dir, {**seeds.files, "c3d": c3d_seed(seeds.dir, C3D_TAKE)})


def test_c3d_seed_and_mutations_meet_the_contract(c3d_seeds, tmp_path):
    assert check_file("c3d", c3d_seeds.files["c3d"], c3d_seeds, tmp_path).kind == "clean"

    @settings(max_examples=20, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.lists(op, min_size=1, max_size=4))
    def check(ops):
        contract("c3d", mutate(c3d_seeds.files["c3d"], ops), c3d_seeds, tmp_path)

    check()


@pytest.mark.parametrize("path", sorted((CORPUS / "c3d").glob("*.ops.json")), ids=lambda p: p.name)
def test_c3d_corpus_meets_the_contract(path, c3d_seeds, tmp_path):
    """C3D corpus entries are the mutations of the data set's walk (the data is never copied here)."""
    ops = [tuple(o) for o in json.loads(path.read_text())]
    contract("c3d", mutate(c3d_seeds.files["c3d"], ops), c3d_seeds, tmp_path)


@pytest.mark.parametrize("fmt", ("bvh", "urdf", "mcap"))
def test_real_processes_meet_the_contract(fmt, seeds, tmp_path):
    """A refused corpus input as a process of its own (the real exit code and every stderr line:
    numpy warnings, urdfdom's and the MCAP reader's output included) for the formats whose readers
    could write more than the one line."""
    path = tmp_path / f"input.{fmt}"
    path.write_bytes(sorted((CORPUS / fmt).glob("refused-*"))[0].read_bytes())
    argv, inputs, outputs, ok = commands(fmt, path, seeds, tmp_path)[0]
    o = run_process(argv, inputs, outputs, ok)
    assert o.kind == "refused", o.detail


@pytest.mark.parametrize("path", sorted(p for p in CORPUS.rglob("*") if p.is_file() and p.parent.name != "c3d"),
                         ids=lambda p: p.name)
def test_corpus_meets_the_contract(path, seeds, tmp_path):
    fmt = path.parent.name
    if fmt == "udp":
        target = PacketTarget()
        try:
            o = target.send([path.read_bytes(), target.seed(False)])
        finally:
            target.close()
        assert o.kind != "failure", o.detail
    else:
        contract(fmt, path.read_bytes(), seeds, tmp_path)


def test_mutated_packets_are_delivered_or_counted():
    rnd = random.Random(7)
    target = PacketTarget()
    try:
        for _ in range(10):
            batch = []
            for _ in range(200):
                p = target.seed(rnd.random() < 0.5)
                ops = [(rnd.choice(OPS), rnd.randrange(1 << 20), rnd.randrange(1 << 20))
                       for _ in range(rnd.randint(1, 3))]
                batch.append(mutate(p, ops) if rnd.random() < 0.7 else p)
            o = target.send(batch)
            assert o.kind != "failure", o.detail
        st_ = target.src.stats
        assert st_.delivered + st_.dropped == 2000 and st_.delivered > 300 and st_.dropped > 300
    finally:
        target.close()


def test_an_ezc3d_probe_left_alone_on_a_looping_file_ends_by_itself(c3d_seeds, tmp_path):
    """The corpus file ezc3d loops on (the pre-check now refuses it before any probe), read by the probe
    program with nobody to time it out, as when livezmp is killed mid-read: its own CPU cap ends it."""
    ops = json.loads((CORPUS / "c3d" / "failure-f615488c5c67.ops.json").read_text())
    path = tmp_path / "loops.c3d"
    path.write_bytes(mutate(c3d_seeds.files["c3d"], [tuple(o) for o in ops]))
    r = subprocess.run([sys.executable, "-c", _PROBE, str(path), "1", "1"], capture_output=True, timeout=60)
    assert r.returncode == -signal.SIGXCPU
