"""`livezmp gait analyze | synth | compare` end to end on files, in process (the `livezmp`
command's own `main`) and as a real `python -m livezmp gait` subprocess."""

import re
import subprocess
import sys

import numpy as np
import pytest
from data_paths import OP3_URDF

from livezmp.cli import main
from livezmp.gait.compare import compare
from livezmp.gait.features import walk_features
from livezmp.gait.sinewalk import sine_bvh, sine_trajectory, walk_spec
from livezmp.gait.tables import read_features
from livezmp.gait.take import load_take
from livezmp.model.bvh import read_bvh, write_bvh
from livezmp.model.trajectory_csv import read_joint_csv, write_joint_csv
from livezmp.model.urdf_body import body_from_urdf

# subject: (frequency, speed, hip amplitude) of the normal walk; the fast walk is ×1.1, ×1.32, ×1.25
PEOPLE = {"01": (0.90, 1.10, 20.0), "02": (0.95, 1.20, 22.0), "03": (0.86, 1.05, 19.0)}


def write_walk(path, f, v, hip, duration=6.0):
    write_bvh(sine_bvh(walk_spec(hip_amp=hip), f, v, duration), path)
    return path


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    d = tmp_path_factory.mktemp("takes")
    for s, (f, v, hip) in PEOPLE.items():
        write_walk(d / f"p{s}_normal.bvh", f, v, hip)
        write_walk(d / f"p{s}_fast.bvh", f * 1.1, v * 1.32, hip * 1.25)
    return d


@pytest.fixture(scope="module")
def analysed(takes, tmp_path_factory):
    out = tmp_path_factory.mktemp("analysis")
    code = main(["gait", "analyze", str(takes), "--pattern", r"p(?P<subject>\d+)_(?P<condition>\w+)\.bvh",
                 "--base", "normal", "--variant", "fast=fast", "--out", str(out)])
    assert code == 0
    return out


def last_number(text):
    return float(text.strip().splitlines()[-1].split()[-1])


def test_analyze_writes_tables_and_features(analysed, capsys):
    a = read_features(analysed / "features.json")
    v = a.variant("fast")
    assert v.pairing.startswith("by subject") and v.n_pairs == 3
    assert v.walk["frequency"].mu == pytest.approx(10.0, rel=1e-6)
    assert v.walk["speed"].mu == pytest.approx(32.0, rel=1e-6)
    hip = v.amplitude[[t.name for t in a.tags].index("UpperLeg_R.Xrotation")]
    assert (hip.mu, hip.sigma, hip.feature) == pytest.approx((25.0, 0.0, True), abs=1e-4)
    assert (analysed / "tables.md").read_text().count("| UpperLeg_") == 2  # both hips, size table


