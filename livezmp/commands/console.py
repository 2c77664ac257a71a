"""The console of a command that must outlive it: a live loop or monitor whose terminal closes (an SSH session
dropping: SIGHUP, then every write to the terminal fails with EIO) or whose reader goes away (a pipe: EPIPE).

Its status lines and events are for a person watching; the robot's stop commands, the summary and the recording
must not depend on them. :func:`outliving_console` wraps ``sys.stdout`` and ``sys.stderr``: once a write or flush
fails because the terminal or pipe is gone, that stream's file descriptor is pointed at ``/dev/null`` (what it
still buffered and everything after is discarded) and the command carries on to its own end. Light (standard
library only): installed before a command's modules are imported.
"""

from __future__ import annotations

import contextlib
import errno
import os
import sys
from collections.abc import Iterator
from typing import TextIO

GONE = (errno.EIO, errno.EPIPE)  # the terminal hung up; the pipe's reader closed it


class OutlivingStream:
    """``stream`` (a text stream with a file descriptor) whose writes stop reaching anyone, silently, once its
    terminal or pipe is gone; other errors are raised as before. ``gone``: it has happened."""

    def __init__(self, stream: TextIO):
        self._stream = stream
        self.gone = False

    def write(self, text: str) -> int:
        try:
            return self._stream.write(text)
        except OSError as e:
            self._went(e)
            return len(text)

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as e:
            self._went(e)

    def _went(self, e: OSError) -> None:
        if e.errno not in GONE:
            raise e
        self.gone = True
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, self._stream.fileno())
        finally:
            os.close(null)
        with contextlib.suppress(OSError):  # what the stream still buffers goes to /dev/null now
            self._stream.flush()

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


@contextlib.contextmanager
def outliving_console() -> Iterator[None]:
    """``sys.stdout`` and ``sys.stderr`` as :class:`OutlivingStream` inside the block (streams without a file
    descriptor, such as a test's captured output, are left as they are); the previous ones back after it."""
    before = sys.stdout, sys.stderr
    wrap = lambda s: OutlivingStream(s) if _has_fd(s) else s  # noqa: E731
    sys.stdout, sys.stderr = wrap(sys.stdout), wrap(sys.stderr)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = before


def _has_fd(stream: TextIO) -> bool:
    try:
        stream.fileno()
    except (AttributeError, OSError, ValueError):
        return False
    return True
