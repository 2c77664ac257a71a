"""Live capture streams through the real clients (qtm-rt, pylsl, livezmp's NatNet client)
against the simulated servers playing a real C3D gait trial: markers and force plates
arrive equal to the file, rate / units / up axis are read from the stream, drops, late
frames and gaps are counted exactly, and a server that goes away is re-connected."""

from __future__ import annotations

import math
import re
import socket
import struct
import threading
import time
import uuid
from dataclasses import replace

import numpy as np
import pytest
from data_paths import C3D
from sim_support import wait_until

from livezmp.errors import InputError
from livezmp.model.plate_frame import plate_axes
from livezmp.sources.mocap_factory import open_mocap_source
from sim_devices.impairments import Impairments
from sim_devices.lsl_publisher import LslPublisher
from sim_devices.mocap_trial import load_c3d_trial
from sim_devices.natnet_server import NatNetServer
from sim_devices.qtm_server import QtmServer

TRIAL = C3D / "walk_plugingait_forceplates.c3d"
IMPAIRED = Impairments(noise_pos=0.0, gap=0.02, drop=0.04, late=0.04, seed=7)
F32 = 2e-6  # m / N: the streams carry float32
IDENTITY = np.eye(3)


@pytest.fixture(scope="module")
def trial():
    return load_c3d_trial(str(TRIAL))


def collect(src, until, deadline: float = 10.0) -> list:
    """Frames read until ``until(frames)`` holds or ``deadline`` s pass."""
    out, end = [], time.monotonic() + deadline
    while not until(out) and time.monotonic() < end:
        f = src.read(0.05)
        if f is not None:
            out.append(f)
    return out


def assert_equal_to_trial(frames, trial, number, R=IDENTITY):
    """Every frame's markers (those not made missing) and plates equal the trial's frame
    ``number(f)`` (in axes R·lab); a marker missing in the file is missing in the stream."""
    for f in frames:
        i = number(f)
        seen = ~np.isnan(f.markers[:, 0])
        assert not np.any(seen & np.isnan(trial.markers[i, :, 0]))
        np.testing.assert_allclose(f.markers[seen] @ R, trial.markers[i][seen], atol=F32)
        np.testing.assert_allclose(f.plates.force @ R, trial.force[i], atol=F32 * 1e3)
        np.testing.assert_allclose(f.plates.cop @ R, trial.cop[i], atol=F32, equal_nan=True)


def expected_gaps(trial, frames, number) -> int:
    """Marker samples the stream left missing that the file has."""
    return sum(int(np.count_nonzero(np.isnan(f.markers[:, 0]) & ~np.isnan(trial.markers[number(f), :, 0])))
               for f in frames)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_plate_axes_from_corners():
    # a 600 x 400 mm plate turned 30° about the vertical, centred at (1, 2, 0): C3D corner order
    a = np.radians(30)
    Rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    local = np.array([[0.3, 0.2, 0], [-0.3, 0.2, 0], [-0.3, -0.2, 0], [0.3, -0.2, 0]])
    R, origin = plate_axes(local @ Rz.T + [1, 2, 0])
    np.testing.assert_allclose(R, Rz @ np.diag([1, 1, 1]), atol=1e-12)
    np.testing.assert_allclose(origin, [1, 2, 0], atol=1e-12)


def test_qtm_markers_and_plates_arrive_with_exact_counts(trial):
    server = QtmServer(trial, impairments=IMPAIRED, speed=0, loop=False)
    src = open_mocap_source(f"qtm://127.0.0.1:{server.port}")
    assert (src.nominal_dt, src.params.up, src.params.labels) == (0.01, "+z", trial.labels)
    assert wait_until(lambda: server.streaming_clients() == 1)
    server.start()
    server.join()
    view = server.counters.receiver_view()
    frames = collect(src, lambda out: len(out) == view["delivered"])
    assert [src.stats.delivered, src.stats.late, src.stats.lost] == [view["delivered"], view["late"], view["lost"]]
    assert view["late"] > 0 and view["lost"] > view["late"]
    assert_equal_to_trial(frames, trial, lambda f: f.frame - 1)
    assert expected_gaps(trial, frames, lambda f: f.frame - 1) == server.counters.gaps > 0
    assert np.diff([f.t for f in frames]).min() > 0 and all(f.latency is None for f in frames)
    src.close()
    server.close()


