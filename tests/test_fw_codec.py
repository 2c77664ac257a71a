"""firmware_protocol codec: published COBS examples, the SPEC's own numbers, shared vectors, round trips."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import re
import struct
import zlib
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import firmware_protocol as fp
from firmware_protocol.can_framing import CanDecoder, encode_can, split_can_id
from firmware_protocol.cobs import cobs_decode, cobs_encode, max_encoded_size
from firmware_protocol.schema import MESSAGES, SCHEMA_TEXT
from firmware_protocol.serial_framing import MAX_ENCODED, MAX_FRAME
from firmware_protocol.strategies import message_of
from firmware_protocol.vectors import VECTORS_PATH, build, dumps

SPEC = (Path(fp.__file__).parent / "SPEC.md").read_text()


def _hex(s: str) -> bytes:
    return bytes.fromhex(s.replace(" ", ""))


# Wikipedia, "Consistent Overhead Byte Stuffing", encoding examples 1-11 (delimiter included).
COBS_EXAMPLES = [
    (_hex("00"), _hex("01 01 00")),
    (_hex("00 00"), _hex("01 01 01 00")),
    (_hex("00 11 00"), _hex("01 02 11 01 00")),
    (_hex("11 22 00 33"), _hex("03 11 22 02 33 00")),
    (_hex("11 22 33 44"), _hex("05 11 22 33 44 00")),
    (_hex("11 00 00 00"), _hex("02 11 01 01 01 00")),
    (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255)) + b"\x00"),
    (bytes(range(0, 255)), b"\x01\xff" + bytes(range(1, 255)) + b"\x00"),
    (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff\x00"),
    (bytes(range(2, 256)) + b"\x00", b"\xff" + bytes(range(2, 256)) + b"\x01\x01\x00"),
    (bytes(range(3, 256)) + b"\x00\x01", b"\xfe" + bytes(range(3, 256)) + b"\x02\x01\x00"),
]


@pytest.mark.parametrize("data, encoded", COBS_EXAMPLES)
def test_cobs_matches_published_examples(data, encoded):
    assert cobs_encode(data) + b"\0" == encoded
    assert cobs_decode(encoded[:-1]) == data
    assert len(encoded) - 1 <= max_encoded_size(len(data))


@given(st.binary(max_size=2000))
def test_cobs_round_trip_has_no_zero_and_bounded_overhead(data):
    enc = cobs_encode(data)
    assert b"\0" not in enc
    assert len(enc) <= max_encoded_size(len(data))
    assert cobs_decode(enc) == data


def test_malformed_cobs_is_a_decode_error():
    with pytest.raises(fp.DecodeError) as err:
        cobs_decode(_hex("05 11 22"))  # block of 4 data bytes with 2 left
    assert err.value.kind == "bad_framing"


def _spec_schema_block() -> str:
    return re.search(r"```\n(version 1\n.*?)```", SPEC, re.S).group(1)


def test_spec_schema_text_is_the_codes_schema_and_hashes_to_the_published_value():
    block = _spec_schema_block()
    assert block == SCHEMA_TEXT
    digest = hashlib.sha256(block.encode("ascii")).digest()
    assert int.from_bytes(digest[:8], "little") == fp.SCHEMA_HASH
    assert f"{fp.SCHEMA_HASH:#018x}" in SPEC


def test_dataclass_fields_follow_the_schema_lines():
    for spec in MESSAGES:
        cls = fp.messages.MESSAGE_CLASSES[spec.msg_id]
        names = [f.name for f in dataclasses.fields(cls)]
        assert names == [f.name for f in (*spec.head, *spec.group)], spec.name


def test_spec_worked_example_built_by_hand():
    """ESTOP from the host, seq 0, assembled from the SPEC's rules without the encoder."""
    seed = zlib.crc32(b"0x01 ESTOP host engage:bool")
    body = struct.pack("<BBBHH", 1, 0, 0x01, 0, 1) + b"\x01"
    crc = zlib.crc32(body + seed.to_bytes(4, "little"))
    assert crc == 0xDCC49B63
    frame = body + crc.to_bytes(4, "little")
    # COBS by hand: zeros at offsets 1, 3, 4 and 6 of the 12-byte frame.
    stuffed = _hex("02 01 02 01 01 02 01 06 01 63 9b c4 dc 00")
    assert fp.encode(fp.Estop(True), seq=0) == stuffed
    assert cobs_decode(stuffed[:-1]) == frame
    assert "02 01 02 01 01 02 01 06 01 63 9b c4 dc 00" in SPEC


def test_crc32_is_iso_hdlc():
    assert zlib.crc32(b"123456789") == 0xCBF43926  # the catalogue check value the SPEC names


def test_payload_sizes_match_the_spec_table():
    sizes = {"ESTOP": 1, "FAULT": 11, "IMU": 44, "WATCHDOG": 3, "STREAM_RATES": 8, "ACK": 3, "NACK": 4,
             "STATUS": 16, "HEARTBEAT": 5, "HELLO": 8}
    for spec in MESSAGES:
        if spec.name in sizes:
            assert spec.fixed_size == sizes[spec.name], spec.name
    assert len(fp.encode_payload(fp.vectors.example_joint_state(20))) == 5 + 15 * 20
    assert MAX_FRAME == 1031 and MAX_ENCODED == 1036


