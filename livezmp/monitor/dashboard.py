"""The live dashboard: one port serves the page over HTTP and its WebSocket feed.

Stack: the ``websockets`` library (asyncio) alone. Its ``process_request`` hook answers
the plain HTTP requests for the page and its two static files, and ``/ws`` upgrades to
the WebSocket; no web framework and no build step (the page is HTML, a canvas and a
small script). It is a maintained, dependency-free library already needed here.

Threading: the server runs its own event loop in a background thread. The monitor
thread only appends each result to a bounded ring and, when a client task is waiting
for news and no wake-up is pending, asks the loop to wake it: publishing costs about a
microsecond whatever the clients do, and the loop thread wakes (taking the GIL from
the monitor) at most once per message sent, not once per frame. Each client task
sends at most ``max_rate`` messages per second, each with the latest frame, the plot
points since its previous message (at most ``MAX_POINTS``) and the alarms it has not
seen. A slow client blocks only its own task (``send`` waits for its socket to drain)
and so simply gets fewer, later frames. Each client's kernel send buffer is fixed
small (``SEND_BUFFER``) rather than left to grow to megabytes: a slow page then shows
the present a little less often, not a backlog seconds old.

Security: by default the server binds 127.0.0.1. Any other address needs
``allow_remote`` and then a token: the page and the WebSocket require ``?token=``
(compared in constant time). ``token=True`` asks for one on loopback too (other users
of a shared machine reach its loopback). WebSocket requests carrying a foreign
``Origin`` are refused. The feed is read-only: there is no control endpoint, and
incoming messages are ignored.

Clients: at most ``MAX_CLIENTS`` WebSocket feeds at once; one more is refused before its handshake with HTTP
503 (Service Unavailable, "too many dashboard clients") and counted (``refused``). Every client costs the
server's thread a message build and send per frame: with 200 loopback clients a frame reached them up to 614 ms
late (audit 10), and all of them share the GIL with the monitor.
"""

from __future__ import annotations

import asyncio
import hmac
import http
import json
import secrets
import socket
import threading
from collections import deque
from collections.abc import Callable
from importlib import resources
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.protocol import State

from livezmp.balance.pipeline import FrameResult
from livezmp.errors import InputError
from livezmp.monitor.alarms import AlarmEvent
from livezmp.monitor.snapshot import frame_snapshot, plot_point
from livezmp.sources.udp import is_loopback

RING = 1024  # recent results kept for the plot points of slow clients
MAX_POINTS = 300
MAX_ALARMS = 50
MAX_CLIENTS = 16  # WebSocket feeds served at once: a page per screen of a lab, well short of the 200 that lagged
STATUS_EVERY = 0.5  # s: a client gets the status at least this often, even with no frames
SEND_BUFFER = 32 * 1024  # bytes of kernel buffer per client (Linux doubles it): about 15 messages
WRITE_LIMIT = 16 * 1024  # bytes buffered in the server before a send waits
STATIC = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/dashboard.js": ("dashboard.js", "text/javascript; charset=utf-8"),
    "/dashboard.css": ("dashboard.css", "text/css; charset=utf-8"),
}
PROTECTED = {"/", "/ws"}
SECURITY_HEADERS = [
    ("Content-Security-Policy", "default-src 'none'; script-src 'self'; style-src 'self'; connect-src 'self'; "
                                "img-src 'self' data:; base-uri 'none'; form-action 'none'; frame-ancestors 'none'"),
    ("X-Content-Type-Options", "nosniff"),
    ("Referrer-Policy", "no-referrer"),
    ("Cache-Control", "no-store"),
]


def parse_address(text: str) -> tuple[str, int]:
    """``HOST:PORT`` (IPv6 as ``[::1]:PORT``) → (host, port)."""
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or int(port) > 65535:
        raise InputError(f"--dashboard {text!r}: need HOST:PORT, e.g. 127.0.0.1:8765")
    return host, int(port)


def _response(status: http.HTTPStatus, body: bytes, content_type: str) -> Response:
    headers = Headers([("Content-Type", content_type), ("Content-Length", str(len(body))), *SECURITY_HEADERS])
    return Response(status.value, status.phrase, headers, body)


