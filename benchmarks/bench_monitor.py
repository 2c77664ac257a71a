"""Monitor: the input rate it sustains over UDP with the dashboard connected and recording
on, and the input-to-page latency, against the bare pipeline measured in the same run.

A Bandai walk (132 channels) is looped into livezmp JSON frames, encoded beforehand,
and sent by this process at a fixed rate for a few seconds to ``livezmp monitor
udp://...`` running as its own process, with ``--dashboard`` (one WebSocket client
here, reading every message) and, in the second setting, ``--record``. A rate is
sustained when every frame sent was analysed (the monitor's own count, no sequence
number lost), the page saw the last result within 0.2 s of the last send, and the
median system latency (below) stayed under 50 ms: a monitor slower than its input
queues frames in the socket and falls further behind every second.

Latency is from sending frame k to the page receiving frame k's result: "total"
includes the estimator's fixed lag (its look-ahead of L frames, L × frame period);
"system" starts at the send of frame k + L, the input that completes the result,
so it is what transport, analysis, hand-off and the ≤ 60 Hz page feed add.

Baseline: ``Pipeline.step`` over the same frames in this process (no I/O at all).

    python benchmarks/bench_monitor.py           # about 2 minutes
    python benchmarks/bench_monitor.py --quick   # 1000 frames/s only, about 20 s
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
from websockets.sync.client import connect

from livezmp.balance.pipeline import Pipeline, default_config
from livezmp.model.body_spec import read_skeleton, skeleton_body
from livezmp.model.bvh import read_bvh
from livezmp.sources.frame_format import WireFrame, encode_json

ROOT = Path(__file__).resolve().parents[1]
WALK = ROOT.parent / "shared" / "data" / "bvh" / "bandai" / "walk_normal_001.bvh"
DURATION = 3.0  # s of sending per rate


def looped(frames: np.ndarray, n: int) -> np.ndarray:
    return np.tile(frames, (n // len(frames) + 1, 1))[:n]


def pipeline_rate(frames: np.ndarray, fps: float) -> tuple[float, int]:
    """Frames per second of the bare pipeline, and its lag in frames."""
    body, _ = skeleton_body(read_skeleton(WALK))
    pipe = Pipeline(body, default_config(body, fps), 1.0 / fps)
    start = time.perf_counter()
    for k, f in enumerate(frames):
        pipe.step(k / fps, f)
    return len(frames) / (time.perf_counter() - start), pipe.lag


class Page(threading.Thread):
    """A dashboard client: when each frame's plot point arrived (monotonic s)."""

    def __init__(self, url: str):
        super().__init__(daemon=True)
        self.ws = connect(url.replace("http://", "ws://").rstrip("/") + "/ws", max_size=None)
        self.seen: dict[int, float] = {}
        self.last = -1
        self.updates: list[float] = []  # arrival of each message that carried frames

    def run(self) -> None:
        try:
            for text in self.ws:
                now = time.monotonic()
                points = json.loads(text).get("points", [])
                if points:
                    self.updates.append(now)
                for p in points:
                    self.seen[p[0]] = now
                    self.last = p[0]
        except Exception:  # noqa: BLE001 - the monitor closing the connection ends the run
            pass


