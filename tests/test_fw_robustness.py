"""Decoders under abuse: random bytes, truncation, bit flips, duplicates, reordering, endless input.

Every test is seeded, so the counts of inputs below are exact and repeatable:
serial random streams 400 (about 0.6 MB), truncations 1 200, bit-flip /
byte-substitution frames 6 000, duplicate / reorder streams 400; CAN random
frames 20 000, transfers with lost / repeated / swapped / altered frames 3 000.
"""

from __future__ import annotations

import random
import struct

import pytest

import firmware_protocol as fp
from firmware_protocol.can_framing import CanDecoder, encode_can, make_can_id
from firmware_protocol.serial_framing import MAX_ENCODED
from firmware_protocol.vectors import examples

ERRORS_NOT_LOSS = ("seq_gap", "seq_restart")


def _random_f32(rng: random.Random) -> float:
    return struct.unpack("<f", struct.pack("<f", rng.uniform(-4, 4)))[0]


def _board_messages(rng: random.Random, n: int) -> list:
    """Board -> host messages: the vectors' ones and random JOINT_STATEs of 0..32 joints. No HELLO_ACK:
    it restarts sequence tracking on purpose (tested on its own)."""
    pool = [m for _, m, *_ in examples() if m.spec.direction in ("board", "both") and m.spec.name != "HELLO_ACK"]
    return [rng.choice(pool) if rng.random() < 0.5 else _joint_state(rng, rng.randrange(33)) for _ in range(n)]


def _joint_state(rng: random.Random, k: int) -> fp.JointState:
    ids = tuple(rng.sample(range(256), k))

    def column() -> tuple[float, ...]:
        return tuple(_random_f32(rng) for _ in ids)

    errors = tuple(rng.getrandbits(16) for _ in ids)
    return fp.JointState(rng.getrandbits(32), ids, column(), column(), column(), errors)


def _frames(msgs: list, first_seq: int = 0) -> list[bytes]:
    return [fp.encode(m, (first_seq + i) & 0xFFFF, True) for i, m in enumerate(msgs)]


def _feed_chunked(dec: fp.StreamDecoder, data: bytes, rng: random.Random) -> list[fp.Received]:
    out = []
    i = 0
    while i < len(data):
        n = rng.choice((1, 7, 64, 1500))
        out += dec.feed_frames(data[i : i + n])
        assert dec.buffered <= MAX_ENCODED
        i += n
    return out


def _garbage(rng: random.Random, n: int) -> bytes:
    data = bytearray(rng.randbytes(n))
    for _ in range(rng.randrange(0, 4)):  # runs of zeros are common on a noisy line
        i = rng.randrange(n) if n else 0
        data[i : i + 3] = b"\0\0\0"
    return bytes(data)


def test_random_bytes_deliver_nothing_and_resync_within_one_frame():
    rng = random.Random(1)
    for _ in range(400):
        dec = fp.StreamDecoder("board")
        junk = _garbage(rng, rng.randrange(0, 3000))
        assert _feed_chunked(dec, junk, rng) == []
        msgs = _board_messages(rng, 5)
        got = _feed_chunked(dec, b"".join(_frames(msgs, 100)), rng)
        # The garbage's tail may swallow the first frame, never more.
        assert [r.message for r in got] in (msgs, msgs[1:])


def test_truncated_frames_are_counted_never_delivered():
    rng = random.Random(2)
    for _ in range(1200):
        msgs = _board_messages(rng, 3)
        f0, f1, f2 = _frames(msgs)
        cut = rng.randrange(1, len(f1) - 1)
        dec = fp.StreamDecoder("board")
        # A sender reset mid-frame: it reopens with a delimiter, so only the cut frame is lost.
        got = dec.feed_frames(f0 + f1[:cut] + b"\0" + f2)
        assert [r.message for r in got] == [msgs[0], msgs[2]]
        assert sum(v for k, v in dec.errors.items() if k not in ERRORS_NOT_LOSS) == 1
        # Without the delimiter the cut frame swallows the next one: still at most one frame more.
        dec = fp.StreamDecoder("board")
        got = dec.feed_frames(f0 + f1[:cut] + f2 + f0)
        assert [r.message for r in got][:1] == [msgs[0]] and len(got) <= 2
        assert sum(v for k, v in dec.errors.items() if k not in ERRORS_NOT_LOSS) >= 1


