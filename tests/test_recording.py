"""MCAP recording: messages valid against their JSON schemas, the body and session read
back, data on disk as soon as a chunk closes, and recovery of files cut anywhere or
corrupted, checked against the chunk index the mcap writer itself wrote."""

from __future__ import annotations

import io
import json

import jsonschema
import numpy as np
import pytest
from data_paths import BANDAI
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Message
from mcap.stream_reader import StreamReader, breakup_chunk

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.errors import InputError
from livezmp.model.body_spec import body_from_spec, read_skeleton, skeleton_body
from livezmp.recording.reader import iter_messages, open_recording
from livezmp.recording.recover import recover
from livezmp.recording.schemas import SCHEMAS
from livezmp.recording.writer import Recorder

WALK = BANDAI / "walk_normal_001.bvh"


@pytest.fixture(scope="module")
def walk():
    sk = read_skeleton(WALK)
    body, spec = skeleton_body(sk)
    return body, spec, sk.motion


def record(path, walk, n: int = 200, **kw) -> list:
    """Record ``n`` Bandai frames and their results; returns the results."""
    body, spec, motion = walk
    rec = Recorder(path, spec, {"fps": 30.0, "mode": "full"}, body.channel_names, **kw)
    pipe = Pipeline(body, default_config(body, 30.0), motion.frame_time)
    out = []
    for k in range(n):
        rec.input(k, k * motion.frame_time, motion.frames[k], None)
        r = pipe.step(k * motion.frame_time, motion.frames[k])
        if r is not None:
            rec.result(r)
            out.append(r)
    rec.close({"inputs": n})
    return out


def test_recording_reads_back_with_valid_schemas(tmp_path, walk):
    path = tmp_path / "s.mcap"
    results = record(path, walk)
    body, spec, motion = walk
    rec = open_recording(path)
    assert rec.body_spec == spec and rec.session["fps"] == 30.0
    assert rec.session["channel_names"] == body.channel_names
    assert rec.counts["/input"] == 200 and rec.counts["/result"] == len(results)
    assert body_from_spec(rec.body_spec).channel_names == body.channel_names
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        json_topics = {c.topic for c in summary.channels.values() if c.message_encoding == "json"}
        assert json_topics == set(SCHEMAS)  # the rest: Foxglove's protobuf scene (test_recording_foxglove)
        validators = {}
        for s in summary.schemas.values():
            if s.encoding == "jsonschema":
                schema = json.loads(s.data)
                jsonschema.Draft202012Validator.check_schema(schema)
                validators[s.id] = jsonschema.Draft202012Validator(schema)
        for _, channel, msg in reader.iter_messages(topics=sorted(json_topics)):
            validators[channel.schema_id].validate(json.loads(msg.data))
    inputs = list(iter_messages(path, "/input"))
    np.testing.assert_array_equal([m["channels"] for m in inputs], motion.frames[:200])  # exact: JSON floats
    got = list(iter_messages(path, "/result"))
    assert [m["index"] for m in got] == [r.index for r in results]
    assert all(m["zmp"] == {"x": r.zmp[0], "y": r.zmp[1], "z": r.zmp[2]} for m, r in zip(got, results, strict=True))


def test_topics_have_schemas():
    assert set(SCHEMAS) == {"/input", "/result", "/correction", "/alarm", "/device_error"}


def count_messages(data: bytes) -> int:
    """Messages readable from the start of an unfinished file (the read ends in EndOfFile)."""
    n = 0
    with pytest.raises(McapError):
        for r in StreamReader(io.BytesIO(data)).records:
            n += isinstance(r, Message)
    return n


def test_a_closed_chunk_is_on_disk(tmp_path, walk):
    """With chunk_seconds=0 every message closes its chunk: the bytes on disk, read
    before the file is finished, hold every message written so far."""
    body, spec, motion = walk
    path = tmp_path / "live.mcap"
    rec = Recorder(path, spec, {}, body.channel_names, chunk_seconds=0.0)
    for k in range(5):
        rec.input(k, k / 30, motion.frames[k], None)
        assert count_messages(path.read_bytes()) == k + 1
    lazy = Recorder(tmp_path / "lazy.mcap", spec, {}, body.channel_names, chunk_seconds=3600.0)
    for k in range(5):
        lazy.input(k, k / 30, motion.frames[k], None)
    assert count_messages((tmp_path / "lazy.mcap").read_bytes()) == 0  # still in the open chunk
    rec.close()
    lazy.close()


def chunk_ends(path) -> list[tuple[int, int]]:
    """(end offset, messages) of every chunk, from the summary the mcap writer wrote."""
    out = []
    with open(path, "rb") as f:
        reader = make_reader(f)
        for ci in sorted(reader.get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset):
            f.seek(ci.chunk_start_offset)
            chunk = next(StreamReader(f, skip_magic=True, emit_chunks=True).records)
            n = sum(isinstance(r, Message) for r in breakup_chunk(chunk))
            out.append((ci.chunk_start_offset + ci.chunk_length, n))
    return out


def test_recover_keeps_every_whole_chunk_wherever_the_file_is_cut(tmp_path, walk):
    full = tmp_path / "full.mcap"
    record(full, walk, n=150, chunk_bytes=8192)
    ends = chunk_ends(full)
    assert len(ends) > 5
    data = full.read_bytes()
    rng = np.random.default_rng(1)
    edges = [e for e, _ in ends[:3] + ends[-2:]]
    cuts = sorted({*edges, *(e - 1 for e in edges), ends[0][0] - 50, len(data) - 1, len(data),
                   *rng.integers(ends[0][0], len(data), 8).tolist()})
    for cut in cuts:
        broken, fixed = tmp_path / f"broken{cut}.mcap", tmp_path / f"fixed{cut}.mcap"
        broken.write_bytes(data[:cut])
        if cut < len(data):
            with pytest.raises(InputError, match="livezmp recover"):
                open_recording(broken)
        rep = recover(broken, fixed)
        expected = sum(n for e, n in ends if e <= cut)
        assert rep.messages == expected, cut
        rec = open_recording(fixed)  # body and session survive any cut after the first chunk
        assert rec.body_spec.kind == "bvh"
        inputs = [m["index"] for m in iter_messages(fixed, "/input")]
        assert inputs == list(range(len(inputs)))
        results = [m["index"] for m in iter_messages(fixed, "/result")]
        assert results == list(range(len(results))) and len(results) <= len(inputs)


def test_recover_stops_at_a_corrupt_chunk(tmp_path, walk):
    full = tmp_path / "full.mcap"
    record(full, walk, n=150, chunk_bytes=8192)
    ends = chunk_ends(full)
    data = bytearray(full.read_bytes())
    data[ends[2][0] - 100] ^= 0xFF  # inside the compressed data of the fourth chunk
    (tmp_path / "bad.mcap").write_bytes(bytes(data))
    rep = recover(tmp_path / "bad.mcap", tmp_path / "fixed.mcap")
    assert not rep.complete and rep.stopped
    assert rep.messages == sum(n for _, n in ends[:2])
    assert rep.chunks == 2


def test_recover_refuses_non_mcap_and_in_place(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(InputError, match="not an MCAP file"):
        recover(junk, tmp_path / "out.mcap")
    assert not (tmp_path / "out.mcap").exists()
    with pytest.raises(InputError, match="already exists"):
        recover(junk, junk)
    with pytest.raises(InputError, match="no such file"):
        recover(tmp_path / "missing.mcap", tmp_path / "out.mcap")
