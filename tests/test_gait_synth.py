"""Speed control (synthesis) and the cycle-normalised comparison, on walks of known sinusoids."""

from dataclasses import replace

import numpy as np
import pytest
from data_paths import OP3_URDF

from livezmp.errors import InputError
from livezmp.gait.compare import compare
from livezmp.gait.features import walk_features
from livezmp.gait.population import analyze
from livezmp.gait.sinewalk import sine_bvh, sine_trajectory, walk_spec
from livezmp.gait.synth import match_channels, synth_take, to_bvh, to_trajectory
from livezmp.gait.take import take_from_bvh, take_from_trajectory
from livezmp.gait.takeset import TakeSpec
from livezmp.model.urdf_body import body_from_urdf

# Two subjects whose fast walk is exactly: frequency ×1.1, stride ×1.2, hip amplitude ×1.25,
# knee DC ×1.2, elbow amplitude ×0.8; so μ is exactly those changes, σ = 0, CV = 0.
BASES = [(0.9, 1.1, 20.0, 30.0, 12.0), (0.95, 1.2, 22.0, 28.0, 14.0)]


def walk(f, v, hip, knee, elbow, duration=6.0, heading=0.0):
    spec = walk_spec(hip_amp=hip, knee_dc=knee, elbow_amp=elbow)
    return sine_bvh(spec, f, v, duration, heading=heading)


def faster(f, v, hip, knee, elbow):
    return f * 1.1, v * 1.1 * 1.2, hip * 1.25, knee * 1.2, elbow * 0.8


@pytest.fixture(scope="module")
def analysis():
    items = []
    for j, b in enumerate(BASES):
        items.append((TakeSpec(f"s{j}_normal", f"s{j}", "normal"), walk_features(take_from_bvh(walk(*b)))))
        items.append((TakeSpec(f"s{j}_fast", f"s{j}", "fast"), walk_features(take_from_bvh(walk(*faster(*b))))))
    return analyze(items, "normal", {"fast": "fast"})


def param(feats, name, which):
    i = [t.name for t in feats.tags].index(name)
    return np.rad2deg(getattr(feats, which)[i])


@pytest.mark.parametrize("amount", [1.0, 0.5, 0.0])
def test_synthesis_changes_exactly_the_feature_parts(analysis, amount):
    base = (0.92, 1.15, 21.0, 29.0, 13.0)  # a third person, not in the analysis
    take = take_from_bvh(walk(*base))
    t, q, plan = synth_take(take, analysis, "fast", amount)
    out = walk_features(take_from_bvh(to_bvh(take, q)))
    before = walk_features(take)

    def r(x):
        return 1 + amount * x

    assert plan.frequency_ratio == pytest.approx(r(0.1), rel=1e-6)
    assert out.frequency == pytest.approx(before.frequency * r(0.1), rel=1e-6)
    assert out.stride_length == pytest.approx(before.stride_length * r(0.2), rel=1e-5)
    assert out.speed == pytest.approx(before.speed * r(0.1) * r(0.2), rel=1e-5)
    assert param(out, "UpperLeg_L.Xrotation", "amplitude") == pytest.approx(21.0 * r(0.25), rel=1e-4)
    assert param(out, "LowerLeg_R.Xrotation", "dc") == pytest.approx(29.0 * r(0.2), rel=1e-5)
    assert param(out, "LowerArm_L.Xrotation", "amplitude") == pytest.approx(13.0 * r(-0.2), rel=1e-4)
    # not feature parts: unchanged
    assert param(out, "LowerLeg_R.Xrotation", "amplitude") == pytest.approx(25.0, rel=1e-4)
    assert param(out, "UpperLeg_L.Xrotation", "dc") == pytest.approx(-5.0, abs=1e-4)
    assert param(out, "Spine.Yrotation", "amplitude") == pytest.approx(4.0, rel=1e-4)
    assert len(t) == int(np.floor((len(take.t) - 1) / r(0.1) + 1e-9)) + 1


def test_synthesis_keeps_the_walking_direction(analysis):
    take = take_from_bvh(walk(*BASES[0], heading=180.0))
    _, q, _ = synth_take(take, analysis, "fast", 1.0)
    motion = to_bvh(take, q)
    z = motion.frames[:, motion.channel_labels().index("Hips.Zposition")]
    assert z[-1] < z[0]  # still walking along −z
    out = walk_features(take_from_bvh(motion))
    assert out.speed == pytest.approx(1.1 * 1.1 * 1.2, rel=1e-5)