def test_qtm_server_that_goes_away_is_reconnected(trial):
    server = QtmServer(trial, speed=2.0, loop=True).start()
    port = server.port
    src = open_mocap_source(f"qtm://127.0.0.1:{port}")
    assert len(collect(src, lambda out: len(out) >= 5)) >= 5
    server.close()
    assert wait_until(lambda: any(e.kind == "disconnected" for e in src.errors.drain()), 3.0)
    server = QtmServer(trial, port=port, speed=2.0, loop=True).start()  # QTM back on its port
    after = collect(src, lambda out: len(out) >= 5 and any(f.restart for f in out[:-4]))
    assert len(after) >= 5 and src.stats.reconnects == 1
    # the new server's numbers and clock start afresh (frames of the old one may still wait before them): its
    # first frame delivered restarts the analysis
    assert sum(f.restart for f in after) == 1
    src.close()
    server.close()


def test_qtm_refuses_what_it_cannot_serve(trial):
    server = QtmServer(trial)
    with pytest.raises(InputError, match="version not accepted"):
        open_mocap_source(f"qtm://127.0.0.1:{server.port}?version=1.2")
    with pytest.raises(InputError, match="unknown parameter 'rate'"):
        open_mocap_source(f"qtm://127.0.0.1:{server.port}?rate=3")
    server.close()


def qtm_frequency(monkeypatch, text: str | None) -> None:
    """Every simulated QTM server's parameters say General/Frequency ``text`` (None: the trial's rate)."""
    from sim_devices import qtm_server as qs

    real = qs.parameters_xml.__wrapped__ if hasattr(qs.parameters_xml, "__wrapped__") else qs.parameters_xml

    def patched(*args, **kwargs):
        return re.sub(r"(<General><Frequency>)[^<]*", lambda m: m[1] + text, real(*args, **kwargs), count=1)

    patched.__wrapped__ = real
    monkeypatch.setattr(qs, "parameters_xml", real if text is None else patched)


@pytest.mark.parametrize(("frequency", "message"), [
    ("abc", "parameters XML General/Frequency: need a number, got 'abc'"),
    ("nan", "parameters XML General/Frequency: need a number, got 'nan'"),
    ("0", "parameters XML General/Frequency: need a positive number of Hz, got 0"),
    ("1e9", "parameters XML General/Frequency 1e+09 Hz: frame period 1e-09 s is outside"),
])
def test_qtm_parameters_without_a_usable_frequency_are_a_one_line_error(trial, monkeypatch, frequency, message):
    """(qtm-rt's float() raised ValueError, 0 a ZeroDivisionError in nominal_dt.) At once, not after the
    connection's timeout."""
    qtm_frequency(monkeypatch, frequency)
    server = QtmServer(trial)
    t0 = time.monotonic()
    with pytest.raises(InputError) as info:
        open_mocap_source(f"qtm://127.0.0.1:{server.port}")
    assert str(info.value).startswith(f"qtm://127.0.0.1:{server.port}: {message}") and "\n" not in str(info.value)
    assert time.monotonic() - t0 < 3.0
    server.close()


def test_qtm_parameters_refused_on_a_reconnect_are_counted_and_the_client_goes_on(trial, monkeypatch):
    """QTM restarted with a frequency that is not a number: the reconnect's parameters are counted as
    malformed (each retry), the client's thread lives on, and QTM back with good parameters streams again."""
    server = QtmServer(trial, speed=2.0, loop=True).start()
    port = server.port
    src = open_mocap_source(f"qtm://127.0.0.1:{port}")
    assert len(collect(src, lambda out: len(out) >= 5)) >= 5
    server.close()
    qtm_frequency(monkeypatch, "fast")
    server = QtmServer(trial, port=port, speed=2.0, loop=True).start()
    assert wait_until(lambda: src.stats.malformed >= 1, 5.0)
    assert src._thread.is_alive() and src.stats.reconnects == 0
    errors = src.errors.drain()
    assert any(e.kind == "malformed" and "General/Frequency: need a number, got 'fast'" in e.message for e in errors)
    qtm_frequency(monkeypatch, None)
    after = collect(src, lambda out: len(out) >= 5 and any(f.restart for f in out[:-4]))
    assert len(after) >= 5 and src.stats.reconnects == 1 and src.nominal_dt == 0.01
    src.close()
    server.close()