def test_synth_moves_a_walk_to_the_fast_condition(analysed, tmp_path, capsys):
    base = write_walk(tmp_path / "mine.bvh", 0.92, 1.15, 21.0)
    out = tmp_path / "mine_fast.bvh"
    assert main(["gait", "synth", str(base), "--features", str(analysed / "features.json"), "--to", "fast",
                 "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "frequency ×1.1000" in text and "up y, ground plane xz" in text
    fo = walk_features(load_take(out))
    assert fo.frequency == pytest.approx(0.92 * 1.1, rel=1e-6)
    assert fo.speed == pytest.approx(1.15 * 1.32, rel=1e-5)
    i = [t.name for t in fo.tags].index("UpperLeg_L.Xrotation")
    assert np.rad2deg(fo.amplitude[i]) == pytest.approx(21.0 * 1.25, rel=1e-4)
    half = tmp_path / "mine_half.bvh"
    assert main(["gait", "synth", str(base), "--features", str(analysed / "features.json"), "--to", "fast",
                 "--amount", "0.5", "-o", str(half)]) == 0
    assert walk_features(load_take(half)).frequency == pytest.approx(0.92 * 1.05, rel=1e-6)


def test_synth_a_robot_csv_with_urdf(analysed, tmp_path, capsys):
    body = body_from_urdf(OP3_URDF)
    spec = {"l_hip_pitch": (0.1, 0.3, 0.0), "r_hip_pitch": (-0.1, 0.3, np.pi), "l_knee": (0.5, 0.3, 1.0)}
    src = tmp_path / "op3.csv"
    write_joint_csv(sine_trajectory(body.joint_names, spec, 1.5, 0.2, 4.0), src)
    out = tmp_path / "op3_fast.csv"
    assert main(["gait", "synth", str(src), "--features", str(analysed / "features.json"), "--to", "fast",
                 "--urdf", str(OP3_URDF), "-o", str(out)]) == 0
    assert "up z, ground plane xy" in capsys.readouterr().out
    traj = read_joint_csv(out, body.joint_names)
    assert traj.base is not None and np.allclose(np.diff(traj.t), 1 / 125.0)
    fo = walk_features(load_take(out, urdf=OP3_URDF))
    assert fo.frequency == pytest.approx(1.5 * 1.1, rel=1e-6)
    i = [t.name for t in fo.tags].index("l_hip_pitch")
    assert fo.amplitude[i] == pytest.approx(0.3 * 1.25, rel=1e-4)


def test_compare_prints_the_total_last(takes, capsys):
    a, b, c = (takes / n for n in ("p01_normal.bvh", "p01_fast.bvh", "p02_fast.bvh"))
    assert main(["gait", "compare", str(a), str(b)]) == 0
    text = capsys.readouterr().out
    ta, tb = load_take(a), load_take(b)
    want = compare(ta, walk_features(ta), tb, walk_features(tb)).total
    assert want > 1.0  # the hips swing 25 % more
    assert last_number(text) == pytest.approx(want, abs=0.006)
    assert "UpperLeg_L:" in text
    assert main(["gait", "compare", str(a), str(b), str(c)]) == 0
    text = capsys.readouterr().out
    tc = load_take(c)
    both = (want + compare(ta, walk_features(ta), tc, walk_features(tc)).total) / 2
    assert "mean over 2 walks" in text.splitlines()[-1]
    assert last_number(text) == pytest.approx(both, abs=0.006)


def one_line_error(capsys):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("livezmp: error: ")
    return err


def test_user_errors_are_one_line_with_exit_code_2(takes, analysed, tmp_path, capsys):
    assert main(["gait", "analyze", str(takes), "--base", "normal", "--variant", "slow=slow",
                 "--pattern", r"p\d+_(?P<condition>\w+)\.bvh", "--out", str(tmp_path / "o")]) == 2
    assert "no takes for condition 'slow'" in one_line_error(capsys)
    short = write_walk(tmp_path / "tiny.bvh", 1.0, 1.0, 20.0, duration=1.5)
    assert main(["gait", "compare", str(short), str(takes / "p01_fast.bvh")]) == 2
    assert "tiny.bvh" in one_line_error(capsys)
    assert main(["gait", "synth", str(takes / "p01_normal.bvh"), "--features", str(tmp_path / "none.json"),
                 "--to", "fast", "-o", str(tmp_path / "x.bvh")]) == 2
    assert "none.json: cannot read" in one_line_error(capsys)
    csv = tmp_path / "robot.csv"
    csv.write_text("time,a\n0,0\n")
    assert main(["gait", "compare", str(csv), str(csv)]) == 2
    assert "robot.csv: a joint-trajectory CSV needs the robot's URDF" in one_line_error(capsys)
    with pytest.raises(SystemExit):
        main(["gait", "analyze", str(takes), "--base", "normal", "--variant", "fast", "--out", str(tmp_path)])


def test_an_unmatched_skeleton_in_the_set_names_the_file(takes, tmp_path, capsys):
    d = tmp_path / "set"
    d.mkdir()
    for p in takes.iterdir():
        (d / p.name).write_text(p.read_text())
    odd = read_bvh(takes / "p02_fast.bvh")
    odd.joints[3].name = "Skull"
    write_bvh(odd, d / "p04_fast.bvh")
    write_walk(d / "p04_normal.bvh", 0.9, 1.1, 20.0)
    assert main(["gait", "analyze", str(d), "--pattern", r"p(?P<subject>\d+)_(?P<condition>\w+)\.bvh",
                 "--base", "normal", "--variant", "fast=fast", "--out", str(tmp_path / "o")]) == 2
    assert "p04_fast.bvh: skeleton does not match" in one_line_error(capsys)


def test_runs_as_a_subprocess(takes):
    r = subprocess.run([sys.executable, "-m", "livezmp", "gait", "compare", str(takes / "p01_normal.bvh"),
                        str(takes / "p01_normal.bvh")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert last_number(r.stdout) == 0.0
    r = subprocess.run([sys.executable, "-m", "livezmp", "gait", "compare", str(takes / "missing.bvh"),
                        str(takes / "p01_normal.bvh")], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stderr.strip().endswith("missing.bvh: no such file")


def test_synth_balance_says_what_it_did(takes, analysed, tmp_path, capsys):
    capsys.readouterr()
    rc = main(["gait", "synth", str(takes / "p01_normal.bvh"), "--features", str(analysed / "features.json"),
               "--to", "fast", "-o", str(tmp_path / "out.bvh"), "--balance"])
    assert rc == 0
    out = capsys.readouterr().out
    m = re.search(r"balanced: (\d+) → (\d+) of (\d+) support frames outside; root rotation max ([\d.]+)°; "
                  r"stance feet moved ≤ ([\d.]+) mm", out)
    assert m, out
    assert int(m[2]) <= int(m[1]) <= int(m[3]) and float(m[5]) <= 1.0
