"""Transports: the protocol over a pyserial port or a python-can bus, behind one small interface.

Both classes offer ``send(msg) -> seq``, ``receive(timeout) -> list[Received]``,
``errors`` (counters by kind) and ``close()``; ``role`` ("host" or "board") is
the side this end plays and fixes the direction of what it sends and accepts.
"""

from __future__ import annotations

import can
import serial

from .can_framing import BROADCAST, MAX_NODE, TID_BITS, CanDecoder, encode_can
from .errors import LinkError, ProtocolError
from .messages import Message
from .serial_framing import Received, StreamDecoder, encode

MAX_READ = 65536  # bytes taken from a serial port per receive() call: bounds its cost
MAX_CAN_FRAMES_PER_RECEIVE = 4096


def _check_role(role: str) -> bool:
    if role not in ("host", "board"):
        raise ProtocolError(f"role must be 'host' or 'board', not {role!r}")
    return role == "board"


class SerialTransport:
    """The serial framing over any pyserial port.

    ``port`` is a pyserial URL or device path (``/dev/ttyACM0``, a pty's path,
    ``socket://127.0.0.1:5000``, ``loop://``) or an already open pyserial port.
    LinkError if it cannot be opened or written.
    """

    def __init__(self, port: str | serial.SerialBase, *, role: str = "host", baudrate: int = 1_000_000):
        self.is_board = _check_role(role)
        if isinstance(port, str):
            try:
                port = serial.serial_for_url(port, baudrate=baudrate, timeout=0)
            except (serial.SerialException, ValueError, OSError) as err:
                raise LinkError(f"{port}: cannot open serial port: {err}") from None
        self.port = port
        self.name = getattr(port, "name", None) or getattr(port, "port", None) or "serial"
        self.decoder = StreamDecoder(accept="host" if self.is_board else "board")
        self.tx_failed = 0
        self._seq = 0
        self._timeout = port.timeout
        self._write(b"\0")  # ends whatever partial frame the peer's decoder holds

    def send(self, msg: Message) -> int:
        """Frame and write ``msg``; returns the frame sequence number used."""
        seq = self._seq
        self._write(encode(msg, seq, self.is_board))
        self._seq = (seq + 1) & 0xFFFF
        return seq

    def receive(self, timeout: float = 0.0) -> list[Received]:
        """Messages from the bytes available now, waiting up to ``timeout`` s for the first byte."""
        if timeout != self._timeout:
            self.port.timeout = self._timeout = timeout
        try:
            data = self.port.read(min(max(self.port.in_waiting, 1), MAX_READ))
            while data and len(data) < MAX_READ and self.port.in_waiting:
                data += self.port.read(min(self.port.in_waiting, MAX_READ - len(data)))
        except (serial.SerialException, OSError) as err:
            raise LinkError(f"{self.name}: read failed: {err}") from None
        return self.decoder.feed_frames(data) if data else []

    @property
    def errors(self) -> dict[str, int]:
        """Receive errors by kind, plus ``tx_failed``."""
        return {**self.decoder.errors, "tx_failed": self.tx_failed}

    def close(self) -> None:
        self.port.close()

    def _write(self, data: bytes) -> None:
        try:
            self.port.write(data)
        except (serial.SerialException, OSError) as err:
            self.tx_failed += 1
            raise LinkError(f"{self.name}: write failed: {err}") from None


class CanTransport:
    """The CAN mapping over any python-can bus (``can.Bus(interface=..., channel=...)``).

    A host talks to ``node`` (1..127); a board is ``node`` and also accepts the
    host's broadcasts (node 0). LinkError when the bus refuses a frame (e.g.
    bus-off or a full transmit queue).
    """

    def __init__(self, bus: can.BusABC, node: int, *, role: str = "host", max_transfers: int = 16):
        self.is_board = _check_role(role)
        if not 1 <= node <= MAX_NODE:
            raise ProtocolError(f"CAN node id {node} is not in 1..{MAX_NODE}")
        self.bus = bus
        self.node = node
        self.name = f"{getattr(bus, 'channel_info', 'can')} node {node}"
        nodes = frozenset({node, BROADCAST}) if self.is_board else frozenset({node})
        self.decoder = CanDecoder("host" if self.is_board else "node", nodes, max_transfers=max_transfers)
        self.tx_failed = 0
        self._tids: dict[tuple[int, int], int] = {}

    def send(self, msg: Message, *, broadcast: bool = False) -> int:
        """Send ``msg`` as one transfer (to every node if ``broadcast``, host only); returns its transfer id."""
        if broadcast and self.is_board:
            raise ProtocolError("only the host sends broadcasts")
        node = BROADCAST if broadcast else self.node
        key = (msg.spec.msg_id, node)
        tid = self._tids.get(key, 0)
        for frame in encode_can(msg, node, tid, self.is_board):
            try:
                self.bus.send(can.Message(arbitration_id=frame.can_id, data=frame.data, is_extended_id=True))
            except can.CanError as err:
                self.tx_failed += 1
                raise LinkError(f"{self.name}: CAN send failed: {err}") from None
        self._tids[key] = (tid + 1) % (1 << TID_BITS)
        return tid

    def receive(self, timeout: float = 0.0) -> list[Received]:
        """Messages completed by the frames available now, waiting up to ``timeout`` s for the first."""
        out: list[Received] = []
        try:
            frame = self.bus.recv(timeout)
            taken = 0
            while frame is not None:
                out += self.decoder.feed(
                    frame.arbitration_id, frame.data, is_extended=frame.is_extended_id,
                    is_error=frame.is_error_frame, is_remote=frame.is_remote_frame,
                )
                taken += 1
                frame = self.bus.recv(0) if taken < MAX_CAN_FRAMES_PER_RECEIVE else None
        except can.CanError as err:
            raise LinkError(f"{self.name}: CAN receive failed: {err}") from None
        return out

    @property
    def errors(self) -> dict[str, int]:
        """Receive errors by kind, plus ``tx_failed``."""
        return {**self.decoder.errors, "tx_failed": self.tx_failed}

    def close(self) -> None:
        """Nothing to release: the bus belongs to the caller, who shuts it down."""
