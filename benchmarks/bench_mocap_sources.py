"""Benchmark: capture streams sustained through livezmp's sources, against the bare clients.

A simulated capture server (LSL publisher, QTM RT server, NatNet server) runs in a
process of its own (the capture PC; here the machine's other core) and plays generated
marker motion — 40 markers and 2 force plates — at 100, 240 and 1000 Hz for a few
seconds. The reader, in this process, is either livezmp's source (``lsl://``,
``qtm://``, ``natnet://``: parsing, ordering, plates, MocapFrames) or the bare client
doing only its own receiving (pylsl ``pull_chunk``; qtm-rt's ``stream_frames`` callback;
a UDP socket after NatNet's connect), side by side.

Columns: frames the server sent; frames delivered in order, lost (numbers skipped)
and late, and those the reader's queue turned away (overflow), so "0 loss" is
delivered = sent; achieved rate; delay of each frame behind its schedule, p50 / p99 ms:
for LSL, from the sample's own stamp (the server's clock, offset-corrected) to the
frame in the reader's hand; for QTM and NatNet, whose stamps are the capture system's own
clock, arrival against the nominal schedule anchored at the earliest frame (the
network and reader delay beyond the fastest frame). The LSL figure carries the error of
LSL's clock-offset estimate (``time_correction``, one round trip under the machine's
load): server and reader share one clock here, so a negative delay is that error.

The whole pipeline (markers → body → ZMP → recording and dashboard) is measured by
``bench_live_capture.py``.

Run: python benchmarks/bench_mocap_sources.py [--seconds 3]
"""

from __future__ import annotations

import argparse
import asyncio
import multiprocessing as mp
import os
import socket
import sys
import time
import uuid
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from machine_load import load_averages

from livezmp.sources import natnet_protocol as nn  # noqa: E402
from livezmp.sources.mocap_factory import open_mocap_source  # noqa: E402
from sim_devices.mocap_trial import generated_trial  # noqa: E402

RATES = (100.0, 240.0, 1000.0)
MARKERS, PLATES = 40, 2


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def serve(kind: str, rate: float, seconds: float, address, ready, go, done) -> None:
    """The capture server process: plays once a client is there and ready (``go``), then
    reports its counters."""
    trial = generated_trial(rate, seconds, MARKERS, PLATES)
    if kind == "lsl":
        from sim_devices.lsl_publisher import LslPublisher

        server = LslPublisher(trial, name=address, source_id=address)
        ready.put(address)
        while not server.has_consumers():
            time.sleep(0.01)
        go.wait(30)
        counters = server.run()
    elif kind == "qtm":
        from sim_devices.qtm_server import QtmServer

        server = QtmServer(trial, loop=False)
        ready.put(server.port)
        while not server.streaming_clients():
            time.sleep(0.01)
        go.wait(30)
        server.start().join()
        counters = server.counters
    else:
        from sim_devices.natnet_server import NatNetServer

        server = NatNetServer(trial, data_port=address, loop=False)
        ready.put(server.command_port)
        while not server.clients:
            time.sleep(0.01)
        go.wait(30)
        server.start().join()
        counters = server.counters
    done.put({"sent": counters.sent, **counters.receiver_view()})
    time.sleep(1.0)  # let the last frames leave before the server goes


def read_livezmp(url: str, go, done) -> dict:
    src = open_mocap_source(url)
    go.set()
    delays, stamps, arrivals = [], [], []
    result = None
    while True:
        f = src.read(0.05)
        if f is not None:
            stamps.append(f.t)
            arrivals.append(f.received)
            if f.latency is not None:
                delays.append(f.latency + (time.monotonic() - f.received))
        elif result is None and not done.empty():
            result = done.get()
        elif result is not None:
            break
    st = src.stats
    src.close()
    if not delays:  # no comparable clock: arrival against the schedule, from the fastest frame
        lag = np.asarray(arrivals) - (np.asarray(stamps) - stamps[0])
        delays = list(lag - lag.min())
    return {**result, "got": st.delivered, "lost": st.lost, "late": st.late, "overflow": st.overflow,
            "span": arrivals[-1] - arrivals[0] if len(arrivals) > 1 else float("nan"), "delays": delays}


def read_bare_lsl(name: str, go, done) -> dict:
    import pylsl

    inlet, plates = (pylsl.StreamInlet(pylsl.resolve_byprop("name", n, 1, 5.0)[0], max_buflen=10)
                     for n in (name, name + " plates"))
    for i in (inlet, plates):
        i.open_stream(5.0)
    offset = inlet.time_correction(5.0)
    go.set()
    n, delays, arrivals, result = 0, [], [], None
    while True:
        plates.pull_chunk(0.0)  # the same work on the plates stream, not counted
        _, ts = inlet.pull_chunk(0.0)
        now = pylsl.local_clock()
        if ts:
            n += len(ts)
            arrivals.append(time.monotonic())
            delays.extend(now - (t + offset) for t in ts)
        elif result is None and not done.empty():
            result = done.get()
        elif result is not None:
            break
        else:
            time.sleep(0.0005)
    return {**result, "got": n, "lost": None, "late": None, "overflow": None,
            "span": arrivals[-1] - arrivals[0], "delays": delays}