def send_paced(sock: socket.socket, port: int, packets: list[bytes], rate: float) -> np.ndarray:
    """Send ``packets`` at ``rate`` per second, those due at each 0.5 ms wake-up together
    (a sleeping sender leaves the CPU to the monitor); returns each one's send time."""
    sent = np.empty(len(packets))
    start, k = time.monotonic(), 0
    while k < len(packets):
        now = time.monotonic()
        while k < len(packets) and start + k / rate <= now:
            sock.sendto(packets[k], ("127.0.0.1", port))
            sent[k] = now
            k += 1
        time.sleep(0.0005)
    return sent


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run(rate: float, record: bool, frames: np.ndarray, lag: int, tmp: Path) -> dict:
    n = int(rate * DURATION)
    packets = [encode_json(WireFrame(k, k / rate, f)) for k, f in enumerate(looped(frames, n))]
    port = free_port()
    cmd = [sys.executable, "-m", "livezmp", "monitor", f"udp://127.0.0.1:{port}", "--skeleton", str(WALK),
           "--fps", str(rate), "--dashboard", "127.0.0.1:0", "--alarm-after", "1e9"]
    if record:
        cmd += ["--record", str(tmp / f"bench_{rate:.0f}.mcap")]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, cwd=ROOT)
    try:
        url = next(line.split()[1] for line in proc.stdout if line.startswith("dashboard:"))
        next(line for line in proc.stdout if line.startswith("source:"))
        page = Page(url)
        page.start()
        time.sleep(0.3)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
            sent = send_paced(sock, port, packets, rate)
        want = n - 1 - lag  # the last result before the end-of-stream flush
        end = time.monotonic() + 10
        while page.last < want and time.monotonic() < end:
            time.sleep(0.005)
        drain = page.seen.get(want, float("inf")) - sent[-1]
        proc.send_signal(signal.SIGINT)
        out = proc.communicate(timeout=30)[0]
    finally:
        proc.kill()
    m = re.search(r"monitor: (\d+) frames in, (\d+) analysed", out)
    analysed = int(m.group(2)) if m else 0
    lost = int(x.group(1)) if (x := re.search(r"lost (\d+)", out)) else 0
    idx = np.array([k for k in page.seen if k + lag < n])
    total = np.array([page.seen[k] - sent[k] for k in idx]) * 1000
    system = np.array([page.seen[k] - sent[k + lag] for k in idx]) * 1000
    achieved = (n - 1) / (sent[-1] - sent[0])
    during = [u for u in page.updates if sent[0] + 0.5 <= u <= sent[-1]]  # page updates while frames flowed
    update_hz = (len(during) - 1) / (during[-1] - during[0]) if len(during) > 1 else 0.0
    ok = analysed == n and lost == 0 and drain < 0.2 and np.median(system) < 50
    return {"rate": rate, "achieved": achieved, "analysed": analysed, "sent": n, "lost": lost, "drain": drain,
            "ok": ok, "total": np.percentile(total, [50, 99]), "system": np.percentile(system, [50, 99]),
            "lag_ms": 1000 * lag / rate, "update_hz": update_hz}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1000 frames/s only")
    quick = parser.parse_args().quick
    rates = [1000.0] if quick else [120.0, 500.0, 1000.0, 1500.0, 2000.0, 2500.0]
    frames = read_bvh(WALK).frames
    base, _ = pipeline_rate(looped(frames, 2000), 1000.0)
    print(f"baseline: bare Pipeline.step, same frames, this process: {base:8.0f} frames/s\n")
    print(f"{'setting':24s} {'rate/s':>7s} {'sent/s':>7s} {'analysed':>9s} {'lost':>5s} {'drain ms':>9s} "
          f"{'sustained':>9s} {'page Hz':>8s}  {'total p50/p99 ms':>17s}  {'system p50/p99 ms':>17s}")
    with tempfile.TemporaryDirectory() as tmp:
        for record in (False, True):
            name = "dashboard + recording" if record else "dashboard"
            best = 0.0
            for rate in rates:
                _, lag = pipeline_rate(frames[:1], rate)
                r = run(rate, record, frames, lag, Path(tmp))
                best = max(best, rate) if r["ok"] else best
                drain = f"{1000 * r['drain']:9.0f}" if np.isfinite(r["drain"]) else f"{'never':>9s}"
                print(f"{name:24s} {rate:7.0f} {r['achieved']:7.0f} {r['analysed']:9d} {r['lost']:5d} {drain} "
                      f"{'yes' if r['ok'] else 'no':>9s} {r['update_hz']:8.1f}  "
                      f"{r['total'][0]:8.1f}/{r['total'][1]:<8.1f}  "
                      f"{r['system'][0]:8.1f}/{r['system'][1]:<8.1f}  (lag {r['lag_ms']:.0f} ms)", flush=True)
                if not r["ok"]:
                    break
            print(f"{name:24s} sustained up to {best:.0f} frames/s (bare pipeline: {base:.0f})\n")


if __name__ == "__main__":
    main()