def lsl_pair(trial, imp=None, **kw):
    name = f"livezmp-test-{uuid.uuid4().hex[:8]}"
    pub = LslPublisher(trial, name=name, source_id=name, impairments=imp, **kw)
    src = open_mocap_source(f"lsl://{name}")
    assert wait_until(pub.has_consumers, 5.0)
    return pub, src


def test_lsl_markers_and_plates_arrive_with_exact_counts(trial):
    pub, src = lsl_pair(trial, IMPAIRED, speed=4.0)
    assert (src.rate, src.up, src.labels, src.plate_names) == (100.0, "+z", trial.labels, trial.plate_names)
    pub.run()
    view = pub.counters.receiver_view()
    frames = collect(src, lambda out: len(out) == view["delivered"])
    assert [src.stats.delivered, src.stats.late, src.stats.lost] == [view["delivered"], view["late"], view["lost"]]
    assert_equal_to_trial(frames, trial, lambda f: f.frame)
    assert expected_gaps(trial, frames, lambda f: f.frame) == pub.counters.gaps > 0
    src.close()


def test_lsl_stream_without_up_axis_needs_one(trial):
    import pylsl

    from sim_devices.lsl_publisher import marker_info

    name = f"livezmp-test-{uuid.uuid4().hex[:8]}"
    info = marker_info(trial, name, name)
    bare = pylsl.StreamInfo(name, "MoCap", info.channel_count(), 100.0, pylsl.cf_float32, name)
    chans = bare.desc().append_child("channels")
    for label in trial.labels:
        for axis in "XYZ":
            c = chans.append_child("channel")
            c.append_child_value("label", f"{label}_{axis}")
            c.append_child_value("type", f"Position{axis}")
            c.append_child_value("unit", "mm")
    outlet = pylsl.StreamOutlet(bare)
    with pytest.raises(InputError, match=r"does not say its up axis.*\?up=z"):
        open_mocap_source(f"lsl://{name}?plates=none")
    src = open_mocap_source(f"lsl://{name}?plates=none&up=y")
    assert src.up == "+y" and src.labels == trial.labels and src.plates is None
    src.close()
    del outlet


def test_lsl_samples_stamped_nan_or_back_in_time_are_dropped_and_a_new_clock_followed(trial):
    """A sample stamped NaN (int(nan) raised out of read(): the monitor stopped) is dropped as malformed; a
    sender whose clock jumps 100 s back is followed at its 8th sample (the 7 before it dropped as late), which
    restarts the analysis."""
    import pylsl

    from sim_devices.lsl_publisher import marker_info

    name = f"livezmp-test-{uuid.uuid4().hex[:8]}"
    outlet = pylsl.StreamOutlet(marker_info(trial, name, name))
    src = open_mocap_source(f"lsl://{name}?plates=none")
    t0, row = pylsl.local_clock(), np.zeros(3 * len(trial.labels))
    stamps = [t0 + 0.01 * k for k in range(10)] + [math.nan] + [t0 - 100.0 + 0.01 * k for k in range(20)]
    for stamp in stamps:
        outlet.push_sample(row, stamp)
    frames = collect(src, lambda out: len(out) >= 10 + 20 - 7, deadline=3.0)
    assert len(frames) == 23 and (src.stats.malformed, src.stats.late, src.stats.resyncs) == (1, 7, 1)
    assert [f.restart for f in frames].index(True) == 10 and sum(f.restart for f in frames) == 1
    src.close()
    del outlet


def test_lsl_frames_waiting_for_a_slow_reader_stay_bounded(trial):
    """A reader slower than the stream: each read pulls every sample liblsl holds and hands
    out one; the frames waiting are capped at the inlet's own buffer (10 s), the rest
    counted as overflow, however long the reader lags."""
    import pylsl

    from sim_devices.lsl_publisher import marker_info

    name = f"livezmp-test-{uuid.uuid4().hex[:8]}"
    outlet = pylsl.StreamOutlet(marker_info(trial, name, name))
    src = open_mocap_source(f"lsl://{name}?plates=none")
    assert wait_until(outlet.have_consumers, 5.0)
    bound = int(10 * src.rate)
    row, sent, t0 = [0.0] * (3 * len(trial.labels)), 0, pylsl.local_clock()
    for _ in range(6):  # 6 bursts of 8 s of frames, one frame read after each
        stamps = [t0 + (sent + i) / src.rate for i in range(800)]
        outlet.push_chunk([row] * 800, stamps)
        sent += 800
        assert wait_until(lambda n=sent: src.read(0.0) is not None and src.stats.delivered >= n, 5.0)
    assert len(src._pending) <= bound
    assert src.stats.delivered == sent and src.stats.overflow > 0
    src.close()
    del outlet


