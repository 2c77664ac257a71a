"""CAN servo link: firmware_protocol's CAN mapping over any python-can interface.

    can:INTERFACE:CHANNEL[?bitrate=1000000&rate=30&watchdog=0.2&timeout=0.1&OPTION=VALUE...]

e.g. ``can:slcan:/dev/ttyACM0?bitrate=1000000``, ``can:socketcan:can0``,
``can:socketcand:can0?host=192.168.1.10&port=29536&tcp_tune=1`` (a socketcand daemon on
the robot's computer: python-can reads its TCP stream 1 kB at a time, where its slcan
reader makes one system call per byte and tops out near 3 000 frames/s). Other options go
to ``can.Bus`` as keyword arguments (numbers converted), e.g. ``sleep_after_open=0`` for an
slcan adapter that needs no settling time.

One node per servo (SPEC.md §6: node id = the servo id of the robot config), or a board
node owning several joints: each node is a firmware_protocol host session; joints are
found by name in the nodes' HELLO_ACK. All sessions share one bus: `CanBoards` reads it
once and hands each node's messages to its session. Everything else (handshake, watchdog,
streams, reads, goals, errors) is `FirmwareLink`'s. ``rate`` defaults to 30 Hz: twenty
one-joint nodes send 60 frames per round of JOINT_STATE, and python-can's slcan reader (one
system call per byte) takes about 3 000 frames/s; the bus itself (1 Mbit/s) carries about
100 rounds/s (SPEC.md §6), so with an interface such as socketcan raise it.
"""

from __future__ import annotations

import logging
import select
import socket
import time
from collections import deque
from collections.abc import Sequence

import can

import firmware_protocol as fp
from livezmp.links.base import LinkError
from livezmp.links.firmware import OPEN_WATCHDOG, POLL_WAIT

MAX_FRAMES_PER_POLL = 256  # bounds one poll's cost
INBOX_LIMIT = 256  # messages kept per node between polls (older ones are dropped)
# s per try of an acknowledged command: an ACK queues behind every node's streams on one bus, and python-can's
# slcan reader takes about 3 000 frames/s
ACK_TIMEOUT = 0.25
# s: the tries of an acknowledged command go on this long (an ACK to any of them counts; before, each try of 0.25 s
# took only its own ACK, so a reader 0.25 s behind for 0.75 s failed the open). A node that never answers is told
# after 2 s, in one line. Not enough on a host loaded beyond what the slcan reader needs: opening the 20-node mini
# beside 1-3 busy loops (load 2.6-3.7), 23 of 24 opens succeeded before, 22 of 24 with this; the failures are the
# reader seconds behind the nodes' streams (an ACK not read within 2 s; the first read then finds a state a second
# old), which no deadline fixes: a lower rate, or socketcand, does.
ACK_DEADLINE = 2.0


class _NodeTransport(fp.CanTransport):
    """A host transport to one node that sends on the shared bus and receives what `CanBoards` routed to it.

    Its transfer ids continue in ``tids`` across reconnects: a node tracks each of our streams by transfer id,
    and a restarted count would have it drop up to four of our transfers (SET_GOALS, HEARTBEAT...) as stale.
    """

    def __init__(self, boards: CanBoards, node: int, tids: dict[tuple[int, int], int]) -> None:
        super().__init__(boards.bus, node)
        self.name = f"{boards.name} node {node}"
        self._tids = tids
        self._boards = boards
        self._inbox: deque[fp.Received] = boards.inboxes[node]

    def receive(self, timeout: float = 0.0) -> list[fp.Received]:
        if not self._inbox and timeout > 0:
            self._boards.pump(timeout)
        out = list(self._inbox)
        self._inbox.clear()
        return out


# A socketcand daemon greets a client at once ("< hi >"); python-can, when the connection is refused, retries it
# for 10 s in a busy loop with a warning a try, which froze the live loop for 10 s at each attempt to reconnect
# to a daemon that had gone (and a CPU with it). A daemon that has not greeted within this is not there.
SOCKETCAND_GREETING_S = 1.0
SOCKETCAND_GREETING = b"< hi >"


def open_can_bus(interface: str, channel: str, **options) -> can.BusABC:
    """python-can's bus ``interface``:``channel`` with its ``options``; a socketcand daemon is first asked for its
    greeting (OSError within SOCKETCAND_GREETING_S when it does not give it)."""
    if interface == "socketcand":
        _check_socketcand(str(options.get("host")), int(options.get("port", 0)))
    return can.Bus(interface=interface, channel=channel, **options)


