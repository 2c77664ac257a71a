"""C3D wherever a motion file is accepted, and the subject file wherever a person's body is built:
the marker body as a chain (joint angles), `correct` writing a corrected C3D, `gait` on gait-lab walks
against what the force plates say, `monitor --subject` against `analyze --subject`."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import ezc3d
import numpy as np
import pinocchio as pin
import pyarrow.parquet as pq
import pytest

from livezmp.balance.plates import unloaded_offset
from livezmp.cli import main
from livezmp.gait.features import walk_features
from livezmp.gait.take import load_take
from livezmp.model.bvh import read_bvh, write_bvh
from livezmp.model.bvh_body import BvhBodyOptions, body_from_bvh
from livezmp.model.c3d import read_c3d
from livezmp.model.c3d_write import write_moved_points
from livezmp.model.marker_bvh import chain_to_bvh
from livezmp.model.marker_chain import chain_body, chain_frames, chain_poses, free_frames, segment_names
from livezmp.model.markers import HAT_POINTS, body_from_markers, hat_table
from livezmp.offline.calibrate import Subject
from livezmp.offline.jobs import CorrectJob, GaitJob
from livezmp.offline.library import find_takes, run_library
from livezmp.offline.take import TakeOptions, analyse_loaded
from livezmp.recording.reader import iter_messages
from livezmp.sources.marker_stream import MarkerStreamSource
from tests.data_paths import DATA
from tests.test_c3d_gaitlab import PLATES, write_lab_c3d

CGM = DATA / "c3d" / "cgm24_walking01_forceplate.c3d"
PIG = DATA / "c3d" / "walk_plugingait_forceplates.c3d"
CUT = (200, 270)  # CGM frames: 18 of them outside support; the left foot strikes the plate at 211
SUBJECT = "[subject]\nhat_fraction = 0.45\nhat_offset_m = [0.03, 0.0, 0.33]\n"


def test_chain_body_places_every_segment_where_the_free_body_does():
    take = body_from_markers(read_c3d(CGM))
    names = segment_names(take.body)
    chain = chain_body(take.body)
    q = chain_frames(names, take.frames)
    assert np.abs(free_frames(names, q) - take.frames).max() < 1e-12
    d_free, d_chain = take.body.model.createData(), chain.model.createData()
    for k in range(0, len(q), 25):
        pin.framesForwardKinematics(take.body.model, d_free, take.frames[k])
        pin.framesForwardKinematics(chain.model, d_chain, q[k])
        for a, b in zip(d_free.oMf, d_chain.oMf, strict=True):
            assert np.abs(a.homogeneous - b.homogeneous).max() < 1e-12
        assert np.allclose(pin.centerOfMass(take.body.model, d_free, take.frames[k]),
                           pin.centerOfMass(chain.model, d_chain, q[k]), atol=1e-12)
    # the knee's flexion channel is the angle between the thigh's and the shank's long axes (its
    # ab/adduction and axial rotation are small in walking)
    poses = chain_poses(names, q)
    between = np.degrees(np.arccos(np.clip(np.einsum("fi,fi->f", poses["thigh_l"][1][:, :, 2],
                                                     poses["shank_l"][1][:, :, 2]), -1, 1)))
    flex = np.degrees(np.abs(q[:, chain.channel_names.index("shank_l.flex")]))
    assert between.max() > 50 and np.abs(flex - between).max() < 5.0
    # a chain: turning the thigh carries its shank and foot (the free body's would stay)
    q2 = q[100].copy()
    q2[chain.channel_names.index("thigh_l.flex")] += 0.2
    pin.framesForwardKinematics(chain.model, d_chain, q2)
    ankle = chain.named_points["left_ankle"]
    moved = d_chain.oMf[ankle].translation.copy()
    pin.framesForwardKinematics(chain.model, d_chain, q[100])
    assert np.linalg.norm(moved - d_chain.oMf[ankle].translation) > 0.05


@pytest.fixture(scope="module")
def corrected(tmp_path_factory):
    """A 0.7 s cut of the CGM 2.4 walk (its plate and model outputs kept) and its correction."""
    d = tmp_path_factory.mktemp("correct")
    c = ezc3d.c3d(str(CGM))
    a, b = CUT
    per = round(c["parameters"]["ANALOG"]["RATE"]["value"][0] / c["parameters"]["POINT"]["RATE"]["value"][0])
    c["data"]["points"] = c["data"]["points"][:, :, a:b]
    for k in ("residuals", "camera_masks"):
        c["data"]["meta_points"][k] = c["data"]["meta_points"][k][:, :, a:b]
    c["data"]["analogs"] = c["data"]["analogs"][:, :, a * per:b * per]
    c.write(str(d / "cut.c3d"))
    rc = main(["correct", str(d / "cut.c3d"), "-o", str(d / "fixed.c3d"), "--report", str(d / "r.json")])
    assert rc == 0
    return d, json.loads((d / "r.json").read_text())


def _analyze(path, out) -> dict:
    assert main(["analyze", str(path), "--summary-json", str(out)]) == 0
    return json.loads(out.read_text())


def test_corrected_c3d_analyses_inside_support(corrected):
    d, report = corrected
    assert report["out_of_support_before"] >= 12 and report["out_of_support_after"] == 0
    before, after = _analyze(d / "cut.c3d", d / "a0.json"), _analyze(d / "fixed.c3d", d / "a1.json")
    # the corrected file, read again and analysed from its markers, keeps the improvement
    assert before["out_of_support_frames"] >= 15 and before["max_excursion_m"] > 0.2
    assert after["out_of_support_frames"] <= 2 and after["max_excursion_m"] < 0.01
    assert "oriented by the file's HAT points" in after["markers"]["hat"]


def test_corrected_c3d_moves_markers_rigidly_and_keeps_weight_bearing_feet(corrected):
    d, report = corrected
    old, new = read_c3d(d / "cut.c3d"), read_c3d(d / "fixed.c3d")
    assert new.labels == old.labels + list(HAT_POINTS)
    move = lambda lab: np.linalg.norm(new.marker(lab) - old.marker(lab), axis=1)  # noqa: E731
    assert np.nanmax(move("LASI")) > 0.005  # the pelvis turned
    pelvis = ("LASI", "RASI", "LPSI", "RPSI")
    for i, a in enumerate(pelvis):
        for b in pelvis[i + 1:]:
            dist = [np.linalg.norm(t.marker(a) - t.marker(b), axis=1) for t in (old, new)]
            assert np.nanmax(np.abs(dist[0] - dist[1])) < 1e-5
    # the plate says when the left foot bears weight: its markers stay within a millimetre then
    plate = old.plates[0]
    fz = plate.force[:, 2] - unloaded_offset(plate, old.analog_rate)[0][2]
    per = round(old.analog_rate / old.rate)
    loaded = fz[::per][: len(old.points)] > 100.0
    heel = old.marker("LHEE")[loaded]
    assert loaded.sum() > 40 and np.all(np.abs(heel[:, :2] - plate.centre[:2]) < 0.35)  # on this plate
    for lab in ("LHEE", "LTOE", "LANK"):
        assert np.nanmax(move(lab)[loaded]) < 1e-3
    assert report["max_stance_foot_marker_move_mm"] < 1.0


def test_batch_correct_of_a_c3d_take_writes_what_correct_writes(corrected):
    """`batch correct` takes C3D takes through the same per-take function: the same file, the same report."""
    d, report = corrected
    lib = d / "lib"
    lib.mkdir()
    (lib / "cut.c3d").symlink_to(d / "cut.c3d")
    job = CorrectJob()
    assert run_library(None, find_takes([str(lib)], d / "batch", job), d / "batch", job).failed == 0
    (row,) = pq.read_table(d / "batch" / "takes.parquet").to_pylist()
    assert Path(row["output"]).read_bytes() == (d / "fixed.c3d").read_bytes()
    for k in ("frames", "out_of_support_before", "out_of_support_after", "max_foot_displacement_mm"):
        assert row[k] == report[k]


def test_corrected_c3d_keeps_plates_analogs_events_and_model_outputs(corrected):
    d, report = corrected
    old, new = ezc3d.c3d(str(d / "cut.c3d")), ezc3d.c3d(str(d / "fixed.c3d"))
    assert np.array_equal(old["data"]["analogs"], new["data"]["analogs"])
    for group, name in (("FORCE_PLATFORM", "CORNERS"), ("FORCE_PLATFORM", "CHANNEL"), ("ANALOG", "LABELS"),
                        ("EVENT", "TIMES"), ("POINT", "ANGLES")):
        assert np.array_equal(np.asarray(old["parameters"][group][name]["value"]),
                              np.asarray(new["parameters"][group][name]["value"])), (group, name)
    labels = [s.split(":")[-1] for s in old["parameters"]["POINT"]["LABELS"]["value"]]
    angle = labels.index("LKneeAngles")
    assert "LKneeAngles" in report["points_unchanged"]
    assert np.array_equal(old["data"]["points"][:, angle], new["data"]["points"][:, angle])


def test_written_c3d_keeps_latin1_text_and_every_channel(tmp_path):
    """The Plug-in Gait walk's analog units hold a Latin-1 byte (mm/s², which ezc3d reads as a surrogate escape
    and could not write back): the copy keeps the units, points and analogs, and adds the points asked for."""
    hat = np.zeros((50, 3))
    write_moved_points(PIG, tmp_path / "copy.c3d", {}, {"HATO": hat}, 10)
    old, new = ezc3d.c3d(str(PIG)), ezc3d.c3d(str(tmp_path / "copy.c3d"))
    assert "mm/s²" in new["parameters"]["ANALOG"]["UNITS"]["value"]
    assert np.array_equal(old["data"]["analogs"], new["data"]["analogs"])
    n = old["data"]["points"].shape[1]
    assert np.array_equal(np.nan_to_num(old["data"]["points"]), np.nan_to_num(new["data"]["points"][:, :n]))
    assert read_c3d(tmp_path / "copy.c3d").labels[-1] == "HATO"


def _bvh_positions(path, joint: str) -> np.ndarray:
    """(F, 3) m: where the BVH at ``path`` puts ``joint``, internal frame (z up)."""
    body = body_from_bvh(read_bvh(path), BvhBodyOptions(units="cm", up_axis="z"))
    motion, data = read_bvh(path), body.model.createData()
    fid = body.model.getFrameId(joint)
    out = []
    for row in motion.frames:
        pin.framesForwardKinematics(body.model, data, body.channels_to_q(row))
        out.append(data.oMf[fid].translation.copy())
    return np.array(out)


@pytest.fixture(scope="module")
def full_lab(tmp_path_factory):
    """The synthetic gait lab's full-body subject (swaying on two plates, arms swinging) and its correction."""
    d = tmp_path_factory.mktemp("full")
    write_lab_c3d(d / "full.c3d", PLATES, full_body=True)
    assert main(["correct", str(d / "full.c3d"), "-o", str(d / "fixed.c3d"), "--report", str(d / "r.json")]) == 0
    return d, json.loads((d / "r.json").read_text())


