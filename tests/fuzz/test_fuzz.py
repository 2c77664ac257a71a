"""The CI part of the fuzz suite (about a minute): hypothesis draws mutations of each
format's seed, every corpus file is replayed, and a few thousand mutated UDP packets
are sent; each input must meet the contract of :mod:`tests.fuzz.harness`. The longer
run is ``python -m tests.fuzz --minutes N``."""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.fuzz.harness import EXTREMES, OPS, PacketTarget, check_file, make_seeds, mutate

CORPUS = Path(__file__).parent / "corpus"
FILE_FORMATS = ("bvh", "csv", "urdf", "toml", "mcap")
EXAMPLES = {"bvh": 40, "csv": 40, "urdf": 40, "toml": 40, "mcap": 40}

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


@pytest.mark.parametrize("path", sorted(p for p in CORPUS.rglob("*") if p.is_file()), ids=lambda p: p.name)
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
