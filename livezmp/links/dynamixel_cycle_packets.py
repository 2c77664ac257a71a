"""The two packets of every loop cycle on a Dynamixel bus, laid out once: the goals' Sync Write
(with the next read's instruction behind it) and the Fast Sync Read's reply.

Protocol 2.0 (ROBOTIS e-manual): a packet is header FF FF FD 00, id, length (2: instruction
to CRC), instruction, parameters, CRC-16 over everything before it; FF FF FD in the
instruction or parameters is sent as FF FF FD FD (byte stuffing). A Sync Write (0x83) to
the broadcast id FE has parameters address (2), data length (2), then id and data per servo.
The Fast Sync Read's status (0x55, from FE) has for each servo in the instruction's order
its error byte, id, data and a CRC; the last CRC is the packet's, over every byte before
it; it is not stuffed.

The sdk builds a sync write from parameter dictionaries and parses a reply byte list by
byte list; the link then copied each servo's data out: about 0.1 ms for each on this
project's machine, a tenth of a 500 Hz period, every cycle. Here the goals are written into
a packet made once (a numpy record view over its buffer) and the reply goes straight from
the port into a buffer made once, checked whole (header, CRC, ids, error bits), its servos'
fields a record view over it: no allocation per cycle but the frame handed on.
"""

from __future__ import annotations

import os
import select
import time

import numpy as np

from livezmp.links.dynamixel_crc import crc16

HEADER = b"\xff\xff\xfd\x00"
BROADCAST_ID = 0xFE
STATUS = 0x55
PREFIX = 8  # header, id, length (2), instruction: the servos' segments follow
SYNC_WRITE = 0x83
STUFFED = b"\xff\xff\xfd"  # a pattern in the instruction or parameters the sender must stuff
ALERT = 0x80  # error byte: the servo's Hardware Error Status is not 0


class FastReply:
    """Receiver of the Fast Sync Read reply of ``ids`` (in instruction order), each servo's data
    laid out as ``fields`` (a numpy dtype, little-endian, e.g. a 4-byte position). After a
    :meth:`receive` that returned None, :attr:`records` (a view over the buffer, overwritten
    by the next receive) holds each servo's ``error``, ``id``, fields and ``crc``."""

    def __init__(self, ids: list[int], fields: np.dtype) -> None:
        self.records_dtype = np.dtype([("error", "u1"), ("id", "u1"), *fields.descr, ("crc", "<u2")])
        step = self.records_dtype.itemsize
        self.size = PREFIX + len(ids) * step
        length = self.size - PREFIX + 1  # instruction, segments (their CRCs included)
        self.prefix = HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, STATUS))
        self.buffer = bytearray(self.size)
        self._view = memoryview(self.buffer)
        self._signed = self._view[:-2]  # what the packet's CRC covers
        self.records = np.frombuffer(self.buffer, dtype=self.records_dtype, offset=PREFIX, count=len(ids))
        # the error bytes and ids are every step-th byte of the buffer: checked as bytes, no numpy call
        self._errors = slice(PREFIX, self.size, step)
        self._ids = slice(PREFIX + 1, self.size, step)
        self._id_bytes = bytes(ids)

    def receive(self, fd: int, timeout: float) -> tuple[str | None, int]:
        """Read the reply from file descriptor ``fd`` (non-blocking), waiting at most ``timeout``
        s for it. Returns (None, bytes read) for a good packet, else (what went wrong:
        "no_reply", "short_reply", "bad_crc" or "bad_reply" as the link counts them, bytes read)."""
        view, size = self._view, self.size
        got = 0
        deadline = time.monotonic() + timeout
        while got < size:
            try:
                n = os.readv(fd, (view[got:],))  # straight into the buffer, no file object per read
            except BlockingIOError:
                n = 0
            if n:
                got += n
                continue
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            select.select([fd], [], [], remaining)
        if got < size:
            return ("short_reply" if got else "no_reply"), got
        buffer = self.buffer
        if buffer[:PREFIX] != self.prefix or crc16(self._signed) != buffer[-2] | buffer[-1] << 8:
            return "bad_crc", got
        if buffer[self._ids] != self._id_bytes:
            return "short_reply", got
        if buffer[self._errors].strip(b"\x00\x80"):  # an error number (bits 0-6) besides the alert bit
            return "bad_reply", got
        return None, got

    def alerted(self) -> list[int]:
        """Indices of the servos whose status had the alert bit (their Hardware Error Status is not 0)."""
        errors = self.buffer[self._errors]
        return [i for i, e in enumerate(errors) if e & ALERT] if max(errors) & ALERT else []


class GoalPacket:
    """The Sync Write of 4-byte goals to ``ids`` at ``address``, followed in the same buffer by
    ``trailer`` (the next read's instruction): :attr:`buffer` is sent as one write."""

    def __init__(self, ids: list[int], address: int, trailer: bytes) -> None:
        n = len(ids)
        length = 1 + 4 + 5 * n + 2  # instruction, address and data length, id + goal per servo, CRC
        prefix = HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8, SYNC_WRITE, address & 0xFF, address >> 8,
                                 4, 0))
        self.size = len(prefix) + 5 * n + 2  # the sync write's bytes (the trailer's follow)
        self.buffer = bytearray(prefix + bytes(5 * n + 2) + trailer)
        goals = np.frombuffer(self.buffer, dtype=[("id", "u1"), ("goal", "<i4")], offset=len(prefix), count=n)
        goals["id"] = ids
        self._goals = goals["goal"]
        self._signed = memoryview(self.buffer)[:self.size - 2]

    def fill(self, ticks: np.ndarray) -> tuple[bytes | bytearray, int]:
        """Write goal ``ticks`` (n,) and the CRC: (what to send: the sync write and the trailer, the
        sync write's bytes). Goals whose bytes hold FF FF FD are sent stuffed, in a new packet (the
        sdk's Python builder does not: it sends them unstuffed, which a servo misreads)."""
        self._goals[:] = ticks
        buffer, size = self.buffer, self.size
        if buffer.find(STUFFED, PREFIX - 1, size - 2) < 0:
            crc = crc16(self._signed)
            buffer[size - 2] = crc & 0xFF
            buffer[size - 1] = crc >> 8
            return buffer, size
        body = bytes(buffer[PREFIX - 1: size - 2]).replace(STUFFED, STUFFED + b"\xfd")
        length = len(body) + 2
        packet = HEADER + bytes((BROADCAST_ID, length & 0xFF, length >> 8)) + body
        crc = crc16(packet)
        packet += bytes((crc & 0xFF, crc >> 8))
        return packet + buffer[size:], len(packet)