def test_features_of_an_unrelated_skeleton_are_refused(analysis):
    alien = replace(analysis, tags=[replace(t, name=f"x{i}", kind="other") for i, t in enumerate(analysis.tags)])
    with pytest.raises(InputError, match="no channel in common"):
        synth_take(take_from_bvh(walk(*BASES[0])), alien, "fast", 1.0)


def test_amount_outside_0_1_is_an_error(analysis):
    take = take_from_bvh(walk(*BASES[0]))
    with pytest.raises(InputError, match="--amount"):
        synth_take(take, analysis, "fast", 1.5)
    with pytest.raises(InputError, match="no variant 'slow'"):
        synth_take(take, analysis, "slow", 1.0)


def test_bvh_features_drive_a_robot_walk_by_segment_and_axis(analysis):
    body = body_from_urdf(OP3_URDF)
    spec = {"l_hip_pitch": (0.1, 0.3, 0.0), "r_hip_pitch": (0.1, 0.3, np.pi), "head_pan": (0.0, 0.1, 0.0)}
    take = take_from_trajectory(sine_trajectory(body.joint_names, spec, 1.5, 0.2, 3.0), body)
    names = [tg.name for tg in take.tags]
    feature_names = [tg.name for tg in analysis.tags]
    match = dict(zip(names, match_channels(take.tags, analysis.tags), strict=True))
    assert feature_names[match["l_hip_pitch"]] == "UpperLeg_L.Xrotation"
    assert feature_names[match["r_knee"]] == "LowerLeg_R.Xrotation"
    assert feature_names[match["head_pan"]] == "Head.Yrotation"
    assert feature_names[match["r_el"]] == "LowerArm_R.Zrotation"  # OP3's elbow bends about the forward axis
    t, q, plan = synth_take(take, analysis, "fast", 1.0)
    assert plan.amp_ratio[names.index("l_hip_pitch")] == pytest.approx(1.25, rel=1e-6)
    assert plan.amp_ratio[names.index("r_el")] == pytest.approx(1.0)
    traj = to_trajectory(take, t, q)
    out = walk_features(take_from_trajectory(traj, body))
    assert out.frequency == pytest.approx(1.5 * 1.1, rel=1e-6)
    i = [tg.name for tg in out.tags].index("l_hip_pitch")
    assert out.amplitude[i] == pytest.approx(0.3 * 1.25, rel=1e-4)
    assert out.speed == pytest.approx(0.2 * 1.1 * 1.2, rel=1e-5)


def test_compare_identical_walks_is_zero_and_a_known_offset_shows_exactly():
    motion = walk(*BASES[0])
    a = take_from_bvh(motion)
    fa = walk_features(a)
    assert compare(a, fa, a, fa).total == pytest.approx(0.0, abs=1e-9)
    shifted = walk(*BASES[0])
    shifted.frames[:, shifted.channel_labels().index("LowerLeg_L.Zrotation")] += 3.0
    b = take_from_bvh(shifted)
    c = compare(a, fa, b, walk_features(b))
    n_moving = len(walk_spec()) + 1  # channels that move, and the shifted one
    assert c.per_channel[c.channels.index("LowerLeg_L.Zrotation")] == pytest.approx(3.0, abs=1e-6)
    assert c.per_joint["LowerLeg_L"] == pytest.approx(3.0 / np.sqrt(2), abs=1e-6)  # Z differs, X moves equal
    assert c.total == pytest.approx(np.sqrt(9.0 / n_moving), abs=1e-6)


def test_compare_is_cycle_normalised_and_ignores_euler_branches():
    a = take_from_bvh(walk(*BASES[0]))
    slower = walk(0.7, 0.9, *BASES[0][2:])  # same shape, other cadence and speed
    slower.frames[:, slower.channel_labels().index("LowerLeg_L.Xrotation")] += 360.0
    b = take_from_bvh(slower)
    assert compare(a, walk_features(a), b, walk_features(b)).total == pytest.approx(0.0, abs=0.005)


def test_compare_refuses_other_skeletons():
    a = take_from_bvh(walk(*BASES[0]))
    other = walk(*BASES[0])
    other.joints[3].name = "Skull"
    b = take_from_bvh(other)
    with pytest.raises(InputError, match="skeleton does not match"):
        compare(a, walk_features(a), b, walk_features(b))