def test_lsl_publisher_that_goes_away_is_reconnected(trial):
    pub, src = lsl_pair(trial, speed=1.0, loop=True, plates=False)
    player = threading.Thread(target=pub.run, daemon=True)
    player.start()
    before = collect(src, lambda out: len(out) >= 20)
    # played in real time and read as it comes: latency = stamp (the frame's due time, on
    # the same LSL clock) to arrival; the reader polls at 2 kHz
    lat = np.array([f.latency for f in before[5:]])
    assert np.all(lat > 0) and np.all(lat < 0.05), lat
    pub.close()
    player.join(5.0)
    del pub
    collect(src, lambda out: False, deadline=0.7)  # what was in flight, then silence
    pub2 = LslPublisher(trial, name=src.name[len("lsl://"):], source_id=src.name[len("lsl://"):], speed=1.0,
                        loop=True, plates=False)
    player = threading.Thread(target=pub2.run, daemon=True)
    player.start()
    after = collect(src, lambda out: len(out) >= 5, deadline=15.0)
    assert len(after) >= 5 and src.stats.reconnects == 1
    pub2.stop()
    player.join(5.0)
    src.close()


def test_natnet_markers_and_plates_arrive_with_exact_counts(trial):
    data_port = free_udp_port()
    server = NatNetServer(trial, data_port=data_port, impairments=IMPAIRED, speed=4.0, loop=False)
    src = open_mocap_source(f"natnet://127.0.0.1:{server.command_port}?data_port={data_port}")
    assert (src.up, src.labels, len(src.plate_names)) == ("+y", trial.labels, len(trial.plate_names))
    server.start()
    server.join()
    view = server.counters.receiver_view()
    frames = collect(src, lambda out: len(out) == view["delivered"])
    assert [src.stats.delivered, src.stats.late, src.stats.lost] == [view["delivered"], view["late"], view["lost"]]
    assert src.stats.kernel_drops == 0  # counted (SO_RXQ_OVFL): the loopback stream kept up
    assert_equal_to_trial(frames, trial, lambda f: f.frame, R=server.R)  # stream: y up
    assert expected_gaps(trial, frames, lambda f: f.frame) == server.counters.gaps > 0
    assert src.nominal_dt == pytest.approx(0.01)
    # a datagram that is not NatNet is counted, never delivered
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(b"\x07\x00\xff\xff junk", ("127.0.0.1", data_port))
    assert collect(src, lambda out: src.stats.malformed == 1, deadline=2.0) == []
    src.close()
    server.close()


def test_natnet_server_that_goes_away_is_reconnected(trial):
    data_port = free_udp_port()
    server = NatNetServer(trial, data_port=data_port, speed=2.0, loop=True).start()
    port = server.command_port
    src = open_mocap_source(f"natnet://127.0.0.1:{port}?data_port={data_port}")
    assert len(collect(src, lambda out: len(out) >= 5)) >= 5
    server.close()
    collect(src, lambda out: False, deadline=0.5)  # what was in flight, then silence
    server = NatNetServer(trial, command_port=port, data_port=data_port, speed=2.0, loop=True)
    src.read(1.5)  # past the retry interval: the client connects again
    assert wait_until(lambda: server.clients, 1.0)
    server.start()  # numbers from 0 again, below the first server's last: not late
    after = collect(src, lambda out: len(out) >= 5)
    assert len(after) >= 5 and src.stats.reconnects == 1 and src.stats.late == 0
    assert after[0].frame == 0 and after[0].restart and not any(f.restart for f in after[1:])
    src.close()
    server.close()


