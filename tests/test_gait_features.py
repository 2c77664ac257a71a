"""One walk's features (cycles, frequency, DC, amplitude, stride, speed) on walks built
from known sinusoids: they must come out as constructed."""

import numpy as np
import pytest
from data_paths import OP3_URDF

from livezmp.errors import InputError
from livezmp.gait import harmonics as hm
from livezmp.gait.channels import robot_joint_kind
from livezmp.gait.cycles import detect_cycles
from livezmp.gait.features import walk_features
from livezmp.gait.sinewalk import sine_bvh, sine_trajectory, walk_spec
from livezmp.gait.take import load_take, take_from_bvh
from livezmp.model.bvh import parse_bvh, write_bvh
from livezmp.model.trajectory_csv import write_joint_csv

OP3_JOINTS = ["head_pan", "head_tilt", "l_hip_yaw", "l_hip_roll", "l_hip_pitch", "l_knee", "l_ank_pitch",
              "l_ank_roll", "l_sho_pitch", "l_sho_roll", "l_el", "r_hip_yaw", "r_hip_roll", "r_hip_pitch",
              "r_knee", "r_ank_pitch", "r_ank_roll", "r_sho_pitch", "r_sho_roll", "r_el"]


def by_name(feats, name):
    i = [t.name for t in feats.tags].index(name)
    return np.rad2deg(feats.dc[i]), np.rad2deg(feats.amplitude[i])


def test_harmonic_fit_recovers_mean_and_amplitude_of_a_sampled_sum_of_harmonics():
    t = np.arange(173) / 30.0  # not a whole number of cycles, not a whole number of samples per cycle
    x = 2.5 + 3.0 * np.cos(2 * np.pi * 0.93 * t + 0.2) + 4.0 * np.sin(2 * np.pi * 2 * 0.93 * t)
    coef, res = hm.fit(t, x, 0.93, 3)
    dc, amp = hm.mean_and_amplitude(coef, 3)
    assert dc[0] == pytest.approx(2.5, abs=1e-12)
    assert amp[0] == pytest.approx(5.0, abs=1e-12)  # sqrt(3² + 4²)
    assert res[0] < 1e-20


def test_sine_walk_features_come_out_as_constructed():
    spec = walk_spec()
    f, v = 0.93, 1.25
    feats = walk_features(take_from_bvh(sine_bvh(spec, f, v, 7.0)))
    assert feats.frequency == pytest.approx(f, rel=1e-8)
    assert feats.speed == pytest.approx(v, rel=1e-9)
    assert feats.stride_length == pytest.approx(v / f, rel=1e-8)
    assert feats.cycles.n_cycles >= 5
    for name, (dc, amp, _) in spec.items():
        got_dc, got_amp = by_name(feats, name)
        assert got_dc == pytest.approx(dc, abs=1e-6), name
        assert got_amp == pytest.approx(amp, abs=1e-6), name
    # channels that do not move have zero amplitude
    assert by_name(feats, "Head.Xrotation") == pytest.approx((0.0, 0.0), abs=1e-9)


def test_channels_get_their_anatomical_axis_and_side():
    take = take_from_bvh(sine_bvh(walk_spec(), 1.0, 1.0, 4.0))
    tag = {t.name: t for t in take.tags}
    assert (tag["UpperLeg_L.Xrotation"].kind, tag["UpperLeg_L.Xrotation"].side) == ("thigh", "left")
    assert tag["UpperLeg_L.Xrotation"].axis == "lateral"
    assert tag["UpperLeg_R.Yrotation"].axis == "vertical"
    assert tag["LowerLeg_R.Zrotation"].axis == "forward"
    assert tag["LowerArm_L.Xrotation"].key == "forearm:left:lateral"


def test_a_walk_in_the_opposite_direction_has_the_same_features():
    spec = {**walk_spec(), "Hips.Yrotation": (0.0, 3.0, 0.5), "Hips.Zrotation": (0.0, 2.0, 1.0)}
    ahead = walk_features(take_from_bvh(sine_bvh(spec, 0.9, 1.1, 6.0)))
    back_take = take_from_bvh(sine_bvh(spec, 0.9, 1.1, 6.0, heading=180.0))
    back = walk_features(back_take)
    assert np.rad2deg(back_take.heading) == pytest.approx(180.0, abs=1e-6) or \
        np.rad2deg(back_take.heading) == pytest.approx(-180.0, abs=1e-6)
    assert back.frequency == pytest.approx(ahead.frequency, rel=1e-9)
    assert back.speed == pytest.approx(ahead.speed, rel=1e-9)
    # the root's yaw is relative to the walking direction, not 180° off
    assert by_name(back, "Hips.Yrotation") == pytest.approx(by_name(ahead, "Hips.Yrotation"), abs=1e-6)
    assert np.allclose(back.dc, ahead.dc, atol=1e-8)
    assert np.allclose(back.amplitude, ahead.amplitude, atol=1e-8)


