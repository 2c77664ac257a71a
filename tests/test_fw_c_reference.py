"""The C reference (firmware_protocol/c) against the Python implementation and the shared vectors.

The C sources are compiled once per session with the system compiler (C99,
-Wall -Wextra -pedantic -Werror). fwp_tool decodes what Python encoded and
prints each message as JSON together with the frame the C encoder makes of it,
so both directions are checked: C decode == Python message, C encode == Python
bytes. Corrupted streams must give the same deliveries and the same error
counters in both implementations.
"""

from __future__ import annotations

import json
import random
import shutil
import subprocess
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import firmware_protocol as fp
from firmware_protocol.can_framing import CanDecoder, encode_can, make_can_id
from firmware_protocol.serial_framing import MAX_ENCODED
from firmware_protocol.strategies import messages
from firmware_protocol.vectors import VECTORS_PATH

C_DIR = Path(fp.__file__).parent / "c"
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror", "-O2"]
C_CAN_TRANSFERS, C_CAN_STREAMS = 4, 32  # the C defaults (fwp_can.h)


@pytest.fixture(scope="session")
def tool(tmp_path_factory) -> Path:
    cc = shutil.which("cc")
    assert cc, "a C compiler (cc) is needed to test the C reference"
    out = tmp_path_factory.mktemp("fwp") / "fwp_tool"
    sources = [str(C_DIR / name) for name in ("fwp.c", "fwp_can.c", "fwp_tool.c")]
    subprocess.run([cc, *CFLAGS, *sources, "-o", str(out)], check=True, capture_output=True, timeout=120)
    return out


def run(tool: Path, args: list[str], stdin: str) -> tuple[list[dict], dict]:
    proc = subprocess.run([str(tool), *args], input=stdin, capture_output=True, text=True, timeout=60, check=True)
    lines = [json.loads(line) for line in proc.stdout.splitlines()]
    return lines[:-1], lines[-1]


def _symbols(obj: Path, option: str) -> set[str]:
    out = subprocess.run(["nm", option, str(obj)], capture_output=True, text=True, check=True).stdout
    return {line.split()[-1] for line in out.splitlines() if line.strip()}


def test_library_needs_only_the_c_standard_library_and_never_allocates(tmp_path):
    objects = []
    for name in ("fwp.c", "fwp_can.c"):
        objects.append(tmp_path / (name + ".o"))
        subprocess.run(["cc", *CFLAGS, "-c", str(C_DIR / name), "-o", str(objects[-1])], check=True, timeout=60)
    defined = set().union(*(_symbols(o, "--defined-only") for o in objects))
    needed = set().union(*(_symbols(o, "-u") for o in objects)) - defined
    assert needed <= {"memcpy", "memset", "memcmp", "strlen"}, needed  # <string.h> only: no malloc, no stdio


def test_constants_agree(tool):
    proc = subprocess.run([str(tool), "info"], capture_output=True, text=True, check=True, timeout=10)
    info = json.loads(proc.stdout)
    assert info["schema_hash"] == fp.SCHEMA_HASH
    assert info["version"] == fp.PROTOCOL_VERSION
    assert info["max_payload"] == fp.MAX_PAYLOAD and info["max_encoded"] == MAX_ENCODED
    assert info["crc_check"] == 0xCBF43926
    expected = {s.name: [s.msg_id, {"host": "h", "board": "b", "both": "*"}[s.direction], s.seed]
                for s in fp.schema.MESSAGES}
    assert info["seeds"] == expected


def test_vectors_decode_and_encode_identically_in_c(tool):
    for v in json.loads(VECTORS_PATH.read_text()):
        msg = fp.from_dict(v["message"])
        got, tail = run(tool, ["serial", "board" if v["from_board"] else "host"], v["serial"])
        assert [fp.from_dict(g["msg"]) for g in got] == [msg], v["name"]
        assert got[0]["frame"] == v["serial"] and got[0]["seq"] == v["seq"], v["name"]
        assert tail["delivered"] == 1 and not any(tail["errors"].values())
        lines = "".join(f"X {can_id:x} {data or '-'}\n" for can_id, data in v["can"])
        got, tail = run(tool, ["can", "node" if v["from_board"] else "host"], lines)
        assert [fp.from_dict(g["msg"]) for g in got] == [msg], v["name"]
        assert got[0]["frames"] == v["can"] and (got[0]["seq"], got[0]["node"]) == (v["can_tid"], v["can_node"])


