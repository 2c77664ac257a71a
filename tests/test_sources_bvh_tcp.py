"""BVH over TCP from the simulated streamer: plain and avatar-prefixed lines, bad lines
counted and dropped, and a reconnect after the server drops the connection."""

from __future__ import annotations

import time

import numpy as np
import pytest
from data_paths import BANDAI
from sim_support import wait_until

from livezmp.errors import InputError
from livezmp.model.bvh import read_bvh
from livezmp.model.euler_orders import clear_of_gimbal_lock
from livezmp.sources.bvh_tcp import parse_frame_line
from livezmp.sources.factory import SourceOptions, open_source
from sim_devices.mocap_streamer import Impairments, TcpStreamer

WALK = BANDAI / "walk_normal_001.bvh"


@pytest.fixture(scope="module")
def motion():
    return read_bvh(WALK)


def collect(src, n: int, deadline: float = 5.0) -> list:
    out, end = [], time.monotonic() + deadline
    while len(out) < n and time.monotonic() < end:
        f = src.read(0.05)
        if f is not None:
            out.append(f)
    return out


def test_parse_frame_line():
    assert parse_frame_line(b"1 2.5 -3", 3).tolist() == [1.0, 2.5, -3.0]
    assert parse_frame_line(b"0 Avatar00 1 2.5 -3 ", 3).tolist() == [1.0, 2.5, -3.0]
    for line, msg in [(b"1 2", "2 values, the hierarchy has 3"), (b"1 x 3", "non-numeric"),
                      (b"1 nan 3", "value 1 is not finite")]:
        with pytest.raises(InputError, match=msg):
            parse_frame_line(line, 3)


@pytest.mark.parametrize("avatar", [False, True])
def test_frames_arrive_as_streamed(motion, avatar):
    server = TcpStreamer(motion, speed=0, max_frames=100, avatar=avatar)
    src = open_source(f"tcp://127.0.0.1:{server.port}", SourceOptions(skeleton=str(WALK)))
    server.run_in_thread()
    frames = collect(src, 100)
    assert len(frames) == 100 and src.nominal_dt == pytest.approx(motion.frame_time)
    # in the orders the body analyses: Bandai's spine, near gimbal lock, is re-expressed line by line as the file is
    clear = clear_of_gimbal_lock(motion)
    assert clear is not motion
    np.testing.assert_allclose(np.array([f.channels for f in frames]), clear.frames[:100], atol=1e-5)
    np.testing.assert_allclose([f.t for f in frames], np.arange(100) * motion.frame_time)
    src.close()
    server.close()


def test_bad_lines_are_dropped_and_a_lost_connection_is_reopened(motion):
    server = TcpStreamer(motion, speed=0, max_frames=0, impairments=Impairments())
    src = open_source(f"tcp://127.0.0.1:{server.port}?max_line=3000", SourceOptions(skeleton=str(WALK)))
    server.run_in_thread()  # accepts clients; sends no frames of its own (max_frames=0)
    wait_until(lambda: server.clients, timeout=5)
    good = [server.line(motion.frames[k]) for k in range(3)]
    server.send_raw(good[0] + b"1 2 3\n" + b"9" * 5000 + b"\n" + b"0 x " * 66 + b"\n" + good[1])
    assert len(collect(src, 2)) == 2
    server.kick()  # the server drops us; the source reconnects by itself
    end = time.monotonic() + 5
    while not server.clients and time.monotonic() < end:
        src.read(0.05)
    server.send_raw(good[2])
    (f,) = collect(src, 1)
    np.testing.assert_allclose(f.channels, clear_of_gimbal_lock(motion).frames[2], atol=1e-5)
    assert f.t == pytest.approx(2 * motion.frame_time)  # frames keep counting across the reconnect
    st = src.stats
    assert (st.delivered, st.malformed, st.oversized, st.reconnects) == (3, 2, 1, 1)
    kinds = [e.kind for e in src.errors.drain()]
    assert "disconnected" in kinds and "malformed" in kinds and "oversized" in kinds
    src.close()
    server.close()