def read_bare_qtm(port: int, go, done) -> dict:
    import qtm_rt

    stamps, arrivals = [], []

    async def run():
        conn = await qtm_rt.connect("127.0.0.1", port, version="1.25")
        fut = asyncio.ensure_future(conn.stream_frames(components=["3d", "force"], on_packet=lambda p: (
            stamps.append(p.timestamp * 1e-6), arrivals.append(time.monotonic()))))
        go.set()
        while done.empty():
            await asyncio.sleep(0.05)
        result = done.get()
        await asyncio.sleep(0.3)
        fut.cancel()
        conn.disconnect()
        return result

    result = asyncio.run(run())
    lag = np.asarray(arrivals) - (np.asarray(stamps) - stamps[0])
    return {**result, "got": len(stamps), "lost": None, "late": None, "overflow": None,
            "span": arrivals[-1] - arrivals[0], "delays": list(lag - lag.min())}


def read_bare_natnet(port: int, data_port: int, go, done) -> dict:
    data = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    data.bind(("127.0.0.1", data_port))
    data.settimeout(0.05)
    cmd = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    cmd.sendto(nn.message(nn.CONNECT, nn.connect_payload()), ("127.0.0.1", port))
    go.set()
    stamps, arrivals, result = [], [], None
    while True:
        try:
            packet = data.recv(65536)
        except TimeoutError:
            if result is None and not done.empty():
                result = done.get()
            elif result is not None:
                break
            continue
        arrivals.append(time.monotonic())
        stamps.append(nn.unpack_frame(nn.split(packet)[1]).timestamp)
    data.close()
    cmd.close()
    lag = np.asarray(arrivals) - (np.asarray(stamps) - stamps[0])
    return {**result, "got": len(stamps), "lost": None, "late": None, "overflow": None,
            "span": arrivals[-1] - arrivals[0], "delays": list(lag - lag.min())}


def spawn_server(target, kind: str, rate: float, amount: float):
    """Start the capture server process ``target(kind, rate, amount, address, ready, go, done)``; returns
    (process, where it listens, livezmp's URL for it, NatNet data port, go, done)."""
    ctx = mp.get_context("spawn")
    ready, done, go = ctx.Queue(), ctx.Queue(), ctx.Event()
    data_port = free_udp_port() if kind == "natnet" else None
    address = f"bench-{uuid.uuid4().hex[:8]}" if kind == "lsl" else data_port
    proc = ctx.Process(target=target, args=(kind, rate, amount, address, ready, go, done), daemon=True)
    proc.start()
    where = ready.get(timeout=60)
    url = {"lsl": f"lsl://{where}", "qtm": f"qtm://127.0.0.1:{where}",
           "natnet": f"natnet://127.0.0.1:{where}?data_port={data_port}"}[kind]
    return proc, where, url, data_port, go, done


def run_case(kind: str, reader: str, rate: float, seconds: float) -> dict:
    proc, where, url, data_port, go, done = spawn_server(serve, kind, rate, seconds)
    if reader == "livezmp":
        out = read_livezmp(url, go, done)
    elif kind == "lsl":
        out = read_bare_lsl(where, go, done)
    elif kind == "qtm":
        out = read_bare_qtm(where, go, done)
    else:
        out = read_bare_natnet(where, data_port, go, done)
    proc.join(10)
    return out


def fmt(v, spec="d") -> str:
    return "-" if v is None else format(v, spec)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seconds", type=float, default=3.0)
    p.add_argument("--systems", default="lsl,qtm,natnet")
    args = p.parse_args()
    print(f"load average {load_averages(' ')} "
          f"({os.cpu_count()} cores); {MARKERS} markers + {PLATES} plates, {args.seconds:g} s per row")
    head = (f"{'system':7} {'reader':8} {'rate':>6} {'sent':>6} {'got':>6} {'lost':>5} {'late':>5} {'ovfl':>5} "
            f"{'Hz got':>8} {'p50 ms':>7} {'p99 ms':>7}  delay measured")
    print(head)
    print("-" * len(head))
    for kind in args.systems.split(","):
        for rate in RATES:
            for reader in ("bare", "livezmp"):
                r = run_case(kind, reader, rate, args.seconds)
                d = np.asarray(r["delays"]) * 1e3
                how = "LSL stamp -> in hand" if kind == "lsl" else "arrival vs schedule"
                print(f"{kind:7} {reader:8} {rate:6.0f} {r['sent']:6d} {r['got']:6d} {fmt(r['lost']):>5} "
                      f"{fmt(r['late']):>5} {fmt(r['overflow']):>5} {(r['got'] - 1) / r['span']:8.1f} "
                      f"{np.percentile(d, 50):7.2f} {np.percentile(d, 99):7.2f}  {how}", flush=True)


if __name__ == "__main__":
    main()