def test_corrected_generated_c3d_keeps_its_feet_and_analyses_inside(full_lab):
    """Both feet stand on the plates all along: every foot marker stays within a millimetre in every frame; the
    trunk, head and arms have their own markers, so no HAT points are written."""
    d, report = full_lab
    before, after = _analyze(d / "full.c3d", d / "a0.json"), _analyze(d / "fixed.c3d", d / "a1.json")
    assert before["out_of_support_frames"] >= 30 and after["out_of_support_frames"] == 0
    old, new = read_c3d(d / "full.c3d"), read_c3d(d / "fixed.c3d")
    assert new.labels == old.labels and report["hat_points_written"] == []
    feet = [lab for lab in old.labels if lab[1:] in ("ANK", "HEE", "TOE")]
    assert max(np.nanmax(np.linalg.norm(new.marker(lab) - old.marker(lab), axis=1)) for lab in feet) < 1e-3
    assert np.nanmax(np.linalg.norm(new.marker("C7") - old.marker("C7"), axis=1)) > 0.005  # the trunk leaned


def test_a_marker_chain_written_as_bvh_places_its_segments_exactly(full_lab, tmp_path):
    """The synthetic full-body subject as BVH (what `correct TRIAL.c3d -o out.bvh` writes): the BVH puts the
    ankles, knees and wrists where the markers put them, under names a skeleton reader knows."""
    path = full_lab[0] / "full.c3d"
    take = body_from_markers(read_c3d(path))
    names = segment_names(take.body)
    write_bvh(chain_to_bvh(take.body, chain_frames(names, take.frames), 0.01, str(path)), tmp_path / "full.bvh")
    for joint, (seg, centre) in {"LeftFoot": ("foot_l", take.centres["ankle"]["left"]),
                                 "RightLeg": ("shank_r", take.centres["knee"]["right"]),
                                 "LeftHand": ("hand_l", None)}.items():
        if centre is None:
            centre = take.frames[:, 6 * names.index(seg):][:, :3]
        assert np.abs(_bvh_positions(tmp_path / "full.bvh", joint) - centre).max() < 1e-6, joint
    names = [j.name for j in read_bvh(tmp_path / "full.bvh").joints]
    assert {"Hips", "Spine", "Head", "LeftArm", "RightForeArm", "LeftHand", "RightUpLeg"} <= set(names)


