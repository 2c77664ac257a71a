"""Dynamixel Protocol 2.0 CRC-16 (CRC-16/BUYPASS: poly 0x8005, init 0, no reflection; ROBOTIS e-manual).

Shared by the link (checking the Fast Sync Read reply it takes every cycle, signing its goals)
and the simulated servos (which check every instruction and sign their replies). With crcmod's
C extension a packet's CRC is one C call (0.7 us for an 86-byte reply, where the numpy sum below
takes 6.7 and the table loop 13; four a cycle on each side of a bus). Without it, long packets
are summed with numpy: the CRC is linear, so a packet's CRC is the XOR of each byte's
contribution at its distance from the end, from one table made once.
"""

from __future__ import annotations

import functools

import numpy as np

try:
    import crcmod
    import crcmod._crcfunext  # noqa: F401  (crcmod without its C extension is a Python table loop)
except ImportError:
    crcmod = None

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


def _crc16_python(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 of ``data`` continuing from register value ``crc`` (0 to start a packet), without crcmod."""
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


# crc16(data, crc=0): the CRC-16 of ``data`` continuing from register value ``crc`` (0 to start a packet)
crc16 = _crc16_python if crcmod is None else crcmod.mkCrcFun(0x10000 | _POLY, initCrc=0, rev=False, xorOut=0)


def crc16_after_itself(crc: int) -> int:
    """The register after its own two bytes (low byte first) are fed to it: ``crc16(bytes((crc & 0xFF,
    crc >> 8)), crc)`` in two table steps (a Fast Sync Read reply signs every device's segment so)."""
    lo, hi = crc & 0xFF, crc >> 8
    crc = ((crc << 8) & 0xFFFF) ^ _TABLE[hi ^ lo]
    return ((crc << 8) & 0xFFFF) ^ _TABLE[(crc >> 8) ^ hi]
