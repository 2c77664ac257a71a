"""Gait analysis and speed control on the real Bandai walks (normal = base, active = fast,
elderly = slow; actors not given, so takes are unpaired)."""

import json
from dataclasses import replace

import numpy as np
import pytest
from data_paths import BANDAI

from livezmp.cli import main
from livezmp.gait.compare import compare
from livezmp.gait.features import walk_features
from livezmp.gait.population import analyze
from livezmp.gait.synth import synth_take
from livezmp.gait.tables import write_outputs
from livezmp.gait.take import take_from_bvh
from livezmp.gait.takeset import takes_from_paths
from livezmp.model.bvh import read_bvh, write_bvh

VARIANTS = {"slow": "elderly", "fast": "active"}
README_SPEED = {"normal": 1.14, "active": 1.46, "elderly": 0.78}  # m/s, data/README.md (whole dataset)


@pytest.fixture(scope="module")
def bandai():
    specs = [s for s in takes_from_paths([BANDAI]) if s.condition in README_SPEED]
    takes = [take_from_bvh(read_bvh(s.path)) for s in specs]
    feats = [walk_features(t) for t in takes]
    return specs, takes, feats


@pytest.fixture(scope="module")
def analysis(bandai):
    specs, _, feats = bandai
    return analyze(list(zip(specs, feats, strict=True)), "normal", VARIANTS, where=str(BANDAI))


def stat(a, label, which, kind, side, axis="lateral"):
    names = [t.key for t in a.tags]
    return getattr(a.variant(label), which)[names.index(f"{kind}:{side}:{axis}")]


def test_walking_speeds_match_the_dataset_readme(bandai):
    specs, _, feats = bandai
    for cond, speed in README_SPEED.items():
        got = np.mean([f.speed for s, f in zip(specs, feats, strict=True) if s.condition == cond])
        assert got == pytest.approx(speed, rel=0.08), cond
    assert all(f.cycles.n_cycles >= 4 for f in feats)


def test_pairing_is_stated(analysis):
    for v in analysis.variants:
        assert "subjects unknown" in v.pairing and v.n_pairs == 6


@pytest.mark.parametrize("side", ["left", "right"])
def test_feature_parts_agree_with_the_papers_signs(analysis, side):
    # paper 003: fast walking raises hip and elbow flexion amplitude and knee flexion posture;
    # slow walking lowers hip, shoulder and elbow flexion amplitude (tables 1-3)
    for label, which, kind, sign in [("fast", "amplitude", "thigh", 1), ("fast", "amplitude", "forearm", 1),
                                     ("fast", "dc", "shank", 1), ("slow", "amplitude", "thigh", -1),
                                     ("slow", "amplitude", "upper_arm", -1), ("slow", "amplitude", "forearm", -1)]:
        s = stat(analysis, label, which, kind, side)
        assert s.feature, (label, which, kind)
        assert np.sign(s.mu) == sign, (label, which, kind, s.mu)


def test_tables_are_written(analysis, tmp_path):
    write_outputs(analysis, tmp_path)
    md = (tmp_path / "tables.md").read_text()
    assert "## fast (active) vs normal: amplitude A (size)" in md
    assert "subjects unknown" in md
    assert "Not computed, base ≈ 0" in md  # the static joint_Root channels


def test_synthesis_towards_fast_is_closer_to_recorded_fast_walks(bandai):
    """For each normal take, features from the *other* takes (leave-one-out) turn it towards fast;
    the result must be closer to the recorded fast walks than the unmodified take, for most takes."""
    specs, takes, feats = bandai
    fast = [i for i, s in enumerate(specs) if s.condition == "active"]
    closer = 0
    for i, s in enumerate(specs):
        if s.condition != "normal":
            continue
        others = [(sp, f) for j, (sp, f) in enumerate(zip(specs, feats, strict=True)) if j != i]
        a = analyze(others, "normal", {"fast": "active"})
        t, q, _ = synth_take(takes[i], a, "fast", 1.0)
        out = replace(takes[i], t=t, q=q)  # the changed walk on the same body (the file round trip is tested elsewhere)
        fo = walk_features(out)
        before = np.mean([compare(takes[i], feats[i], takes[k], feats[k]).total for k in fast])
        after = np.mean([compare(out, fo, takes[k], feats[k]).total for k in fast])
        closer += after < before
    assert closer >= 4  # of 6


def test_synth_balance_passes_the_result_through_the_balance_correction(analysis, tmp_path):
    clip = read_bvh(BANDAI / "walk_normal_001.bvh")
    clip.frames = clip.frames[40:125]  # 2.8 s, two whole cycles: keeps the correction quick
    write_bvh(clip, tmp_path / "clip.bvh")
    (tmp_path / "features.json").write_text(json.dumps(analysis.to_json()))
    common = ["gait", "synth", str(tmp_path / "clip.bvh"), "--features", str(tmp_path / "features.json"),
              "--to", "fast"]
    assert main([*common, "-o", str(tmp_path / "plain.bvh")]) == 0
    assert main([*common, "--balance", "-o", str(tmp_path / "balanced.bvh")]) == 0
    plain, balanced = read_bvh(tmp_path / "plain.bvh"), read_bvh(tmp_path / "balanced.bvh")
    assert balanced.frames.shape == plain.frames.shape
    changed = {lab.split(".")[0] for lab, c in zip(plain.channel_labels(),
                                                   np.any(np.abs(balanced.frames - plain.frames) > 1e-4, axis=0),
                                                   strict=True) if c}
    # the corrector moves the root (waist) and re-solves the legs from the hips; nothing else
    assert "Hips" in changed
    assert changed <= {"Hips", "UpperLeg_L", "UpperLeg_R", "LowerLeg_L", "LowerLeg_R", "Foot_L", "Foot_R"}