def test_a_channel_that_wraps_through_180_degrees_is_unwrapped():
    spec = {**walk_spec(), "Foot_L.Zrotation": (178.0, 6.0, 0.3)}
    motion = sine_bvh(spec, 1.0, 1.0, 5.0)
    col = motion.channel_labels().index("Foot_L.Zrotation")
    motion.frames[:, col] = 180.0 - (180.0 - motion.frames[:, col]) % 360.0  # as a file stores it: (−180, 180]
    assert motion.frames[:, col].min() < -170.0  # the file really jumps
    dc, amp = by_name(walk_features(take_from_bvh(motion)), "Foot_L.Zrotation")
    assert (dc, amp) == pytest.approx((178.0, 6.0), abs=1e-6)


def test_standing_still_before_walking_is_left_out():
    motion = sine_bvh(walk_spec(), 1.0, 1.2, 6.0)
    still = np.repeat(motion.frames[:1], 45, axis=0)  # 1.5 s standing in the first pose
    still[:, :3] = motion.frames[0, :3]
    motion.frames = np.vstack([still, motion.frames])
    feats = walk_features(take_from_bvh(motion))
    assert feats.cycles.events[0] >= 1.5
    assert feats.frequency == pytest.approx(1.0, rel=1e-3)
    assert by_name(feats, "LowerLeg_L.Xrotation") == pytest.approx((30.0, 25.0), abs=0.05)


def test_cycles_survive_measurement_noise():
    rng = np.random.default_rng(3)
    t = np.arange(300) / 30.0
    x = np.deg2rad(20.0 * np.sin(2 * np.pi * 0.9 * t) + rng.normal(0.0, 1.0, t.size))
    cyc = detect_cycles(t, x, "noisy")
    assert cyc.n_cycles == 7  # up-crossings at k / 0.9 s, k = 1..8, inside the 10 s
    assert cyc.frequency == pytest.approx(0.9, rel=0.01)


def test_too_short_take_is_a_clear_error_naming_the_file(tmp_path):
    path = tmp_path / "short_walk.bvh"
    write_bvh(sine_bvh(walk_spec(), 1.0, 1.0, 1.6), path)  # 1.6 cycles
    with pytest.raises(InputError, match=r"short_walk\.bvh.*fewer than two whole gait cycles"):
        walk_features(load_take(path))


def test_standing_take_is_a_clear_error():
    motion = sine_bvh({}, 1.0, 0.0, 3.0)
    with pytest.raises(InputError, match="not a walk"):
        walk_features(take_from_bvh(motion))


def test_malformed_bvh_names_file_and_line(tmp_path):
    path = tmp_path / "broken.bvh"
    write_bvh(sine_bvh(walk_spec(), 1.0, 1.0, 3.0), path)
    lines = path.read_text().splitlines()
    lines[-5] = lines[-5].replace(" ", " x", 1)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError, match=rf"broken\.bvh:{len(lines) - 4}"):
        load_take(path)


def test_near_gimbal_lock_euler_channels_are_flagged():
    spec = {**walk_spec(), "Spine.Xrotation": (88.0, 1.0, 0.0)}  # ZXY with X ≈ 90°: Z and Y nearly coincide
    tag = {t.name: t for t in take_from_bvh(sine_bvh(spec, 1.0, 1.0, 3.0)).tags}
    assert tag["Spine.Zrotation"].gimbal and tag["Spine.Yrotation"].gimbal
    assert not tag["Spine.Xrotation"].gimbal
    assert not tag["UpperLeg_L.Xrotation"].gimbal


def test_robot_joint_names_map_to_segments():
    assert robot_joint_kind("l_hip_pitch") == ("thigh", "left")
    assert robot_joint_kind("r_knee") == ("shank", "right")
    assert robot_joint_kind("l_el") == ("forearm", "left")
    assert robot_joint_kind("r_sho_roll") == ("upper_arm", "right")
    assert robot_joint_kind("r_ank_pitch") == ("foot", "right")
    assert robot_joint_kind("head_pan") == ("head", "center")
    assert robot_joint_kind("base_yaw") == ("pelvis", "center")


