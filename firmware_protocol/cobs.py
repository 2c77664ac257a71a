"""Consistent Overhead Byte Stuffing (Cheshire & Baker, 1999) without the trailing delimiter.

The encoding holds no 0x00 byte, so 0x00 can delimit frames; it costs at most
one byte per 254 bytes of data, plus one. The encoder is the canonical one: a
final run of exactly 254 non-zero bytes is not followed by an empty block.
"""

from __future__ import annotations

from .errors import DecodeError


def max_encoded_size(n: int) -> int:
    """Worst-case encoded size, in bytes, of n data bytes."""
    return n + n // 254 + 1


def cobs_encode(data: bytes) -> bytes:
    """COBS-encode ``data`` (no 0x00 in the result, no delimiter appended)."""
    out = bytearray()
    chunks = data.split(b"\0")
    last = len(chunks) - 1
    for i, chunk in enumerate(chunks):
        start = 0
        while len(chunk) - start >= 254:
            out.append(0xFF)
            out += chunk[start : start + 254]
            start += 254
        if start < len(chunk) or i < last or start == 0:
            out.append(len(chunk) - start + 1)
            out += chunk[start:]
    return bytes(out)


def cobs_decode(encoded: bytes) -> bytes:
    """Decode one COBS block sequence (no delimiter); DecodeError(kind='bad_framing') if malformed."""
    n = len(encoded)
    if not n:
        return b""
    if b"\0" in encoded:
        raise DecodeError("0x00 inside a COBS frame", "bad_framing")
    out = bytearray(encoded)
    dropped = []  # code bytes after a full (0xFF) block stand for nothing
    i = 0
    while True:
        code = encoded[i]
        j = i + code
        if j >= n:
            break
        # Each later code byte sits where the data had a zero: overwrite it in place.
        if code == 0xFF:
            dropped.append(j)
        else:
            out[j] = 0
        i = j
    if j > n:
        raise DecodeError("COBS block runs past the end of the frame", "bad_framing")
    for j in reversed(dropped):
        del out[j]
    del out[:1]
    return bytes(out)
