"""Benchmark: a capture stream end to end — from each frame's capture to its ZMP ready and on the
dashboard page — at 100, 240 and 1000 Hz, with recording on, against the transport alone.

A simulated capture server (QTM RT, NatNet, LSL) runs in a process of its own (the capture PC) and
plays the Plug-in Gait walk with its 4 force plates (``walk_plugingait_forceplates.c3d``, 96
labelled points) resampled to the row's rate, ``--laps`` times. This process runs ``livezmp
monitor``'s loop on it (the marker body calibrated on the same file; the real clients; recording
to MCAP; the dashboard with one WebSocket page reading every message).

Times are all on this machine's monotonic clock (the server process shares it): a frame's
"capture" is when the server handed it to its socket (the camera's frame time on this clock;
QTM's and NatNet's own stamps are their capture clocks, which a real client cannot relate to
its own). The estimator gives frame k's result when frame k + L arrives (its configured lag L
frames, stated apart), so the work beyond the lag is measured from the capture of frame k + L:

- ``in hand``: capture -> the MocapFrame in livezmp's source (the transport and the client: the
  baseline, measured on the same frames);
- ``result``: capture of k + L -> frame k's result analysed, recorded and handed to the dashboard;
- ``page``: capture of k + L -> the page receiving frame k's point (the page feed sends at most
  60 messages a second, so this includes up to ~17 ms of waiting for the next message).

Columns: frames sent, analysed, lost + late + overflow (0 = sustained without loss), p50/p99 ms.
Target: p99 of ``result`` within 5 ms at 240 Hz; 1000 Hz with 0 frames lost. ``result`` is taken when
the dashboard has the frame; its recording follows on the same thread (in ``monitor`` CPU below).

CPU per frame (ms of CPU time per input frame, this process's threads; the load average of the
minute is printed beside each row since the machine may be shared):

- the monitor thread by stage: ``read`` (the source's queue and the marker body: frames already
  waiting are converted together), ``pipeline`` (Pipeline.step), ``record`` (MCAP input, result,
  scene), ``dash`` (the hand-off to the dashboard), and the monitor thread's total;
- ``client``: the capture client's receiving thread (qtm-rt's asyncio loop and livezmp's parsing; the
  NatNet receiver; LSL's pulls run in the monitor thread, under ``read``);
- ``server``: the dashboard's thread (the page feed); ``all``: the whole process (with the page
  client, which a browser would be).

Then per-frame CPU of each stage measured offline on the same walk at 240 Hz, old against new in
one run: QTM packets read by qtm-rt's records against livezmp's numpy blocks; the marker body
one frame per call against 32 frames per call (what a reader behind its stream does); then the
pipeline, the recording (input, result and its Foxglove scene) and the dashboard hand-off.

Run: python benchmarks/bench_live_capture.py [--laps 2] [--systems qtm,natnet,lsl] [--rates 100,240,1000]
     [--realtime-priority 50]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from collections import deque
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_mocap_sources import spawn_server  # noqa: E402
from bench_monitor import Page  # noqa: E402

from livezmp.balance.pipeline import Pipeline, default_config  # noqa: E402
from livezmp.live.realtime import realtime_priority  # noqa: E402
from livezmp.monitor.dashboard import DashboardServer  # noqa: E402
from livezmp.monitor.loop import Monitor  # noqa: E402
from livezmp.recording.writer import Recorder  # noqa: E402
from livezmp.sources.factory import SourceOptions, open_source  # noqa: E402
from livezmp.sources.interface import ErrorLog, SourceStats  # noqa: E402

TRIAL = ROOT.parent / "shared" / "data" / "c3d" / "walk_plugingait_forceplates.c3d"
RATES = (100.0, 240.0, 1000.0)


def serve(kind: str, rate: float, laps: int, address, ready, go, done) -> None:
    """The capture server process: plays once a client is connected and the monitor runs (``go``);
    reports each frame's send time."""
    from sim_devices.mocap_trial import load_c3d_trial, resampled

    trial = resampled(load_c3d_trial(str(TRIAL)), rate)
    frames = laps * trial.n_frames
    sent: dict[int, float] = {}

    def logged(send):
        def out(f):
            sent[f.number] = time.monotonic()
            send(f)
        return out

    if kind == "lsl":
        from sim_devices.lsl_publisher import LslPublisher

        server = LslPublisher(trial, name=address, source_id=address, loop=True, max_frames=frames)
        ready.put(address)
        go.wait(60)
        server.player.play(logged(server._send))
    else:
        if kind == "qtm":
            from sim_devices.qtm_server import QtmServer

            server = QtmServer(trial, loop=True, max_frames=frames)
            ready.put(server.port)
            connected = server.streaming_clients
        else:
            from sim_devices.natnet_server import NatNetServer

            server = NatNetServer(trial, data_port=address, loop=True, max_frames=frames)
            ready.put(server.command_port)
            connected = lambda: bool(server.clients)  # noqa: E731
        while not connected():
            time.sleep(0.01)
        go.wait(60)
        server.player.start(logged(server._frame), "camera")
        server.player.join()
    done.put({"sent": sent, "counters": server.counters.receiver_view()})
    time.sleep(1.0)


