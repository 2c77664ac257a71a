"""`livezmp analyze`: outputs, the demo, Bandai walks, and one-line errors for bad input."""

from __future__ import annotations

import csv
import json
import subprocess
import sys

import numpy as np
import pytest
from data_paths import BANDAI, OP3_URDF
from test_body import make_bvh

from livezmp.cli import main
from livezmp.offline.report import ZMP_COLUMNS


def test_bvh_outputs(tmp_path):
    out, js, png = tmp_path / "zmp.csv", tmp_path / "s.json", tmp_path / "zmp.png"
    rc = main(["analyze", str(BANDAI / "walk_normal_002.bvh"), "--out", str(out), "--summary-json", str(js),
               "--plot", str(png), "--mode", "seed"])
    assert rc == 0
    summary = json.loads(js.read_text())
    for key in ("frames", "fps", "duration_s", "up_axis", "units", "mode", "support_frames", "flight_frames",
                "out_of_support_frames", "inside_fraction", "max_excursion_m"):
        assert key in summary
    assert summary["frames"] == 265 and summary["units"] == "cm" and summary["up_axis"] == "y"
    assert summary["mode"] == "seed"
    rows = list(csv.DictReader(out.open()))
    assert tuple(rows[0].keys()) == ZMP_COLUMNS
    assert len(rows) == 265 and [int(r["frame"]) for r in rows] == list(range(265))
    judged = [r for r in rows if r["inside"] != ""]
    assert summary["out_of_support_frames"] == sum(r["inside"] == "0" for r in judged)
    # y is up: ZMP and clamp lie on the ground plane, the CoM about 0.9 m above it
    for r in judged[:50]:
        assert float(r["zmp_y"]) == pytest.approx(float(r["clamped_y"]))
        assert 0.7 < float(r["com_y"]) - float(r["zmp_y"]) < 1.1
    for r in judged:  # the clamp only moves frames that are outside
        moved = np.hypot(float(r["zmp_x"]) - float(r["clamped_x"]), float(r["zmp_z"]) - float(r["clamped_z"]))
        assert (moved > 1e-9) == (r["inside"] == "0")
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"


def test_demo_runs_as_a_subprocess(tmp_path):
    js = tmp_path / "demo.json"
    r = subprocess.run([sys.executable, "-m", "livezmp", "analyze", "--summary-json", str(js)],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    s = json.loads(js.read_text())
    assert s["frames"] == 1200 and s["units"] == "m" and s["up_axis"] == "z"
    # the demo leans past its toes for about two seconds: some frames must be out of support
    assert 50 < s["out_of_support_frames"] < 600


def test_robot_csv_with_and_without_base(tmp_path, op3_body):
    names = op3_body.joint_names
    t = np.arange(200) / 100
    q = np.zeros((200, len(names)))
    bend = 0.3 * (1 - np.cos(t))
    # rotations about world +y; the OP3's pitch axes are ±y (URDF), hence the signs
    for joint, world, axis_y in (("l_hip_pitch", -1, 1), ("l_knee", 2, 1), ("l_ank_pitch", -1, -1),
                                 ("r_hip_pitch", -1, -1), ("r_knee", 2, -1), ("r_ank_pitch", -1, 1)):
        q[:, names.index(joint)] = world * axis_y * bend
    path = tmp_path / "squat.csv"
    np.savetxt(path, np.column_stack([t, q]), delimiter=",", header=",".join(["time", *names]), comments="")
    js = tmp_path / "s.json"
    assert main(["analyze", str(path), "--robot", str(OP3_URDF), "--summary-json", str(js)]) == 0
    s = json.loads(js.read_text())
    assert s["frames"] == 200 and s["inside_fraction"] == 1.0  # a slow symmetric squat stays balanced
    # with explicit base columns: a base lifted 1 m into the air is in flight or unsupported
    base = np.column_stack([np.zeros(200), np.zeros(200), np.full(200, 1.3), np.zeros((200, 3))])
    path2 = tmp_path / "base.csv"
    cols = ["time", *names, "base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw"]
    np.savetxt(path2, np.column_stack([t, q, base]), delimiter=",", header=",".join(cols), comments="")
    assert main(["analyze", str(path2), "--robot", str(OP3_URDF), "--summary-json", str(js), "--ground", "0"]) == 0
    assert json.loads(js.read_text())["support_frames"] == 0


BAD_BVH = {
    "truncated": (lambda t: t[: t.index("MOTION") - 30], "unexpected end of file"),
    "wrong channel count": (lambda t: t.replace("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 4 Zrotation "
                                                "Xrotation Yrotation", 1), "CHANNELS says 4"),
    "non-numeric": (lambda t: t[: t.rindex("\n", 0, -2)] + "\n" + "0 " * 35 + "abc\n", "non-numeric"),
    "zero frames": (lambda t: t.replace("Frames: 3", "Frames: 0"), "zero frames"),
    "short frame": (lambda t: t.rstrip()[: t.rstrip().rindex(" ")] + "\n", "has 35 values"),
    "missing frames": (lambda t: t.replace("Frames: 3", "Frames: 5"), "truncated"),
}


@pytest.mark.parametrize("case", sorted(BAD_BVH))
def test_bad_bvh_one_line_error(tmp_path, case, capsys):
    edit, message = BAD_BVH[case]
    path = tmp_path / "bad.bvh"
    path.write_text(edit(make_bvh()))
    assert main(["analyze", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(path) in err and message in err, err


def test_bad_csv_and_unknown_skeleton_errors(tmp_path, op3_body, capsys):
    names = op3_body.joint_names
    csv_path = tmp_path / "m.csv"
    csv_path.write_text(",".join(["time", *names[:-1]]) + "\n" + ",".join(["0"] * len(names)) + "\n")
    assert main(["analyze", str(csv_path), "--robot", str(OP3_URDF)]) == 2
    assert "missing joint column(s): r_el" in capsys.readouterr().err
    csv_path.write_text(",".join(["time", *names]) + "\n" + ",".join(["0"] * len(names)) + ",x\n")
    assert main(["analyze", str(csv_path), "--robot", str(OP3_URDF)]) == 2
    err = capsys.readouterr().err
    assert "m.csv:2: field r_el: not a number" in err
    assert main(["analyze", str(csv_path)]) == 2
    assert "needs --robot" in capsys.readouterr().err
    odd = tmp_path / "odd.bvh"
    odd.write_text(make_bvh(names={"thigh": "Femur", "shin": "Crus"}).replace("LeftFemur", "FemA")
                   .replace("RightFemur", "FemB"))
    assert main(["analyze", str(odd)]) == 2
    err = capsys.readouterr().err
    assert "odd.bvh: unknown skeleton: no joint found for thigh:left, shank:left, thigh:right" in err
    assert "--mapping" in err


def test_every_bandai_walk_analyses(capsys):
    """Every real walk runs; the inside fraction per file is printed for the record."""
    files = sorted(BANDAI.glob("*.bvh"))
    assert len(files) == 24
    for f in files:
        assert main(["analyze", str(f)]) == 0
    out = capsys.readouterr().out
    assert out.count("inside") == 24
    with capsys.disabled():
        print("\n" + out)


def test_a_robot_without_its_motion_is_refused_not_swapped_for_the_demo_robot(capsys):
    # before: exit 0, the built-in livezmp_mini's demo analysed (3.65 kg) and the OP3 never loaded
    assert main(["analyze", "--robot", str(OP3_URDF)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"--robot {OP3_URDF}: give the robot's motion" in err
