"""The synthetic gait lab (tests/test_c3d_gaitlab.py) written the ways real labs write C3D: a y-up, an x-up and a z-down
lab, walking along -x, +y or a diagonal, an origin far from the plates; POINT:UNITS cm and m; point rates 50-240 Hz
with analog rates 1-20 times them; TYPE-2 plates as the C3D spec has them (z down, corners in its quadrant order,
ORIGIN below the surface) and with ORIGIN's z written positive or its x, y from the centre to a corner, TYPE-1 (the CoP
and free moment as channels), TYPE-4
(CAL_MATRIX), TYPE-3 (Kistler's eight channels), TYPE-5 (eight channels through a 6 x 8 CAL_MATRIX); ANALOG SCALE,
OFFSET and GEN_SCALE; integer files (POINT:SCALE > 0); plates turned 90 and 180 degrees in the floor; labels without
a subject prefix and no mass in the file. Each must give the true CoP from its plates and the ZMP on it to a
millimetre, the up axis and units it was written in, and the reference's summary figures. What cannot be read is
refused in one line."""

from __future__ import annotations

import struct
from dataclasses import replace

import ezc3d
import numpy as np
import pytest

from livezmp.balance.plates import PULL_N, lowpass, plate_frames, unloaded_offset
from livezmp.cli import main
from livezmp.model import c3d as c3d_mod
from livezmp.model.c3d import PlateRecord, _zero_samples, read_c3d
from livezmp.model.markers import MarkerBodyOptions
from livezmp.offline import calibrate as calibration
from livezmp.offline.gaitlab import LabOptions, analyse_lab_take
from tests.test_c3d_gaitlab import PLATES, Lab, parameter_at, write_lab_c3d

SECONDS = 3.0  # s: short takes keep the file fast
Y_UP = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0))  # lab y = up, lab z = the subject's right


def _turn(deg: float) -> tuple:
    """The reference turned ``deg`` about the vertical (the subject then faces that way in the lab)."""
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return ((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0))