class Timing:
    """A monitor listener: when each result was handed over (after recording and the dashboard)."""

    def __init__(self):
        self.ready: dict[int, float] = {}

    def publish(self, r, cop=None) -> None:
        self.ready[r.index] = time.monotonic()

    def alarm(self, ev) -> None:
        pass


class StageClock:
    """CPU time (``time.thread_time``, s) spent in wrapped calls, per stage."""

    def __init__(self):
        self.cpu: dict[str, float] = {}

    def wrap(self, stage: str, fn):
        self.cpu.setdefault(stage, 0.0)

        def timed(*args, **kwargs):
            t = time.thread_time()
            try:
                return fn(*args, **kwargs)
            finally:
                self.cpu[stage] += time.thread_time() - t
        return timed


TICK = os.sysconf("SC_CLK_TCK")


def thread_cpu(thread: threading.Thread | None) -> float:
    """CPU time (s, user + system) of a running thread, from /proc (10 ms resolution); 0 without."""
    if thread is None or thread.native_id is None:
        return 0.0
    try:
        with open(f"/proc/self/task/{thread.native_id}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / TICK


class InHand:
    """The source, noting when each input frame reached livezmp (the transport's share)."""

    def __init__(self, source):
        self.source, self.received = source, []

    def __getattr__(self, name):
        return getattr(self.source, name)

    def read(self, timeout):
        f = self.source.read(timeout)
        if f is not None:
            self.received.append(f.received)
        return f


def run_case(kind: str, rate: float, laps: int, tmp: Path) -> dict:
    proc, _, url, _, go, done = spawn_server(serve, kind, rate, laps)
    source = InHand(open_source(url, SourceOptions(calibration=str(TRIAL))))
    fps = 1.0 / source.nominal_dt
    session = {"source": url, "fps": fps, "mode": "full", "ground_z": source.ground_z, "alarm_after": 1e9,
               "correct": False}
    recorder = Recorder(str(tmp / f"{kind}_{rate:.0f}.mcap"), source.body_spec, session, source.body.channel_names)
    timing = Timing()
    cfg = default_config(source.body, fps, "full", source.ground_z)
    monitor = Monitor(source, cfg, alarm_after=1e9, recorder=recorder)
    dash = DashboardServer("127.0.0.1", 0, monitor.status, {"source": url})
    page = Page(dash.start())
    page.start()
    clock = StageClock()
    source.read = clock.wrap("read", source.read)
    monitor.pipeline.step = clock.wrap("pipeline", monitor.pipeline.step)
    for name in ("input", "result", "write", "tick"):
        setattr(recorder, name, clock.wrap("record", getattr(recorder, name)))
    dash.publish = clock.wrap("dash", dash.publish)
    monitor.listeners += [dash, timing]
    stop = threading.Event()
    loop = threading.Thread(target=monitor.run, args=(stop,), daemon=True)
    loop.start()
    client = getattr(source.source.mocap, "_thread", None)
    threads = {"client": client, "server": dash._thread, "monitor": loop}
    go.set()
    cpu0 = {k: thread_cpu(t) for k, t in threads.items()} | {"all": time.process_time()}
    result = done.get(timeout=600)
    load = os.getloadavg()[0]
    lag = monitor.pipeline.lag
    want = len(result["sent"]) - 1 - lag
    end = time.monotonic() + 10
    while page.last < want and time.monotonic() < end:
        time.sleep(0.01)
    cpu1 = {k: thread_cpu(t) for k, t in threads.items()} | {"all": time.process_time()}  # a late reader's too
    stop.set()
    loop.join(30)
    dash.stop()
    proc.join(10)
    sent, st = result["sent"], source.stats
    # input index k is frame number k when nothing was lost or late (checked in the table)
    n = min(len(source.received), len(sent))
    in_hand = np.array([source.received[k] - sent[k] for k in range(n)])
    ks = [k for k in timing.ready if k + lag in sent]
    res = np.array([timing.ready[k] - sent[k + lag] for k in ks])
    pg = np.array([page.seen[k] - sent[k + lag] for k in ks if k in page.seen])
    per = 1e3 / max(1, len(sent))  # ms per frame sent
    cpu = {k: v * per for k, v in clock.cpu.items()} | {k: (cpu1[k] - cpu0[k]) * per for k in cpu1}
    return {"sent": len(sent), "analysed": monitor.results, "lost": st.lost + st.late + st.overflow + st.dropped,
            "lag_frames": lag, "lag_ms": 1e3 * lag / fps, "in_hand": in_hand * 1e3, "result": res * 1e3,
            "page": pg * 1e3, "cpu": cpu, "load": load}


def pct(x: np.ndarray) -> str:
    return f"{np.percentile(x, 50):6.2f} {np.percentile(x, 99):6.2f}" if len(x) else f"{'-':>6} {'-':>6}"


CPU_COLUMNS = ("read", "pipeline", "record", "dash", "monitor", "client", "server", "all")


def offline_stages(rate: float = 240.0) -> None:
    """Per-frame CPU (ms) of the stages on the walk's frames, without the network: old against new."""
    from dataclasses import replace

    from qtm_rt.packet import QRTPacket

    from livezmp.model.c3d import read_c3d
    from livezmp.model.markers import MarkerBodyOptions
    from livezmp.model.plate_frame import plate_axes
    from livezmp.sources.marker_stream import MarkerStreamSource
    from livezmp.sources.qtm import frame_of_packet, parse_parameters
    from sim_devices import qtm_server as qs
    from sim_devices.mocap_trial import TrialPlayer, load_c3d_trial, resampled

    trial = resampled(load_c3d_trial(str(TRIAL)), rate)
    axes = [plate_axes(c) for c in trial.corners]
    params = parse_parameters(qs.parameters_xml(trial, "1.25", ["all"]), "bench")
    packets = [qs.data_packet(trial, f, [qs.COMPONENT_3D, qs.COMPONENT_FORCE], axes)[qs.HEADER.size:]
               for f in TrialPlayer(trial, speed=0).frames()]

    def per_frame(fn) -> float:
        t = time.process_time()
        fn()
        return 1e3 * (time.process_time() - t) / len(packets)

    def qtm_rt_records():  # the client's own records, one per marker and plate sample, into the same arrays
        for b in packets:
            p = QRTPacket(b)
            np.array([(m.x, m.y, m.z) for m in p.get_3d_markers()[1]], float) * 1e-3
            for info, samples in p.get_force()[1]:
                s, (R, origin) = samples[-1], params.axes[info.id - 1]
                R @ (s.x, s.y, s.z), R @ (s.x_m, s.y_m, s.z_m), R @ (np.array([s.x_a, s.y_a, s.z_a]) * 1e-3) + origin

    frames = [frame_of_packet(QRTPacket(b), params, 0.0) for b in packets]
    calibration = read_c3d(str(TRIAL))

    class Replay:  # the frames as a connected stream that is never waited for
        name, nominal_dt, up, labels, finished = "bench", 1 / rate, params.up, params.labels, False
        stats, errors = SourceStats(), ErrorLog()

        def __init__(self):
            self.left = deque(frames)

        def read(self, timeout):
            return self.left.popleft() if self.left else None

        def close(self):
            pass

    def convert(batch: int):
        src = MarkerStreamSource(Replay(), calibration, replace(MarkerBodyOptions(), total_mass=70.0), batch=batch)
        return lambda: [src.read(0.0) for _ in frames]

    rows = [("QTM packet -> MocapFrame", per_frame(qtm_rt_records), per_frame(
                lambda: [frame_of_packet(QRTPacket(b), params, 0.0) for b in packets])),
            ("marker body (channels)", per_frame(convert(1)), per_frame(convert(32)))]
    src = MarkerStreamSource(Replay(), calibration, replace(MarkerBodyOptions(), total_mass=70.0))
    inputs = list(iter(lambda: src.read(0.0), None))
    pipeline = Pipeline(src.body, default_config(src.body, rate, "full", src.ground_z), 1 / rate)
    results = []
    rows.append(("pipeline (Pipeline.step)", None, per_frame(lambda: results.extend(
        pipeline.step(f.t, f.channels, f.contacts, f.gravity) for f in inputs))))
    results = [r for r in results if r is not None]
    with tempfile.TemporaryDirectory() as tmp:
        rec = Recorder(f"{tmp}/stages.mcap", src.body_spec, {"fps": rate}, src.body.channel_names)
        cops = [None if f.cop is None or np.isnan(f.cop[0]) else f.cop for f in inputs]  # z up: the result's axes
        rows.append(("recording (input + result)", None, per_frame(lambda: (
            [rec.input(k, f.t, f.channels, f.contacts, f.gravity) for k, f in enumerate(inputs)],
            [rec.result(r, cops[r.index]) for r in results]))))
        rec.close()
    dash = DashboardServer("127.0.0.1", 0, dict, {})
    dash.start()
    rows.append(("dashboard hand-off", None, per_frame(lambda: [dash.publish(r) for r in results])))
    dash.stop()
    print(f"\nper-frame CPU offline (ms), walk at {rate:g} Hz, {len(packets)} frames")
    print(f"{'stage':28} {'old':>7} {'new':>7}   (old: qtm-rt's records / one frame per call; "
          "new: numpy blocks / 32 frames per call)")
    for name, old, new in rows:
        print(f"{name:28} {'-' if old is None else format(old, '7.3f'):>7} {new:7.3f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--laps", type=int, default=2, help="times the 2.2 s walk is played per row")
    p.add_argument("--systems", default="qtm,natnet,lsl")
    p.add_argument("--rates", default=",".join(f"{r:g}" for r in RATES), help="Hz, comma separated")
    p.add_argument("--realtime-priority", type=int, default=0,
                   help="as livezmp monitor's: this process's threads under SCHED_FIFO (0: normal scheduling)")
    args = p.parse_args()
    la = os.getloadavg()
    print(f"load average {la[0]:.2f} {la[1]:.2f} {la[2]:.2f} ({os.cpu_count()} cores); Plug-in Gait walk, "
          f"4 plates, {args.laps} laps per row; recording + dashboard page on")
    head = (f"{'system':7} {'rate':>5} {'sent':>6} {'analysed':>8} {'lost':>5} {'lag ms':>7}   "
            f"{'in hand p50/p99':>15}   {'result p50/p99':>14}   {'page p50/p99':>13}  (ms beyond the lag)   "
            f"CPU ms/frame: {' '.join(f'{c:>8}' for c in CPU_COLUMNS)}   load")
    print(head)
    print("-" * len(head))
    with tempfile.TemporaryDirectory() as tmp, realtime_priority(args.realtime_priority) as refused:
        if args.realtime_priority:
            print(f"SCHED_FIFO priority {args.realtime_priority}: {refused or 'granted'} (the servers: normal)")
        for kind in args.systems.split(","):
            for rate in (float(r) for r in args.rates.split(",")):
                r = run_case(kind, rate, args.laps, Path(tmp))
                cpu = " ".join(f"{r['cpu'].get(c, 0.0):8.3f}" for c in CPU_COLUMNS)
                print(f"{kind:7} {rate:5.0f} {r['sent']:6d} {r['analysed']:8d} {r['lost']:5d} {r['lag_ms']:7.1f}   "
                      f"{pct(r['in_hand'])}     {pct(r['result'])}     {pct(r['page'])}                       "
                      f"{cpu}   {r['load']:4.1f}", flush=True)
    offline_stages()


if __name__ == "__main__":
    main()
