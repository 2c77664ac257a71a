"""A simulated server's acceptor: hands each new TCP connection over until told to stop."""

from __future__ import annotations

import socket
import threading
from collections.abc import Callable


def accept_until(server: socket.socket, closing: threading.Event, handle: Callable[[socket.socket], None]) -> None:
    """Accept on ``server`` (a listening socket with a short timeout, so ``closing`` is
    seen) and call ``handle(conn)`` for each connection, until ``closing`` is set or the
    socket is closed."""
    while not closing.is_set():
        try:
            conn, _ = server.accept()
        except TimeoutError:
            continue
        except OSError:
            return
        handle(conn)
