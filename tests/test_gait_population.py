"""K, μ, σ, CV and feature parts across people, take sets, and the analysis outputs."""

import csv
import json

import numpy as np
import pytest

from livezmp.errors import InputError
from livezmp.gait.features import walk_features
from livezmp.gait.population import analyze, change_stat
from livezmp.gait.sinewalk import sine_bvh, walk_spec
from livezmp.gait.tables import read_features, write_outputs
from livezmp.gait.take import take_from_bvh
from livezmp.gait.takeset import TakeSpec, read_manifest, takes_from_paths
from livezmp.model.bvh import write_bvh

# Per subject: (frequency Hz, speed m/s, hip amplitude °, knee DC °) for base and fast walks.
SUBJECTS = {
    "s1": ((0.90, 1.10, 20.0, 30.0), (1.00, 1.40, 24.0, 33.0)),
    "s2": ((0.95, 1.20, 22.0, 28.0), (1.02, 1.45, 25.0, 31.0)),
    "s3": ((0.85, 1.00, 18.0, 32.0), (0.97, 1.35, 23.0, 36.0)),
}


def walk(f, v, hip, knee):
    return sine_bvh(walk_spec(hip_amp=hip, knee_dc=knee), f, v, 6.0)


def feats_of(motion):
    return walk_features(take_from_bvh(motion))


@pytest.fixture(scope="module")
def paired_items():
    items = []
    for s, (base, fast) in SUBJECTS.items():
        items.append((TakeSpec(f"{s}_normal.bvh", s, "normal"), feats_of(walk(*base))))
        items.append((TakeSpec(f"{s}_fast.bvh", s, "fast"), feats_of(walk(*fast))))
    return items


def expected(values_base, values_var):
    k = (np.array(values_var) - np.array(values_base)) / np.array(values_base) * 100
    mu, sigma = k.mean(), np.sqrt(np.mean((k - k.mean()) ** 2))
    return k, mu, sigma, sigma / mu * 100


def test_change_stat_closed_form():
    s = change_stat(np.array([10.0, 20.0]), np.array([12.0, 18.0]), 250.0, 1.0)
    assert s.k == pytest.approx([20.0, -10.0])
    assert (s.mu, s.sigma, s.cv) == pytest.approx((5.0, 15.0, 300.0))
    assert not s.feature  # |CV| 300 % > 250 %
    assert not change_stat(np.array([10.0, 20.0]), np.array([10.01, 20.02]), 250.0, 1.0).feature  # μ 0.1 %
    assert change_stat(np.array([10.0, 20.0]), np.array([10.01, 20.02]), 250.0, 1.0, min_change=0.0).feature
    assert change_stat(np.array([10.0, 20.0]), np.array([12.0, 18.0]), 400.0, 1.0).feature
    neg = change_stat(np.array([-10.0, -10.0]), np.array([-12.0, -11.0]), 250.0, 1.0)
    assert (neg.mu, neg.cv) == pytest.approx((15.0, 5.0 / 15.0 * 100))  # larger in the same direction: K > 0


def test_near_zero_base_says_so_instead_of_a_huge_ratio():
    s = change_stat(np.array([0.2, 3.0]), np.array([5.0, 4.0]), 250.0, 1.0)
    assert s.mu is None and s.cv is None and not s.feature
    assert "base ≈ 0" in s.note and "meaningless" in s.note


def test_paired_analysis_reproduces_k_mu_sigma_cv_of_the_construction(paired_items):
    a = analyze(paired_items, "normal", {"fast": "fast"})
    v = a.variant("fast")
    assert v.n_pairs == 3 and v.pairing.startswith("by subject")
    names = [t.name for t in a.tags]
    base = [b for b, _ in SUBJECTS.values()]
    fast = [f for _, f in SUBJECTS.values()]
    for param, col in (("frequency", 0), ("speed", 1)):
        k, mu, sigma, cv = expected([b[col] for b in base], [f[col] for f in fast])
        s = v.walk[param]
        assert s.k == pytest.approx(k, rel=1e-6)
        assert (s.mu, s.sigma, s.cv) == pytest.approx((mu, sigma, cv), rel=1e-5)
    stride = expected([b[1] / b[0] for b in base], [f[1] / f[0] for f in fast])
    assert v.walk["stride_length"].mu == pytest.approx(stride[1], rel=1e-6)
    hip = v.amplitude[names.index("UpperLeg_L.Xrotation")]
    k, mu, sigma, cv = expected([b[2] for b in base], [f[2] for f in fast])
    assert hip.k == pytest.approx(k, abs=1e-5)
    assert (hip.mu, hip.sigma, hip.cv) == pytest.approx((mu, sigma, cv), abs=1e-4)
    assert hip.feature == (abs(cv) <= 250)
    knee = v.dc[names.index("LowerLeg_R.Xrotation")]
    k, mu, sigma, cv = expected([b[3] for b in base], [f[3] for f in fast])
    assert (knee.mu, knee.sigma, knee.cv) == pytest.approx((mu, sigma, cv), abs=1e-4)
    # an unchanged parameter (μ ≈ 0 up to rounding) is not a feature part, whatever its CV
    elbow_amp = v.amplitude[names.index("LowerArm_L.Xrotation")]
    assert elbow_amp.mu == pytest.approx(0.0, abs=1e-5) and not elbow_amp.feature
    assert "no real change" in elbow_amp.note
    # a DC of 0° in the base (trunk twist) gives no ratio
    assert v.dc[names.index("Spine.Yrotation")].mu is None


