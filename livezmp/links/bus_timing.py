"""What a half-duplex servo bus physically allows: wire time, return delays, USB adapter latency.

One model shared by the Dynamixel link (the ``bus`` block of a run's summary: the
ceiling its packet sizes allow) and the simulated bus (which delays its replies by it):

* each byte takes 10 bit times (start, 8 data, stop) at the line's baud rate;
* a servo waits its Return Delay Time before answering;
* the USB-serial adapter adds latency in each direction (`Adapter`): ``out_s`` from the
  host's write to the first byte on the wire, ``in_s`` from the last reply byte on the
  wire to the host having it. A full-speed FTDI adapter (FT232R, the U2D2's class)
  sends a write in the next 1 ms USB frame (``out_s`` 0.5 ms, the mean wait) and holds a
  short reply until its latency timer expires (``in_s`` 1 ms, the timer at 1 ms as
  dynamixel-sdk's setup asks for; the FTDI default is 16 ms). A high-speed adapter
  (480 Mbit/s USB, 125 us microframes, polled every microframe) adds 62.5 us out and
  125 us in. The delays are taken as fixed: their means, not the spread the frame
  alignment gives a real one.

A cycle of the live loop is one read transaction (instruction, then the servos'
replies) and one write (no reply), sent back to back: it cannot take less than their
wire time plus the return delays plus the adapter's round trip, which is the ceiling
rate (`BusCeiling`).
"""

from __future__ import annotations

from dataclasses import dataclass

BITS_PER_BYTE = 10  # UART 8N1: start bit, 8 data bits, stop bit


@dataclass(frozen=True)
class Adapter:
    """A USB-serial adapter's latency (s): host write → wire (``out_s``), wire → host (``in_s``)."""

    name: str
    out_s: float
    in_s: float

    @property
    def round_trip_s(self) -> float:
        """Latency one request/reply transaction pays, s."""
        return self.out_s + self.in_s


ADAPTERS = {
    "ftdi-fs": Adapter("ftdi-fs", 0.5e-3, 1.0e-3),  # full-speed FTDI, latency timer 1 ms
    "hs": Adapter("hs", 62.5e-6, 125e-6),  # high-speed USB adapter, one 125 us microframe
    "none": Adapter("none", 0.0, 0.0),  # a UART on the host's own bus
}
DEFAULT_ADAPTER = "ftdi-fs"


def parse_adapter(spec: str | float | Adapter) -> Adapter:
    """An adapter by name (`ADAPTERS`), or a round-trip latency in ms (all of it on the reply side).
    ValueError naming the choices."""
    if isinstance(spec, Adapter):
        return spec
    if isinstance(spec, str) and spec in ADAPTERS:
        return ADAPTERS[spec]
    try:
        ms = float(spec)
    except ValueError:
        ms = -1.0
    if not 0.0 <= ms < 1e3:
        raise ValueError(f"USB adapter '{spec}': expected {', '.join(ADAPTERS)} or a latency in ms >= 0")
    return Adapter(f"{ms:g} ms", 0.0, ms * 1e-3)


def wire_time(n_bytes: int, baud: int) -> float:
    """Seconds ``n_bytes`` take on a line at ``baud`` bit/s."""
    return n_bytes * BITS_PER_BYTE / baud


# Dynamixel Protocol 2.0 packet sizes (ROBOTIS e-manual), without byte stuffing (rare on these packets).
INSTRUCTION_OVERHEAD = 10  # header 4, id, length 2, instruction, CRC 2
STATUS_OVERHEAD = 11  # header 4, id, length 2, instruction 0x55, error, CRC 2
FAST_STATUS_OVERHEAD = 8  # header 4, id, length 2, instruction 0x55; then error, id, data, CRC 2 per servo


def sync_read_bytes(n_servos: int, length: int, fast: bool) -> tuple[int, int]:
    """(instruction bytes, reply bytes) of a (Fast) Sync Read of ``length`` bytes from ``n_servos``."""
    instruction = INSTRUCTION_OVERHEAD + 4 + n_servos
    if fast:
        return instruction, FAST_STATUS_OVERHEAD + n_servos * (4 + length)
    return instruction, n_servos * (STATUS_OVERHEAD + length)


def bulk_read_bytes(lengths: list[int], fast: bool) -> tuple[int, int]:
    """(instruction bytes, reply bytes) of a (Fast) Bulk Read of ``lengths[i]`` bytes from device i."""
    instruction = INSTRUCTION_OVERHEAD + 5 * len(lengths)
    if fast:
        return instruction, FAST_STATUS_OVERHEAD + sum(4 + n for n in lengths)
    return instruction, sum(STATUS_OVERHEAD + n for n in lengths)


def sync_write_bytes(n_servos: int, length: int) -> int:
    """Bytes of a Sync Write of ``length`` bytes to each of ``n_servos``."""
    return INSTRUCTION_OVERHEAD + 4 + n_servos * (1 + length)


@dataclass(frozen=True)
class BusCeiling:
    """The fastest a read + write cycle can go on one bus: ``cycle_s`` = wire time of
    ``bytes_per_cycle`` + ``return_delays_s`` + the adapter's round trip."""

    baud: int
    bytes_per_cycle: float
    return_delays_s: float
    adapter: Adapter

    @property
    def wire_s(self) -> float:
        return self.bytes_per_cycle * BITS_PER_BYTE / self.baud

    @property
    def cycle_s(self) -> float:
        return self.wire_s + self.return_delays_s + self.adapter.round_trip_s

    @property
    def ceiling_hz(self) -> float:
        return 1.0 / self.cycle_s


def bus_summary(ceilings: list[BusCeiling], read: str, achieved_hz: float) -> dict | None:
    """The summary's ``bus`` block for buses read and written in parallel (the slowest sets the
    ceiling). ``utilisation``: achieved rate / ceiling; ``wire_busy``: share of time the
    busiest wire carries bytes. Times in ms, rates in Hz. On a CAN bus ``bytes_per_cycle`` is the
    frames' data and ``bits_per_cycle`` what they hold the wire for (stuff bits included). None without
    buses: a link whose buses were gone at the run's end (its reconnection failed) has none to describe."""
    if not ceilings:
        return None
    slowest = max(ceilings, key=lambda c: c.cycle_s)
    wire_busy = max(achieved_hz * c.wire_s for c in ceilings)
    return {
        "baud": slowest.baud,
        "read": read,
        "buses": len(ceilings),
        "bytes_per_cycle": round(slowest.bytes_per_cycle, 1),
        "wire_ms_per_cycle": round(1e3 * slowest.wire_s, 4),
        "return_delays_ms": round(1e3 * slowest.return_delays_s, 4),
        "adapter": slowest.adapter.name,
        "adapter_latency_ms": round(1e3 * slowest.adapter.round_trip_s, 4),
        "ceiling_hz": round(slowest.ceiling_hz, 1),
        "utilisation": round(achieved_hz / slowest.ceiling_hz, 4),
        "wire_busy": round(wire_busy, 4),
        **({"frames_per_cycle": slowest.frames_per_cycle, "bits_per_cycle": slowest.bits_per_cycle}
           if hasattr(slowest, "bits_per_cycle") else {}),  # a CAN bus (can_timing.CanBusCeiling, no import circle)
    }