def _direction(msg, i: int) -> bool:
    return msg.spec.direction == "board" or (msg.spec.direction == "both" and i % 2 == 1)


def _serial_frames(msgs: list) -> list[bytes]:
    """Each direction numbers its own frames."""
    seqs = [0, 0]
    frames = []
    for i, m in enumerate(msgs):
        from_board = _direction(m, i)
        frames.append(fp.encode(m, seqs[from_board], from_board))
        seqs[from_board] += 1
    return frames


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.lists(messages(), min_size=1, max_size=40))
def test_random_messages_cross_the_language_boundary_serial(tool, msgs):
    frames = _serial_frames(msgs)
    got, tail = run(tool, ["serial", "any"], b"".join(frames).hex())
    assert [fp.from_dict(g["msg"]) for g in got] == msgs
    assert [bytes.fromhex(g["frame"]) for g in got] == frames
    assert tail["delivered"] == len(msgs) and not any(tail["errors"].values())


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.lists(messages(), min_size=1, max_size=40), st.booleans())
def test_random_messages_cross_the_language_boundary_can(tool, msgs, from_node):
    msgs = [m for m in msgs if m.spec.direction in ("both", "board" if from_node else "host")]
    transfers = [encode_can(m, 1 + i % 127, i % 32, from_node) for i, m in enumerate(msgs)]
    lines = "".join(f"X {f.can_id:x} {f.data.hex() or '-'}\n" for t in transfers for f in t)
    got, tail = run(tool, ["can", "node" if from_node else "host"], lines)
    assert [fp.from_dict(g["msg"]) for g in got] == msgs
    assert [[[f.can_id, f.data.hex()] for f in t] for t in transfers] == [g["frames"] for g in got]
    assert tail["delivered"] == len(msgs)


def _corrupted_serial_stream(rng: random.Random, segments: int) -> bytes:
    out = bytearray()
    seq = 0
    pool = [m for _, m, *_ in fp.vectors.examples() if m.spec.direction != "host"]
    for _ in range(segments):
        seq = (seq + rng.choice((1, 1, 1, 2, 0, -1, 300, 40000))) & 0xFFFF
        frame = bytearray(fp.encode(rng.choice(pool), seq, True))
        fault = rng.randrange(8)
        if fault == 0:
            frame[rng.randrange(len(frame))] ^= 1 << rng.randrange(8)
        elif fault == 1:
            frame = frame[: rng.randrange(1, len(frame))]
        elif fault == 2:
            frame = bytearray(rng.randbytes(rng.randrange(1, 60))) + frame
        elif fault == 3:
            frame = frame + frame
        elif fault == 4:
            frame = bytearray(b"\x05" * rng.choice((1, MAX_ENCODED + 10))) + frame
        elif fault == 5:
            frame = bytearray(fp.encode(fp.Estop(), seq, False))  # wrong direction
        out += frame
    return bytes(out)


@pytest.mark.parametrize("seed", range(4))
def test_corrupted_serial_streams_give_identical_results(tool, seed):
    stream = _corrupted_serial_stream(random.Random(seed), 1500)
    dec = fp.StreamDecoder("board")
    py = dec.feed_frames(stream)
    got, tail = run(tool, ["serial", "board"], stream.hex())
    assert [(fp.from_dict(g["msg"]), g["seq"]) for g in got] == [(r.message, r.seq) for r in py]
    assert tail["delivered"] == dec.delivered
    assert {k: tail["errors"][k] for k in dec.errors} == dec.errors
    assert sum(dec.errors.values()) > 500  # the stream really was damaged


