"""Built-in label conventions: a synthetic gait lab's C3D relabelled as other systems and marker sets write
it gives the same ZMP as its Plug-in Gait labels; two labels claiming one marker are refused in one line."""

from __future__ import annotations

from dataclasses import replace

import ezc3d
import numpy as np
import pytest

from livezmp.cli import main
from livezmp.model.c3d import read_c3d
from livezmp.model.marker_labels import match_labels, role_of
from livezmp.model.marker_map import load_marker_map
from livezmp.model.markers import MarkerBodyOptions, body_from_markers
from livezmp.offline.gaitlab import LabOptions, analyse_lab_take
from tests.test_c3d_gaitlab import PLATES, RATE, _trial, write_lab_c3d

SIDE_NAMES = {"ASI": "ASIS", "PSI": "PSIS", "KNE": "Knee", "ANK": "Ankle", "HEE": "Heel", "TOE": "Toe"}
CAST = {"ASI": "IAS", "PSI": "IPS", "KNE": "FLE", "ANK": "FAL", "HEE": "FCC", "TOE": "FM2"}
# the synthetic lab's labels (PiG, prefixed Sub01:) -> each convention's; wands keep Plug-in Gait's names
CONVENTIONS = {
    "Motion Analysis / Codamotion": lambda s, m: f"{s}.{SIDE_NAMES.get(m, m)}",
    "QTM / Visual3D CAST": lambda s, m: f"{s}_{CAST.get(m, m)}",
    "side words, lower case": lambda s, m: ("left" if s == "L" else "right") + SIDE_NAMES.get(m, m).lower(),
    "side behind, subject prefix and suffix on every label": lambda s, m: f"{SIDE_NAMES.get(m, m)}_{s}",
    "lab's anatomical names": lambda s, m: s + {"KNE": "LFC", "ANK": "LMA", "HEE": "CAL", "TOE": "TO"}.get(m, m),
    # OpenSim's Stanford walking trials (opensim-core OpenSim/Tests/shared/walking2.c3d)
    "OpenSim walking trials": lambda s, m: s + {"KNE": "LFC", "ANK": "LMAL", "HEE": "CAL", "TOE": "MT2"}.get(m, m),
    # AnyBody's Qualisys gait examples (AMMR S3_Gait_Shod_1, SlowRun)
    "AnyBody / Qualisys": lambda s, m: s + {"ASI": "Asis", "PSI": "Psis", "KNE": "KneeLateral", "ANK": "AnkleLateral",
                                            "HEE": "Heel", "TOE": "Toe"}.get(m, m),
    # RealTimeBiomechanics/rtosim's Vicon Nexus set (data/ViconNexus/walking_1.c3d, S01.vsk)
    "rtosim (Vicon Nexus)": lambda s, m: s + {"KNE": "FCL", "ANK": "MALL", "HEE": "CAL"}.get(m, m),
}


@pytest.mark.parametrize("label, role", [
    ("V.Sacral", "SACR"), ("VSAC", "SACR"), ("SACRUM", "SACR"), ("L.TO", "LTOE"), ("R.Toe", "RTOE"),
    ("LLKN", "LKNE"), ("LMKN", "LKNM"), ("RLFC", "RKNE"), ("RLMA", "RANK"), ("RCAL", "RHEE"),
    ("L_IAS", "LASI"), ("R_IPS", "RPSI"), ("R_FLE", "RKNE"), ("L_FME", "LKNM"), ("L_FAL", "LANK"),
    ("L_TAM", "LMED"), ("R_FM2", "RTOE"), ("LeftASIS", "LASI"), ("l.asis", "LASI"), ("ASIS_L", "LASI"),
    ("L_ASI", "LASI"), ("LASIS", "LASI"), ("Knee.Right", "RKNE"), ("LKNE", "LKNE"), ("C7", "C7"), ("LSC", "LCLA"),
    ("R_SC", "RCLA"), ("R.Knee.Medial", "RKNM"), ("L.Ankle.Medial", "LMED"), ("RKneeLateral", "RKNE"),
    ("LANKLELATERAL", "LANK"), ("RLMAL", "RANK"), ("LMMAL", "LMED"), ("LMT2", "LTOE"), ("LLKNE", "LKNE"),
    ("RLKNE", "RKNE"), ("LKneeLat", "LKNE"), ("RAnkleLat", "RANK"), ("LLMA", "LANK"), ("R_KNEE_MED", "RKNM"),
    ("L_ANKLE_MED", "LMED"), ("RFCL", "RKNE"), ("LFCM", "LKNM"), ("RMALL", "RANK"), ("LMALM", "LMED"),
    ("LKNEL", "LKNE"), ("RKNEM", "RKNM"), ("RLM", "RANK"), ("LMM", "LMED"), ("RCA", "RHEE"),
    ("SNJ", "CLAV"), ("SJN", "CLAV"), ("SXS", "STRN"), ("TV8", "T10"), ("r knee 1", "RKNE"), ("l should", "LSHO"),
    ("r mall", "RANK"), ("sacrum", "SACR"),
])
def test_labels_of_the_common_conventions_name_their_roles(label, role):
    assert role_of(label)[0] == role


