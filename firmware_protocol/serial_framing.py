"""Serial framing: header + payload + CRC-32, COBS-stuffed, 0x00-delimited (SPEC.md, "Serial framing").

Frame before stuffing (little-endian):

    version u8 | flags u8 | msg_id u8 | seq u16 | length u16 | payload | crc u32

``crc`` is CRC-32 (ISO-HDLC, as zlib.crc32) over header, payload and the
message's 4-byte schema seed. ``StreamDecoder`` takes bytes in any chunking,
returns the messages of every valid frame and counts every rejected one by kind.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

from .cobs import cobs_decode, cobs_encode, max_encoded_size
from .errors import DecodeError, ProtocolError
from .messages import Message
from .payload import decode_payload, encode_payload
from .schema import BY_ID, MAX_PAYLOAD, PROTOCOL_VERSION
from .sequence import SequenceTracker

FLAG_FROM_BOARD = 0x01
HEADER = struct.Struct("<BBBHH")
CRC_SIZE = 4
MIN_FRAME = HEADER.size + CRC_SIZE
MAX_FRAME = HEADER.size + MAX_PAYLOAD + CRC_SIZE
MAX_ENCODED = max_encoded_size(MAX_FRAME)  # COBS bytes of the largest frame, without the delimiter
SEQ_BITS = 16
SEQ_BEHIND = 256  # a frame up to this far behind the last one is a stale reordering, not a restart
SYNC_SESSION = frozenset({"HELLO", "HELLO_ACK"})  # these reset the receiver's sequence tracking

ERROR_KINDS = (
    "oversize", "bad_framing", "bad_length", "bad_header", "unknown_id", "bad_crc", "bad_value",
    "wrong_direction", "duplicate", "stale", "seq_gap", "seq_restart",
)
_SEED_BYTES = {msg_id: spec.seed.to_bytes(4, "little") for msg_id, spec in BY_ID.items()}
_CRC = struct.Struct("<I")
_SENDER_FLAGS = {"host": (0,), "board": (FLAG_FROM_BOARD,), "both": (0, FLAG_FROM_BOARD), "any": (0, FLAG_FROM_BOARD)}
_SYNC_IDS = frozenset(spec.msg_id for spec in BY_ID.values() if spec.name in SYNC_SESSION)


@dataclass(frozen=True, slots=True)
class Received:
    """A delivered message with its envelope: sequence number (serial frame seq or CAN transfer id) and
    CAN node id (the sender's, or for host frames the addressee's, 0 = broadcast; None on serial)."""

    message: Message
    seq: int
    node: int | None = None


def frame_crc(msg_id: int, body: bytes) -> int:
    """CRC-32 of header + payload followed by the message's schema seed (little-endian u32)."""
    return zlib.crc32(_SEED_BYTES[msg_id], zlib.crc32(body))