def test_robot_csv_walk_features_come_out_as_constructed(tmp_path):
    spec = {"l_hip_pitch": (0.1, 0.35, 0.0), "r_hip_pitch": (-0.1, 0.35, np.pi), "l_knee": (0.6, 0.4, 1.0),
            "r_knee": (-0.6, 0.4, 1.0 + np.pi), "l_sho_pitch": (0.2, 0.15, np.pi)}
    path = tmp_path / "op3_walk.csv"
    write_joint_csv(sine_trajectory(OP3_JOINTS, spec, 1.6, 0.22, 4.0), path)
    take = load_take(path, urdf=OP3_URDF)
    tag = {t.name: t for t in take.tags}
    assert tag["l_hip_pitch"].key == "thigh:left:lateral"
    assert tag["r_knee"].key == "shank:right:lateral"
    assert tag["l_hip_roll"].axis == "forward" and tag["l_hip_yaw"].axis == "vertical"
    feats = walk_features(take)
    assert feats.frequency == pytest.approx(1.6, rel=1e-6)
    assert feats.speed == pytest.approx(0.22, rel=1e-6)
    for name, (dc, amp, _) in spec.items():
        i = [t.name for t in feats.tags].index(name)
        assert (feats.dc[i], feats.amplitude[i]) == pytest.approx((dc, amp), abs=1e-6), name


def test_robot_csv_without_urdf_is_a_clear_error(tmp_path):
    path = tmp_path / "op3_walk.csv"
    write_joint_csv(sine_trajectory(OP3_JOINTS, {"l_hip_pitch": (0.0, 0.3, 0.0)}, 1.0, 0.2, 3.0), path)
    with pytest.raises(InputError, match=r"op3_walk\.csv.*URDF"):
        load_take(path)


def test_bvh_round_trip_keeps_features(tmp_path):
    motion = sine_bvh(walk_spec(), 0.95, 1.1, 5.0)
    path = tmp_path / "w.bvh"
    write_bvh(motion, path)
    a = walk_features(take_from_bvh(motion))
    b = walk_features(take_from_bvh(parse_bvh(path.read_text(), str(path))))
    assert b.frequency == pytest.approx(a.frequency, rel=1e-6)
    assert np.allclose(b.amplitude, a.amplitude, atol=1e-6)


def test_a_looped_stride_is_read_as_the_walk_it_loops(tmp_path):
    """An animation cycle (one stride whose last frame repeats its first, as Mixamo's walks) is played on as a walk:
    it gives the features of the long walk it is a stride of. Read as it is, it has no whole gait cycle."""
    spec, f, v, fps = walk_spec(), 1.0, 1.2, 30.0
    long = walk_features(take_from_bvh(sine_bvh(spec, f, v, 7.0, fps)))
    stride = sine_bvh(spec, f, v, 1.0 + 1.0 / fps, fps)  # 31 frames: the 31st is the first's pose, a stride on
    write_bvh(stride, tmp_path / "loop.bvh")
    looped = walk_features(load_take(tmp_path / "loop.bvh"))
    assert looped.frequency == pytest.approx(f, rel=1e-6) and looped.speed == pytest.approx(v, rel=1e-3)
    for name in spec:
        assert np.allclose(by_name(looped, name), by_name(long, name), atol=1e-3), name  # deg (the file's decimals)
    with pytest.raises(InputError, match="fewer than two whole gait cycles"):
        walk_features(take_from_bvh(stride))


# the generated walk's root, turned to z up, is at gimbal lock in its ZXY order (the test's own decomposition says so)
@pytest.mark.filterwarnings("ignore:Gimbal lock detected:UserWarning")
def test_a_z_up_walk_is_read_with_its_detected_up_axis(tmp_path):
    """A walk exported z up is read as one (as `analyze` detects it), not taken as y up by default."""
    import skeleton_variants as sv

    spec, f, v = walk_spec(), 0.93, 1.25
    write_bvh(sv.compose(sv.z_up(sv.decompose(sine_bvh(spec, f, v, 7.0)))), tmp_path / "zup.bvh")
    feats = walk_features(load_take(tmp_path / "zup.bvh"))
    assert feats.frequency == pytest.approx(f, rel=1e-6) and feats.speed == pytest.approx(v, rel=1e-4)
