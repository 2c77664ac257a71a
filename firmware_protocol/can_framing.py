"""CAN mapping: messages on classic CAN (8-byte data, 29-bit extended ids) (SPEC.md, "CAN mapping").

Identifier, most significant bit first:

    msg_id (8) | from_node (1) | node (7) | transfer id (5) | last (1) | frame index (7)

A payload of at most 8 bytes travels in one frame (index 0, last set, DLC =
payload length). A longer one is split into 8-byte frames followed by its
CRC-32 (over payload and schema seed), at most 128 frames. Arbitration favours
low message ids, so ESTOP (0x01) wins over everything else on the bus.
"""

from __future__ import annotations

import zlib
from collections import OrderedDict
from dataclasses import dataclass

from .errors import DecodeError, ProtocolError
from .messages import Message
from .payload import decode_payload, encode_payload
from .schema import BY_ID
from .sequence import SequenceTracker
from .serial_framing import SYNC_SESSION, Received

MAX_NODE = 127
BROADCAST = 0  # node id of host -> all-nodes frames
TID_BITS = 5
TID_BEHIND = 4  # transfers up to this far behind the last one are stale reorderings
MAX_FRAMES = 128  # frames of one transfer (7-bit index)
CRC_SIZE = 4

ERROR_KINDS = (
    "foreign", "error_frame", "bad_length", "unknown_id", "bad_header", "bad_transfer", "bad_crc",
    "bad_value", "wrong_direction", "duplicate", "stale", "seq_gap", "seq_restart",
)
_SEED_BYTES = {msg_id: spec.seed.to_bytes(4, "little") for msg_id, spec in BY_ID.items()}


@dataclass(frozen=True, slots=True)
class CanFrame:
    """One classic CAN data frame: 29-bit extended identifier and 0..8 data bytes."""

    can_id: int
    data: bytes


def make_can_id(msg_id: int, from_node: bool, node: int, tid: int, last: bool, index: int) -> int:
    """The 29-bit identifier of one frame of a transfer."""
    return msg_id << 21 | from_node << 20 | node << 13 | tid << 8 | last << 7 | index


def split_can_id(can_id: int) -> tuple[int, bool, int, int, bool, int]:
    """(msg_id, from_node, node, tid, last, index) of a 29-bit identifier."""
    return (
        can_id >> 21 & 0xFF, bool(can_id >> 20 & 1), can_id >> 13 & 0x7F, can_id >> 8 & 0x1F,
        bool(can_id >> 7 & 1), can_id & 0x7F,
    )


def transfer_crc(msg_id: int, payload: bytes) -> int:
    """CRC-32 of a multi-frame payload followed by the message's schema seed."""
    return zlib.crc32(_SEED_BYTES[msg_id], zlib.crc32(payload))


def encode_can(msg: Message, node: int, tid: int, from_node: bool) -> list[CanFrame]:
    """The frames of one transfer of ``msg`` to (host -> node) or from (node -> host) ``node``.

    ``tid`` is the sender's transfer counter (0..31) for this message, direction
    and node. ProtocolError on a bad argument or value.
    """
    spec = msg.spec
    if spec.direction != "both" and (spec.direction == "board") != from_node:
        raise ProtocolError(f"{spec.name} is sent by the {spec.direction} only")
    if not (1 if from_node else 0) <= node <= MAX_NODE:
        raise ProtocolError(f"CAN node id {node} is not in {1 if from_node else 0}..{MAX_NODE}")
    if not 0 <= tid < 1 << TID_BITS:
        raise ProtocolError(f"CAN transfer id {tid} is not in 0..31")
    payload = encode_payload(msg)
    if len(payload) <= 8:
        return [CanFrame(make_can_id(spec.msg_id, from_node, node, tid, True, 0), payload)]
    data = payload + transfer_crc(spec.msg_id, payload).to_bytes(CRC_SIZE, "little")
    count = (len(data) + 7) // 8
    if count > MAX_FRAMES:
        raise ProtocolError(f"{spec.name}: {len(payload)} bytes need {count} CAN frames, limit {MAX_FRAMES}")
    return [
        CanFrame(make_can_id(spec.msg_id, from_node, node, tid, i == count - 1, i), data[8 * i : 8 * i + 8])
        for i in range(count)
    ]


@dataclass
class _Transfer:
    tid: int
    next_index: int
    last_data: bytes
    data: bytearray
    done: bool = False  # complete: kept only to recognise a repeat of its last frame