@pytest.mark.parametrize("mode", ["bit_flips", "byte_substitution"])
def test_corrupted_frames_are_counted_and_none_delivered(mode):
    rng = random.Random(3 if mode == "bit_flips" else 4)
    for _ in range(3000):
        msgs = _board_messages(rng, 3)
        frames = _frames(msgs, rng.randrange(65536))
        bad = bytearray(frames[1])
        if mode == "bit_flips":
            for _ in range(rng.randint(1, 3)):
                bad[rng.randrange(len(bad))] ^= 1 << rng.randrange(8)
        else:
            i = rng.randrange(len(bad))
            bad[i] = (bad[i] + rng.randrange(1, 256)) % 256
        if bytes(bad) == frames[1]:
            continue  # two flips of the same bit
        dec = fp.StreamDecoder("board")
        got = dec.feed_frames(frames[0] + bytes(bad) + frames[2])
        losses = sum(v for k, v in dec.errors.items() if k not in ERRORS_NOT_LOSS)
        assert losses >= 1
        delivered = [r.message for r in got]
        if bad[-1] == 0:
            assert delivered == [msgs[0], msgs[2]]
        else:  # the delimiter itself was hit: the corrupted frame swallows its neighbour
            assert delivered == [msgs[0]]


def test_duplicated_and_reordered_frames_are_counted_and_dropped():
    rng = random.Random(5)
    for _ in range(400):
        msgs = _board_messages(rng, 12)
        frames = _frames(msgs, rng.randrange(65536))
        order = list(range(12))
        dups = swaps = 0
        for _ in range(3):
            i = rng.randrange(1, len(order) - 1)
            if rng.random() < 0.5:
                order.insert(i, order[i])  # a repeated frame
                dups += 1
            else:
                order[i], order[i + 1] = order[i + 1], order[i]  # two frames swapped
                swaps += 1
        dec = fp.StreamDecoder("board")
        got = dec.feed_frames(b"".join(frames[k] for k in order))
        seqs = [r.seq for r in got]
        assert all((b - a) % 65536 < 32768 and b != a for a, b in zip(seqs, seqs[1:], strict=False))
        expected = []  # what a receiver that drops every repeat and every late frame keeps
        for k in order:
            if not expected or k > expected[-1]:
                expected.append(k)
        assert [r.message for r in got] == [msgs[k] for k in expected]
        assert dec.errors["duplicate"] + dec.errors["stale"] == len(order) - len(expected)
        assert dec.errors["duplicate"] + dec.errors["stale"] >= (1 if dups or swaps else 0)


def test_endless_input_without_delimiter_keeps_memory_bounded():
    dec = fp.StreamDecoder("board")
    block = bytes(range(1, 256)) * 16
    for _ in range(256):  # 1 MB with no delimiter
        assert dec.feed(block) == []
        assert dec.buffered <= MAX_ENCODED
    assert dec.errors["oversize"] == 1
    msg = fp.Heartbeat(5, fp.BoardState.ACTIVE)
    assert dec.feed(b"\0" + fp.encode(msg, 0, True)) == [msg]


def test_oversize_frame_between_good_frames_costs_only_itself():
    msg = fp.Heartbeat(5, fp.BoardState.ACTIVE)
    dec = fp.StreamDecoder("board")
    got = dec.feed(fp.encode(msg, 0, True) + b"\x01" * (MAX_ENCODED + 1) + b"\0" + fp.encode(msg, 1, True))
    assert got == [msg, msg] and dec.errors["oversize"] == 1


