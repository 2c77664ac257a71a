"""Dynamixel Protocol 2.0 packet codec: CRC-16, byte stuffing, framing.

Packet layout (ROBOTIS e-manual, Protocol 2.0)::

    FF FF FD 00 | ID | LEN_L LEN_H | INST | PARAMS... | CRC_L CRC_H

LEN counts INST, PARAMS and CRC. Status packets use INST 0x55 and start their
parameters with the error byte. Transmitters stuff ``FF FF FD`` into
``FF FF FD FD`` from INST up to the end of the parameters; the CRC
(CRC-16/BUYPASS: poly 0x8005, init 0, no reflection) covers the stuffed packet
from the header on. Fast Sync/Bulk Read replies are not stuffed and carry one
running CRC per device segment.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from livezmp.links.dynamixel_crc import MAX_PACKET, crc16, crc16_after_itself

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
STATUS = 0x55
ALERT = 0x80
_PATTERN = b"\xff\xff\xfd"
_STUFFED = b"\xff\xff\xfd\xfd"


class Instruction(enum.IntEnum):
    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REG_WRITE = 0x04
    ACTION = 0x05
    FACTORY_RESET = 0x06
    REBOOT = 0x08
    CLEAR = 0x10
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A
    BULK_READ = 0x92
    BULK_WRITE = 0x93
    FAST_BULK_READ = 0x9A


class ErrorCode(enum.IntEnum):
    """Error numbers of a status packet's error byte (bits 0-6; bit 7 is `ALERT`)."""

    NONE = 0
    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


def stuff(body: bytes) -> bytes:
    """Byte-stuff a packet body (INST and parameters): FF FF FD -> FF FF FD FD."""
    return body.replace(_PATTERN, _STUFFED) if _PATTERN in body else body


def unstuff(body: bytes) -> bytes:
    """Undo `stuff`."""
    return body.replace(_STUFFED, _PATTERN) if _STUFFED in body else body


def encode_packet(packet_id: int, instruction: int, params: bytes = b"") -> bytes:
    """A complete stuffed packet with length and CRC."""
    body = stuff(bytes((instruction,)) + params)
    length = len(body) + 2
    packet = HEADER + bytes((packet_id, length & 0xFF, length >> 8)) + body
    crc = crc16(packet)
    return packet + bytes((crc & 0xFF, crc >> 8))


def encode_status(packet_id: int, error: int, params: bytes = b"") -> bytes:
    """A status packet from ``packet_id`` with error byte ``error``."""
    return encode_packet(packet_id, STATUS, bytes((error,)) + params)


def encode_fast_status(segments: Iterable[tuple[int, int, bytes]]) -> bytes:
    """The single reply to Fast Sync/Bulk Read from ``(error, id, data)`` segments, in order.

    Each device appends error, id, data and the running CRC of everything sent so
    far; the last segment's CRC is the packet CRC. No byte stuffing.
    """
    segments = list(segments)
    length = 1 + sum(4 + len(data) for _, _, data in segments)
    out = bytearray(HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, STATUS)))
    crc = crc16(out)
    for error, dxl_id, data in segments:
        segment = bytes((error, dxl_id)) + data
        crc = crc16(segment, crc)
        tail = bytes((crc & 0xFF, crc >> 8))
        crc = crc16_after_itself(crc)
        out += segment
        out += tail
    return bytes(out)


class FastStatus:
    """`encode_fast_status` of servos ``ids`` (in order) reading ``length`` bytes each, laid out once: a
    chain's answer to the Fast Sync Read a control loop sends every cycle. The errors and data go into
    a numpy record view over the packet, then one CRC call a segment signs it (where building each
    segment took a dozen Python operations a servo)."""

    def __init__(self, ids: bytes, length: int) -> None:
        step = length + 4  # error, id, data, CRC
        size = 1 + len(ids) * step
        self._buffer = bytearray(HEADER + bytes((BROADCAST_ID, size & 0xFF, size >> 8, STATUS)) + bytes(size - 1))
        self._records = np.frombuffer(self._buffer, dtype=[("error", "u1"), ("id", "u1"), ("data", "u1", (length,)),
                                                           ("crc", "<u2")], offset=8)
        self._records["id"] = np.frombuffer(ids, dtype=np.uint8)
        self._view = memoryview(self._buffer)
        self._crc_at = [8 + k * step + 2 + length for k in range(len(ids))]  # where each segment's CRC goes

    def encode(self, errors: np.ndarray, data: np.ndarray) -> bytes:
        """The reply: each servo's error byte ``errors`` (n,) and ``data`` (n, length) uint8."""
        self._records["error"] = errors
        self._records["data"] = data
        buffer, view = self._buffer, self._view
        crc, start = 0, 0
        for at in self._crc_at:  # the running CRC of every byte before it, the segments' CRCs included
            crc = crc16(view[start:at], crc)
            buffer[at] = crc & 0xFF
            buffer[at + 1] = crc >> 8
            start = at
        return bytes(buffer)


class Packet(NamedTuple):
    """One received packet: parameters are un-stuffed; ``size`` is its length on the wire. (A named tuple: made
    for each packet a bus carries, 2 µs where a frozen dataclass took 6 on a loaded machine.)"""

    id: int
    instruction: int
    params: bytes
    crc_ok: bool
    size: int


class PacketReader:
    """Split a byte stream into packets; bounded buffer, resynchronises on garbage.

    A partial packet older than ``inter_byte_timeout`` seconds when more bytes
    arrive is discarded, as a servo does after 1.5 ms of silence mid-packet.
    """

    def __init__(self, inter_byte_timeout: float = 1.5e-3) -> None:
        self._buffer = bytearray()
        self._last = 0.0
        self._timeout = inter_byte_timeout

    def clear(self) -> None:
        self._buffer.clear()

    def feed(self, data: bytes, now: float) -> list[Packet]:
        """Add bytes received at ``now`` (s); return the packets they complete."""
        buffer = self._buffer
        if buffer and now - self._last > self._timeout:
            buffer.clear()
        self._last = now
        buffer += data
        packets = []
        while True:
            start = buffer.find(HEADER)
            if start < 0:
                del buffer[:-3]  # keep what may be the start of a header
                return packets
            if start:
                del buffer[:start]
            if len(buffer) < 7:
                return packets
            length = buffer[5] | buffer[6] << 8
            if length < 3 or length > MAX_PACKET - 7:
                del buffer[:4]  # not a packet: look for the next header
                continue
            end = 7 + length
            if len(buffer) < end:
                return packets
            raw = bytes(buffer[:end])
            del buffer[:end]
            crc_ok = crc16(memoryview(raw)[:-2]) == raw[-2] | raw[-1] << 8
            body = unstuff(raw[7:-2]) if crc_ok else raw[7:-2]
            packets.append(Packet(raw[4], body[0], body[1:], crc_ok, end))
