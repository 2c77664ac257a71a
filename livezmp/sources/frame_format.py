"""The livezmp frame format for streamed poses: JSON and a compact binary form.

Both carry a sequence number (uint32, +1 per frame, wrapping), the frame time ``t``
(s, sender clock, strictly increasing), the channel values in the body's channel
order and input units, and optionally the two foot contacts. The full specification,
with examples, is ``docs/frame_format.md``. Decoding checks size and schema strictly
and raises :class:`FrameError` naming the field; a receiver counts and drops such packets.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass

import numpy as np

from livezmp.checks import MAX_CHANNEL_VALUE, first_out_of_range
from livezmp.errors import InputError

MAGIC = b"LZF1"
HEADER = struct.Struct("<4sBBHId")  # magic, flags, reserved, channel count, seq, t
FLAG_CONTACTS, FLAG_LEFT, FLAG_RIGHT = 0x01, 0x02, 0x04
SEQ_MOD = 1 << 32
JSON_KEYS = {"v", "seq", "t", "channels", "contacts"}
# A frame is one object holding at most two arrays: deeper nesting is refused before parsing
# (the JSON parser recurses), and integers longer than uint32 before they are converted.
MAX_BRACKETS, MAX_BRACES, MAX_INT_DIGITS = 2, 1, 10
MAX_TIME_S = 1e9  # sender clock, s (31 years): larger times lose the precision of a frame period
NUMBER_TYPES = {int, float}


class FrameError(InputError):
    """A packet that is not a valid frame; ``kind`` is "malformed" or "oversized"."""

    def __init__(self, kind: str, message: str):
        super().__init__(message)
        self.kind = kind


@dataclass(frozen=True)
class WireFrame:
    """A decoded frame: ``seq`` uint32, ``t`` s, ``channels`` (n,), ``contacts`` or None."""

    seq: int
    t: float
    channels: np.ndarray
    contacts: tuple[bool, bool] | None = None


def max_packet_bytes(n_channels: int) -> int:
    """Default size limit: room for a JSON frame with every value at full precision."""
    return 256 + 32 * n_channels


def encode_json(frame: WireFrame) -> bytes:
    doc = {"v": 1, "seq": frame.seq, "t": frame.t, "channels": frame.channels.tolist()}
    if frame.contacts is not None:
        doc["contacts"] = [bool(frame.contacts[0]), bool(frame.contacts[1])]
    return json.dumps(doc, separators=(",", ":")).encode()


def encode_binary(frame: WireFrame) -> bytes:
    """Little-endian header then float32 channels (about 7 significant digits)."""
    flags = 0
    if frame.contacts is not None:
        flags = FLAG_CONTACTS | (FLAG_LEFT if frame.contacts[0] else 0) | (FLAG_RIGHT if frame.contacts[1] else 0)
    n = len(frame.channels)
    head = HEADER.pack(MAGIC, flags, 0, n, frame.seq % SEQ_MOD, frame.t)
    return head + np.asarray(frame.channels, dtype="<f4").tobytes()


def _check_values(channels: np.ndarray, n_channels: int) -> None:
    if len(channels) != n_channels:
        raise FrameError("malformed", f"field channels: {len(channels)} values, the body has {n_channels}")
    bad = first_out_of_range(channels, MAX_CHANNEL_VALUE)
    if bad is not None:
        raise FrameError("malformed", f"field channels[{bad[0]}]: not finite or beyond ±{MAX_CHANNEL_VALUE:g}")


def _check_time(t: float) -> None:
    if not (math.isfinite(t) and abs(t) <= MAX_TIME_S):
        raise FrameError("malformed", f"field t: need a finite number within ±{MAX_TIME_S:g} s")


def _json_int(text: str) -> int:
    if len(text.lstrip("-")) > MAX_INT_DIGITS:
        raise FrameError("malformed", f"JSON frame: integer of {len(text)} digits")
    return int(text)


def _decode_binary(data: bytes, n_channels: int) -> WireFrame:
    if len(data) < HEADER.size:
        raise FrameError("malformed", f"binary frame: {len(data)} bytes, header needs {HEADER.size}")
    _, flags, reserved, n, seq, t = HEADER.unpack_from(data)
    if flags & ~(FLAG_CONTACTS | FLAG_LEFT | FLAG_RIGHT) or reserved:
        raise FrameError("malformed", f"binary frame: unknown flags 0x{flags:02x} / reserved byte {reserved}")
    if len(data) != HEADER.size + 4 * n:
        raise FrameError("malformed", f"binary frame: {len(data)} bytes, {n} channels need {HEADER.size + 4 * n}")
    _check_time(t)
    channels = np.frombuffer(data, dtype="<f4", offset=HEADER.size).astype(float)
    _check_values(channels, n_channels)
    contacts = (bool(flags & FLAG_LEFT), bool(flags & FLAG_RIGHT)) if flags & FLAG_CONTACTS else None
    return WireFrame(seq, t, channels, contacts)


def _decode_json(data: bytes, n_channels: int) -> WireFrame:
    if data.count(b"[") > MAX_BRACKETS or data.count(b"{") > MAX_BRACES:
        raise FrameError("malformed", "JSON frame: nested deeper than a frame")
    try:
        doc = json.loads(data, parse_int=_json_int)
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise FrameError("malformed", f"JSON frame: {e}") from None
    if not isinstance(doc, dict):
        raise FrameError("malformed", "JSON frame: not an object")
    extra = set(doc) - JSON_KEYS
    if extra:
        raise FrameError("malformed", f"JSON frame: unknown field {sorted(extra)[0]!r}")
    if doc.get("v", 1) != 1:
        raise FrameError("malformed", f"field v: version {doc['v']!r} not supported (1)")
    seq = doc.get("seq")
    if type(seq) is not int or not 0 <= seq < SEQ_MOD:
        raise FrameError("malformed", "field seq: need an integer 0 .. 2^32-1")
    t = doc.get("t")
    if type(t) not in (int, float):
        raise FrameError("malformed", "field t: need a finite number (s)")
    _check_time(t)
    values = doc.get("channels")
    if not isinstance(values, list) or not set(map(type, values)) <= NUMBER_TYPES:  # bool is not a number here
        raise FrameError("malformed", "field channels: need an array of numbers")
    channels = np.array(values, dtype=float)
    _check_values(channels, n_channels)
    contacts = doc.get("contacts")
    if contacts is not None:
        if not isinstance(contacts, list) or len(contacts) != 2 or not all(type(c) is bool for c in contacts):
            raise FrameError("malformed", "field contacts: need [left, right] booleans")
        contacts = (contacts[0], contacts[1])
    return WireFrame(seq, float(t), channels, contacts)


def decode_frame(data: bytes, n_channels: int, max_bytes: int | None = None) -> WireFrame:
    """Decode one packet (binary if it starts with ``LZF1``, else JSON) for a body of
    ``n_channels`` channels. Raises :class:`FrameError`."""
    limit = max_packet_bytes(n_channels) if max_bytes is None else max_bytes
    if len(data) > limit:
        raise FrameError("oversized", f"packet of {len(data)} bytes exceeds the {limit}-byte limit")
    if data[:4] == MAGIC:
        return _decode_binary(data, n_channels)
    return _decode_json(data, n_channels)
