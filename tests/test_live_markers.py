"""Live == offline: a real C3D gait trial streamed by each simulated capture server (QTM RT through
qtm-rt, LSL through pylsl, NatNet through livezmp's client, loopback) into ``livezmp monitor`` gives
the ZMP of ``livezmp analyze`` of the same file, frame by frame, and the monitor's ``cop_vs_zmp`` is
that ZMP against the file's plate CoP.

Tolerances: the monitor steps frame by frame where analyze runs the batch path (they agree to
~1e-13 m); QTM and LSL carry millimetres as float32, which is what the C3D file stores, so nothing
is lost: 1e-9 m. NatNet carries metres as float32: its ZMP equals analyze of the file with the
markers rounded to float32 metres to 1e-8 m (the monitor's body is calibrated on the unrounded file;
measured 3e-9 m), and the unrounded analyze to 1 µm (measured 0.3 µm). A NatNet skeleton stream (the
segments' poses alone, no markers) drives the body directly: analyze's ZMP to 2 µm (float32 poses).
"""

from __future__ import annotations

import _thread
import threading
import time
import uuid
from dataclasses import replace

import numpy as np
import pytest
from data_paths import C3D
from sim_support import wait_until

from livezmp.balance.foot_sensors import CopVsZmp
from livezmp.balance.support import SUPPORT_LABELS
from livezmp.cli import main
from livezmp.model.c3d import read_c3d
from livezmp.model.markers import MarkerBodyOptions
from livezmp.offline.gaitlab import LabOptions, analyse_lab_take
from livezmp.recording.reader import iter_messages
from sim_devices.impairments import Impairments
from sim_devices.lsl_publisher import LslPublisher
from sim_devices.mocap_trial import load_c3d_trial, with_segments
from sim_devices.natnet_server import NatNetServer
from sim_devices.qtm_server import QtmServer

TRIAL = C3D / "walk_plugingait_forceplates.c3d"
MONITOR_LIMIT_S = 60.0  # s: one streamed trial takes 3-7 s
SAME_ESTIMATOR = ["--cutoff-hz", "6", "--window-s", "0.8", "--lag-s", "0.4"]  # analyze's for a C3D take (gaitlab)
# NatNet's y-up axes (x, z, -y) of the z-up file, turned into the internal frame as y-up input is: (-y, x, z)
NATNET_TURN = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def trial():
    return load_c3d_trial(str(TRIAL))


@pytest.fixture(scope="module")
def skeleton_trial(trial):
    """The trial with its segments' poses, as a skeleton solver would stream them."""
    return with_segments(trial, str(TRIAL))


@pytest.fixture(scope="module")
def offline():
    """analyze's analysis of the file, and of the file with its markers rounded to float32 metres; the placed
    HAT moving with the mid-hip and no lateral band, as in a stream (which has no whole-take trend for the HAT to
    sway about, nor the future a zero-phase filter needs)."""
    c3d = read_c3d(TRIAL)
    rounded = replace(c3d, points=c3d.points.astype(np.float32).astype(float))
    opts = LabOptions(markers=MarkerBodyOptions(hat_sway_gain=None), lateral_cutoff_fraction=None)
    return analyse_lab_take(c3d, opts), analyse_lab_take(rounded, opts)


def _serve(kind: str, trial):
    """(server, URL, start): the server plays the trial once (3x real time: the analysis does not depend
    on when frames arrive, only on their stamps), from when the monitor is connected."""
    if kind.startswith("qtm"):  # "qtm-6d" / "qtm-skeleton": every marker occluded, the segments' poses tracked
        hidden = Impairments(gap=1.0) if kind != "qtm" else None  # as 6DOF bodies / as QTM's solved skeleton
        poses = ("skeleton",) if kind == "qtm-skeleton" else ("6d",)
        server = QtmServer(trial, 0, loop=False, speed=3.0, impairments=hidden, poses=poses)
        return server, f"qtm://127.0.0.1:{server.port}", lambda: wait_until(server.streaming_clients, 10) and \
            server.start()
    if kind.startswith("natnet"):  # "natnet-skeleton": the segment poses alone, no markers
        server = NatNetServer(trial, 0, _free_udp_port(), loop=False, speed=3.0, markers=kind == "natnet")
        url = f"natnet://127.0.0.1:{server.command_port}?data_port={server.data_port}"
        return server, url, lambda: wait_until(lambda: bool(server.clients), 10) and server.start()
    name = f"livezmp-test-{uuid.uuid4().hex[:8]}"
    server = LslPublisher(trial, name=name, source_id=name, speed=3.0)
    return server, f"lsl://{name}", lambda: wait_until(server.has_consumers, 10) and server.run()