def test_vectors_file_is_current_and_decodes():
    assert VECTORS_PATH.read_text() == dumps(build()), "regenerate: python -m firmware_protocol.vectors"
    for v in json.loads(VECTORS_PATH.read_text()):
        msg = fp.from_dict(v["message"])
        dec = fp.StreamDecoder("board" if v["from_board"] else "host")
        (got,) = dec.feed_frames(bytes.fromhex(v["serial"]))
        assert (got.message, got.seq) == (msg, v["seq"]), v["name"]
        assert fp.encode(got.message, v["seq"], v["from_board"]).hex() == v["serial"]
        can_dec = CanDecoder("node" if v["from_board"] else "host")
        out = [r for can_id, data in v["can"] for r in can_dec.feed(can_id, bytes.fromhex(data))]
        assert [(r.message, r.seq, r.node) for r in out] == [(msg, v["can_tid"], v["can_node"])], v["name"]
        assert all(split_can_id(can_id)[0] == msg.spec.msg_id for can_id, _ in v["can"])


NAMES = [spec.name for spec in MESSAGES]


@pytest.mark.parametrize("name", NAMES)
@settings(max_examples=60)
@given(data=st.data())
def test_payload_round_trip(name, data):
    msg = data.draw(message_of(name))
    payload = fp.encode_payload(msg)
    assert fp.decode_payload(msg.spec, payload) == msg
    assert fp.encode_payload(fp.decode_payload(msg.spec, payload)) == payload  # bytes, so -0.0 survives too


@pytest.mark.parametrize("name", NAMES)
@settings(max_examples=60)
@given(seq=st.integers(0, 0xFFFF), data=st.data())
def test_serial_round_trip_in_any_chunking(name, seq, data):
    msg = data.draw(message_of(name))
    from_board = msg.spec.direction == "board" or (msg.spec.direction == "both" and seq % 2 == 1)
    frame = fp.encode(msg, seq, from_board)
    assert frame.endswith(b"\0") and b"\0" not in frame[:-1]
    assert len(frame) - 1 <= MAX_ENCODED
    cuts = sorted(data.draw(st.lists(st.integers(0, len(frame)), max_size=6)))
    dec = fp.StreamDecoder("any")
    got = []
    for a, b in zip([0, *cuts], [*cuts, len(frame)], strict=True):
        got += dec.feed_frames(frame[a:b])
    assert [(r.message, r.seq) for r in got] == [(msg, seq)]
    assert not any(dec.errors.values())