def encode(msg: Message, seq: int = 0, from_board: bool = False) -> bytes:
    """One complete serial frame for ``msg``: COBS bytes plus the 0x00 delimiter.

    ``seq`` is the sender's frame counter (0..65535) for this direction;
    ``from_board`` sets the direction flag. ProtocolError on a bad value or
    a message sent in the wrong direction.
    """
    spec = msg.spec
    if spec.direction != "both" and (spec.direction == "board") != from_board:
        raise ProtocolError(f"{spec.name} is sent by the {spec.direction} only")
    if not 0 <= seq <= 0xFFFF:
        raise ProtocolError(f"frame seq {seq} is not in 0..65535")
    payload = encode_payload(msg)
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(f"{spec.name}: payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    body = HEADER.pack(PROTOCOL_VERSION, FLAG_FROM_BOARD if from_board else 0, spec.msg_id, seq, len(payload))
    body += payload
    return cobs_encode(body + frame_crc(spec.msg_id, body).to_bytes(4, "little")) + b"\0"


class StreamDecoder:
    """Incremental decoder of a serial byte stream.

    ``accept`` is the direction delivered: "board" (frames the board sent, for a
    host), "host" (for a board) or "any". The input buffer never exceeds
    MAX_ENCODED bytes; a longer run without a delimiter is dropped as
    ``oversize`` and decoding resumes at the next 0x00. ``errors`` counts every
    rejected frame by kind (plus ``seq_gap``: frames lost, ``seq_restart``:
    peer restarts); ``delivered`` counts messages returned.
    """

    def __init__(self, accept: str = "any"):
        if accept not in ("board", "host", "any"):
            raise ProtocolError(f"accept must be 'board', 'host' or 'any', not {accept!r}")
        self.accept = accept
        self.errors = dict.fromkeys(ERROR_KINDS, 0)
        self.delivered = 0
        self._buf = bytearray()
        self._skipping = False  # inside an oversize run: drop until the next delimiter
        self._trackers = (SequenceTracker(SEQ_BITS, SEQ_BEHIND), SequenceTracker(SEQ_BITS, SEQ_BEHIND))

    @property
    def buffered(self) -> int:
        """Bytes of an incomplete frame held (never more than MAX_ENCODED)."""
        return len(self._buf)

    def feed(self, data: bytes) -> list[Message]:
        """Messages completed by ``data``, in order."""
        return [r.message for r in self.feed_frames(data)]

    def feed_frames(self, data: bytes) -> list[Received]:
        """Like ``feed`` but with each message's envelope."""
        out: list[Received] = []
        if b"\0" not in data:
            self._append(data)
            return out
        parts = data.split(b"\0")
        if self._skipping:
            self._skipping = False
        else:
            first = parts[0]
            if len(self._buf) + len(first) > MAX_ENCODED:
                self.errors["oversize"] += 1
            else:
                self._frame(bytes(self._buf) + first, out)
        self._buf.clear()
        for part in parts[1:-1]:
            self._frame(part, out)
        self._append(parts[-1])
        return out

    def _append(self, data: bytes) -> None:
        if self._skipping:
            return
        if len(self._buf) + len(data) > MAX_ENCODED:
            self.errors["oversize"] += 1
            self._buf.clear()
            self._skipping = True
        else:
            self._buf += data

    def _frame(self, encoded: bytes, out: list[Received]) -> None:
        if not encoded:
            return  # back-to-back delimiters: idle fill
        if len(encoded) > MAX_ENCODED:
            self.errors["oversize"] += 1
            return
        try:
            received = self._parse(encoded)
        except DecodeError as err:
            self.errors[err.kind] += 1
            return
        if received is not None:
            self.delivered += 1
            out.append(received)

    def _parse(self, encoded: bytes) -> Received | None:
        raw = cobs_decode(encoded)
        n = len(raw)
        if n < MIN_FRAME:
            raise DecodeError("frame shorter than header + CRC", "bad_length")
        version, flags, msg_id, seq, length = HEADER.unpack_from(raw)
        if version != PROTOCOL_VERSION:
            raise DecodeError(f"protocol version {version}", "bad_header")
        spec = BY_ID.get(msg_id)
        if spec is None:
            raise DecodeError(f"message id {msg_id:#04x}", "unknown_id")
        if zlib.crc32(_SEED_BYTES[msg_id], zlib.crc32(raw[:-CRC_SIZE])) != _CRC.unpack_from(raw, n - CRC_SIZE)[0]:
            raise DecodeError("CRC mismatch", "bad_crc")
        if flags > FLAG_FROM_BOARD:
            raise DecodeError(f"reserved flag bits {flags:#04x}", "bad_header")
        if length != n - MIN_FRAME:
            raise DecodeError("length field disagrees with the frame", "bad_length")
        if flags not in _SENDER_FLAGS[spec.direction]:
            raise DecodeError(f"{spec.name} in the wrong direction", "bad_header")
        if flags not in _SENDER_FLAGS[self.accept]:
            raise DecodeError("frame from our own side (echo?)", "wrong_direction")
        msg = decode_payload(spec, raw[HEADER.size : -CRC_SIZE])
        tracker = self._trackers[flags]
        if msg_id in _SYNC_IDS:
            tracker.reset()
        verdict, lost = tracker.classify(seq)
        if verdict == "new":
            if lost:
                self.errors["seq_gap"] += lost
        elif verdict == "restart":
            self.errors["seq_restart"] += 1
        else:
            self.errors[verdict] += 1  # duplicate or stale: dropped
            return None
        return Received(msg, seq)
