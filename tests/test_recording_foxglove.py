"""The Foxglove scene of a recording: every message parses against the schema stored in
the file (built from it alone, as Foxglove does), those schemas are Foxglove's published
ones, and what they draw is the /result of the same frame."""

from __future__ import annotations

import json

import numpy as np
import pytest
from data_paths import BANDAI
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.model.body_spec import read_skeleton, skeleton_body
from livezmp.recording.foxglove import SCENE_TOPICS
from livezmp.recording.writer import Recorder

WALK = BANDAI / "walk_normal_001.bvh"


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    sk = read_skeleton(WALK)
    body, spec = skeleton_body(sk)
    path = tmp_path_factory.mktemp("fox") / "s.mcap"
    rec = Recorder(path, spec, {"fps": 30.0}, body.channel_names, scene_hz=None)
    pipe = Pipeline(body, default_config(body, 30.0), sk.motion.frame_time)
    results = []
    for k in range(120):
        r = pipe.step(k * sk.motion.frame_time, sk.motion.frames[k])
        if r is not None:
            cop = None if r.zmp is None else np.array([r.zmp[0] + 0.01, r.zmp[1], r.ground_z])
            rec.result(r, cop, log_time_ns=10**9 + k)
            results.append((r, cop))
    rec.close()
    return path, results


def classes_from_file(summary):
    """Message classes built only from the FileDescriptorSets stored in the file."""
    out = {}
    for s in summary.schemas.values():
        if s.encoding != "protobuf":
            continue
        fds = descriptor_pb2.FileDescriptorSet.FromString(s.data)
        pool = descriptor_pool.DescriptorPool()
        for fd in fds.file:
            pool.Add(fd)
        out[s.id] = (s.name, message_factory.GetMessageClass(pool.FindMessageTypeByName(s.name)))
    return out


def test_scene_messages_parse_against_foxglove_schemas(recording):
    path, results = recording
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        classes = classes_from_file(summary)
        by_topic = {c.topic: c for c in summary.channels.values()}
        for topic, cls in SCENE_TOPICS.items():
            ch = by_topic[topic]
            assert ch.message_encoding == "protobuf" and classes[ch.schema_id][0] == cls.DESCRIPTOR.full_name
            # the stored schema is Foxglove's: the same message description as the published package's
            stored = descriptor_pb2.DescriptorProto()
            classes[ch.schema_id][1].DESCRIPTOR.CopyToProto(stored)
            published = descriptor_pb2.DescriptorProto()
            cls.DESCRIPTOR.CopyToProto(published)
            assert stored == published
        n = {t: 0 for t in SCENE_TOPICS}
        for _, channel, msg in reader.iter_messages(topics=list(SCENE_TOPICS)):
            m = classes[channel.schema_id][1].FromString(msg.data)
            assert m.SerializeToString() == msg.data  # every byte accounted for by the schema
            n[channel.topic] += 1
    assert n["/foxglove/scene"] == n["/foxglove/tf"] == n["/foxglove/com"] == len(results)
    assert n["/foxglove/zmp"] == sum(r.zmp is not None for r, _ in results)


def test_scene_draws_the_result_of_its_frame(recording):
    path, results = recording
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        scenes = [(m.log_time, d) for _, _, m, d in reader.iter_decoded_messages(topics=["/foxglove/scene"])]
    with open(path, "rb") as f:
        res = {m.log_time: json.loads(m.data) for _, _, m in make_reader(f).iter_messages(topics=["/result"])}
    assert len(scenes) == len(results) > 50
    for (log_time, scene), (r, cop) in zip(scenes, results, strict=True):
        assert scene.DESCRIPTOR.full_name == "foxglove.SceneUpdate" and res[log_time]["index"] == r.index
        (e,) = scene.entities
        assert e.frame_id == "world" and e.timestamp.ToNanoseconds() == log_time
        centres = [np.array([s.pose.position.x, s.pose.position.y, s.pose.position.z]) for s in e.spheres]
        expect = [p for p in (r.zmp, r.clamped, r.com, cop) if p is not None]
        np.testing.assert_allclose(centres, expect, atol=1e-12)
        polygon = [(p.x, p.y) for p in e.lines[1].points] if len(r.polygon) else []
        np.testing.assert_allclose(np.reshape(polygon, (-1, 2)), np.reshape(r.polygon, (-1, 2)), atol=1e-12)


def test_a_fast_stream_draws_its_scene_at_the_display_rate_and_keeps_every_result(tmp_path):
    """240 results a second: a scene every fourth (60 Hz, the default), each the scene of the result
    logged at its time; /result has all 240."""
    sk = read_skeleton(WALK)
    body, spec = skeleton_body(sk)
    rec = Recorder(tmp_path / "fast.mcap", spec, {"fps": 240.0}, body.channel_names)
    pipe = Pipeline(body, default_config(body, 30.0), sk.motion.frame_time)
    logged = {}
    for k in range(240):
        r = pipe.step(k * sk.motion.frame_time, sk.motion.frames[k % len(sk.motion.frames)])
        if r is not None:
            t = 10**9 + round(k * 1e9 / 240)
            rec.result(r, log_time_ns=t)
            logged[t] = r
    rec.close()
    with open(tmp_path / "fast.mcap", "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        scenes = [(m.log_time, d) for _, _, m, d in reader.iter_decoded_messages(topics=["/foxglove/scene"])]
    with open(tmp_path / "fast.mcap", "rb") as f:
        n_results = sum(1 for _ in make_reader(f).iter_messages(topics=["/result"]))
    times = sorted(logged)
    assert n_results == len(logged) > 200
    assert [t for t, _ in scenes] == times[::4]
    for t, scene in scenes:
        (e,) = scene.entities
        com = e.spheres[-1].pose.position  # the last sphere: no plate CoP is drawn here
        np.testing.assert_allclose([com.x, com.y, com.z], logged[t].com, atol=1e-12)
