"""A capture stream's markers as marker-body frames (livezmp.sources.marker_stream), in process:
short gaps carried on at the marker's velocity (exact for a body gliding at constant velocity;
without the rule those frames have no pelvis), long gaps reported and counted, the body calibrated
on the stream's first seconds when no trial is given."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from data_paths import C3D

from livezmp.errors import InputError
from livezmp.model.c3d import read_c3d
from livezmp.sources.interface import ErrorLog, SourceStats
from livezmp.sources.marker_stream import MarkerStreamSource
from livezmp.sources.mocap_frame import MocapFrame

TRIAL = C3D / "walk_plugingait_forceplates.c3d"
RATE = 100.0


class FakeStream:
    """A capture stream handing out ``markers`` (F, n, 3) m with ``labels``, z up, at 100 Hz."""

    def __init__(self, labels, markers, up="+z"):
        self.name, self.nominal_dt, self.up = "fake://", 1.0 / RATE, up
        self.labels = tuple(labels)
        self.markers = markers
        self.stats, self.errors = SourceStats(), ErrorLog(interval=0.0)
        self.k = 0
        self.finished = False

    def read(self, timeout):
        if self.k >= len(self.markers):
            self.finished = True
            return None
        k, self.k = self.k, self.k + 1
        return MocapFrame(k / RATE, 0.0, k, self.labels, self.markers[k], self.up)

    def close(self):
        pass


@pytest.fixture(scope="module")
def c3d():
    return read_c3d(TRIAL)


def gliding(c3d, frames=60, v=(1.2, -0.3, 0.05)):
    """The trial's first frame moving rigidly at constant velocity ``v`` m/s: ``frames`` frames."""
    t = np.arange(frames) / RATE
    return c3d.points[0][None] + t[:, None, None] * np.array(v)


def read_all(src):
    out = []
    while (f := src.read(0.0)) is not None:
        out.append(f.channels)
    return np.array(out)


def test_short_gap_is_carried_on_at_the_marker_velocity(c3d):
    truth = gliding(c3d)
    gapped = truth.copy()
    lasi = c3d.labels.index("LASI")
    gapped[30:40, lasi] = np.nan  # 0.1 s: the longest gap carried
    want = read_all(MarkerStreamSource(FakeStream(c3d.labels, truth), c3d))
    src = MarkerStreamSource(FakeStream(c3d.labels, gapped), c3d)
    got = read_all(src)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert src.details()["markers"]["filled_samples"] == 10
    assert src.details()["markers"]["long_gaps"] == 0
    # without carrying (a gap limit of zero) the pelvis is missing there
    src = MarkerStreamSource(FakeStream(c3d.labels, gapped), c3d, max_gap_s=0.0)
    bare = read_all(src)
    pelvis = [src.body.channel_names.index(f"pelvis.{c}") for c in ("x", "y", "z", "yaw", "pitch", "roll")]
    assert np.isnan(bare[30:40, pelvis]).all() and np.isfinite(bare[:30]).all()


def test_long_gap_is_left_out_reported_and_counted(c3d):
    gapped = gliding(c3d)
    rank = c3d.labels.index("RANK")
    gapped[20:45, rank] = np.nan  # 0.25 s
    src = MarkerStreamSource(FakeStream(c3d.labels, gapped), c3d)
    got = read_all(src)
    d = src.details()["markers"]
    assert (d["filled_samples"], d["long_gaps"], d["frames_with_long_gap"]) == (10, 1, 15)
    ankle_r = src.body.channel_names.index("foot_r.x")  # the foot hangs at the ankle centre
    assert np.isfinite(got[20:30, ankle_r]).all() and np.isnan(got[30:45, ankle_r]).all()
    assert np.isfinite(got[45:]).all()  # back once seen again
    reports = [e for e in src.errors.drain() if e.kind == "marker_gap"]
    assert len(reports) == 1 and "RANK missing for more than 100 ms" in reports[0].message