# RLEP: a lateral epicondyle, the femur's or the humerus' (ISB names them apart: FLE, HLE); LLA_TOE, LMT5 and r met
# are the toe's stand-ins only where no label claims the toe (test_the_metatarsal_heads_stand_in_for_a_missing_toe);
# r knee 2, r bar 1: the Davis set's fibular head and thigh wand
@pytest.mark.parametrize("label", ["LKneeAngles", "R_THIGH_1", "VLKN", "LFEO", "L.Sac.Wand", "LTHI2", "LMT5",
                                   "r knee 2", "r bar 1", "r met", "PELO", "LHipPower", "RLEP", "LLA_TOE",
                                   "RBackAsis", "R.Shoulder"])
def test_other_labels_name_no_role(label):
    assert role_of(label) is None


def _relabelled(src, dst, rename) -> None:
    c3d = ezc3d.c3d(str(src))
    labels = c3d["parameters"]["POINT"]["LABELS"]["value"]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = [rename(v.split(":")[-1]) for v in labels]
    c3d.write(str(dst))


@pytest.fixture(scope="module")
def std(tmp_path_factory):
    path = tmp_path_factory.mktemp("labels") / "pig.c3d"
    write_lab_c3d(path, PLATES)
    return path, analyse_lab_take(read_c3d(path))


@pytest.mark.parametrize("convention", CONVENTIONS)
def test_a_relabelled_trial_gives_the_plug_in_gait_zmp(std, tmp_path, convention):
    path, ref = std
    name = CONVENTIONS[convention]
    other = tmp_path / "other.c3d"
    prefix = "p07_" if "prefix" in convention else ""
    suffix = ".trial3" if "prefix" in convention else ""
    _relabelled(path, other, lambda lab: prefix + (name(lab[0], lab[1:]) if lab[0] in "LR" and lab[1:] in SIDE_NAMES
                                                   else lab) + suffix)
    trial = read_c3d(other)
    assert "LKNE" not in trial.labels  # really renamed
    a = analyse_lab_take(trial)
    assert a.summary["cop_vs_zmp"]["frames"] == ref.summary["cop_vs_zmp"]["frames"] > 250
    np.testing.assert_array_equal(a.result.zmp, ref.result.zmp)  # the same markers: the same numbers
    labels = a.summary["markers"]["labels"]
    assert labels["aliases"]["LKNE"] == prefix + name("L", "KNE") + suffix and labels["conventions"]
    assert "labels read as" in a.summary["markers"]["marker_set"]
    # the long gap is reported under the file's own label
    assert a.summary["markers"]["marker_gaps_open"][0]["marker"] == prefix + name("R", "TOE") + suffix


DAVIS = {"ASI": "asis", "KNE": "knee 1", "ANK": "mall", "HEE": "heel", "TOE": "met", "SHO": "should"}


def test_the_davis_set_as_bts_labels_it_gives_the_plug_in_gait_zmp(tmp_path):
    """The Davis protocol as BTS writes it (``r asis``, ``r knee 1``, ``r mall``, ``r met``, ``r should``: lower case,
    a blank after the side) on a lab whose thorax is tracked by its shoulders: the same markers read, the same ZMP;
    ``met``, the fifth metatarsal head, stands in for the toe."""
    path, davis = tmp_path / "pig.c3d", tmp_path / "davis.c3d"
    write_lab_c3d(path, PLATES, trunk="shoulders")
    _relabelled(path, davis, lambda lab: f"{lab[0].lower()} {DAVIS[lab[1:]]}" if lab[1:] in DAVIS and lab[0] in "LR"
                else lab)
    ref, a = analyse_lab_take(read_c3d(path)), analyse_lab_take(read_c3d(davis))
    np.testing.assert_array_equal(a.result.zmp, ref.result.zmp)
    assert a.summary["cop_vs_zmp"]["frames"] == ref.summary["cop_vs_zmp"]["frames"] > 250
    labels = a.summary["markers"]["labels"]
    assert labels["aliases"]["LKNE"] == "l knee 1" and labels["aliases"]["RSHO"] == "r should"
    assert "fifth metatarsal head alone" in labels["toe"]["LTOE"]
    assert "thorax from LSHO RSHO" in a.summary["markers"]["marker_set"]