SPEC = {"spec_plates": True}
VARIANTS = {
    "y-up": Lab(rot=Y_UP),
    "walk -x": Lab(rot=_turn(180)),
    "walk +y": Lab(rot=_turn(90)),
    "walk diagonal": Lab(rot=_turn(-135)),
    "far origin": Lab(origin=(12.5, -7.25, 0.0)),
    "y-up, diagonal, far, cm": Lab(rot=tuple(map(tuple, np.asarray(Y_UP) @ np.asarray(_turn(30)))),
                                   origin=(-9.0, 0.35, 6.0), units="cm", **SPEC),  # the floor 0.35 m up
    "cm": Lab(units="cm"),
    "m": Lab(units="m"),
    "no POINT:UNITS (mm)": Lab(units_given=False),  # ezc3d then labels its plates m: the plates were 1000x off
    "50 Hz x20": Lab(rate=50, analog=1000),
    "100 Hz x1": Lab(rate=100, analog=100),
    "120 Hz x5": Lab(rate=120, analog=600),
    "240 Hz x2": Lab(rate=240, analog=480),
    "240 Hz x10": Lab(rate=240, analog=2400),
    "type 2 spec": Lab(**SPEC),
    "type 2 origin z>0": Lab(origin_sign=-1.0, **SPEC),
    # a treadmill belt measuring about a corner, ORIGIN written from the centre to it (rtosim's walking_1.c3d)
    "type 2 corner origin, written from the centre": Lab(corner_origin=True, **SPEC),
    "type 4, SCALE OFFSET GEN_SCALE": Lab(plate_type=4, scale=(0.25, 1500, 2.0), **SPEC),
    # Qualisys' Kistler plates as QTM writes them (cgm2-web-report-uploader's WithNewPafFields walk): ezc3d refuses them
    "type 5 (CAL_MATRIX 6 x 8)": Lab(plate_type=5, **SPEC),
    # BTS writes its Bertec plates so (RehabEngGroup/MOtoNMS' UNIPD walks): ezc3d's moment for them is negated
    "type 1 (CoP channels), y-up": Lab(plate_type=1, rot=Y_UP, **SPEC),
    "integer mm": Lab(integer=0.06, scale=(1.0, 2048, 1.0)),
    "integer cm, y-up, type 3": Lab(integer=0.006, units="cm", rot=Y_UP, plate_type=3, **SPEC),
    "type 3": Lab(plate_type=3, **SPEC),
    "type 3 y-up m": Lab(plate_type=3, rot=Y_UP, units="m", **SPEC),
    # az0 written positive (AnyBody's GaitUniMiami, Vicon Workstation): ezc3d negated a and b with it
    "type 3 az0 > 0": Lab(plate_type=3, origin_sign=-1.0, **SPEC),
    "plates turned 90": Lab(plate_turn=90.0, **SPEC),
    "plates turned 180": Lab(plate_turn=180.0, plate_type=3, **SPEC),
    "no prefix, no mass": Lab(prefix="", mass=False),
    "x-up": Lab(rot=((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (-1.0, 0.0, 0.0))),
    "z down (-z up), type 3": Lab(rot=((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, -1.0)), plate_type=3, **SPEC),
}


def _up(lab: Lab) -> str:
    """The lab axis (signed) the reference's z points along."""
    col = np.asarray(lab.rot)[:, 2]
    ax = int(np.argmax(np.abs(col)))
    return ("-" if col[ax] < 0 else "") + "xyz"[ax]


def _analysis(tmp_path_factory, lab: Lab):
    path = tmp_path_factory.mktemp("variant") / "trial.c3d"
    cop = write_lab_c3d(path, PLATES, lab=replace(lab, seconds=SECONDS))
    data = path.read_bytes()
    offset = parameter_at(data)[("ANALOG", "OFFSET")]
    stored = struct.unpack_from("<f", data, 12)[0], struct.unpack_from("<h", data, offset)[0]
    assert stored == (pytest.approx(lab.integer or -1.0), lab.scale[1])  # POINT:SCALE (the header's), ANALOG:OFFSET
    trial = read_c3d(path)
    return trial, analyse_lab_take(trial), cop


@pytest.fixture(scope="module", autouse=True)
def _no_read_probe():
    """These files are ezc3d's own: the crash probe before each read (a new interpreter, ~0.4 s, tested with the
    fuzz suite) is left out to keep the variants fast."""
    with pytest.MonkeyPatch.context() as m:
        m.setattr(c3d_mod, "_check_ezc3d_survives", lambda p, size, plates: None)
        yield


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    return _analysis(tmp_path_factory, Lab())


@pytest.mark.parametrize("name", list(VARIANTS))
def test_a_lab_variant_reads_as_the_reference(name, reference, tmp_path_factory):
    lab = VARIANTS[name]
    trial, a, true_cop = _analysis(tmp_path_factory, lab)
    _, ref, _ = reference
    body = a.take.body
    assert body.up_axis == _up(lab)
    assert a.summary["input"]["point_units"] == lab.units
    # the plates' CoP, back in the reference frame, is the true one
    rows = a.complete & (a.times > 0.5) & (a.times < SECONDS - 0.5)
    k = np.rint(a.times[rows] * lab.analog).astype(int)
    cop_lab = body.to_input_frame(a.plates.cop[rows])
    cop_ref = (cop_lab - lab.origin) @ np.asarray(lab.rot)
    assert np.abs(cop_ref[:, :2] - true_cop[k]).max() < 2e-4
    assert np.abs(cop_ref[:, 2]).max() < 1e-6
    # ORIGIN read against the spec only where the spec's reading puts the CoP off the plate (the corner origin)
    assert sorted(a.summary["plates"].get("read", {})) == ([1, 2] if lab.corner_origin else [])
    cv, rv = a.summary["cop_vs_zmp"], ref.summary["cop_vs_zmp"]
    assert cv["max_mm"] < 1.0 and cv["rms_mm"] < 0.5
    assert cv["frames"] == pytest.approx(rv["frames"] * lab.rate / 100, rel=0.05)
    # along the way the subject faces and to its left, whichever way the lab's axes point (walking along -x the
    # lab's +x made it [-0.05, -0.06] against the reference's [0.05, 0.06])
    same = lab.rate == 100 and lab.analog == 1000 and lab.mass and not lab.integer
    # without the file's Height (written with its mass) the stature comes from the legs, and it sizes the placed HAT
    # and its centre of mass' offset behind the mid-hip (anthropometry: Dumas et al.) that the plates were made with
    assert cv["bias_mm"] == pytest.approx(rv["bias_mm"], abs=0.011 if same else 0.07 if lab.mass else 0.25)
    if same:  # the same samples: the same figures
        assert (cv["rms_mm"], cv["max_mm"]) == pytest.approx((rv["rms_mm"], rv["max_mm"]), abs=0.011)
    # no mass in the file and no whole gait cycle: the plates' mean vertical force over the take stood on them
    assert a.summary["mass"]["used_kg"] == pytest.approx(75.0, abs=0.2)
    assert a.summary["mass"]["source"].startswith("file" if lab.mass else "plates")
    assert a.summary["com_acc_vs_plates"]["r"] == pytest.approx(ref.summary["com_acc_vs_plates"]["r"], abs=0.02)
    # the plates' CoP against their force line, along the walk and across it, whichever way the lab's axes point
    fl, rf = a.summary["cop_vs_force_line"], ref.summary["cop_vs_force_line"]
    assert fl["plates_rms_mm"] == pytest.approx(rf["plates_rms_mm"], abs=0.4)  # ~1.5 / 0.5 mm: a swap would show


@pytest.mark.parametrize(("lab", "says"), [
    (Lab(rot=((1.0, 0.0, 0.0), (0.0, 0.7071, -0.7071), (0.0, 0.7071, 0.7071))), "cannot tell the up axis"),  # 45 deg
    (Lab(plate_type=6, spec_plates=True), "Type 6 is not supported"),  # ezc3d reads plate TYPEs 1-4, livezmp 5
    # ezc3d subtracts |OFFSET|: a negative one on signed data would shift the channel (0 complete frames here)
    (Lab(scale=(0.5, -500, 1.0)), "ANALOG:OFFSET of force-plate channel 1 is negative (-500)"),
], ids=["tilted 45 deg", "type 6", "negative offset"])
def test_a_lab_it_cannot_read_is_refused_in_one_line(lab, says, tmp_path, capsys):
    path = tmp_path / "trial.c3d"
    write_lab_c3d(path, PLATES, lab=replace(lab, seconds=SECONDS))
    assert main(["analyze", str(path), "--out", str(tmp_path / "z.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert says in err and len(err.splitlines()) == 1 and "Traceback" not in err


def test_calibration_does_not_depend_on_the_labs_axes(tmp_path):
    """A trunk swaying 0.5 times the mid-hip fore-aft and 0.7 times sideways (above 0.1 Hz: the synthetic sway is at
    0.3-0.4 Hz, so calibrate is given that follow frequency), written by the reference lab and by a
    y-up lab the subject faces diagonally in: `calibrate` reports the same errors (its sway axes are the way the
    subject faces when the take barely travels; with the lab's +x they were those of another sway)."""
    body = MarkerBodyOptions(hat_sway_gain=(0.5, 0.7), hat_follow_hz=0.1)
    opts = LabOptions(markers=MarkerBodyOptions(hat_follow_hz=0.1))
    reports = []
    for lab in (Lab(seconds=SECONDS), VARIANTS["y-up, diagonal, far, cm"]):
        write_lab_c3d(tmp_path / "sway.c3d", PLATES, body=body, lab=replace(lab, seconds=SECONDS))
        reports.append(calibration.calibrate([read_c3d(tmp_path / "sway.c3d")], opts)[1])
    keys = ("rms_table_mm", "rms_fitted_mm", "rms_held_out_table_mm", "rms_held_out_fitted_mm")
    assert reports[0]["rms_table_mm"] > 3.5
    assert [reports[1][k] for k in keys] == pytest.approx([reports[0][k] for k in keys], abs=0.02)


def test_each_trial_is_scored_with_the_other_trials_calibration(tmp_path, capsys):
    """Two takes of one subject (its HAT 40 mm forward, 45 % of the mass), from the reference lab and from a y-up lab
    it faces diagonally in: calibrated on either, the other's ZMP agrees with its plates to a few millimetres, where
    the table is off by over 15 mm. Pooled with another subject's take, the command says they do not transfer."""
    body = MarkerBodyOptions(hat_offset=(0.04, 0.0, 0.33), hat_fraction=0.45, hat_sway_gain=None)
    trials = []
    for k, lab in enumerate((Lab(seconds=SECONDS), VARIANTS["y-up, diagonal, far, cm"])):
        write_lab_c3d(tmp_path / f"{k}.c3d", PLATES, body=body, lab=replace(lab, seconds=SECONDS))
        trials.append(read_c3d(tmp_path / f"{k}.c3d"))
    report = calibration.calibrate(trials)[1]
    assert report["rms_other_trials_table_mm"] > 15 and report["rms_other_trials_fitted_mm"] < 4
    # a take of another subject (its HAT 40 mm back) pooled with the first: each scored with the other's
    # calibration is worse than with the table, and the command asks whether they are one subject
    other = replace(body, hat_offset=(-0.04, 0.0, 0.33), hat_fraction=0.52)
    write_lab_c3d(tmp_path / "other.c3d", PLATES, body=other, lab=Lab(seconds=SECONDS))
    assert main(["calibrate", str(tmp_path / "0.c3d"), str(tmp_path / "other.c3d"), "-o", str(tmp_path / "s.t")]) == 0
    assert "are these takes of one subject?" in capsys.readouterr().out


def test_a_constant_of_one_take_is_not_calibrated_into_the_subject(tmp_path):
    """Two takes of one subject at the table, the second's markers 30 mm off its plates along the walk (a take's own
    constant: that day's registration, a plate's origin). Each take held out in turn, a fit to the offset makes the
    other take worse, so the table is kept. With every other 0.2 s block of both takes as the folds (as before), both
    folds held the offset and the fit moved the HAT's centre of mass to make up for it."""
    write_lab_c3d(tmp_path / "a.c3d", PLATES, lab=Lab(seconds=SECONDS))
    take = read_c3d(tmp_path / "a.c3d")
    shifted = replace(take, points=take.points + np.array([0.03, 0.0, 0.0]))
    report = calibration.calibrate([take, shifted])[1]
    assert report["rms_table_mm"] > 10 and report["table_kept"] and report["prior_weight"] is None
    assert report["folds"] == "each trial held out"
    # each take scored with the other's calibration: no better than the table
    assert report["rms_other_trials_fitted_mm"] >= report["rms_other_trials_table_mm"]


def test_a_plates_dc_offset_is_taken_over_the_files_zero_frames(tmp_path):
    """c3d.org's TYPE-3 sample has plates that read -80 to -212 N unloaded (an amplifier's DC offset) until walked
    on, and names its unloaded frames in FORCE_PLATFORM:ZERO. Here the right plate (Kistler's eight channels) reads
    -200 N while the left foot carries the whole body for 0.3 s, ZERO naming frames 1-20: that baseline is removed
    and the plates give the true CoP. The left plate, loaded in those frames, keeps none (its reading falls below
    that baseline later). Without the ZERO range nothing tells the offset from a load: the right plate reads a
    pull, is set aside, and no frame is complete."""
    def analysed(zero):
        lab = Lab(plate_type=3, seconds=SECONDS, zero=zero, **SPEC)
        cop = write_lab_c3d(tmp_path / "t.c3d", PLATES, lab=lab, right_free_s=0.3, right_bias_n=-200.0)
        return analyse_lab_take(read_c3d(tmp_path / "t.c3d")), cop

    a, true_cop = analysed((1, 20))
    plates = a.summary["plates"]
    assert plates["set_aside"] == []
    assert plates["offsets_removed_n"][0] is None
    assert plates["offsets_removed_n"][1] == pytest.approx([0.0, 0.0, -200.0], abs=1e-3)
    rows = a.complete & (a.times > 0.5) & (a.times < SECONDS - 0.5)
    assert rows.sum() > 150
    k = np.rint(a.times[rows] * 1000).astype(int)
    assert np.abs(a.take.body.to_input_frame(a.plates.cop[rows])[:, :2] - true_cop[k]).max() < 2e-4
    assert a.summary["cop_vs_zmp"]["max_mm"] < 1.0
    without = analysed((1, 0))[0].summary
    assert [p["plate"] for p in without["plates"]["set_aside"]] == [2] and without["cop_vs_zmp"]["frames"] == 0


@pytest.mark.parametrize(("zero", "samples"), [([1, 20], (0, 200)), ([0, 20], (0, 200)), ([0, 0], None),
                                               ([1.0, float("inf")], None), ([float("nan"), 5.0], None),
                                               (["a", "b"], None), ([5, 500], (40, 1000))])
def test_force_platform_zero_frames_as_analog_samples(zero, samples):
    """FORCE_PLATFORM:ZERO (first frame 1, 0 read as 1) in analog samples at 10 a frame over 100 frames; a range
    that is none, or not numbers (NaN, an infinite float, text), names nothing instead of raising."""
    assert _zero_samples({"FORCE_PLATFORM": {"ZERO": {"value": zero}}}, 1000, 100) == samples


def test_a_zero_range_that_is_no_unloaded_reading_is_not_taken():
    """FORCE_PLATFORM:ZERO names frames that are not an unloaded plate's reading: a blank first frame (all zeros,
    as c3d.org's Innovative Sports Training sample stores before its plates read 21 N unloaded), or a plate stood on
    all along. Neither is taken: the first plate's offset is its unloaded 21 N, the second keeps the weight."""
    t = np.arange(3000) / 1000.0
    step = np.clip(np.sin(np.pi * (t - 1.0)), 0.0, None) * (t < 2.0)  # stepped on from 1 to 2 s
    fz = {"blank": 21.0 + 0.5 * np.sin(2 * np.pi * 7 * t) + 700.0 * step, "standing": 700.0 + 5 * np.sin(t)}
    fz["blank"][:18] = 0.0

    def offset(name):
        force = np.column_stack([np.zeros((len(t), 2)), fz[name]])
        return unloaded_offset(PlateRecord(force, np.zeros_like(force), np.zeros(3), np.zeros((4, 3)), (0, 18)),
                               1000.0)

    assert offset("blank")[0][2] == pytest.approx(21.0, abs=0.5)  # a 0.1 s stretch of its 0.5 N, 7 Hz noise
    assert offset("standing") is None


def test_blank_samples_before_the_zero_ranges_reading_are_left_out():
    """AnyBody's GaitUniMiami sample (Vicon Workstation, Kistler plates) names frames 0-20 unloaded; one plate's
    channels are blank (exact zeros) for their first 0.1 s, then read its amplifier's -103 N, beyond what a quiet
    stretch may read. Its offset is the -103 N read after the blank samples: before, the blank and the reading
    together were not steady, no quiet stretch was near zero, and the plate, reading -103 N, was set aside as
    pulling."""
    t = np.arange(3000) / 1000.0
    fz = -103.0 + 1.2 * np.sin(2 * np.pi * 7 * t) + 800.0 * np.clip(np.sin(np.pi * (t - 1.0)), 0.0, None) * (t < 2.0)
    fz[:150] = 0.0
    force = np.column_stack([np.zeros((len(t), 2)), fz])
    got = unloaded_offset(PlateRecord(force, np.zeros_like(force), np.zeros(3), np.zeros((4, 3)), (0, 300)), 1000.0)
    assert got is not None and got[0][2] == pytest.approx(-103.0, abs=0.5)


@pytest.mark.parametrize("layout", ["(2, n)", "flat pairs", "labels beyond USED"])
def test_event_times_as_labs_write_them(layout, tmp_path):
    """EVENT:TIMES is (2, USED) minutes and seconds; some writers store it flat, the pairs interleaved (as a
    Plug-in Gait sample of BTK's test data does: 24 numbers for 12 events), and some list more labels than USED
    counts. Each reads as the same events (the flat file was a traceback before)."""
    path = tmp_path / "trial.c3d"
    write_lab_c3d(path, PLATES, lab=Lab(seconds=SECONDS))
    events = [("Left", "Foot Strike", 0.52), ("Right", "Foot Off", 61.25), ("Left", "Foot Off", 1.5)]
    minutes_seconds = np.array([[t // 60, t % 60] for _, _, t in events])
    c3d = ezc3d.c3d(str(path))
    labels, contexts = [lab for _, lab, _ in events], [c for c, _, _ in events]
    if layout == "(2, n)":
        c3d.add_parameter("EVENT", "TIMES", minutes_seconds.T)
    else:
        c3d.add_parameter("EVENT", "TIMES", minutes_seconds.ravel())
    if layout == "labels beyond USED":
        labels, contexts = labels + ["Foot Strike"], contexts + ["Right"]
    c3d.add_parameter("EVENT", "USED", [len(events)])
    c3d.add_parameter("EVENT", "LABELS", labels)
    c3d.add_parameter("EVENT", "CONTEXTS", contexts)
    c3d.write(str(path))
    got = read_c3d(path).events
    assert [(c, lab) for c, lab, _ in got] == [(c, lab) for c, lab, _ in events]
    assert [t for _, _, t in got] == pytest.approx([t for _, _, t in events], abs=1e-4)


@pytest.mark.parametrize(("plate", "refused"), [(1, True), (2, True), (3, False)], ids=["left", "right", "spare"])
def test_plates_stepped_on_at_two_heights_are_refused_in_one_line(plate, refused, tmp_path, capsys):
    """pyCGM's Movement_trial climbs a stair of four plates 0, 195, 389 and 584 mm up; read as one floor at their
    mean height it gave a ZMP RMS of 22 mm against plates that are no one plane. A plate stepped on 0.2 m above
    the other is refused in one line naming the plates' heights; the unloaded spare plate 0.2 m up is not in the
    walk and changes nothing."""
    path = tmp_path / "trial.c3d"
    write_lab_c3d(path, PLATES, lab=Lab(seconds=SECONDS))
    c3d = ezc3d.c3d(str(path))
    corners = np.array(c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"], dtype=float)
    corners[2, :, plate - 1] += 200.0  # mm
    c3d.add_parameter("FORCE_PLATFORM", "CORNERS", corners)
    c3d.write(str(path))
    code = main(["analyze", str(path), "--out", str(tmp_path / "z.csv")])
    err = capsys.readouterr().err.strip()
    if refused:
        heights = "0, 200" if plate == 2 else "200, 0"
        assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err
        assert f"not one level floor (plates 1, 2 at {heights} mm)" in err
    else:
        assert code == 0 and err == ""


def test_a_plate_stepped_on_leaning_like_a_ramp_is_refused_in_one_line(tmp_path, capsys):
    """fhstp/autoSIM's FH Campus Wien walks go up two plates leaning 9.9 deg (a ramp). A plate stepped on with its
    far edge 86 mm up (its mean height 43 mm up, within one floor's LEVEL_M) was read as level, its CoP compared
    with a ZMP on a floor it is not; it is refused in one line naming the plate and its lean. Leaning 0.5 deg (the
    most of any plate stepped on in the trials read is 0.8) it is read."""
    for rise, refused in ((86.0, True), (4.0, False)):
        path = tmp_path / f"trial_{rise:.0f}.c3d"
        write_lab_c3d(path, PLATES, lab=Lab(seconds=SECONDS))
        c3d = ezc3d.c3d(str(path))
        corners = np.array(c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"], dtype=float)
        far = np.argsort(corners[0, :, 1])[2:]  # plate 2's two corners furthest along the lab's x
        corners[2, far, 1] += rise  # mm
        c3d.add_parameter("FORCE_PLATFORM", "CORNERS", corners)
        c3d.write(str(path))
        code = main(["analyze", str(path), "--out", str(tmp_path / "z.csv")])
        err = capsys.readouterr().err.strip()
        if refused:
            lean = np.degrees(np.arctan(rise / np.ptp(corners[0, :, 1])))
            assert code == 2 and len(err.splitlines()) == 1 and "Traceback" not in err
            assert f"force plate stepped on 2 leans {lean:.1f} deg from level: a ramp" in err
        else:
            assert code == 0 and err == ""


def test_a_running_step_is_no_pull():
    """A running step loads a plate hard and briefly (AnyBody's SlowRun: 1750 N over about 0.25 s); low-passed at
    the estimator's 4.9 Hz it rings 40 N below zero after the step, and both of SlowRun's plates were set aside as
    pulling. A plate is judged on its mean over 0.1 s: kept; one drifting to -60 N is still set aside."""
    rate, t = 2000.0, np.arange(4000) / 2000.0
    step = np.where((t > 0.8) & (t < 1.05), 1750.0 * np.sin(np.pi * (t - 0.8) / 0.25), 0.0)
    assert lowpass(step, rate, 4.9).min() < -PULL_N  # what set it aside

    def aside(fz):
        force = np.column_stack([np.zeros((len(t), 2)), fz])
        plate = PlateRecord(force, np.zeros_like(force), np.zeros(3), np.zeros((4, 3)), (0, 100))
        return plate_frames([plate], rate, 100.0, np.arange(200), np.eye(3), 4.9).set_aside

    assert aside(step) == []
    assert [p["plate"] for p in aside(step - 60.0 * np.clip(t - 1.5, 0.0, None) * 2)] == [1]


def test_plates_raised_above_the_floor_are_read_from_the_feet_on_them(tmp_path):
    """Qualisys' ClinicalGait walks step 88 mm up onto their plates (portable plates on the lab's floor): the take's
    lowest markers stand off the plates, below their surface, and the soles measured from that surface lay the feet
    on the plates 40 mm and more above it: no frame was complete. The subject here first stands 1 m behind the
    plates on a floor 88 mm below them, then steps up (0.5 s) onto them: the soles are the level lab's, the summary
    says how far the plates stand up, and the ZMP on them is the plates' CoP."""
    path, stepped = tmp_path / "level.c3d", tmp_path / "stepped.c3d"
    write_lab_c3d(path, PLATES, with_offsets=False, lab=Lab(seconds=SECONDS))
    c3d = ezc3d.c3d(str(path))
    pts = np.array(c3d["data"]["points"])
    toe = [v.split(":")[-1] for v in c3d["parameters"]["POINT"]["LABELS"]["value"]].index("RTOE")
    pts[:, toe] = pts[:, toe, -1:]  # its gap at the start (the feet stand still)
    before, up = 1.0, 0.5  # s: standing off the plates, stepping up onto them
    t = np.arange(round((before + up) * 100)) / 100.0
    w = np.clip((t - before) / up, 0.0, 1.0)
    shift = np.outer([-1000.0, 0.0, -88.0, 0.0], 1 - w * w * (3 - 2 * w))  # mm, the x and z of the floor stance
    pts = np.concatenate([pts[:, :, :1] + shift[:, None], pts], axis=2)
    analogs = np.array(c3d["data"]["analogs"])
    analogs = np.concatenate([np.zeros((1, analogs.shape[1], round((before + up) * 1000))), analogs], axis=2)
    c3d["data"]["points"], c3d["data"]["analogs"] = pts, analogs
    del c3d["data"]["meta_points"]  # residuals of the shorter take
    c3d.write(str(stepped))
    # the written plates read nothing of the step's own dynamics: no delay to measure against it
    ref, a = (analyse_lab_take(read_c3d(p), LabOptions(plate_delay_s=0.0)) for p in (path, stepped))
    assert a.summary["markers"]["floor"]["below_plates_mm"] == pytest.approx(88.0, abs=2.0)
    for side, foot in a.take.body.feet.items():
        level = ref.take.body.feet[side]
        assert (foot.ankle_height, foot.toe_height) == pytest.approx((level.ankle_height, level.toe_height), abs=0.003)
    # the placed HAT's slow follow carries the step for a second: compared 1.5 s after it
    rows = a.complete & (a.times > before + up + 1.5)
    assert rows.sum() > 100
    assert 1000 * np.abs(a.result.zmp[rows, :2] - a.plates.cop[rows, :2]).max() < 1.0
