"""The exception types of firmware_protocol.

Every error the package raises on purpose is a ``ProtocolError``; its message
is one line naming the message, field or port at fault.
"""


class ProtocolError(ValueError):
    """A message or frame that cannot be encoded, or a bad protocol argument."""


class LinkError(ProtocolError):
    """The transport failed: the port cannot be opened, or a frame cannot be sent (e.g. CAN bus-off)."""


class HandshakeError(ProtocolError):
    """The board refused or did not answer HELLO, or speaks a different schema."""


class CommandRefused(ProtocolError):
    """The board answered a command with NACK; ``code`` is the NackCode."""

    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.code = code


class DecodeError(ProtocolError):
    """A received payload that does not decode; ``kind`` is the error counter it is charged to."""

    def __init__(self, message: str, kind: str):
        super().__init__(message)
        self.kind = kind
