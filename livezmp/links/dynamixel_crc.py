"""Dynamixel Protocol 2.0 CRC-16 (CRC-16/BUYPASS: poly 0x8005, init 0, no reflection; ROBOTIS e-manual).

Shared by the link (checking the Fast Sync Read reply it takes every cycle) and the
simulated servos (which sign their replies). Long packets are summed with numpy: the CRC
is linear, so a packet's CRC is the XOR of each byte's contribution at its distance from
the end, from one table made once.
"""

from __future__ import annotations

import functools

import numpy as np

MAX_PACKET = 1024  # bytes on the wire, as dynamixel-sdk's RXPACKET_MAX_LEN
_POLY = 0x8005


def _byte_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = (crc << 1) ^ _POLY if crc & 0x8000 else crc << 1
        table.append(crc & 0xFFFF)
    return tuple(table)


_TABLE = _byte_table()
# Below this length the table loop beats numpy's call overhead.
_VECTOR_MIN = 48


@functools.cache
def _shift_table() -> np.ndarray:
    """Row k, column v: the CRC register after byte v followed by k zero bytes, from zero."""
    table = np.empty((MAX_PACKET, 256), dtype=np.uint16)
    row = np.array(_TABLE, dtype=np.uint32)
    lookup = row.copy()
    table[0] = row
    for k in range(1, MAX_PACKET):
        row = ((row << 8) & 0xFFFF) ^ lookup[row >> 8]
        table[k] = row
    return table


_DESCENDING = np.arange(MAX_PACKET - 1, -1, -1)


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 of ``data`` continuing from register value ``crc`` (0 to start a packet)."""
    n = len(data)
    if n < _VECTOR_MIN or n > MAX_PACKET:
        table = _TABLE
        for byte in data:
            crc = ((crc << 8) & 0xFFFF) ^ table[(crc >> 8) ^ byte]
        return crc
    # The CRC is linear: XOR the contribution of each byte at its distance from the end,
    # and that of the starting register shifted through n bytes.
    shift = _shift_table()
    value = int(np.bitwise_xor.reduce(shift[_DESCENDING[-n:], np.frombuffer(data, dtype=np.uint8)]))
    if crc:
        value ^= int(shift[n - 1, crc >> 8]) ^ int(shift[n - 2, crc & 0xFF])
    return value


def crc16_after_itself(crc: int) -> int:
    """The register after its own two bytes (low byte first) are fed to it: ``crc16(bytes((crc & 0xFF,
    crc >> 8)), crc)`` in two table steps (a Fast Sync Read reply signs every device's segment so)."""
    lo, hi = crc & 0xFF, crc >> 8
    crc = ((crc << 8) & 0xFFFF) ^ _TABLE[hi ^ lo]
    return ((crc << 8) & 0xFFFF) ^ _TABLE[(crc >> 8) ^ hi]
