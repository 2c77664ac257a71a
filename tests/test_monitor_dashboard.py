"""The dashboard server with real clients (urllib, the websockets client, a raw socket):
the page and its headers, the feed carrying every frame's plot point exactly once,
alarms, a stalled client that never slows the pipeline, tokens and origins."""

from __future__ import annotations

import base64
import json
import os
import socket
import threading
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from livezmp.balance.pipeline import default_config
from livezmp.errors import InputError
from livezmp.model.body_spec import robot_body
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.motion_file import trajectory_frames
from livezmp.monitor.dashboard import MAX_CLIENTS, MAX_POINTS, DashboardServer, parse_address
from livezmp.monitor.loop import Monitor
from livezmp.sources.file_replay import FileReplaySource

HELLO = {"source": "test", "body": "urdf", "alarm_after": 0.2}


@pytest.fixture(scope="module")
def demo():
    body, spec = robot_body(demo_robot_path())
    traj = demo_trajectory(body.joint_names)
    return body, spec, traj.t, trajectory_frames(body, traj)


def start_monitor(demo, speed: float = 0.0, loop: bool = False, **dash):
    """A monitor over the demo in a thread, not started, with its dashboard serving."""
    body, spec, times, frames = demo
    src = FileReplaySource("<demo>", body, spec, times, frames, speed=speed, loop=loop)
    mon = Monitor(src, default_config(body, 100.0), alarm_after=0.2)
    server = DashboardServer("127.0.0.1", 0, mon.status, HELLO, **dash)
    server.start()
    mon.listeners.append(server)
    stop = threading.Event()
    return mon, server, stop, threading.Thread(target=mon.run, args=(stop,))


def get(url: str, headers: dict | None = None):
    try:
        with urllib.request.urlopen(urllib.request.Request(url, headers=headers or {}), timeout=5) as r:
            return r.status, dict(r.headers), r.read()
    except urllib.error.HTTPError as e:
        return e.code, dict(e.headers), e.read()


def test_page_and_static_files():
    server = DashboardServer("127.0.0.1", 0, dict, HELLO)
    base = server.start()
    status, headers, body = get(base)
    assert status == 200 and headers["Content-Type"].startswith("text/html")
    assert b'<canvas id="top"' in body and b"dashboard.js" in body
    assert "script-src 'self'" in headers["Content-Security-Policy"] and headers["X-Content-Type-Options"] == "nosniff"
    assert get(base + "dashboard.js")[1]["Content-Type"].startswith("text/javascript")
    assert get(base + "dashboard.css")[1]["Content-Type"].startswith("text/css")
    assert get(base + "secrets.txt")[0] == 404
    assert get(base + "../pyproject.toml")[0] == 404
    server.stop()


def test_feed_carries_every_frame_once_and_the_alarm(demo):
    # at 1000 frames/s a client keeps every point unless it lags MAX_POINTS frames (0.3 s)
    mon, server, stop, runner = start_monitor(demo, speed=10.0)
    with connect(f"ws://127.0.0.1:{server.port}/ws") as ws:
        hello = json.loads(ws.recv(timeout=5))
        assert hello["type"] == "hello" and hello["source"] == "test"
        runner.start()
        start = time.monotonic()
        updates = []
        while not updates or updates[-1]["frame"] is None or updates[-1]["frame"]["index"] < 1199:
            updates.append(json.loads(ws.recv(timeout=10)))
        elapsed = time.monotonic() - start
    runner.join(10)
    points = [p[0] for u in updates for p in u["points"]]
    assert points == list(range(1200))  # each frame's plot point exactly once, in order
    assert len(updates) < 1200 and len(updates) <= 60 * elapsed + 3  # decimated, at most 60 messages/s
    alarms = [a for u in updates for a in u["alarms"]]
    assert [a["event"] for a in alarms] == ["raised", "cleared"] and "ALARM" in alarms[0]["message"]
    last = updates[-1]
    assert last["status"]["results"] <= 1200 and last["frame"]["support"] in ("left", "right", "double")
    assert len(last["frame"]["polygon"]) >= 3 and len(last["frame"]["soles"]["left"]) == 4
    server.stop()


def stalled_client(port: int) -> socket.socket:
    """A WebSocket client that completes the handshake and then never reads."""
    s = socket.socket()
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    s.connect(("127.0.0.1", port))
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
               f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n").encode())
    assert s.recv(12) == b"HTTP/1.1 101"
    return s