def _check_socketcand(host: str, port: int) -> None:
    deadline = time.monotonic() + SOCKETCAND_GREETING_S
    with socket.create_connection((host, port), timeout=SOCKETCAND_GREETING_S) as s:
        heard = b""
        while not heard.startswith(SOCKETCAND_GREETING):
            s.settimeout(max(1e-3, deadline - time.monotonic()))
            data = s.recv(len(SOCKETCAND_GREETING) - len(heard))  # TimeoutError (an OSError) once it is late
            if not data or not SOCKETCAND_GREETING.startswith(heard + data):
                raise OSError(f"{host}:{port} is not a socketcand daemon (no {SOCKETCAND_GREETING.decode()!r})")
            heard += data


class CanBoards:
    """The nodes ``nodes`` on one python-can bus (the `Boards` of a CAN `FirmwareLink`); ``tids``: the
    transfer counters, kept by the caller from one connection to the next."""

    def __init__(self, interface: str, channel: str, nodes: Sequence[int], tids: dict[tuple[int, int], int],
                 **bus_options) -> None:
        self.name = f"can:{interface}:{channel}"
        # python-can's socketcand logs a warning whenever a TCP read ends inside a frame's line, which at a few
        # thousand frames a second is most reads (measured: a quarter of the link's time went to writing them)
        logging.getLogger("can.interfaces.socketcand.socketcand").setLevel(logging.ERROR)
        try:
            self.bus = open_can_bus(interface, channel, **bus_options)
        except (can.CanError, ValueError, TypeError, OSError, ImportError) as err:
            raise LinkError(f"{self.name}: cannot open the CAN bus: {err}") from None
        try:
            self._fd: int | None = self.bus.fileno()
        except NotImplementedError:
            self._fd = None  # e.g. the virtual bus: wait inside recv instead
        self._decoder = fp.CanDecoder("node", frozenset(nodes))
        self._garbled = 0
        self.inboxes = {node: deque(maxlen=INBOX_LIMIT) for node in nodes}
        self.sessions = [fp.HostSession(_NodeTransport(self, node, tids), watchdog_timeout=OPEN_WATCHDOG,
                                        ack_timeout=ACK_TIMEOUT, ack_deadline=ACK_DEADLINE) for node in nodes]
        try:
            self.pump(0.0)
        except fp.LinkError as err:
            self.close()
            raise LinkError(str(err)) from None
        for inbox in self.inboxes.values():
            inbox.clear()  # what the nodes sent before we opened is stale

    def pump(self, timeout: float) -> None:
        """Read the frames available (waiting up to ``timeout`` s for the first) into the nodes' inboxes."""
        bus, fd, decoder, inboxes = self.bus, self._fd, self._decoder, self.inboxes
        try:
            for _ in range(MAX_FRAMES_PER_POLL):
                # With a file descriptor, select waits and recv(0) never blocks: python-can's slcan would
                # otherwise wait its poll interval (1 ms) in every recv that finds nothing.
                if fd is not None and not select.select([fd], [], [], timeout)[0]:
                    return
                try:
                    frame = bus.recv(0.0 if fd is not None else timeout)
                except (IndexError, ValueError):  # python-can could not parse a garbled line: that frame is lost
                    self._garbled += 1
                    continue
                timeout = 0.0
                if frame is None:
                    if fd is None:
                        return
                    continue  # a partial line or an adapter acknowledgement: more bytes are coming
                for received in decoder.feed(frame.arbitration_id, frame.data, is_extended=frame.is_extended_id,
                                             is_error=frame.is_error_frame, is_remote=frame.is_remote_frame):
                    inboxes[received.node].append(received)
        except (can.CanError, OSError) as err:
            raise fp.LinkError(f"{self.name}: CAN receive failed: {err}") from None

    def poll(self) -> list[tuple[int, fp.Message]]:
        self.pump(POLL_WAIT)
        return [(k, msg) for k, session in enumerate(self.sessions) for msg in session.poll(0.0)]

    def pending(self) -> bool:
        if any(self.inboxes.values()):
            return True
        return self._fd is not None and bool(select.select([self._fd], [], [], 0.0)[0])

    def errors(self) -> dict[str, int]:
        return {**self._decoder.errors, "garbled": self._garbled}

    def close(self) -> None:
        try:
            self.bus.shutdown()
        except (can.CanError, OSError, ValueError):
            pass  # the adapter is gone already
