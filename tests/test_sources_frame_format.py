"""The livezmp frame format: the documented examples, byte layouts built with struct,
strict schema checks, and random bytes that only ever raise FrameError."""

from __future__ import annotations

import json
import re
import struct

import numpy as np
import pytest
from data_paths import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st

from livezmp.sources.frame_format import FrameError, WireFrame, decode_frame, encode_binary, encode_json

DOC = (ROOT / "docs" / "frame_format.md").read_text()


def doc_examples() -> tuple[bytes, bytes]:
    """The JSON example and the hex dump of its binary form, from docs/frame_format.md."""
    js = re.search(r"```json\n(.*?)\n```", DOC, re.S).group(1).encode()
    hexdump = re.search(r"in binary \(32 bytes\):\n\n```\n(.*?)\n```", DOC, re.S).group(1)
    return js, bytes.fromhex(hexdump)


def test_documented_examples_decode_to_the_documented_values():
    js, binary = doc_examples()
    for data in (js, binary):
        f = decode_frame(data, 3)
        assert (f.seq, f.t, f.contacts) == (7, 0.25, (True, False))
        assert f.channels.tolist() == [1.5, -2.0, 90.0]


def test_encoders_reproduce_the_documented_bytes():
    js, binary = doc_examples()
    frame = WireFrame(7, 0.25, np.array([1.5, -2.0, 90.0]), (True, False))
    assert encode_binary(frame) == binary
    assert json.loads(encode_json(frame)) == json.loads(js)


def test_binary_layout_from_struct():
    values = [0.1, 123.456, -7.0, 1e-3]
    data = struct.pack("<4sBBHId4f", b"LZF1", 0, 0, 4, 2**32 - 1, 12.5, *values)
    f = decode_frame(data, 4)
    assert f.seq == 2**32 - 1 and f.t == 12.5 and f.contacts is None
    np.testing.assert_allclose(f.channels, values, rtol=1e-7)  # float32 precision
    flags = struct.pack("<4sBBHId", b"LZF1", 0x01 | 0x04, 0, 0, 1, 0.0)  # contacts: right only
    assert decode_frame(flags, 0).contacts == (False, True)


@pytest.mark.parametrize("data, field", [
    (b'{"seq": 1, "t": 0.1, "channels": [1, 2]}', "channels: 2 values"),
    (b'{"seq": -1, "t": 0.1, "channels": [1, 2, 3]}', "field seq"),
    (b'{"seq": 1.5, "t": 0.1, "channels": [1, 2, 3]}', "field seq"),
    (b'{"seq": 4294967296, "t": 0.1, "channels": [1, 2, 3]}', "field seq"),
    (b'{"seq": 1, "t": "x", "channels": [1, 2, 3]}', "field t"),
    (b'{"seq": 1, "t": NaN, "channels": [1, 2, 3]}', "field t"),
    (b'{"seq": 1, "t": 0.1, "channels": [1, true, 3]}', "field channels"),
    (b'{"seq": 1, "t": 0.1, "channels": [1, Infinity, 3]}', "channels[1]: not finite"),
    (b'{"seq": 1, "t": 0.1, "channels": [1, 2, 3], "contacts": [1, 0]}', "field contacts"),
    (b'{"seq": 1, "t": 0.1, "channels": [1, 2, 3], "extra": 0}', "unknown field 'extra'"),
    (b'{"v": 2, "seq": 1, "t": 0.1, "channels": [1, 2, 3]}', "field v"),
    (b'[1, 2, 3]', "not an object"),
    (b'{"seq": 1, "t": 0.1, "channels": [1, 2, 3]', "JSON frame"),
    (b'\xff\xfe', "JSON frame"),
    (struct.pack("<4sBBHId3f", b"LZF1", 0x08, 0, 3, 1, 0.1, 1, 2, 3), "unknown flags"),
    (struct.pack("<4sBBHId2f", b"LZF1", 0, 0, 3, 1, 0.1, 1, 2), "3 channels need 32"),
    (struct.pack("<4sBBHId3f", b"LZF1", 0, 0, 3, 1, float("inf"), 1, 2, 3), "field t"),
    (struct.pack("<4sBBHId3f", b"LZF1", 0, 0, 3, 1, 0.1, 1, float("nan"), 3), "channels[1]"),
    (b"LZF1\x00", "header needs 20"),
])
def test_malformed_frames_name_the_problem(data, field):
    with pytest.raises(FrameError, match=re.escape(field)) as e:
        decode_frame(data, 3)
    assert e.value.kind == "malformed" and "\n" not in str(e.value)


def test_oversized_frames_are_refused_before_parsing():
    data = b'{"seq": 1, "t": 0.1, "channels": [1, 2, 3]}' + b" " * 400
    with pytest.raises(FrameError, match="exceeds the 352-byte limit") as e:
        decode_frame(data, 3)
    assert e.value.kind == "oversized"
    assert decode_frame(data, 3, max_bytes=1000).seq == 1


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=80), st.binary(max_size=40).map(lambda b: b"LZF1" + b)))
def test_random_bytes_raise_only_frame_errors(data):
    try:
        f = decode_frame(data, 3)
    except FrameError:
        return
    assert len(f.channels) == 3 and np.all(np.isfinite(f.channels))
