"""Bad files and options: one stderr line naming the file/option and exit 2, never a
traceback, never exit 0 with NaN (issue 12, classes 3-8). Each case failed on the tree
before the checks in livezmp/checks.py (a traceback, exit 0 with a misread, or NaN)."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest

from livezmp.cli import main
from livezmp.gait.sinewalk import sine_bvh, walk_spec
from livezmp.model.bvh import write_bvh
from livezmp.model.demo_robot import demo_robot_path, demo_trajectory
from livezmp.model.trajectory_csv import write_joint_csv
from livezmp.model.urdf_body import body_from_urdf


def run(capsys, *argv) -> tuple[int, list[str], str]:
    rc = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return rc, cap.err.splitlines(), cap.out


def refused(capsys, *argv, names: str, says: str) -> None:
    """exit 2, exactly one stderr line, naming ``names`` and saying ``says`` (regex)."""
    rc, err, _ = run(capsys, *argv)
    assert rc == 2, err
    assert len(err) == 1, err
    assert names in err[0] and re.search(says, err[0]), err[0]


@pytest.fixture(scope="module")
def walk_text(tmp_path_factory) -> str:
    p = tmp_path_factory.mktemp("walk") / "walk.bvh"
    write_bvh(sine_bvh(walk_spec(), 1.0, 100.0, 2.0), p)
    return p.read_text()


@pytest.fixture(scope="module")
def robot(tmp_path_factory) -> tuple[Path, str]:
    """The demo robot's URDF text and a 1 s joint CSV text for it."""
    d = tmp_path_factory.mktemp("robot")
    body = body_from_urdf(demo_robot_path())
    write_joint_csv(demo_trajectory(body.joint_names, duration=1.0), d / "t.csv")
    return demo_robot_path().read_text(), (d / "t.csv").read_text()


def put(tmp_path: Path, name: str, text: str | bytes) -> Path:
    p = tmp_path / name
    (p.write_bytes if isinstance(text, bytes) else p.write_text)(text)
    return p


def with_line(text: str, prefix: str, new: str) -> str:
    return "\n".join(new if ln.startswith(prefix) else ln for ln in text.splitlines()) + "\n"


# -- class 5 and 6: frame time, sizes, deep hierarchies --------------------------------------------


@pytest.mark.parametrize("ft", ["1e-300", "1e-9", "3600", "1e308", "nan", "-0.01"])
def test_extreme_frame_time_is_one_line(tmp_path, capsys, walk_text, ft):
    p = put(tmp_path, "w.bvh", with_line(walk_text, "Frame Time:", f"Frame Time: {ft}"))
    refused(capsys, "analyze", p, names="w.bvh:", says="Frame Time")