class DashboardServer:
    """Serves the dashboard on ``host``:``port`` (0 = any free port); ``status`` is called
    from the server thread for the status panel (plain JSON values)."""

    def __init__(self, host: str, port: int, status: Callable[[], dict], hello: dict,
                 allow_remote: bool = False, token: bool = False, max_rate: float = 60.0):
        if not is_loopback(host) and not allow_remote:
            raise InputError(f"--dashboard {host}:{port}: serving beyond loopback needs --allow-remote "
                             "(a token is then required)")
        self.host, self.port = host, port
        self.token = secrets.token_urlsafe(18) if token or not is_loopback(host) else None
        self.status, self.hello = status, hello
        self.min_interval = 1.0 / max_rate
        self.files = {path: (resources.files("livezmp.monitor").joinpath("static", name).read_bytes(), ctype)
                      for path, (name, ctype) in STATIC.items()}
        self._lock = threading.Lock()
        self._ring: deque[tuple] = deque(maxlen=RING)  # (seq, FrameResult, measured CoP or None)
        self._alarms: deque[tuple[int, dict]] = deque(maxlen=MAX_ALARMS)
        self._seq = 0
        self._alarm_id = 0
        self._wake_pending = False
        self._waiting = 0  # client tasks waiting for news
        self.client_messages: dict[str, int] = {}  # "host:port" of each connected client → messages sent
        # feeds let through to their handshake, counted against MAX_CLIENTS from then (their tasks start later)
        self._admitted: set[ServerConnection] = set()
        self.refused = 0  # WebSocket requests refused for MAX_CLIENTS
        self._loop: asyncio.AbstractEventLoop | None = None
        self._changed: asyncio.Event | None = None
        self._stopping: asyncio.Future | None = None
        self._ready = threading.Event()
        self._error: OSError | None = None
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.token else "")

    # -- monitor thread --------------------------------------------------------

    def start(self, timeout: float = 10.0) -> str:
        """Start serving; returns the page URL (with the token, if any)."""
        self._thread = threading.Thread(target=lambda: asyncio.run(self._main()), name="dashboard", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise InputError(f"--dashboard {self.host}:{self.port}: server did not start within {timeout} s")
        if self._error is not None:
            raise InputError(f"--dashboard {self.host}:{self.port}: cannot listen: {self._error.strerror}")
        return self.url

    def publish(self, r: FrameResult, cop=None) -> None:
        """Offer one analysed frame (and its measured centre of pressure, internal frame)
        to the page (cheap; never blocks on clients)."""
        with self._lock:
            self._seq += 1
            self._ring.append((self._seq, r, cop))
        self._wake()

    def alarm(self, ev: AlarmEvent) -> None:
        with self._lock:
            self._alarm_id += 1
            self._alarms.append((self._alarm_id, ev.as_message()))
        self._wake()

    def _wake(self) -> None:
        if self._waiting and not self._wake_pending:
            self._wake_pending = True
            self._loop.call_soon_threadsafe(self._notify)

    def stop(self, timeout: float = 5.0) -> None:
        if self._loop is not None and self._stopping is not None:
            try:
                self._loop.call_soon_threadsafe(lambda: self._stopping.done() or self._stopping.set_result(None))
            except RuntimeError:  # its loop is closed: the server ended by itself (it could not listen)
                pass
        if self._thread is not None:
            self._thread.join(timeout)

    # -- server thread ---------------------------------------------------------

    def _notify(self) -> None:
        self._wake_pending = False
        changed, self._changed = self._changed, asyncio.Event()
        changed.set()

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._changed = asyncio.Event()
        self._stopping = self._loop.create_future()
        try:
            server = await serve(self._client, self.host, self.port, process_request=self._http,
                                 compression=None, max_size=4096, write_limit=WRITE_LIMIT, server_header=None)
        except OSError as e:
            self._error = e
            self._ready.set()
            return
        self.port = server.sockets[0].getsockname()[1]
        self._ready.set()
        await self._stopping
        server.close()
        await server.wait_closed()

    def _http(self, conn: ServerConnection, request: Request) -> Response | None:
        url = urlsplit(request.path)
        if url.path not in STATIC and url.path != "/ws":
            return _response(http.HTTPStatus.NOT_FOUND, b"not found\n", "text/plain; charset=utf-8")
        if self.token and url.path in PROTECTED:
            given = parse_qs(url.query).get("token", [""])[-1]
            if not hmac.compare_digest(given.encode(), self.token.encode()):
                return _response(http.HTTPStatus.FORBIDDEN, b"token required\n", "text/plain; charset=utf-8")
        if url.path != "/ws":
            body, ctype = self.files[url.path]
            return _response(http.HTTPStatus.OK, body, ctype)
        origin = request.headers.get("Origin")
        if origin is not None and urlsplit(origin).netloc != request.headers.get("Host"):
            return _response(http.HTTPStatus.FORBIDDEN, b"foreign origin\n", "text/plain; charset=utf-8")
        # a feed whose handshake failed never reaches _client: its closed connection frees its place here
        self._admitted = {c for c in self._admitted if c.state is not State.CLOSED}
        if len(self._admitted) >= MAX_CLIENTS:
            self.refused += 1
            return _response(http.HTTPStatus.SERVICE_UNAVAILABLE,
                             f"too many dashboard clients: at most {MAX_CLIENTS} at once\n".encode(),
                             "text/plain; charset=utf-8")
        self._admitted.add(conn)
        return None  # go on with the WebSocket handshake

    def _message(self, last_seq: int, last_alarm: int) -> tuple[str, int, int]:
        with self._lock:
            ring = [item for item in self._ring if item[0] > last_seq][-MAX_POINTS:]
            alarms = [(i, a) for i, a in self._alarms if i > last_alarm]
        msg = {"type": "update", "status": self.status(), "alarms": [a for _, a in alarms],
               "points": [plot_point(r) for _, r, _ in ring],
               "frame": frame_snapshot(*ring[-1][1:]) if ring else None}
        return (json.dumps(msg, separators=(",", ":")), ring[-1][0] if ring else last_seq,
                alarms[-1][0] if alarms else last_alarm)

    async def _client(self, ws: ServerConnection) -> None:
        peer = "{}:{}".format(*ws.remote_address[:2])
        self.client_messages[peer] = 0
        ws.transport.get_extra_info("socket").setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER)
        try:
            await ws.send(json.dumps({"type": "hello", **self.hello}))
            last_seq, last_alarm = 0, 0
            while True:
                changed = self._changed
                self._waiting += 1  # before the check: a publish in between then sees it and wakes us
                try:
                    if self._seq == last_seq and self._alarm_id == last_alarm:
                        await asyncio.wait_for(changed.wait(), STATUS_EVERY)
                except TimeoutError:
                    pass
                finally:
                    self._waiting -= 1
                text, last_seq, last_alarm = self._message(last_seq, last_alarm)
                await ws.send(text)
                self.client_messages[peer] += 1
                await asyncio.sleep(self.min_interval)
        except ConnectionClosed:
            pass
        finally:
            del self.client_messages[peer]
            self._admitted.discard(ws)