@pytest.mark.parametrize("name", NAMES)
@settings(max_examples=60)
@given(node=st.integers(1, 127), tid=st.integers(0, 31), data=st.data())
def test_can_round_trip(name, node, tid, data):
    msg = data.draw(message_of(name))
    from_node = msg.spec.direction == "board" or (msg.spec.direction == "both" and tid % 2 == 1)
    frames = encode_can(msg, node, tid, from_node)
    payload = fp.encode_payload(msg)
    assert len(frames) == (1 if len(payload) <= 8 else (len(payload) + 4 + 7) // 8)
    assert all(len(f.data) <= 8 for f in frames) and all(len(f.data) == 8 for f in frames[:-1])
    dec = CanDecoder("node" if from_node else "host")
    got = [r for f in frames for r in dec.feed(f.can_id, f.data)]
    assert [(r.message, r.seq, r.node) for r in got] == [(msg, tid, node)]
    assert not any(dec.errors.values())


@given(message_of("JOINT_STATE"))
def test_joint_state_layout_is_the_documented_one(msg):
    """Independent reading of the SPEC table: u32 time, u8 count, then 15-byte records."""
    payload = fp.encode_payload(msg)
    t, n = struct.unpack_from("<IB", payload)
    assert (t, n) == (msg.board_time_us, len(msg.ids))
    for i, rec in enumerate(struct.iter_unpack("<BfffH", payload[5:])):
        assert rec == (msg.ids[i], msg.position[i], msg.velocity[i], msg.current[i], msg.error[i])


def test_can_id_layout_and_priority():
    (estop,) = encode_can(fp.Estop(True), 0, 0, False)
    (goal,) = encode_can(fp.SetGoals(9, (4,), (0.5,)), 4, 2, False)
    (beat,) = encode_can(fp.Heartbeat(1000, fp.BoardState.ACTIVE), 4, 2, True)
    assert goal.can_id == 0x08 << 21 | 4 << 13 | 2 << 8 | 1 << 7
    assert beat.can_id == 0x1B << 21 | 1 << 20 | 4 << 13 | 2 << 8 | 1 << 7
    assert goal.data == _hex("09 00 01 04 00 00 00 3f")
    assert estop.can_id < goal.can_id < beat.can_id  # lower id wins arbitration


BAD_MESSAGES = [
    (fp.SetGoals(1, (1, 1), (0.0, 0.0)), "SET_GOALS.ids: duplicated"),
    (fp.SetGoals(1, (1,), (float("nan"),)), "SET_GOALS.position[0]: nan is not finite"),
    (fp.SetGoals(1, (1,), (1e39,)), "SET_GOALS.position[0]: 1e+39 is out of float32 range"),
    (fp.SetGoals(1, (300,), (0.0,)), "SET_GOALS.ids[0]: 300 is not an integer in 0..255"),
    (fp.SetGoals(70000, (1,), (0.0,)), "SET_GOALS.cmd_seq: 70000 is not an integer in 0..65535"),
    (fp.SetGoals(1, (1, 2), (0.0,)), "SET_GOALS.position: 1 entries, but ids has 2"),
    (fp.SetGoals(1, (1,), ("x",)), "SET_GOALS.position[0]: expected a number, got 'x'"),
    (fp.SetGoals(1, tuple(range(33)), (0.0,) * 33), "SET_GOALS: 33 records, at most 32"),
    (fp.Watchdog(5, 7), "WATCHDOG.action: 7 is not one of [0, 1]"),
    (fp.Torque((1,), (2,)), "TORQUE.enable: 2 is not one of [0, 1]"),
    (fp.Imu(1, (1.0, 0.0, 0.0), (0.0,) * 3, (0.0,) * 3), "IMU.orientation: expected 4 values, got 3"),
    (fp.HelloAck(1, 1, 1, 1, (1,), ("é",)), "HELLO_ACK.joint_names: 'é' is not 1..16 printable ASCII"),
    (fp.HelloAck(1, 1, 1, 1, (1,), ("x" * 17,)), "is not 1..16 printable ASCII"),
]


@pytest.mark.parametrize("msg, text", BAD_MESSAGES)
def test_bad_values_raise_one_line_protocol_error_naming_the_field(msg, text):
    with pytest.raises(fp.ProtocolError) as err:
        fp.encode(msg, 0, msg.spec.direction == "board")
    assert text in str(err.value) and "\n" not in str(err.value)


def test_wrong_direction_and_bad_envelope_arguments_are_refused():
    with pytest.raises(fp.ProtocolError, match="JOINT_STATE is sent by the board only"):
        fp.encode(fp.vectors.example_joint_state(1), 0, from_board=False)
    with pytest.raises(fp.ProtocolError, match="seq 70000"):
        fp.encode(fp.Estop(), 70000)
    with pytest.raises(fp.ProtocolError, match="node id 0"):
        encode_can(fp.Heartbeat(0, fp.BoardState.ACTIVE), 0, 0, True)
    with pytest.raises(fp.ProtocolError, match="transfer id 32"):
        encode_can(fp.Estop(), 1, 32, False)
    with pytest.raises(fp.ProtocolError, match="unknown field"):
        fp.from_dict({"type": "ESTOP", "engage": True, "force": 1})
    with pytest.raises(fp.ProtocolError, match="missing field 'engage'"):
        fp.from_dict({"type": "ESTOP"})
    with pytest.raises(fp.ProtocolError, match="WATCHDOG.action: 9 is not a valid WatchdogAction"):
        fp.from_dict({"type": "WATCHDOG", "timeout_ms": 5, "action": 9})


DECODE_CASES = [
    ("SET_GOALS", _hex("0100 02 01 0000003f"), "bad_length"),  # 2 records announced, 1 present
    ("SET_GOALS", _hex("0100 21") + bytes(33 * 5), "bad_length"),  # 33 > 32 records
    ("SET_GOALS", _hex("0100 02 01 0000003f 01 0000803f"), "bad_value"),  # id 1 twice
    ("SET_GOALS", _hex("0100 01 01 0000c07f"), "bad_value"),  # NaN
    ("JOINT_STATE", _hex("00000000 01 01 0000807f 00000000 00000000 0000"), "bad_value"),  # +inf
    ("WATCHDOG", _hex("c800 02"), "bad_value"),  # action 2 undefined
    ("ESTOP", _hex("02"), "bad_value"),  # bool 2
    ("ESTOP", _hex("0101"), "bad_length"),
    ("HELLO_ACK", _hex("00" * 20 + "01 05 00"), "bad_value"),  # empty name
    ("HELLO_ACK", _hex("00" * 20 + "01 05 03 4142"), "bad_length"),  # name cut short
    ("HELLO_ACK", _hex("00" * 20 + "01 05 01 07"), "bad_value"),  # control character
    ("HELLO_ACK", _hex("00" * 20 + "01 05 01 41 00"), "bad_length"),  # trailing byte
]


@pytest.mark.parametrize("name, payload, kind", DECODE_CASES)
def test_malformed_payloads_are_charged_to_the_right_kind(name, payload, kind):
    spec = fp.schema.BY_NAME[name]
    with pytest.raises(fp.DecodeError) as err:
        fp.decode_payload(spec, payload)
    assert err.value.kind == kind