def test_natnet_stray_datagrams_never_stop_the_stream():
    """One datagram each (from loopback, to the client's data port): a frame numbered far ahead (every later
    frame was late: locked out), a skeleton bone whose quaternion is NaN (the receiving thread died on it: no
    frame ever again), a frame whose time goes back (the monitor stopped on it). Each is dropped or read
    as untracked, and the frames that follow them are read."""
    import livezmp.sources.natnet_protocol as nn
    from sim_devices.mocap_trial import generated_trial

    trial = generated_trial(100.0, 2.0, n_markers=3, n_plates=1)
    n = trial.n_frames
    trial = replace(trial, segment_names=("pelvis",), segment_pos=trial.markers[:, :1],
                    segment_rot=np.tile(np.eye(3), (n, 1, 1, 1)))
    data_port = free_udp_port()
    server = NatNetServer(trial, data_port=data_port, speed=1.0, loop=False, max_frames=20)
    src = open_mocap_source(f"natnet://127.0.0.1:{server.command_port}?data_port={data_port}")
    server.start()
    served = collect(src, lambda out: len(out) == 20, deadline=3.0)  # then the server is silent: only ours come
    assert len(served) == 20 and served[-1].segments.tracked.all()
    last = served[-1]

    def stray(number: int, t: float, quat) -> bytes:
        bone = {1: {1: nn.Pose(np.zeros(3), np.array(quat, float))}}
        return nn.message(nn.FRAMEOFDATA, nn.pack_frame(nn.FrameOfData(number, {"trial": trial.markers[0]}, {}, t,
                                                                          skeletons=bone)))
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        for packet in (stray(last.frame + 10**6, last.t + 0.02, [0, 0, 0, 1]),  # dropped: jumps
                       stray(last.frame + 1, last.t + 0.01, [np.nan, 0, 0, 1]),  # delivered, its bone untracked
                       stray(last.frame + 2, last.t - 1.0, [0, 0, 0, 1]),  # dropped: time goes back (malformed)
                       *(stray(last.frame + k, last.t + 0.01 * k, [0, 0, 0, 1]) for k in range(2, 12))):
            s.sendto(packet, ("127.0.0.1", data_port))
    after = collect(src, lambda out: len(out) >= 11, deadline=3.0)
    assert [f.frame for f in after] == list(range(last.frame + 1, last.frame + 12))
    assert not after[0].segments.tracked.any() and all(f.segments.tracked.all() for f in after[1:])
    assert not any(f.restart for f in after[1:])  # (the first restarts if the client reconnected in the silence)
    assert (src.stats.jumps, src.stats.malformed) == (1, 1)
    src.close()
    server.close()


def test_natnet_takes_frames_from_the_server_only():
    """Off loopback the data port listens on every interface: a frame any host sent it was taken as the
    server's. Datagrams from another address (here 127.0.0.2) are counted as rejected and dropped; the same
    frames from the server's address are read."""
    import livezmp.sources.natnet_protocol as nn
    from sim_devices.mocap_trial import generated_trial

    trial = generated_trial(100.0, 2.0, n_markers=3, n_plates=1)
    data_port = free_udp_port()
    server = NatNetServer(trial, data_port=data_port, speed=1.0, loop=False, max_frames=5)
    src = open_mocap_source(f"natnet://127.0.0.1:{server.command_port}?data_port={data_port}")
    server.start()
    served = collect(src, lambda out: len(out) == 5, deadline=3.0)
    last = served[-1]
    frames = [nn.message(nn.FRAMEOFDATA, nn.pack_frame(nn.FrameOfData(last.frame + k, {"trial": trial.markers[0]},
                                                                        {}, last.t + 0.01 * k))) for k in (1, 2, 3)]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
        other.bind(("127.0.0.2", 0))
        for packet in frames:
            other.sendto(packet, ("127.0.0.1", data_port))
    wait_until(lambda: src.stats.rejected == 3, 2.0)
    assert src.read(0.2) is None
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as same:
        for packet in frames:
            same.sendto(packet, ("127.0.0.1", data_port))
    after = collect(src, lambda out: len(out) >= 3, deadline=3.0)
    assert [f.frame for f in after] == [last.frame + 1, last.frame + 2, last.frame + 3]
    assert src.stats.rejected == 3
    src.close()
    server.close()


def test_natnet_nobody_there():
    port, data_port = free_udp_port(), free_udp_port()
    with pytest.raises(InputError, match="no NatNet server answered"):
        open_mocap_source(f"natnet://127.0.0.1:{port}?data_port={data_port}&timeout=0.3")