def _corrupted_can_frames(rng: random.Random, transfers: int) -> list[tuple[str, int, bytes]]:
    out = []
    tids = {}
    for _ in range(transfers):
        msg = rng.choice([fp.vectors.example_joint_state(rng.randrange(6)), fp.Heartbeat(rng.getrandbits(32), 1),
                          fp.Status(1, 0, 200, 3, 7, 12.0, 0), fp.vectors.example_joint_state(rng.randrange(30))])
        node = rng.randrange(1, 7)  # more streams than the C receiver's 4 transfer slots
        key = (msg.spec.msg_id, node)
        tids[key] = (tids.get(key, 0) + rng.choice((1, 1, 1, 0, 2, 20))) % 32
        frames = [("X", f.can_id, f.data) for f in encode_can(msg, node, tids[key], True)]
        fault = rng.randrange(9)
        k = rng.randrange(len(frames))
        if fault == 0:
            del frames[k]
        elif fault == 1:
            frames.insert(k, frames[k])
        elif fault == 2 and k + 1 < len(frames):
            frames[k], frames[k + 1] = frames[k + 1], frames[k]
        elif fault == 3 and frames[k][2]:
            kind, can_id, data = frames[k]
            frames[k] = (kind, can_id, bytes([data[0] ^ 0x10]) + data[1:])
        elif fault == 4:
            frames.insert(k, rng.choice([("S", 0x123, b"\x01"), ("R", 0x1FFFFFFF, b""), ("E", 0, b""),
                                         ("X", make_can_id(0x77, True, node, 0, True, 0), b"\x00")]))
        elif fault == 5:
            frames = frames[::2]  # interleaving with lost frames
        out += frames
    rng.shuffle(out[: len(out) // 10])  # a burst of disorder at the start
    return out


@pytest.mark.parametrize("seed", range(4))
def test_corrupted_can_streams_give_identical_results(tool, seed):
    frames = _corrupted_can_frames(random.Random(100 + seed), 600)
    dec = CanDecoder("node", max_transfers=C_CAN_TRANSFERS, max_streams=C_CAN_STREAMS)
    py = [r for kind, can_id, data in frames
          for r in dec.feed(can_id, data, is_extended=kind in "XR", is_error=kind == "E", is_remote=kind == "R")]
    lines = "".join(f"{kind} {can_id:x} {data.hex() or '-'}\n" for kind, can_id, data in frames)
    got, tail = run(tool, ["can", "node"], lines)
    assert [(fp.from_dict(g["msg"]), g["seq"], g["node"]) for g in got] == [(r.message, r.seq, r.node) for r in py]
    assert {k: tail["errors"][k] for k in dec.errors} == dec.errors
    assert dec.errors["bad_transfer"] > 50 and dec.errors["duplicate"] > 0


def _raw_frame(msg_id: int, payload: bytes, seq: int, from_board: bool) -> bytes:
    """A frame with a valid CRC around an arbitrary payload: only the payload checks can reject it."""
    from firmware_protocol.cobs import cobs_encode
    from firmware_protocol.serial_framing import HEADER, frame_crc

    body = HEADER.pack(fp.PROTOCOL_VERSION, int(from_board), msg_id, seq, len(payload)) + payload
    return cobs_encode(body + frame_crc(msg_id, body).to_bytes(4, "little")) + b"\0"


def test_payload_validation_agrees_on_random_payloads(tool):
    """12 000 payloads with valid CRCs (800 per message type): sizes near the right ones, random bytes
    (so bad enums and repeated ids), NaNs."""
    rng = random.Random(7)
    frames = []
    seqs = [0, 0]
    for _ in range(800):
        for spec in fp.schema.MESSAGES:
            from_board = spec.direction == "board"
            size = spec.fixed_size + (rng.randrange(4) * 5 if spec.group_max else 0) + rng.choice((0, 0, 0, -1, 1))
            payload = bytearray(rng.randbytes(max(size, 0)))
            if spec.group_max and len(payload) >= spec.fixed_size:
                payload[spec.fixed_size - 1] = rng.choice((0, 1, 2, 3, 40))
            if rng.random() < 0.2 and len(payload) >= 4:
                i = rng.randrange(len(payload) - 3)
                payload[i : i + 4] = b"\x00\x00\xc0\x7f"  # NaN somewhere
            frames.append(_raw_frame(spec.msg_id, bytes(payload), seqs[from_board], from_board))
            seqs[from_board] += 1
    stream = b"".join(frames)
    dec = fp.StreamDecoder("any")
    py = dec.feed_frames(stream)
    got, tail = run(tool, ["serial", "any"], stream.hex())
    assert [(fp.from_dict(g["msg"]), g["seq"]) for g in got] == [(r.message, r.seq) for r in py]
    assert {k: tail["errors"][k] for k in dec.errors} == dec.errors
    assert dec.errors["bad_value"] > 500 and dec.errors["bad_length"] > 500 and len(py) > 500