@pytest.mark.parametrize("far", [1e30, np.inf, -2000.0])
def test_a_marker_at_infinity_or_beyond_a_km_is_left_out_and_counted(c3d, far):
    """As a C3D reader refuses a file with such a coordinate, a stream's frame with one is counted
    (``bad_markers``) and reported, the marker left out as an occluded one (carried on over a short gap:
    the same frames as the glide without it) and the frame's other markers kept."""
    truth = gliding(c3d)
    broken = truth.copy()
    lasi = c3d.labels.index("LASI")
    broken[30:33, lasi, 1] = far  # 30 ms: carried on
    broken[50, lasi] = np.nan  # an occluded marker is not a broken one
    want = read_all(MarkerStreamSource(FakeStream(c3d.labels, truth), c3d))
    src = MarkerStreamSource(FakeStream(c3d.labels, broken), c3d)
    got = read_all(src)
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert src.stats.bad_markers == 3 and src.stats.dropped == 0
    errors = [e for e in src.errors.drain() if e.kind == "bad_markers"]
    assert len(errors) == 3 and errors[0].message == ("fake://: frame 30: LASI at infinity or beyond 1000 m of the "
                                                      "origin: left out")


def test_frames_converted_together_equal_frames_converted_one_by_one(c3d, monkeypatch):
    """A reader behind its stream converts the waiting frames in one call: the same channels (to rounding)
    and the same gap counts as one frame per call, across batch boundaries, with short and long gaps."""
    import livezmp.sources.marker_stream as ms

    walk = c3d.points[:150].copy()
    walk[30:40, c3d.labels.index("LASI")] = np.nan  # carried on (0.1 s)
    walk[50:80, c3d.labels.index("RANK")] = np.nan  # left out after 0.1 s
    walk[33:36, c3d.labels.index("LTOE")] = np.nan
    calls = []
    convert = ms.marker_channels
    monkeypatch.setattr(ms, "marker_channels", lambda take, m: calls.append(len(next(iter(m.values()))))
                        or convert(take, m))
    single = MarkerStreamSource(FakeStream(c3d.labels, walk), c3d, batch=1)
    one = read_all(single)
    assert set(calls) == {1}
    calls.clear()
    batched = MarkerStreamSource(FakeStream(c3d.labels, walk), c3d, batch=32)
    together = read_all(batched)
    assert calls == [32, 32, 32, 32, 22]  # every frame was already waiting
    assert np.isnan(one).any() and np.isfinite(one[:30]).all()
    np.testing.assert_allclose(together, one, rtol=0, atol=1e-12)
    assert batched.details() == single.details()
    assert single.details()["markers"]["filled_samples"] == 10 + 3 + 10


def test_body_calibrated_on_the_stream_when_no_trial_is_given(c3d):
    prefixed = [f"Subject:{x}" for x in c3d.labels]  # prefixes go, as in a C3D
    src = MarkerStreamSource(FakeStream(prefixed, c3d.points), None)
    assert src.calibration == {"source": "stream", "frames": 201, "seconds": 2.0}
    frames = read_all(src)
    assert len(frames) == len(c3d.points) - 201 and np.isfinite(frames).all()
    # the pelvis measured on those 2 s is the one measured on the whole file (within 1 %)
    whole = MarkerStreamSource(FakeStream(c3d.labels, c3d.points[:3]), c3d).take.notes["dimensions"]
    for k in ("pelvis_width_m", "pelvis_depth_m"):
        assert src.take.notes["dimensions"][k] == pytest.approx(whole[k], rel=0.01)
    # and it is the same body whichever way the stream's axes are turned (y up here)
    y_up = c3d.points @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]]).T
    turned = MarkerStreamSource(FakeStream(c3d.labels, y_up, "+y"), None)
    assert turned.take.notes["dimensions"] == pytest.approx(src.take.notes["dimensions"], rel=1e-9)