class CanDecoder:
    """Reassembles and checks transfers from a stream of CAN frames.

    ``accept`` selects the direction delivered: "node" (frames nodes sent; for a
    host) or "host" (frames the host sent; for a node). ``nodes`` limits the
    node ids accepted (None: any). Memory is bounded: at most ``max_transfers``
    transfers in reassembly and ``max_streams`` sequence trackers, the least
    recently used evicted first. ``errors`` counts rejected frames by kind.
    """

    def __init__(self, accept: str, nodes: frozenset[int] | None = None, max_transfers: int = 16,
                 max_streams: int = 256):
        if accept not in ("node", "host"):
            raise ProtocolError(f"accept must be 'node' or 'host', not {accept!r}")
        self.accept_from_node = accept == "node"
        self.nodes = nodes
        self.max_transfers = max_transfers
        self.max_streams = max_streams
        self.errors = dict.fromkeys(ERROR_KINDS, 0)
        self.delivered = 0
        self._transfers: OrderedDict[tuple[int, int], _Transfer] = OrderedDict()
        self._streams: OrderedDict[tuple[int, int], SequenceTracker] = OrderedDict()

    @property
    def held(self) -> tuple[int, int]:
        """(transfers in reassembly, streams tracked): bounded by max_transfers and max_streams."""
        return len(self._transfers), len(self._streams)

    def feed(self, can_id: int, data: bytes, *, is_extended: bool = True, is_error: bool = False,
             is_remote: bool = False) -> list[Received]:
        """The message completed by this frame, if any (a list of 0 or 1 ``Received``).

        Error frames count as ``error_frame``; standard-id and remote frames,
        which this protocol never sends, as ``foreign``.
        """
        if is_error:
            self.errors["error_frame"] += 1
            return []
        if not is_extended or is_remote:
            self.errors["foreign"] += 1
            return []
        msg_id, from_node, node, tid, last, index = split_can_id(can_id)
        if from_node != self.accept_from_node:
            self.errors["wrong_direction"] += 1
            return []
        if self.nodes is not None and node not in self.nodes:
            return []  # another node's traffic: not ours, not an error
        if len(data) > 8:
            self.errors["bad_length"] += 1
            return []
        try:
            received = self._frame(msg_id, from_node, node, tid, last, index, bytes(data))
        except DecodeError as err:
            self.errors[err.kind] += 1
            return []
        if received is None:
            return []
        self.delivered += 1
        return [received]

    def _frame(self, msg_id, from_node, node, tid, last, index, data) -> Received | None:
        spec = BY_ID.get(msg_id)
        if spec is None:
            raise DecodeError(f"message id {msg_id:#04x}", "unknown_id")
        if spec.direction != "both" and (spec.direction == "board") != from_node:
            raise DecodeError(f"{spec.name} in the wrong direction", "bad_header")
        key = (msg_id, node)
        if index == 0 and last:
            self._abort(key)
            payload = data
        else:
            payload = self._segment(key, tid, last, index, data)
            if payload is None:
                return None
            if len(payload) <= 8 + CRC_SIZE:
                raise DecodeError("multi-frame transfer of a payload that fits one frame", "bad_length")
            payload, crc = payload[:-CRC_SIZE], int.from_bytes(payload[-CRC_SIZE:], "little")
            if transfer_crc(msg_id, payload) != crc:
                raise DecodeError("transfer CRC mismatch", "bad_crc")
        msg = decode_payload(spec, payload)
        tracker = self._tracker(key)
        if spec.name in SYNC_SESSION:
            tracker.reset()
        verdict, lost = tracker.classify(tid)
        if verdict in ("duplicate", "stale"):
            self.errors[verdict] += 1
            return None
        if verdict == "restart":
            self.errors["seq_restart"] += 1
        self.errors["seq_gap"] += lost
        return Received(msg, tid, node)

    def _abort(self, key) -> None:
        transfer = self._transfers.pop(key, None)
        if transfer is not None and not transfer.done:
            self.errors["bad_transfer"] += 1

    def _segment(self, key, tid, last, index, data) -> bytes | None:
        """Add one frame of a multi-frame transfer; the reassembled bytes once the last frame is in."""
        transfer = self._transfers.get(key)
        if index == 0:
            if transfer is not None and transfer.tid == tid and transfer.next_index == 1 and data == transfer.last_data:
                raise DecodeError("frame received twice", "duplicate")
            self._abort(key)
            if len(data) != 8:
                raise DecodeError("first frame of a transfer shorter than 8 bytes", "bad_transfer")
            if len(self._transfers) >= self.max_transfers:
                _, evicted = self._transfers.popitem(last=False)
                if not evicted.done:
                    self.errors["bad_transfer"] += 1
            self._transfers[key] = _Transfer(tid, 1, data, bytearray(data))
            return None
        if transfer is None:
            raise DecodeError("frame of a transfer that never started", "bad_transfer")
        self._transfers.move_to_end(key)
        if transfer.tid == tid and index == transfer.next_index - 1 and data == transfer.last_data:
            raise DecodeError("frame received twice", "duplicate")
        if transfer.done or transfer.tid != tid or index != transfer.next_index or (not last and len(data) != 8) \
                or not data:
            self._transfers.pop(key)
            raise DecodeError("missing, reordered or short frame", "bad_transfer")
        transfer.data += data
        transfer.next_index += 1
        transfer.last_data = data
        if not last:
            if transfer.next_index == MAX_FRAMES:
                self._transfers.pop(key)
                raise DecodeError(f"transfer longer than {MAX_FRAMES} frames", "bad_transfer")
            return None
        transfer.done = True
        return bytes(transfer.data)

    def _tracker(self, key) -> SequenceTracker:
        tracker = self._streams.get(key)
        if tracker is None:
            if len(self._streams) >= self.max_streams:
                self._streams.popitem(last=False)
            tracker = self._streams[key] = SequenceTracker(TID_BITS, TID_BEHIND)
        else:
            self._streams.move_to_end(key)
        return tracker