def _free_udp_port() -> int:
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _monitor(kind: str, trial, tmp_path) -> tuple[dict, dict]:
    """Stream the trial into ``livezmp monitor`` (calibrated on the same file); its /result messages
    by frame and its summary."""
    import json

    server, url, start = _serve(kind, trial)
    if kind == "lsl":  # the plates' stream may come more than the default 3 frames late on a loaded host: this
        url += "?align=100"  # test is of equality with analyze, so every frame waits for its plates (1 s)
    player = threading.Thread(target=start, daemon=True)
    player.start()
    rec, summary = tmp_path / f"{kind}.mcap", tmp_path / f"{kind}.json"
    # the monitor stops after the trial's frames; should one never come (a datagram lost on a loaded host), it is
    # stopped as by Ctrl-C rather than waiting for ever (and the frame count below fails)
    guard = threading.Timer(MONITOR_LIMIT_S, _thread.interrupt_main)
    guard.start()
    try:
        rc = main(["monitor", url, "--calibration", str(TRIAL), *SAME_ESTIMATOR, "--frames", str(trial.n_frames),
                   "--record", str(rec), "--summary-json", str(summary)])
    finally:
        guard.cancel()
        player.join(10)
        server.close()
    assert rc == 0
    # the recording re-runs to the same analysis (the stream's body rebuilt from the recorded calibration)
    assert main(["replay", str(rec)]) == 0
    return {m["index"]: m for m in iter_messages(str(rec), "/result")}, json.loads(summary.read_text())


def _plates_cop(trial) -> np.ndarray:
    """(F, 3) the file's combined plate CoP at the marker frames (z up): the plates' CoPs weighted by
    their vertical force, NaN below 20 N."""
    fz = np.abs(trial.force[:, :, 2])
    fz = np.where(np.isfinite(trial.cop).all(axis=2), fz, 0.0)
    total = fz.sum(axis=1)
    cop = np.einsum("fp,fpk->fk", fz, np.nan_to_num(trial.cop)) / np.where(total > 0, total, 1.0)[:, None]
    return np.where((total >= 20.0)[:, None], cop, np.nan)


@pytest.mark.parametrize("kind", ["qtm", "lsl", "natnet"])
def test_streamed_trial_gives_the_zmp_of_analyze(kind, trial, offline, tmp_path):
    results, summary = _monitor(kind, trial, tmp_path)
    exact, rounded = offline
    turn = NATNET_TURN if kind == "natnet" else np.eye(3)  # the stream's internal frame vs the file's
    reference = rounded if kind == "natnet" else exact
    assert sorted(results) == list(range(trial.n_frames))
    assert summary["frames_in"] == summary["analysed_frames"] == trial.n_frames
    assert summary["dropped"]["total"] == 0 and summary["markers"]["filled_samples"] == 0
    zmp = np.array([[r["zmp"][a] for a in "xyz"] for _, r in sorted(results.items())]) @ turn
    assert reference.result.has_zmp.all()
    np.testing.assert_allclose(zmp, reference.result.zmp, rtol=0, atol=1e-8 if kind == "natnet" else 1e-9)
    np.testing.assert_allclose(zmp, exact.result.zmp, rtol=0, atol=1e-6)
    assert [r["support"] for _, r in sorted(results.items())] == [SUPPORT_LABELS[s] for s in exact.result.support]

    # the monitor's cop_vs_zmp: that ZMP against the file's plate CoP of the same frames
    cop = _plates_cop(trial)
    recorded = np.array([[r["cop"][a] for a in "xyz"] if "cop" in r else [np.nan] * 3
                         for _, r in sorted(results.items())]) @ turn
    np.testing.assert_allclose(recorded, cop, rtol=0, atol=2e-6, equal_nan=True)
    truth = CopVsZmp()
    for i in range(trial.n_frames):
        truth.add(None if np.isnan(cop[i, 0]) else cop[i], exact.result.zmp[i], exact.result.clamped[i])
    want, got = truth.summary(), summary["cop_vs_zmp"]
    assert (got["frames"], got["no_cop"]) == (want["frames"], want["no_cop"]) and want["frames"] > 150
    assert got["mean_mm"] == pytest.approx(want["mean_mm"], abs=1e-3)
    assert got["max_mm"] == pytest.approx(want["max_mm"], abs=1e-3)


