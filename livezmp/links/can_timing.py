"""What a classic CAN bus physically allows: the bits each frame holds the wire for, stuffing included.

A classic (CAN 2.0) data frame is, in bus order (ISO 11898-1):

* standard id: SOF, 11 id bits, RTR, IDE, r0, 4 DLC bits, the data, a 15-bit CRC;
* extended id: SOF, 11 base id bits, SRR, IDE, 18 id bits, RTR, r1, r0, DLC, data, CRC;

then CRC delimiter, ACK slot, ACK delimiter, 7 bits of end of frame and 3 of interframe
space (13 bits). Between SOF and the CRC's last bit the transmitter inserts a stuff bit of
the other level after every 5 equal bits (the stuff bit counts towards the next run), so
a frame's length depends on its id and data: 47 + 8 x data bytes (standard) or 67 + 8 x
data bytes (extended) plus 0 to (stuffed bits - 1) // 4 stuff bits. The simulated bus
holds the wire for exactly these bits, and a CAN link's ``bus`` summary adds up the bits
of the frames it exchanges in a cycle (`CanBusCeiling`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

from livezmp.links.bus_timing import BusCeiling

CRC15_POLY = 0x4599  # x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1
TRAILER_BITS = 13  # CRC delimiter, ACK slot, ACK delimiter, end of frame (7), interframe space (3)


def crc15(bits: str) -> int:
    """CAN's CRC-15 of a string of '0'/'1' bits (MSB first, initial value 0)."""
    crc = 0
    for bit in bits:
        top = ((crc >> 14) & 1) ^ (bit == "1")
        crc = (crc << 1) & 0x7FFF
        if top:
            crc ^= CRC15_POLY
    return crc


def stuff_bits(bits: str) -> int:
    """How many stuff bits a transmitter inserts into ``bits`` ('0'/'1'): one after every 5 equal bits,
    itself the first bit of the next run."""
    count, run, last = 0, 0, ""
    for bit in bits:
        if bit == last:
            run += 1
        else:
            last, run = bit, 1
        if run == 5:
            count += 1
            last, run = ("1" if bit == "0" else "0"), 1  # the stuff bit starts the next run
    return count


def _stuffed_part(arbitration_id: int, data: bytes, extended: bool, remote: bool, dlc: int) -> str:
    """SOF to the end of the CRC, before stuffing."""
    rtr = "1" if remote else "0"
    if extended:
        head = f"0{arbitration_id >> 18:011b}11{arbitration_id & 0x3FFFF:018b}{rtr}00"
    else:
        head = f"0{arbitration_id:011b}{rtr}00"
    body = head + f"{dlc:04b}" + "".join(f"{b:08b}" for b in data)
    return body + f"{crc15(body):015b}"


@lru_cache(maxsize=8192)
def frame_bits(arbitration_id: int, data: bytes = b"", extended: bool = False, remote: bool = False,
               dlc: int | None = None) -> int:
    """Bit times a classic CAN frame holds the bus for: its fields, its stuff bits and the 3-bit
    interframe space (``dlc``: a remote frame's, default len(data))."""
    n = len(data) if dlc is None else dlc
    bits = _stuffed_part(arbitration_id, bytes(data) if not remote else b"", extended, remote, n)
    return len(bits) + stuff_bits(bits) + TRAILER_BITS


def max_frame_bits(n_data: int, extended: bool = False) -> int:
    """The longest a data frame of ``n_data`` bytes can be: every possible stuff bit inserted."""
    stuffed = (54 if extended else 34) + 8 * n_data
    return stuffed + (stuffed - 1) // 4 + TRAILER_BITS


@dataclass(frozen=True)
class CanBusCeiling(BusCeiling):
    """The fastest a cycle can go on one CAN bus at ``baud`` (its bitrate, bit/s): the
    ``bits_per_cycle`` of its ``frames_per_cycle`` frames (``bytes_per_cycle`` of data in them)
    on the wire one after the other, plus the host adapter's round trip. Nodes answer from
    their receive interrupt: ``return_delays_s`` 0."""

    bits_per_cycle: int = 0
    frames_per_cycle: int = 0

    @property
    def wire_s(self) -> float:
        return self.bits_per_cycle / self.baud