@pytest.mark.parametrize(("motion", "output", "message"), [
    (DATA / "bvh" / "bandai" / "walk_normal_001.bvh", "out.c3d", "only a C3D take"),
    (CGM, "out.csv", "written as C3D"),
])
def test_correct_output_format_it_cannot_write_is_one_line(motion, output, message, tmp_path, capsys):
    assert main(["correct", str(motion), "-o", str(tmp_path / output)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


def _plate_strikes(trial) -> list[tuple[float, np.ndarray]]:
    """(time s, CoP (2,) m 50 ms after the strike) of every plate the subject stepped on, in time order:
    the strike is where the plate's vertical force (its unloaded offset removed) first passes 20 N."""
    out = []
    for plate in trial.plates:
        force, moment = unloaded_offset(plate, trial.analog_rate)
        f, m = plate.force - force, plate.moment - moment
        if f[:, 2].max() < 200:
            continue
        i = int(np.argmax(f[:, 2] > 20.0))
        j = i + round(0.05 * trial.analog_rate)
        out.append((i / trial.analog_rate, plate.centre[:2] + np.array([-m[j, 1], m[j, 0]]) / f[j, 2]))
    return sorted(out, key=lambda s: s[0])


def test_gait_features_of_the_plugin_gait_walk_match_its_plates():
    """Three strikes on plates (right, left, right): one stride of 1.086 s and 0.99 m. The take (2.2 s) has
    one whole thigh cycle, a later stride than the plates' (the file's own events make it 1.11 s)."""
    strikes = _plate_strikes(read_c3d(PIG))
    assert len(strikes) == 3
    stride_time = strikes[2][0] - strikes[0][0]
    stride = float(np.linalg.norm(strikes[2][1] - strikes[0][1]))
    f = walk_features(load_take(PIG))
    assert f.cycles.n_cycles == 1
    assert f.frequency == pytest.approx(1 / stride_time, rel=0.05)
    assert f.stride_length == pytest.approx(stride, rel=0.03)
    ahead = (strikes[2][1] - strikes[0][1]) / stride  # step lengths along the walk (feet are apart sideways)
    steps = [float((b[1] - a[1]) @ ahead) for a, b in zip(strikes[:-1], strikes[1:], strict=True)]
    assert np.mean(steps) == pytest.approx(f.stride_length / 2, rel=0.03)


def test_gait_features_of_the_cgm_walk_match_its_foot_strikes():
    """Four whole cycles. Its one plate's strike is the file's left foot strike to the millisecond, so the
    file's strikes are the reference: cadence from their times, stride length from the heel markers there."""
    trial = read_c3d(CGM)
    (plate_strike, _), = _plate_strikes(trial)
    f = walk_features(load_take(CGM))
    strides, lengths = [], []
    for side in ("Left", "Right"):
        t = np.array(sorted(s - trial.start_time for c, lab, s in trial.events if (c, lab) == (side, "Foot Strike")))
        t = t[t < len(trial.points) / trial.rate]
        if side == "Left":
            assert np.min(np.abs(t - plate_strike)) < 0.002
        strides += np.diff(t).tolist()
        heel = trial.marker(side[0] + "HEE")[np.rint(t * trial.rate).astype(int), :2]
        lengths += np.linalg.norm(np.diff(heel, axis=0), axis=1).tolist()
    assert f.cycles.n_cycles == 4
    assert 120 * f.frequency == pytest.approx(120 / np.mean(strides), rel=0.01)  # cadence, steps/min
    assert f.stride_length == pytest.approx(np.mean(lengths), rel=0.03)


def test_batch_gait_reads_c3d_walks_as_gait_does(tmp_path):
    job = GaitJob()
    progress = run_library(None, find_takes([str(CGM), str(PIG)], tmp_path, job), tmp_path, job)
    assert (progress.done, progress.failed) == (2, 0)
    rows = {Path(r["file"]).name: r for r in pq.read_table(tmp_path / "takes.parquet").to_pylist()}
    for path in (CGM, PIG):
        f = walk_features(load_take(path))
        assert rows[path.name]["frequency_hz"] == pytest.approx(f.frequency, abs=1e-6)
        assert rows[path.name]["stride_length_m"] == pytest.approx(f.stride_length, abs=1e-6)


def test_gait_compare_reads_c3d_and_synth_refuses_it_in_one_line(tmp_path, capsys):
    assert main(["gait", "compare", str(CGM), str(CGM)]) == 0
    assert "total RMS error 0.00°" in capsys.readouterr().out
    assert main(["gait", "synth", str(CGM), "--features", str(tmp_path / "f.json"), "--to", "fast",
                 "-o", str(tmp_path / "o.bvh")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "C3D" in err


def _recorded_zmp(path) -> np.ndarray:
    return np.array([[m["zmp"]["x"], m["zmp"]["y"]] for m in iter_messages(path, "/result")])


def test_monitor_and_analyze_give_the_same_zmp_with_a_subject_file(tmp_path):
    """A BVH walk: the subject's HAT mass fraction reweights the trunk, head and arms, in `analyze` and in the
    monitor's per-frame pipeline alike (and the recording's body keeps it: replay is the same)."""
    walk = DATA / "bvh" / "bandai" / "walk_normal_001.bvh"
    (tmp_path / "s.toml").write_text(SUBJECT)
    zmp = {}
    for name, extra in (("subject", ["--subject", str(tmp_path / "s.toml")]), ("table", [])):
        assert main(["analyze", str(walk), "--out", str(tmp_path / f"{name}.csv"), *extra]) == 0
        assert main(["monitor", str(walk), "--speed", "0", "--record", str(tmp_path / f"{name}.mcap"), *extra]) == 0
        rows = np.genfromtxt(tmp_path / f"{name}.csv", delimiter=",", names=True)
        zmp[name] = np.column_stack([rows["zmp_z"], rows["zmp_x"]])  # y-up file: internal x, y = input z, x
        assert np.abs(_recorded_zmp(tmp_path / f"{name}.mcap") - zmp[name]).max() < 1e-6  # the CSV's rounding
    assert np.abs(zmp["subject"] - zmp["table"]).max() > 0.005  # the subject file changed the ZMP
    assert main(["replay", str(tmp_path / "subject.mcap")]) == 0


def test_monitor_replays_a_c3d_with_the_subjects_hat(corrected, tmp_path):
    """The monitor's per-frame pipeline over a C3D's marker body with a subject file gives the ZMP of the same
    analysis run over the whole take (analyze's engine with the live estimator settings), and the subject's HAT,
    45 % of the mass and 30 mm forward of the table's, moves it forward."""
    d, _ = corrected
    (tmp_path / "s.toml").write_text(SUBJECT)
    # the table's HAT as a subject file (its sway the default's, as calibrate fits it)
    fraction, com, _ = hat_table(body_from_markers(read_c3d(d / "cut.c3d")).notes["stature_m"])
    (tmp_path / "t.toml").write_text(f"[subject]\nhat_fraction = {fraction}\n"
                                     f"hat_offset_m = [{com[0]}, {com[1]}, {com[2]}]\n")
    runs = {}
    for name, extra in (("subject", ["--subject", str(tmp_path / "s.toml")]),
                        ("table", ["--subject", str(tmp_path / "t.toml")])):
        assert main(["monitor", str(d / "cut.c3d"), "--speed", "0", "--record", str(tmp_path / f"{name}.mcap"),
                     *extra]) == 0
        runs[name] = _recorded_zmp(tmp_path / f"{name}.mcap")
    offline = analyse_loaded(TakeOptions(subject=str(tmp_path / "s.toml")).load(d / "cut.c3d"))
    assert np.abs(offline.zmp[:, :2] - runs["subject"]).max() < 1e-9
    trial = read_c3d(d / "cut.c3d")
    fwd = trial.marker("LASI")[-1, :2] - trial.marker("LASI")[0, :2]
    along = float(np.median(runs["subject"] - runs["table"], axis=0) @ fwd / np.linalg.norm(fwd))
    assert 0.005 < along < 0.03
    assert main(["replay", str(tmp_path / "subject.mcap")]) == 0


def test_monitor_replays_a_full_body_c3d_with_a_tracked_trunks_subject(tmp_path, capsys):
    """A tracked trunk's subject file (trunk_fraction, trunk_offset_m) on a full-body C3D: the monitor's per-frame
    pipeline gives the whole-take analysis' ZMP with the subject's thorax, which moves it, and the recording's body
    keeps the thorax (replay: the same analysis)."""
    from tests.test_c3d_gaitlab import PLATES, write_lab_c3d

    path, subject = tmp_path / "full.c3d", tmp_path / "s.toml"
    write_lab_c3d(path, PLATES, full_body=True)
    subject.write_text("[subject]\ntrunk_fraction = 0.38\ntrunk_offset_m = [0.04, 0.0, -0.20]\n")
    assert main(["monitor", str(path), "--speed", "0", "--record", str(tmp_path / "s.mcap"),
                 "--subject", str(subject)]) == 0
    live = _recorded_zmp(tmp_path / "s.mcap")
    offline = analyse_loaded(TakeOptions(subject=str(subject)).load(path))
    table = analyse_loaded(TakeOptions().load(path))
    assert np.abs(offline.zmp[:, :2] - live).max() < 1e-9
    assert np.abs(table.zmp[:, :2] - live).max() > 0.005  # the subject's thorax moved it
    capsys.readouterr()
    assert main(["replay", str(tmp_path / "s.mcap")]) == 0
    assert "same analysis" in capsys.readouterr().out


@pytest.mark.parametrize(("subject", "source", "message"), [
    ("[subject]\nhat_fraction = 0.5\nhat_offset_m = [0.0, 0.3]\n", "bvh", "hat_offset_m"),
    ("[subject]\ntrunk_fraction = 0.35\ntrunk_offset_m = [0.0, 0.0, -0.2]\n", "bvh", "a BVH takes a placed HAT's"),
    ("[person]\nhat_fraction = 0.5\n", "bvh", "[subject]"),
    ("[subject]\nhat_fraction = 0.5\nhat_offset_m = [0.0, 0.0, 0.3]\nhat_follow_hz = 0\n", "bvh", "hat_follow_hz"),
    (SUBJECT, "mcap", "describes a person"),
])
def test_bad_subject_for_monitor_is_one_line(subject, source, message, tmp_path, capsys):
    (tmp_path / "s.toml").write_text(subject)
    path = DATA / "bvh" / "bandai" / "walk_normal_001.bvh"
    if source == "mcap":
        path = tmp_path / "x.mcap"
        path.write_bytes(b"\x89MCAP0\r\n")
    assert main(["monitor", str(path), "--speed", "0", "--subject", str(tmp_path / "s.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


def test_a_capture_streams_marker_body_takes_the_subjects_hat():
    """What `monitor lsl://... --subject` builds: the marker stream's body with the subject's HAT (45 % of the
    mass) instead of the table's."""
    from tests.test_marker_stream import FakeStream  # a stream handing out a trial's markers

    trial = read_c3d(CGM)
    subject = Subject(0.45, (0.03, 0.0, 0.33))
    src = MarkerStreamSource(FakeStream(trial.labels, trial.points[:60]), trial,
                             replace(subject.marker_options(), total_mass=70.0))
    model = src.body.model
    hat = model.inertias[src.body.channel_names.index("hat.roll") + 1].mass
    assert hat == pytest.approx(0.45 * 70.0)