@pytest.mark.parametrize("kind", ["natnet-skeleton", "qtm-6d", "qtm-skeleton"])
def test_segment_poses_drive_the_body_directly(kind, skeleton_trial, offline, tmp_path):
    """The segments' poses without markers (a NatNet skeleton; QTM 6DOF bodies or QTM's solved skeleton
    with every marker occluded): the body is driven by the poses and gives analyze's ZMP to float32 (positions,
    quaternions or rotation matrices)."""
    results, summary = _monitor(kind, skeleton_trial, tmp_path)
    exact, _ = offline
    assert summary["frames_from_segment_poses"] == summary["analysed_frames"] == skeleton_trial.n_frames
    turn = NATNET_TURN if kind.startswith("natnet") else np.eye(3)
    zmp = np.array([[r["zmp"][a] for a in "xyz"] for _, r in sorted(results.items())]) @ turn
    np.testing.assert_allclose(zmp, exact.result.zmp, rtol=0, atol=2e-6)  # measured: 0.6 µm (NatNet)


def _first_frames(kind: str, trial, n: int = 50, check=None) -> list:
    """The first ``n`` MocapFrames the capture client reads from the ``kind`` server playing ``trial``
    (``check(source)`` first, before any frame is sent)."""
    from livezmp.sources.mocap_factory import open_mocap_source

    server, url, start = _serve(kind, trial)
    src = open_mocap_source(url)
    frames, deadline = [], time.monotonic() + 10
    try:
        if check is not None:
            check(src)
        threading.Thread(target=start, daemon=True).start()
        while len(frames) < n and time.monotonic() < deadline:
            f = src.read(0.05)
            if f is not None:
                frames.append(f)
    finally:
        src.close()
        server.close()
    assert len(frames) >= n and frames[0].segments.names == trial.segment_names
    return frames


def test_natnet_client_reads_rigid_bodies_and_skeleton_bones(skeleton_trial):
    """Each bone arrives as the pose the server sent: position and rotation in Motive's y-up axes."""
    def asked_rate(src):  # asked ("FrameRate") before any frame came
        assert src.nominal_dt == 1 / skeleton_trial.rate

    y_up = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # Motive's axes of the z-up trial
    for f in _first_frames("natnet-skeleton", skeleton_trial, check=asked_rate):
        seg = f.segments
        assert seg.tracked.all() and len(f.markers) == 0
        np.testing.assert_allclose(seg.position, skeleton_trial.segment_pos[f.frame] @ y_up.T, atol=1e-6)
        np.testing.assert_allclose(seg.rotation, y_up @ skeleton_trial.segment_rot[f.frame], atol=1e-6)


def test_qtm_client_reads_6dof_bodies(skeleton_trial):
    """qtm-rt's 6D component arrives as the bodies the server sent (QTM's z-up lab axes)."""
    for f in _first_frames("qtm", skeleton_trial):
        seg = f.segments
        assert seg.tracked.all()
        i = f.frame - 1  # QTM numbers frames from 1
        np.testing.assert_allclose(seg.position, skeleton_trial.segment_pos[i], atol=1e-6)
        np.testing.assert_allclose(seg.rotation, skeleton_trial.segment_rot[i], atol=1e-6)


def test_qtm_client_reads_skeleton_segments(skeleton_trial):
    """qtm-rt's skeleton component (global poses) arrives as the segments the server solved: positions
    mm -> m and quaternions -> rotation matrices, in QTM's z-up lab axes; no 6DOF bodies then."""
    for f in _first_frames("qtm-skeleton", skeleton_trial):
        seg = f.segments
        assert seg.tracked.all() and np.isnan(f.markers).all()
        i = f.frame - 1  # QTM numbers frames from 1
        np.testing.assert_allclose(seg.position, skeleton_trial.segment_pos[i], atol=1e-6)
        np.testing.assert_allclose(seg.rotation, skeleton_trial.segment_rot[i], atol=1e-6)