def test_a_stalled_client_never_slows_the_pipeline(demo):
    # 1000 frames/s (the demo is 100 Hz, played 10x): the monitor's target rate; flat out, the
    # monitor thread starves this test's own client thread of the GIL on a quiet machine
    mon, server, stop, runner = start_monitor(demo, speed=10.0, loop=True)
    stalled = stalled_client(server.port)
    stalled_peer = f"127.0.0.1:{stalled.getsockname()[1]}"
    with connect(f"ws://127.0.0.1:{server.port}/ws") as ws:
        ws.recv(timeout=5)
        runner.start()
        seen, truncated, early = [], 0, None
        while mon.inputs < 4000:
            points = [p[0] for p in json.loads(ws.recv(timeout=10))["points"]]
            if seen and points and points[0] != seen[-1] + 1:
                assert len(points) == MAX_POINTS  # a gap only where the client lagged: newest points kept
                truncated += 1
            seen += points
            if early is None and mon.inputs >= 2500:
                early = server.client_messages[stalled_peer]
        late = server.client_messages[stalled_peer]
        live = server.client_messages[f"127.0.0.1:{ws.local_address[1]}"]
        stop.set()
        runner.join(10)
    assert mon.results >= 4000 - mon.pipeline.lag  # the loop kept going, frame after frame
    assert np.all(np.diff(seen) > 0) and len(seen) > 2000 and truncated < 5  # the live client kept up
    assert early == late < live / 2  # the stalled one filled its small buffers, then got nothing more
    stalled.close()
    server.stop()


def test_token_required_when_asked_and_origins_checked():
    server = DashboardServer("127.0.0.1", 0, dict, HELLO, token=True)
    url = server.start()
    assert "?token=" in url and len(server.token) >= 20
    base = f"http://127.0.0.1:{server.port}/"
    assert get(base)[0] == 403 and get(base + "?token=wrong")[0] == 403
    assert get(url)[0] == 200
    assert get(base + "dashboard.js")[0] == 200  # static code holds no data
    ws_url = f"ws://127.0.0.1:{server.port}/ws"
    with pytest.raises(InvalidStatus) as e:
        connect(ws_url)
    assert e.value.response.status_code == 403
    with connect(f"{ws_url}?token={server.token}") as ws:
        assert json.loads(ws.recv(timeout=5))["type"] == "hello"
    with pytest.raises(InvalidStatus):
        connect(f"{ws_url}?token={server.token}", origin="http://evil.example")
    with connect(f"{ws_url}?token={server.token}", origin=f"http://127.0.0.1:{server.port}") as ws:
        assert json.loads(ws.recv(timeout=5))["type"] == "hello"
    server.stop()


def test_clients_beyond_the_cap_are_refused_with_503_and_a_closed_one_frees_its_place():
    """MAX_CLIENTS feeds are served at once; the next ones are refused before their handshake (HTTP 503, saying
    why) and counted; the page itself is still served; when a feed closes, a new one takes its place. On main
    every client was served (200 at once: frames up to 614 ms late)."""
    server = DashboardServer("127.0.0.1", 0, dict, HELLO)
    server.start()
    ws_url = f"ws://127.0.0.1:{server.port}/ws"
    clients = [connect(ws_url) for _ in range(MAX_CLIENTS)]
    try:
        assert all(json.loads(c.recv(timeout=5))["type"] == "hello" for c in clients)
        for _ in range(3):
            with pytest.raises(InvalidStatus) as e:
                connect(ws_url)
            assert e.value.response.status_code == 503 and b"too many dashboard clients" in e.value.response.body
        assert server.refused == 3 and get(f"http://127.0.0.1:{server.port}/")[0] == 200
        clients.pop().close()
        deadline = time.monotonic() + 5.0
        while len(server.client_messages) >= MAX_CLIENTS and time.monotonic() < deadline:
            time.sleep(0.01)
        clients.append(connect(ws_url))
        assert json.loads(clients[-1].recv(timeout=5))["type"] == "hello" and server.refused == 3
    finally:
        for c in clients:
            c.close()
        server.stop()


def test_beyond_loopback_needs_allow_remote_and_then_a_token():
    with pytest.raises(InputError, match="--allow-remote"):
        DashboardServer("0.0.0.0", 8765, dict, HELLO)
    remote = DashboardServer("0.0.0.0", 8765, dict, HELLO, allow_remote=True)  # not started: nothing bound
    assert remote.token and remote.url.endswith(f"?token={remote.token}")
    assert DashboardServer("127.0.0.1", 8765, dict, HELLO).token is None


def test_address_parsing():
    assert parse_address("127.0.0.1:8765") == ("127.0.0.1", 8765)
    assert parse_address("[::1]:80") == ("::1", 80)
    for bad in ("8765", "host:", "host:99999", ":80"):
        with pytest.raises(InputError, match="need HOST:PORT"):
            parse_address(bad)


def test_busy_port_is_a_one_line_error():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        server = DashboardServer("127.0.0.1", s.getsockname()[1], dict, HELLO)
        with pytest.raises(InputError, match="cannot listen"):
            server.start()
        server._thread.join(5.0)  # the server's loop has closed: stopping it (the monitor's finally) is a no-op,
        server.stop()  # not 'Event loop is closed' (a traceback after the one-line error, when the loop closed first)