def test_stream_too_short_to_calibrate_is_one_line(c3d):
    with pytest.raises(InputError, match="too few to calibrate"):
        MarkerStreamSource(FakeStream(c3d.labels, c3d.points[:3]), None, timeout=0.2)
    missing = replace(c3d, labels=[x if x != "LASI" else "XXXX" for x in c3d.labels])
    with pytest.raises(InputError, match="missing LASI"):
        MarkerStreamSource(FakeStream(missing.labels, c3d.points), None)


@pytest.mark.parametrize(("args", "message"), [
    (["qtm://127.0.0.1:1", "--calibration", "/no/such.c3d"], "/no/such.c3d: no such file"),
    (["udp://127.0.0.1:9", "--calibration", str(TRIAL)], "--calibration is for capture streams"),
    # a file (or a link) carries its own body: the calibration had been ignored without a word
    ([str(TRIAL), "--calibration", str(TRIAL)], "--calibration is for capture streams"),
    (["qtm://127.0.0.1:1", "--frames", "0"], "--frames must be a positive number"),
    (["qtm://127.0.0.1:1", "--lag-s", "-1"], "--lag-s (s): -1 is outside [0, 10]"),
    (["qtm://127.0.0.1:1", "--window-s", "nan"], "--window-s (s): nan is outside (0, 10]"),
])
def test_monitor_capture_options_refused_in_one_line(args, message, capsys):
    from livezmp.cli import main

    assert main(["monitor", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err


def test_a_stream_labelled_in_another_convention_gives_the_same_frames(c3d):
    """Codamotion's names (L.ASIS, R.Knee ...) from a live stream: the body calibrated on it reads them as
    the Plug-in Gait labels (the built-in conventions), and looks them up under the stream's own names."""
    coda = {"ASI": "ASIS", "PSI": "PSIS", "KNE": "Knee", "ANK": "Ankle", "HEE": "Heel", "TOE": "Toe"}
    labels = [f"{x[0]}.{coda[x[1:]]}" if x[:1] in "LR" and x[1:] in coda else x for x in c3d.labels]
    assert labels != c3d.labels
    pig = read_all(MarkerStreamSource(FakeStream(c3d.labels, c3d.points[:260]), None))
    src = MarkerStreamSource(FakeStream(labels, c3d.points[:260]), None)
    assert src.take.roles["LKNE"] == "L.Knee"
    np.testing.assert_array_equal(read_all(src), pig)


def test_a_stream_without_toe_markers_reads_the_metatarsal_heads_mid_point(c3d):
    """A set with the first and fifth metatarsal heads and no toe marker: the body calibrated on the stream reads
    the toe as their mid-point, as a C3D trial does, and looks both up in every frame (before, the stream reported
    a missing marker 'LMT1+LMT5' and the feet had no toe)."""
    across = np.array([0.0, 0.03, 0.0])
    toes = [c3d.labels.index(s + "TOE") for s in "LR"]
    heads = np.concatenate([c3d.points[:260, toes] - across, c3d.points[:260, toes] + across], axis=1)
    keep = [i for i in range(len(c3d.labels)) if i not in toes]
    labels = [c3d.labels[i] for i in keep] + ["LMT1", "RMT1", "LMT5", "RMT5"]
    points = np.concatenate([c3d.points[:260, keep], heads], axis=1)
    pig = read_all(MarkerStreamSource(FakeStream(c3d.labels, c3d.points[:260]), None))
    src = MarkerStreamSource(FakeStream(labels, points), None)
    assert src.take.roles["LTOE"] == "LMT1+LMT5" and src.take.mean_of["RMT1+RMT5"] == ("RMT1", "RMT5")
    frames = read_all(src)
    assert frames.shape == pig.shape and np.isfinite(frames).all() and not src.errors.drain()
    np.testing.assert_allclose(frames, pig, atol=1e-9)