def test_natnet_packets_round_trip_and_every_truncation_is_an_error():
    import livezmp.sources.natnet_protocol as nn

    f = nn.FrameOfData(7, {"a": np.arange(6.0).reshape(2, 3), "b": np.ones((1, 3))},
                       {1: np.arange(9.0), 2: -np.arange(9.0)}, 12.5, 99)
    data = nn.pack_frame(f)
    g = nn.unpack_frame(data)
    assert (g.frame, g.timestamp, g.stamp_transmit, list(g.marker_sets)) == (7, 12.5, 99, ["a", "b"])
    np.testing.assert_array_equal(g.marker_sets["a"], f.marker_sets["a"])
    np.testing.assert_array_equal(g.plates[2], f.plates[2])
    for n in range(len(data)):  # a datagram cut anywhere is refused, never mis-read
        with pytest.raises(nn.NatNetError):
            nn.unpack_frame(data[:n])
    model = nn.ModelDef({"a": ("x", "y")}, (nn.ForcePlateDef(3, "S3", 0.4, 0.6, np.eye(4, 3), ("Fx", "Cy")),))
    back = nn.unpack_modeldef(nn.pack_modeldef(model))
    assert back.marker_sets == model.marker_sets and back.plates[0].channels == ("Fx", "Cy")
    np.testing.assert_allclose(back.plates[0].corners, np.eye(4, 3))


def test_natnet_plate_channels_read_as_one_block_or_one_by_one():
    """Channels of one sample each are read as one block; any other count (none, several: a plate
    faster than the cameras) one by one, the newest sample kept: both give the samples packed."""
    import livezmp.sources.natnet_protocol as nn

    def channels(samples):
        return b"".join(struct.pack("<i", len(x)) + np.asarray(x, "<f4").tobytes() for x in samples) + b"tail"

    for samples, want in (([[1.5], [-2.0], [3.25]], [1.5, -2.0, 3.25]),
                          ([[1.5], [], [7.0, 8.0, 9.5], [4.0]], [1.5, np.nan, 9.5, 4.0])):
        r = nn._Reader(channels(samples))
        np.testing.assert_array_equal(nn._plate_channels(r, len(samples)), want)
        assert r.data[r.pos:] == b"tail"


def test_qtm_components_read_as_the_qtm_rt_client_reads_them(trial):
    """livezmp reads the 3D, force and 6D components as numpy blocks: equal to qtm-rt's own records
    of the same packets (markers, plates' newest sample in the lab, bodies); a packet shorter than
    its counts say is an error, not a frame."""
    from qtm_rt.packet import QRTPacket

    from livezmp.sources.qtm import frame_of_packet, parse_parameters
    from sim_devices import qtm_server as qs
    from sim_devices.mocap_trial import TrialPlayer, with_segments

    posed = with_segments(trial, str(TRIAL))
    params = parse_parameters(qs.parameters_xml(posed, "1.25", ["all"]), "test")
    axes = [plate_axes(c) for c in posed.corners]
    player = TrialPlayer(posed, IMPAIRED, speed=0)
    comps = [qs.COMPONENT_3D, qs.COMPONENT_FORCE, qs.COMPONENT_6D]
    for f in list(player.frames())[::7]:
        data = qs.data_packet(posed, f, comps, axes)[qs.HEADER.size:]
        packet = QRTPacket(data)
        got = frame_of_packet(packet, params, 0.0)
        markers = np.array([(m.x, m.y, m.z) for m in packet.get_3d_markers()[1]]) * 1e-3
        np.testing.assert_array_equal(got.markers, markers)
        assert len(packet.get_force()[1]) == len(params.plates) == 4
        assert len(packet.get_6d()[1]) == len(params.bodies) > 0
        for info, samples in packet.get_force()[1]:
            s, (R, origin) = samples[-1], params.axes[info.id - 1]
            np.testing.assert_array_equal(got.plates.force[info.id - 1], R @ (s.x, s.y, s.z))
            np.testing.assert_array_equal(got.plates.moment[info.id - 1], R @ (s.x_m, s.y_m, s.z_m))
            np.testing.assert_array_equal(got.plates.cop[info.id - 1], R @ (np.array([s.x_a, s.y_a, s.z_a]) * 1e-3)
                                          + origin)
        for i, (pos, rot) in enumerate(packet.get_6d()[1]):
            np.testing.assert_array_equal(got.segments.position[i], np.array([pos.x, pos.y, pos.z]) * 1e-3)
            np.testing.assert_array_equal(got.segments.rotation[i], np.reshape(rot.matrix, (3, 3)).T)
    with pytest.raises((ValueError, struct.error)):
        frame_of_packet(QRTPacket(data[:-40]), params, 0.0)