def test_deep_hierarchy_is_one_line_not_recursion_error(tmp_path, capsys):
    depth = 1500
    lines = ["HIERARCHY", "ROOT J0", "{", "OFFSET 0 0 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    for k in range(1, depth):
        lines += [f"JOINT J{k}", "{", "OFFSET 0 1 0", "CHANNELS 1 Xrotation"]
    lines += ["}"] * depth + ["MOTION", "Frames: 1", "Frame Time: 0.01", " ".join(["0"] * (depth + 2))]
    refused(capsys, "analyze", put(tmp_path, "deep.bvh", "\n".join(lines)), names="deep.bvh:", says="joints")


def test_channel_count_is_refused_before_allocating(tmp_path, capsys):
    """A file's channels are bounded by its joints (MAX_JOINTS, 6 channels each; the model's own channels by
    MAX_CHANNELS, tests/test_bvh_massless.py): a flat skeleton of 301 joints is refused while its hierarchy is read."""
    lines = ["HIERARCHY", "ROOT R", "{", "OFFSET 0 0 0", "CHANNELS 6 Xposition Yposition Zposition "
             "Zrotation Xrotation Yrotation"]
    for k in range(300):  # 1806 channels
        lines += [f"JOINT J{k}", "{", "OFFSET 0 1 0", "CHANNELS 6 Xposition Yposition Zposition Zrotation "
                  "Xrotation Yrotation", "}"]
    lines += ["}", "MOTION", "Frames: 1", "Frame Time: 0.01", " ".join(["0"] * 1806)]
    refused(capsys, "analyze", put(tmp_path, "wide.bvh", "\n".join(lines)), names="wide.bvh:", says="joints")


def test_estimator_window_limit_refuses_before_allocating():
    from livezmp.errors import InputError
    from livezmp.estimate.estimator import EstimatorConfig

    with pytest.raises(InputError, match="more than"):
        EstimatorConfig(rate_hz=1e9, cutoff_hz=6.0)


# -- class 4: never NaN/inf with exit 0 --------------------------------------------------------------


@pytest.mark.parametrize("option", [["--mass", "1e308"], ["--ground", "1e308"], ["--mass", "0"],
                                    ["--sole-width", "0"], ["--sole-width", "inf"], ["--sole-width", "-0.1"]])
def test_out_of_range_options_are_refused(tmp_path, capsys, walk_text, option):
    p = put(tmp_path, "w.bvh", walk_text)
    refused(capsys, "analyze", p, *option, "--summary-json", tmp_path / "s.json", names=option[0], says="outside")
    assert not (tmp_path / "s.json").exists()


def test_huge_cell_is_refused_naming_the_line(tmp_path, capsys, walk_text):
    lines = walk_text.splitlines()
    first = next(i for i, ln in enumerate(lines) if ln.startswith("Frame Time")) + 3
    cells = lines[first].split()
    cells[0] = "1e300"
    lines[first] = " ".join(cells)
    refused(capsys, "analyze", put(tmp_path, "w.bvh", "\n".join(lines)), names=f"w.bvh:{first + 1}",
            says="not finite or beyond")


def test_summary_writer_refuses_nan(tmp_path):
    from livezmp.errors import InputError
    from livezmp.jsonfile import write_json

    with pytest.raises(InputError, match=r"field a\.b\[1\] is not finite"):
        write_json({"a": {"b": [1.0, float("nan")]}}, tmp_path / "s.json")
    write_json({"a": 1.5}, tmp_path / "ok.json")
    assert json.loads((tmp_path / "ok.json").read_text()) == {"a": 1.5}


def test_csv_base_far_away_is_refused(tmp_path, capsys, robot):
    urdf, csv_text = robot
    u = put(tmp_path, "r.urdf", urdf)
    lines = csv_text.splitlines()
    lines[0] += ",base_x,base_y,base_z,base_roll,base_pitch,base_yaw"
    lines[1:] = [ln + ",0,0,0.3,0,0,0" for ln in lines[1:]]
    lines[5] = lines[5].rsplit(",", 6)[0] + ",1e300,0,0.3,0,0,0"
    refused(capsys, "analyze", put(tmp_path, "t.csv", "\n".join(lines)), "--robot", u, names="t.csv:6",
            says="base_x")


# -- class 5 and 8: encodings, paths -------------------------------------------------------------------


def test_utf8_bom_is_accepted(tmp_path, capsys, walk_text, robot):
    p = put(tmp_path, "w.bvh", b"\xef\xbb\xbf" + walk_text.encode())
    assert run(capsys, "analyze", p)[0] == 0
    urdf, csv_text = robot
    u = put(tmp_path, "r.urdf", urdf)
    assert run(capsys, "analyze", put(tmp_path, "t.csv", b"\xef\xbb\xbf" + csv_text.encode()), "--robot", u)[0] == 0


@pytest.mark.parametrize("encoding", ["utf-16", "latin-1"])
def test_other_encodings_are_one_line(tmp_path, capsys, robot, encoding):
    urdf, csv_text = robot
    u = put(tmp_path, "r.urdf", urdf)
    text = csv_text.replace("time", "tíme", 1) if encoding == "latin-1" else csv_text
    refused(capsys, "analyze", put(tmp_path, "t.csv", text.encode(encoding)), "--robot", u, names="t.csv:1",
            says="UTF")


def test_directory_fifo_device_as_motion(tmp_path, capsys):
    refused(capsys, "analyze", tmp_path, names=str(tmp_path), says="is a directory")
    fifo = tmp_path / "f.bvh"
    os.mkfifo(fifo)
    refused(capsys, "analyze", fifo, names="f.bvh", says="not a regular file")
    refused(capsys, "analyze", "/dev/null", names="/dev/null", says="not a regular file")


@pytest.mark.parametrize("option", ["--out", "--plot", "--summary-json"])
def test_output_in_missing_directory_is_checked_first(tmp_path, capsys, walk_text, option):
    p = put(tmp_path, "w.bvh", walk_text)
    refused(capsys, "analyze", p, option, tmp_path / "missing" / "x", names=option, says="does not exist")


def test_correct_output_in_missing_directory(tmp_path, capsys, walk_text):
    p = put(tmp_path, "w.bvh", walk_text)
    refused(capsys, "correct", p, "-o", tmp_path / "no" / "c.bvh", names="-o", says="does not exist")


# -- class 7: silent misreads ---------------------------------------------------------------------------


def test_frames_count_disagreeing_with_rows(tmp_path, capsys, walk_text):
    p = put(tmp_path, "w.bvh", with_line(walk_text, "Frames:", "Frames: 30"))
    refused(capsys, "analyze", p, names="w.bvh:", says="Frames: 30, file has 60 rows")


def test_csv_duplicated_column(tmp_path, capsys, robot):
    urdf, csv_text = robot
    u = put(tmp_path, "r.urdf", urdf)
    lines = csv_text.splitlines()
    first = lines[0].split(",")[1]
    lines[0] += f",{first}"
    lines[1:] = [ln + ",0" for ln in lines[1:]]
    refused(capsys, "analyze", put(tmp_path, "t.csv", "\n".join(lines)), "--robot", u, names="t.csv:1",
            says=f"'{first}' appears more than once")


def test_csv_row_with_extra_field(tmp_path, capsys, robot):
    urdf, csv_text = robot
    u = put(tmp_path, "r.urdf", urdf)
    lines = csv_text.splitlines()
    lines[3] = lines[3].replace(".", ",", 1)  # a decimal comma
    refused(capsys, "analyze", put(tmp_path, "t.csv", "\n".join(lines)), "--robot", u, names="t.csv:4",
            says="fields, header has")


def test_robot_with_bvh_is_refused(tmp_path, capsys, walk_text):
    p = put(tmp_path, "w.bvh", walk_text)
    refused(capsys, "analyze", p, "--robot", demo_robot_path(), names="w.bvh", says="--robot")


# -- class 3: URDF physics, robot config types, robot names --------------------------------------------


def _first_inertial(urdf: str, mass: str | None = None, inertia: str | None = None, com: str | None = None) -> str:
    if mass is not None:
        urdf = re.sub(r'<mass value="[^"]*"', f'<mass value="{mass}"', urdf, count=1)
    if inertia is not None:
        urdf = re.sub(r"<inertia [^/]*/>", inertia, urdf, count=1)
    if com is not None:
        urdf = re.sub(r'(<inertial>\s*<origin[^/]*xyz=)"[^"]*"', rf'\1"{com}"', urdf, count=1)
    return urdf


@pytest.mark.parametrize("change, says", [
    ({"mass": "nan"}, "mass"), ({"mass": "inf"}, "mass"), ({"mass": "heavy"}, "mass"), ({"mass": "-1"}, "mass"),
    ({"inertia": '<inertia ixx="nan" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>'}, "ixx"),
    ({"inertia": '<inertia ixx="-1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/>'}, "positive semi-definite"),
    ({"com": "nan 0 0"}, "xyz"),
])
def test_urdf_bad_physics_is_refused(tmp_path, capsys, robot, change, says):
    urdf, csv_text = robot
    bad = _first_inertial(urdf, **change)
    assert bad != urdf
    u = put(tmp_path, "r.urdf", bad)
    refused(capsys, "analyze", put(tmp_path, "t.csv", csv_text), "--robot", u, names="r.urdf: link", says=says)


def test_an_inertia_below_semi_definite_by_a_negligible_amount_is_taken_as_the_nearest(tmp_path, capsys, robot):
    """HRP-4C's 13 g wrists are written with a principal moment of -7e-08 kg m^2 (a CAD export's rounding): the
    whole robot was refused for them. A deficit negligible for the robot (its ZMP answer well under a mm) is now
    taken as the nearest positive semi-definite inertia with one warning; one that is not is still refused."""
    urdf, csv_text = robot
    turn = np.linalg.qr(np.array([[1.0, 0.4, 0.2], [0.3, 1.0, 0.5], [0.1, 0.2, 1.0]]))[0]

    def inertia(moments) -> str:
        i = (turn @ np.diag(moments) @ turn.T).tolist()
        return (f'<inertia ixx="{i[0][0]!r}" ixy="{i[0][1]!r}" ixz="{i[0][2]!r}" iyy="{i[1][1]!r}" '
                f'iyz="{i[1][2]!r}" izz="{i[2][2]!r}"/>')

    u = put(tmp_path, "r.urdf", _first_inertial(urdf, inertia=inertia([-1e-8, 2e-4, 3e-4])))
    ref = put(tmp_path, "ref.urdf", _first_inertial(urdf, inertia=inertia([0.0, 2e-4, 3e-4])))
    link = re.search(r'<link name="([^"]+)">\s*<inertial>', urdf)[1]
    with pytest.warns(UserWarning, match="negligible"):
        got = body_from_urdf(u).model
    want = body_from_urdf(ref).model
    assert max(np.abs(a.inertia - b.inertia).max() for a, b in zip(got.inertias, want.inertias, strict=True)) < 1e-12
    out = tmp_path / "z.csv"
    with pytest.warns(UserWarning) as said:
        assert main(["analyze", str(put(tmp_path, "t.csv", csv_text)), "--robot", str(u), "--out", str(out)]) == 0
    ours = [str(w.message) for w in said if w.category is UserWarning]
    assert len(ours) == 1 and ours[0].startswith(f"{u}: link '{link}' <inertia>: principal moments down to -1e-08")
    assert main(["analyze", str(tmp_path / "t.csv"), "--robot", str(ref), "--out", str(tmp_path / "ref.csv")]) == 0
    assert out.read_text() == (tmp_path / "ref.csv").read_text()
    big = put(tmp_path, "big.urdf", _first_inertial(urdf, inertia=inertia([-1e-3, 2e-4, 3e-4])))
    refused(capsys, "analyze", tmp_path / "t.csv", "--robot", big, names="big.urdf: link",
            says="positive semi-definite")


@pytest.mark.parametrize("toml, says", [
    ('[feet.left]\nlink = 3\n', "link"),
    ('[feet.left]\nlink = "l_foot"\nbox = { length = -0.1, width = 0.05 }\n', "box.length"),
    ('[feet.left]\nlink = "l_foot"\nbox = { length = 0.1, width = "wide" }\n', "box.width"),
    ('[feet.left]\nlink = "l_foot"\nsole = [[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]]\n', "no area"),
    ('[feet.left]\nlink = "l_foot"\nsole = [[0, 0], [1, 0], [1, 1]]\n', "sole"),
    ("feet = 3\n", "table"),
    ("[servos.l_knee]\nid = \"x\"\n", "id"),
    ("[servos.l_knee]\nid = 1\ndirection = 2\n", "direction"),
    # these two were accepted: a misspelt key ignored (the joint driven the default way), and one servo given
    # two joints' goals
    ("[servos.l_knee]\nid = 1\ndirecton = -1\n", "unknown key 'directon'"),
    ("[servos.l_knee]\nid = 1\n[servos.r_knee]\nid = 1\n", r"\[servos.r_knee\] id: 1 is already the id of l_knee"),
    ('[correction.legs]\nleft = "l_knee"\n', "list"),
    ("[servos.l_knee]\nid = 1\nmodel = -5\n", "model"),
    ('[servos.l_knee]\nid = 1\nmodel = "XM430"\n', "model"),
])
def test_robot_config_types_one_line_per_field(tmp_path, capsys, robot, toml, says):
    urdf, csv_text = robot
    u = put(tmp_path, "r.urdf", urdf)
    cfg = put(tmp_path, "cfg.toml", toml)
    refused(capsys, "analyze", put(tmp_path, "t.csv", csv_text), "--robot", u, "--robot-config", cfg,
            names="cfg.toml", says=says)


def test_a_robot_name_that_is_no_file_name_looks_up_no_config(tmp_path, robot):
    # a URDF's robot name is free text ("My Humanoid v2"): not a reason to refuse the robot; a name with a path
    # in it must not reach a config file by it (this one would reach the built-in livezmp_mini.toml)
    from livezmp.model.robot import load_robot

    urdf, _ = robot
    for name, source in (("livezmp_mini", "livezmp:livezmp_mini.toml"), ("../robots/livezmp_mini", "<defaults>"),
                         ("My Humanoid v2", "<defaults>")):
        u = put(tmp_path, "r.urdf", re.sub(r'<robot name="[^"]*"', f'<robot name="{name}"', urdf, count=1))
        assert load_robot(str(u), None).config.source == source


def test_good_robot_still_loads(tmp_path, capsys, robot):
    urdf, csv_text = robot
    u = put(tmp_path, "r.urdf", urdf)
    rc, err, _ = run(capsys, "analyze", put(tmp_path, "t.csv", csv_text), "--robot", u,
                     "--summary-json", tmp_path / "s.json")
    assert rc == 0, err
    s = json.loads((tmp_path / "s.json").read_text())
    assert np.isfinite(s["max_excursion_m"])
    # the estimator's settings are in the summary, at the take's rate (the demo CSV is at 100 Hz)
    assert s["estimator"]["rate_hz"] == pytest.approx(100.0) and s["estimator"]["cutoff_hz"] > 0


# -- the sixth audit: faults found by hostile inputs (/work/coord/audit6.txt) ---------------------------------------


def test_a_hierarchy_without_channels_is_one_line(tmp_path, capsys, walk_text):
    """No channels: its rows of no values cannot be counted (a ZeroDivisionError traceback)."""
    text = re.sub(r"CHANNELS \d+[^\n]*", "CHANNELS 0", walk_text.split("MOTION")[0]) + "MOTION\nFrames: 2\n" \
        "Frame Time: 0.01\n\n\n"
    refused(capsys, "analyze", put(tmp_path, "w.bvh", text), names="w.bvh:", says="no channels")


@pytest.mark.parametrize("encoding, line", [("utf-16", 1), ("latin-1", 2)])
def test_a_bvh_in_another_encoding_is_named_so_not_an_empty_file(tmp_path, capsys, walk_text, encoding, line):
    """The first line's decoding error had been taken for the end of the file ("empty file, not a BVH")."""
    text = walk_text.replace("ROOT ", "ROOT é", 1)
    refused(capsys, "analyze", put(tmp_path, "w.bvh", text.encode(encoding)), names=f"w.bvh:{line}:", says="UTF")


@pytest.mark.parametrize("option", [["--tolerance-mm", "nan"], ["--tolerance-mm", "-5"], ["--cutoff-hz", "1e6"],
                                    ["--cutoff-hz", "nan"], ["--cutoff-hz", "1e-9"], ["--cutoff-hz", "0.1"]])
def test_analysis_numbers_are_refused_naming_the_option(tmp_path, capsys, walk_text, option):
    """--tolerance-mm nan was refused only when the summary came to be written, naming its field (without
    --summary-json: "within nan mm"), -5 was used; --cutoff-hz 1e6 was refused as EstimatorConfig.window_s;
    --cutoff-hz 1e-9 ended in scipy's LinAlgError traceback, 0.1 analysed a walk as all flight, no verdict
    (audit 9)."""
    p = put(tmp_path, "w.bvh", walk_text)
    refused(capsys, "analyze", p, *option, "--summary-json", tmp_path / "s.json", names=option[0], says="outside")


def test_a_figure_name_without_a_figure_format_is_refused_before_work(tmp_path, capsys, walk_text):
    """Matplotlib's ValueError (a traceback) after the whole analysis."""
    refused(capsys, "analyze", put(tmp_path, "w.bvh", walk_text), "--plot", tmp_path / "z.txt", names="--plot",
            says="not a figure file name")


@pytest.mark.parametrize("option", [["--max-rotation-deg", "nan", "5", "5"], ["--max-rate-deg-s", "nan"],
                                    ["--margin-mm", "nan"], ["--margin-mm", "1e9"]])
def test_correction_limits_are_refused_when_not_finite(tmp_path, capsys, walk_text, option):
    """NaN passed the old `<= 0` test and reached the solver (an unnamed "point: non-finite coordinate")."""
    refused(capsys, "correct", put(tmp_path, "w.bvh", walk_text), "-o", tmp_path / "o.bvh", *option,
            names=option[0], says="outside")


def test_correct_refuses_a_one_frame_take_as_analyze_does(tmp_path, capsys, walk_text):
    """It had said "rate_hz = 0.0: must be a positive number"."""
    lines = walk_text.split("MOTION")[1].strip().splitlines()
    text = walk_text.split("MOTION")[0] + "MOTION\nFrames: 1\n" + lines[1] + "\n" + lines[2] + "\n"
    refused(capsys, "correct", put(tmp_path, "w.bvh", text), "-o", tmp_path / "o.bvh", names="w.bvh",
            says="need at least 2 frames, got 1")


def test_batch_checks_the_body_options_before_starting_a_cluster(tmp_path, capsys, walk_text):
    """Every take had failed on the cluster ("total mass must be positive") and the command exited 0."""
    refused(capsys, "batch", "analyze", put(tmp_path, "w.bvh", walk_text), "--out", tmp_path / "b", "--mass", "-1",
            names="--mass", says="outside")
    assert not (tmp_path / "b").exists()


def test_calibrate_checks_its_options_and_that_a_trial_is_a_c3d(tmp_path, capsys, walk_text):
    """A BVH given as a trial was read as a C3D's parameters ("claims 7.25e+76 values"); --mass nan was named
    "total mass"; -o a directory was an IsADirectoryError traceback after the fit."""
    bvh = put(tmp_path, "w.bvh", walk_text)
    refused(capsys, "calibrate", bvh, names="w.bvh", says="not a readable C3D file .no C3D header")
    refused(capsys, "calibrate", bvh, "--mass", "nan", names="--mass", says="outside")
    refused(capsys, "calibrate", bvh, "-o", tmp_path, names="-o", says="is a directory")


def test_batch_output_and_cluster_options_are_one_line(tmp_path, capsys, walk_text):
    """--out naming a file was a FileExistsError traceback, --scheduler wibble a ValueError one, and
    --workers 100000 started that many processes."""
    w = put(tmp_path, "w.bvh", walk_text)
    refused(capsys, "batch", "analyze", w, "--out", w, names="--out", says="is a file, not a directory")
    refused(capsys, "batch", "analyze", w, "--out", tmp_path / "b", "--scheduler", "wibble", names="--scheduler wibble",
            says="cannot connect")
    refused(capsys, "batch", "analyze", w, "--out", tmp_path / "b", "--workers", "100000", names="--workers",
            says="must be 1 to")


def test_a_joint_limit_whose_lower_is_above_its_upper_is_refused(tmp_path, capsys, robot):
    """It was accepted: the live loop then refused every reading as beyond the limits and held (exit 0)."""
    urdf, csv_text = robot
    bad = re.sub(r'lower="[^"]*" upper="[^"]*"', 'lower="1" upper="-1"', urdf, count=1)
    assert bad != urdf
    refused(capsys, "analyze", put(tmp_path, "t.csv", csv_text), "--robot", put(tmp_path, "r.urdf", bad),
            names="r.urdf: joint", says="lower 1 is above upper -1")