def test_unpaired_takes_use_the_mean_of_the_base_takes_and_say_so(paired_items):
    items = [(TakeSpec(s.path, None, s.condition), f) for s, f in paired_items]
    v = analyze(items, "normal", {"fast": "fast"}).variant("fast")
    assert "subjects unknown" in v.pairing and "mean of all 3 normal takes" in v.pairing
    g = np.mean([b[0] for b, _ in SUBJECTS.values()])
    k = [(f[0] - g) / g * 100 for _, f in SUBJECTS.values()]
    assert v.walk["frequency"].k == pytest.approx(k, rel=1e-6)


def test_missing_condition_and_bad_pairings_are_clear_errors(paired_items):
    with pytest.raises(InputError, match=r"bandai: no takes for condition 'slow' \(found: fast, normal\)"):
        analyze(paired_items, "normal", {"slow": "slow"}, where="bandai")
    mixed = [(TakeSpec(s.path, None if i == 0 else s.subject, s.condition), f) for i, (s, f) in enumerate(paired_items)]
    with pytest.raises(InputError, match="subject given for some takes"):
        analyze(mixed, "normal", {"fast": "fast"})
    with pytest.raises(InputError, match="need at least two"):
        analyze(paired_items[:2], "normal", {"fast": "fast"})


def test_unmatched_skeleton_names_the_file(paired_items):
    other = sine_bvh(walk_spec(), 1.0, 1.0, 4.0)
    other.joints[8].name = "LeftUpLeg"  # UpperLeg_L renamed
    items = [*paired_items, (TakeSpec("odd_fast.bvh", "s1", "fast"), feats_of(other))]
    with pytest.raises(InputError, match=r"odd_fast\.bvh: skeleton does not match s1_normal\.bvh"):
        analyze(items, "normal", {"fast": "fast"})


def test_outputs_tables_and_features_round_trip(paired_items, tmp_path):
    a = analyze(paired_items, "normal", {"fast": "fast"}, threshold=150.0)
    paths = write_outputs(a, tmp_path / "out")
    assert {p.name for p in paths} >= {"walk.csv", "fast_posture.csv", "fast_size.csv", "tables.md", "tables.json",
                                       "features.json", "gait.png"}
    back = read_features(tmp_path / "out" / "features.json")
    assert back.to_json() == a.to_json()
    rows = list(csv.DictReader(open(tmp_path / "out" / "fast_size.csv")))
    hip = next(r for r in rows if r["channel"] == "UpperLeg_L.Xrotation")
    assert float(hip["mu_percent"]) == pytest.approx(a.variant("fast").amplitude[[t.name for t in a.tags].index(
        "UpperLeg_L.Xrotation")].mu)
    md = (tmp_path / "out" / "tables.md").read_text()
    assert "## fast (fast) vs normal: amplitude A (size)" in md
    assert "| UpperLeg_L.Xrotation | lateral |" in md
    assert "Not computed, base ≈ 0" in md and "Spine.Yrotation" in md
    tables = json.loads((tmp_path / "out" / "tables.json").read_text())
    assert [r["parameter"] for r in tables["walk"]] == ["frequency", "stride_length", "speed"]
    assert (tmp_path / "out" / "gait.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_features_file_errors(tmp_path):
    bad = tmp_path / "f.json"
    bad.write_text("{not json")
    with pytest.raises(InputError, match=r"f\.json:1: not JSON"):
        read_features(bad)
    bad.write_text('{"format": "something else"}')
    with pytest.raises(InputError, match="not a livezmp gait features file"):
        read_features(bad)


def test_manifest_and_file_name_patterns(tmp_path):
    for name in ("walk_normal_001.bvh", "walk_active_002.bvh"):
        write_bvh(sine_bvh(walk_spec(), 1.0, 1.0, 3.0), tmp_path / name)
    specs = takes_from_paths([tmp_path])
    assert [(s.path.name, s.subject, s.condition) for s in specs] == [
        ("walk_active_002.bvh", None, "active"), ("walk_normal_001.bvh", None, "normal")]
    specs = takes_from_paths([tmp_path], r"walk_(?P<condition>\w+?)_(?P<subject>\d+)\.bvh")
    assert {s.subject for s in specs} == {"001", "002"}
    (tmp_path / "notes.csv").write_text("x\n")
    with pytest.raises(InputError, match=r"notes\.csv: file name does not match"):
        takes_from_paths([tmp_path])
    man = tmp_path / "m.csv"
    man.write_text("path,subject,condition\nwalk_normal_001.bvh,ann,normal\nwalk_active_002.bvh,,fast\n")
    specs = read_manifest(man)
    assert specs[0] == TakeSpec(tmp_path / "walk_normal_001.bvh", "ann", "normal")
    assert specs[1].subject is None
    man.write_text("path,condition\nwalk_normal_001.bvh,normal\n")
    with pytest.raises(InputError, match=r"m\.csv:1: .*missing subject"):
        read_manifest(man)
    man.write_text("path,subject,condition\nwalk_normal_001.bvh,ann\n")
    with pytest.raises(InputError, match=r"m\.csv:2: 2 fields"):
        read_manifest(man)