def test_qtm_skeleton_segments_nested_untracked_and_unknown():
    """QTM 1.22+ nests a skeleton's segments under their parents: they are named in document order;
    a segment sent with a zero quaternion (not solved) or not sent is untracked, an id the parameters
    do not name is ignored, and each pose is the quaternion's rotation (x y z w) and the position in m."""
    from qtm_rt.packet import QRTPacket
    from scipy.spatial.transform import Rotation

    from livezmp.sources.qtm import frame_of_packet, parse_parameters

    xml = ("<QTM_Parameters_Ver_1.25><General><Frequency>100</Frequency></General><The_3D><AxisUpwards>Z"
           "</AxisUpwards></The_3D><Skeletons><Skeleton Name='a'><Segments><Segment Name='pelvis' ID='1'>"
           "<Segment Name='thigh_l' ID='2'><Segment Name='shank_l' ID='3'/></Segment></Segment>"
           "<Segment Name='thigh_r' ID='7'/></Segments></Skeleton></Skeletons></QTM_Parameters_Ver_1.25>")
    p = parse_parameters(xml, "test")
    assert p.segments == ("pelvis", "thigh_l", "shank_l", "thigh_r") and p.skeletons == ((1, 2, 3, 7),)
    q = Rotation.from_euler("zyx", [0.3, -0.2, 0.1]).as_quat()
    segments = [(2, (10.0, 20.0, 30.0), q), (1, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0)),
                (9, (5.0, 5.0, 5.0), q), (3, (4.0, 4.0, 4.0), (0.0, 0.0, 0.0, 0.0))]
    body = struct.pack("<ii", 1, len(segments)) + b"".join(struct.pack("<i3f4f", i, *x, *r) for i, x, r in segments)
    component = struct.pack("<II", 8 + len(body), 18) + body
    f = frame_of_packet(QRTPacket(struct.pack("<qII", 5, 1, 1) + component), p, 0.0)
    assert f.segments.names == p.segments and f.segments.tracked.tolist() == [True, True, False, False]
    np.testing.assert_allclose(f.segments.position[:2], [[1e-3, 2e-3, 3e-3], [0.01, 0.02, 0.03]], atol=1e-9)
    np.testing.assert_allclose(f.segments.rotation[1], Rotation.from_euler("zyx", [0.3, -0.2, 0.1]).as_matrix(),
                               atol=1e-6)
    np.testing.assert_array_equal(f.segments.rotation[0], np.eye(3))


@pytest.mark.parametrize("url, message", [
    ("vicon://127.0.0.1", "not a capture stream"),
    ("qtm://", "need a host"),
    ("qtm://127.0.0.1:1?rate=3", "unknown parameter 'rate'"),
    ("lsl://x?timeout=soon", "timeout: need seconds"),
    ("lsl://x?align=-1", "align: need frame periods"),
    ("lsl://x?align=soon", "align: need frame periods"),
    ("lsl://no-such-stream-livezmp?timeout=0.2", "no LSL stream with name"),
    ("natnet://127.0.0.1?data_port=abc", "data_port: need a port number"),
    ("natnet://127.0.0.1?up=w", "up axis 'w'"),
    # waits taken as given: -1 made liblsl wait for ever, 1e308 overflowed select() (a traceback)
    ("lsl://x?timeout=-1", re.escape("timeout: need seconds in (0, 3600], got '-1'")),
    ("lsl://x?timeout=nan", re.escape("timeout: need seconds in (0, 3600]")),
    ("natnet://127.0.0.1:9?timeout=1e308", re.escape("timeout: need seconds in (0, 3600], got '1e308'")),
    ("natnet://127.0.0.1:9?timeout=0", re.escape("timeout: need seconds in (0, 3600]")),
])
def test_bad_capture_urls_are_one_line_errors(url, message):
    with pytest.raises(InputError, match=message):
        open_mocap_source(url)


def test_streamer_bad_input_is_a_one_line_error(capsys):
    from sim_devices.mocap_streamer import main

    assert main([str(C3D / "nope.c3d"), "--qtm", "0"]) == 2
    assert main(["generated:fast", "--natnet", "0"]) == 2
    assert main([str(TRIAL), "--lsl", "x", "--skeleton"]) == 2  # skeletons: NatNet and QTM only
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and "nope.c3d: not a readable C3D file" in err[0] and "generated:RATE" in err[1]
    assert "--skeleton: a C3D trial served over --natnet or --qtm" in err[2]