def test_echoed_own_frames_are_not_delivered():
    dec = fp.StreamDecoder("board")
    assert dec.feed(fp.encode(fp.Heartbeat(1, fp.BoardState.ACTIVE), 0, from_board=False)) == []
    assert dec.errors["wrong_direction"] == 1


def test_sequence_restart_and_hello_resync():
    dec = fp.StreamDecoder("board")
    beat = fp.Heartbeat(1, fp.BoardState.ACTIVE)
    ack = fp.HelloAck(fp.SCHEMA_HASH, 1, 1, 0, (), ())
    assert len(dec.feed(fp.encode(beat, 40000, True) + fp.encode(beat, 40003, True))) == 2
    assert dec.errors["seq_gap"] == 2
    # A rebooted board that starts again at 0 after HELLO_ACK is accepted without complaint...
    assert len(dec.feed(fp.encode(ack, 0, True) + fp.encode(beat, 1, True))) == 2
    # ...and one far behind without HELLO_ACK counts as a restart, not as lost or stale.
    assert len(dec.feed(fp.encode(beat, 40000, True))) == 1
    assert dec.errors["seq_restart"] == 1 and dec.errors["stale"] == 0


# ---- CAN --------------------------------------------------------------------------------------


def test_can_random_frames_never_raise_and_state_stays_bounded():
    rng = random.Random(6)
    dec = CanDecoder("node", max_transfers=4, max_streams=16)
    for _ in range(20000):
        msg_id = rng.choice([0x09, 0x0A, 0x1A, 0x21, 0x1B, rng.randrange(256)])
        can_id = make_can_id(msg_id, rng.random() < 0.95, rng.randrange(128), rng.randrange(32),
                             rng.random() < 0.3, rng.choice([0, 0, 1, 2, rng.randrange(128)]))
        kind = rng.random()
        for r in dec.feed(can_id, rng.randbytes(rng.randrange(9)), is_extended=kind > 0.02,
                          is_error=kind < 0.01, is_remote=0.02 < kind < 0.03):
            assert isinstance(r.message, tuple(fp.messages.MESSAGE_CLASSES.values()))
        n_transfers, n_streams = dec.held
        assert n_transfers <= 4 and n_streams <= 16
    assert dec.errors["foreign"] > 0 and dec.errors["error_frame"] > 0 and dec.errors["bad_transfer"] > 0


@pytest.mark.parametrize("fault", ["lost", "repeated", "swapped", "altered"])
def test_can_transfer_faults_never_deliver_a_wrong_message(fault):
    rng = random.Random(hash(fault) & 0xFFFF)
    for trial in range(750):
        # Two transfers of the same stream: a transfer that lost its last frame is known to be lost when the
        # next one starts.
        msgs = [_joint_state(rng, rng.randint(1, 32)) for _ in range(2)]
        tid = trial % 32
        frames = [f for i, m in enumerate(msgs) for f in encode_can(m, 7, (tid + i) % 32, True)]
        first = encode_can(msgs[0], 7, tid, True)
        k = rng.randrange(len(first))  # the fault hits the first transfer
        data = [(f.can_id, f.data) for f in frames]
        if fault == "lost":
            del data[k]
        elif fault == "repeated":
            data.insert(k, data[k])
        elif fault == "swapped" and len(first) > 1:
            k = min(k, len(first) - 2)
            data[k], data[k + 1] = data[k + 1], data[k]
        elif fault == "altered":
            can_id, payload = data[k]
            if not payload:
                continue
            j = rng.randrange(len(payload))
            data[k] = (can_id, payload[:j] + bytes([payload[j] ^ (1 << rng.randrange(8))]) + payload[j + 1 :])
        dec = CanDecoder("node")
        got = [r.message for can_id, payload in data for r in dec.feed(can_id, payload)]
        if fault == "repeated":
            assert got == msgs and dec.errors["duplicate"] == 1
        elif fault == "swapped" and len(first) == 1:
            assert got == msgs
        else:
            assert got == msgs[1:], (fault, k, dec.errors)
            assert sum(dec.errors.values()) - dec.errors["seq_gap"] >= 1