def test_two_labels_claiming_one_marker_are_refused_naming_both(std, tmp_path, capsys):
    path, ref = std
    other = tmp_path / "twice.c3d"
    _relabelled(path, other, lambda lab: {"LKNE": "L.Knee", "LTHI": "LLFC"}.get(lab, lab))
    assert main(["analyze", str(other), "--out", str(tmp_path / "z.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "labels 'LLFC' and 'L.Knee' both name the LKNE marker" in err
    assert 'chooses: LKNE = "LLFC" or LKNE = "L.Knee"' in err
    assert not (tmp_path / "z.csv").exists()
    # a marker map says which one: then read, with the Plug-in Gait ZMP
    map_path = tmp_path / "map.toml"
    map_path.write_text('[labels]\nLKNE = "L.Knee"\n')
    a = analyse_lab_take(read_c3d(other), LabOptions(markers=MarkerBodyOptions(marker_map=load_marker_map(map_path))))
    assert np.abs(a.result.zmp - ref.result.zmp).max() < 1e-4


def test_a_map_naming_a_role_sets_the_files_own_marker_of_that_name_apart(std, tmp_path, capsys):
    """TYPE-3's case: its LANK and LLMA both claim the ankle (refused); a map naming LLMA as LANK sets the
    file's LANK apart (here LLMA carries the ankle marker and LANK the thigh wand's, which the knee does not use)."""
    path, ref = std
    other = tmp_path / "type3.c3d"
    _relabelled(path, other, lambda lab: {"LANK": "LLMA", "LTHI": "LANK"}.get(lab, lab))
    assert main(["analyze", str(other)]) == 2
    assert "labels 'LANK' and 'LLMA' both name the LANK marker" in capsys.readouterr().err
    map_path = tmp_path / "map.toml"
    map_path.write_text('[labels]\nLANK = "LLMA"\n')
    a = analyse_lab_take(read_c3d(other), LabOptions(markers=MarkerBodyOptions(marker_map=load_marker_map(map_path))))
    assert np.abs(a.result.zmp - ref.result.zmp).max() < 1e-4


def _ankles_named_by_the_lab(apart_m: float):
    """The synthetic lab's markers as TYPE-3 names its ankles: the lateral malleolus ``LLMA`` (Plug-in Gait's
    LANK), and ``LANK`` on the medial malleolus ``apart_m`` medially of it (each side); and the true ankle centres."""
    trial = _trial(np.arange(200) / RATE, RATE)
    labels, points, centres = list(trial.labels), [trial.points], {}
    for side, medial in (("L", np.array([0.0, -1.0, 0.0])), ("R", np.array([0.0, 1.0, 0.0]))):
        lateral = trial.marker(side + "ANK")
        labels[labels.index(side + "ANK")] = side + "LMA"
        labels.append(side + "ANK")
        points.append((lateral + apart_m * medial)[:, None])
        centres[side] = lateral + apart_m / 2 * medial
    return replace(trial, labels=labels, points=np.concatenate(points, axis=1)), centres


def test_two_ankle_labels_a_joints_width_apart_are_told_lateral_and_medial_by_position():
    trial, centres = _ankles_named_by_the_lab(0.09)
    match = match_labels(trial)
    assert not match.ambiguous
    assert match.roles["LANK"] == "LLMA" and match.roles["LMED"] == "LANK" and match.roles["RMED"] == "RANK"
    assert match.by_position["LANK"] == "LLMA: 90 mm lateral of LANK"
    take = body_from_markers(trial)
    assert take.notes["labels"]["by_position"]["RMED"] == "RANK: 90 mm medial of RLMA"
    for side, name in (("L", "left"), ("R", "right")):  # the ankle centre between the two malleoli
        assert np.abs(take.centres["ankle"][name] @ np.linalg.inv(take.body.world_from_input).T
                      - centres[side]).max() < 1e-9
    # two markers 2 cm apart are not one ankle's two sides: which one the lab meant stays unsaid
    assert set(match_labels(_ankles_named_by_the_lab(0.02)[0]).ambiguous) == {"LANK", "RANK"}



def _with_medial_repeats(src, dst, describe: bool) -> None:
    """``src`` with each knee's and ankle's medial marker (a joint's width medial of the lateral one) added as a
    second ``LKNE`` / ``LANK`` ..., described ``L.Knee.Medial`` ... when ``describe`` (Motion Analysis' Helen
    Hayes template)."""
    c3d = ezc3d.c3d(str(src))
    point = c3d["parameters"]["POINT"]
    labels = list(point["LABELS"]["value"])
    bare = [v.split(":")[-1] for v in labels]
    pts = c3d["data"]["points"]
    added, descriptions = [], []
    for side, medial_y, word in (("L", -1.0, "L"), ("R", 1.0, "R")):
        for mk, joint, width in (("KNE", "Knee", 0.10), ("ANK", "Ankle", 0.07)):
            medial = pts[:, bare.index(side + mk)].copy()
            medial[1] += 1000.0 * width * medial_y  # mm, the lab's unit; the walk faces +x, left is +y
            added.append(medial)
            labels.append(labels[bare.index(side + mk)])
            descriptions.append(f"{word}.{joint}.Medial" if describe else "")
    c3d["data"]["points"] = np.concatenate([pts, np.stack(added, axis=1)], axis=1)
    shape = c3d["data"]["points"].shape[1:]
    c3d["data"]["meta_points"]["residuals"] = np.zeros((1, *shape))
    c3d["data"]["meta_points"]["camera_masks"] = np.zeros((7, *shape), dtype=bool)
    point["LABELS"]["value"] = labels
    c3d.add_parameter("POINT", "DESCRIPTIONS", [""] * (len(labels) - 4) + descriptions)
    c3d.write(str(dst))


@pytest.mark.parametrize("describe", [True, False])
def test_medial_markers_written_as_repeated_labels_are_told_by_their_descriptions(std, tmp_path, capsys, describe):
    """Motion Analysis' Helen Hayes template writes the medial knee and ankle markers as a second RKNE / RANK
    described R.Knee.Medial / R.Ankle.Medial (BTK's Gait sample; c3d.org's Walk1 and newwalk, never seen there):
    the descriptions name them, so each knee and ankle centre is the mid-point of its two markers. Without
    descriptions the repeat is refused in one line, as before."""
    path = tmp_path / "repeats.c3d"
    _with_medial_repeats(std[0], path, describe)
    if not describe:
        assert main(["analyze", str(path), "--out", str(tmp_path / "z.csv")]) == 2
        err = capsys.readouterr().err.strip()
        assert "is written 2 times with data" in err and len(err.splitlines()) == 1
        return
    trial = read_c3d(path)
    assert trial.labels[-4:] == ["L.Knee.Medial", "L.Ankle.Medial", "R.Knee.Medial", "R.Ankle.Medial"]
    take = body_from_markers(trial)
    assert take.notes["labels"]["aliases"]["RKNM"] == "R.Knee.Medial"
    for side, name in (("L", "left"), ("R", "right")):
        for joint, mk, word in (("knee", "KNE", "Knee"), ("ankle", "ANK", "Ankle")):
            mid = (trial.marker(side + mk) + trial.marker(f"{side}.{word}.Medial")) / 2
            got = take.centres[joint][name] @ np.linalg.inv(take.body.world_from_input).T
            first, last = take.notes["frames_used"]
            assert np.abs(got - mid[first:last + 1]).max() < 1e-9


def _with_markers(trial, extra: dict, drop=()):
    """``trial`` with the markers ``extra`` (label -> (F, 3) m) added and the labels ``drop`` removed."""
    keep = [i for i, lab in enumerate(trial.labels) if lab not in drop]
    return replace(trial, labels=[trial.labels[i] for i in keep] + list(extra),
                   points=np.concatenate([trial.points[:, keep], np.stack(list(extra.values()), axis=1)], axis=1))


def test_a_toe_claimant_away_from_the_foot_is_set_aside_by_position():
    """osim_jogging's case: its femur cluster's middle marker RFM2 (CAST's FM2 name) and RTOE both claim the toe."""
    trial = _trial(np.arange(200) / RATE, RATE)
    thigh = {s + "FM2": trial.marker(s + "THI") + [0.05, 0.0, 0.0] for s in "LR"}
    match = match_labels(_with_markers(trial, thigh))
    assert not match.ambiguous and match.roles["LTOE"] == "LTOE" and match.roles["RTOE"] == "RTOE"
    assert match.toe["LTOE"].startswith("LTOE: at the foot, 159 mm from LANK; LFM2 set aside: 626 mm")
    take = body_from_markers(_with_markers(trial, thigh))
    assert "not at the foot" in take.notes["labels"]["toe"]["RTOE"]
    # two claimants both at the foot: which one the lab meant stays unsaid
    near = {"LFM2": trial.marker("LTOE") + [0.02, 0.0, 0.0]}
    assert set(match_labels(_with_markers(trial, near)).ambiguous) == {"LTOE"}


def test_the_metatarsal_heads_stand_in_for_a_missing_toe():
    """No TOE, FM2 or MT2: the mid-point of the first and fifth metatarsal heads, else the fifth alone."""
    trial = _trial(np.arange(200) / RATE, RATE)
    ref = body_from_markers(trial)
    across = np.array([0.0, 0.03, 0.0])  # the synthetic lab's +y is the left side's lateral
    heads = {"LMT1": trial.marker("LTOE") - across, "LMT5": trial.marker("LTOE") + across,
             "R_FM1": trial.marker("RTOE") + across, "R_FM5": trial.marker("RTOE") - across}
    take = body_from_markers(_with_markers(trial, heads, drop=("LTOE", "RTOE")))
    assert take.notes["labels"]["aliases"]["LTOE"] == "LMT1+LMT5"
    assert take.notes["labels"]["toe"]["RTOE"].startswith("mid-point of R_FM1 and R_FM5")
    assert np.abs(take.frames - ref.frames).max() < 1e-9  # the heads' mid-point is where the toe marker was
    # tsalemink's AUC set: a lateral toe marker alone, near the fifth metatarsal head
    lateral = {s + "LA_TOE": trial.marker(s + "TOE") + (across if s == "L" else -across) for s in "LR"}
    match = match_labels(_with_markers(trial, lateral, drop=("LTOE", "RTOE")))
    assert match.roles["LTOE"] == "LLA_TOE" and "fifth metatarsal head alone" in match.toe["LTOE"]


def test_an_epicondyle_is_the_knees_where_it_lies_along_the_leg():
    """La Trobe's RLEPI, the UNIPD set's RLE / RME name an epicondyle, the femur's or the humerus'. Along the leg
    (half way from the ASIS down to the ankle marker) it is the knee's; beside the waist, an elbow's, it claims
    nothing. The UNIPD set's malleoli RLM / RMM, calcaneus RCA and metatarsal heads RIMH / RVMH are read too."""
    trial = _trial(np.arange(200) / RATE, RATE)
    ref = body_from_markers(trial)
    knees = {s + "LEPI": trial.marker(s + "KNE") for s in "LR"}
    match = match_labels(_with_markers(trial, knees, drop=("LKNE", "RKNE")))
    assert match.roles["LKNE"] == "LLEPI" and match.roles["RKNE"] == "RLEPI" and not match.ambiguous
    assert match.epicondyles["LLEPI"].startswith("LKNE: ") and "of the way from LASI down to LANK" in \
        match.epicondyles["LLEPI"]
    take = body_from_markers(_with_markers(trial, knees, drop=("LKNE", "RKNE")))
    assert np.abs(take.frames - ref.frames).max() < 1e-9  # the same markers: the same body
    # the UNIPD names, the toe from the two metatarsal heads
    across = np.array([0.0, 0.03, 0.0])
    unipd = {s + "LE": trial.marker(s + "KNE") for s in "LR"} | {s + "LM": trial.marker(s + "ANK") for s in "LR"} | \
        {s + "CA": trial.marker(s + "HEE") for s in "LR"} | \
        {s + h: trial.marker(s + "TOE") + (1 if (s == "L") == (h == "VMH") else -1) * across
         for s in "LR" for h in ("IMH", "VMH")}
    take = body_from_markers(_with_markers(trial, unipd, drop=[s + m for s in "LR" for m in ("KNE", "ANK", "HEE",
                                                                                         "TOE")]))
    assert take.notes["labels"]["aliases"]["RKNE"] == "RLE" and take.notes["labels"]["aliases"]["LTOE"] == "LIMH+LVMH"
    assert np.abs(take.frames - ref.frames).max() < 1e-9
    # an elbow's epicondyle: level with the ASIS, 0.25 m out from it; the knee marker keeps its role alone
    elbows = {s + "LE": trial.marker(s + "ASI") + (1 if s == "L" else -1) * np.array([0.0, 0.25, 0.05]) for s in "LR"}
    match = match_labels(_with_markers(trial, elbows))
    assert match.roles["LKNE"] == "LKNE" and not match.ambiguous
    assert match.epicondyles["RLE"].startswith("not read (RKNE?): ") and "an elbow's" in match.epicondyles["RLE"]


def test_a_set_read_but_for_one_role_is_refused_naming_only_that_role(std, tmp_path, capsys):
    """pyorerun's running set: lateral knee and ankle names read, its back-of-pelvis markers not (no PSIS name)."""
    path, _ = std
    other = tmp_path / "run.c3d"
    names = {"KNE": "KneeLat", "ANK": "AnkleLat", "HEE": "Heel", "ASI": "ASIS", "PSI": "BackAsis"}
    _relabelled(path, other, lambda lab: lab[0] + names[lab[1:]] if lab[1:] in names else lab)
    assert main(["analyze", str(other), "--out", str(tmp_path / "z.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "no Plug-in Gait / Helen Hayes marker set: missing LPSI+RPSI or SACR (markers in the file:" in err


@pytest.mark.parametrize("names", [("CV7", "TV8", "SNJ", "SXS"), ("CV7", "TV10", "SJN", "SXS")])
def test_the_isb_trunk_names_track_the_thorax(tmp_path, names):
    """A Qualisys sample's (ezc3d's Qualisys.c3d) and AnyBody's (AMMR 2014001) trunk names, the jugular notch
    SNJ / SJN, the xiphisternal joint SXS and the eighth (or tenth) thoracic spinous process: the thorax is tracked
    as by Plug-in Gait's C7 T10 CLAV STRN, the same ZMP to the last digit (unread, the HAT was placed)."""
    path = tmp_path / "trunk.c3d"
    write_lab_c3d(path, PLATES, trunk=True)
    isb_names = dict(zip(("C7", "T10", "CLAV", "STRN"), names, strict=True))
    _relabelled(path, tmp_path / "isb.c3d", lambda lab: isb_names.get(lab, lab))
    ref, isb = (analyse_lab_take(read_c3d(p)) for p in (path, tmp_path / "isb.c3d"))
    assert "thorax from C7 T10 CLAV STRN" in isb.summary["markers"]["marker_set"]
    np.testing.assert_array_equal(isb.result.zmp, ref.result.zmp)
    assert isb.summary["cop_vs_zmp"]["max_mm"] < 1.0


def test_a_toe_marker_off_the_foots_long_axis_gives_way_to_the_metatarsal_heads():
    """Qualisys' NewPaf 1 (CGM2.4's forefoot LFMH LSMH LVMH): its toe markers lie 33 deg off the line from the heel
    to the first and fifth metatarsal heads' mid-point, behind the heads; the foot read along them turned its sole
    and the plates' CoP fell off it. Such a toe gives way to the heads' mid-point; one 10 deg off is kept."""
    trial = _trial(np.arange(200) / RATE, RATE)
    ref = body_from_markers(trial)
    across = np.array([0.0, 0.03, 0.0])  # the synthetic lab's +y is the left side's lateral
    heads = {"LFMH": trial.marker("LTOE") - across, "LVMH": trial.marker("LTOE") + across,
             "RFMH": trial.marker("RTOE") + across, "RVMH": trial.marker("RTOE") - across}

    def toe_turned(deg: float) -> dict:
        """The toe markers turned ``deg`` medially about the heel marker, 60 % as far from it."""
        out = {}
        for s, sign in (("L", -1.0), ("R", 1.0)):
            heel, toe = trial.marker(s + "HEE"), trial.marker(s + "TOE")
            a = np.radians(sign * deg)
            turn = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
            out[s + "TOE"] = heel + 0.6 * (toe - heel) @ turn.T
        return out

    off = _with_markers(_with_markers(trial, heads), toe_turned(33.0), drop=("LTOE", "RTOE"))
    take = body_from_markers(off)
    assert take.notes["labels"]["aliases"]["LTOE"] == "LFMH+LVMH"
    assert "LTOE set aside: 33 deg off the line from LHEE" in take.notes["labels"]["toe"]["LTOE"]
    assert np.abs(take.frames - ref.frames).max() < 1e-9  # the heads' mid-point is where the toe marker was
    kept = match_labels(_with_markers(_with_markers(trial, heads), toe_turned(10.0), drop=("LTOE", "RTOE")))
    assert kept.roles["LTOE"] == "LTOE" and kept.roles["RTOE"] == "RTOE" and not kept.toe
