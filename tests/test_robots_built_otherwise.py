"""Humanoid URDFs built the ways real ones are (tests/humanoid_gen.py's `HumanoidSpec`): a waist above the
legs with the torso as root, leg link frames turned so the pitch axis is local z, 2-joint arms, no arms,
continuous joints and revolute ones without limits, a mimic finger, a link named as a joint, a robot name
with spaces, massless root and sensor links. Each case here failed before the fixes it names (benchmarks/
bench_any_humanoid.py is the full sweep). Truth: the names and geometry the generator gave, and the
simulated humanoid's exact whole-body dynamics (simulated time)."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest
from humanoid_gen import CONVENTIONS, HumanoidSpec, build_humanoid, com_height, malformed
from scipy.optimize import brentq
from test_live_loop_closed import balance

from livezmp.cli import main
from livezmp.correct.online import MARGIN_M, size_scaled_accel, size_scaled_margin
from livezmp.correct.root_motion import RootMover
from livezmp.live import scenarios as scenarios_module
from livezmp.live.config import SafetyConfig
from livezmp.live.scenarios import (
    LEAN_LEAD,
    G,
    Poser,
    Push,
    Scenario,
    hip_height,
    joint_roles,
    lean_angle,
    lean_ramp,
    make_scenario,
    standing_support,
)
from livezmp.model.base_placement import BasePlacer
from livezmp.model.body import foot_soles
from livezmp.model.robot import load_robot

# generated humanoids with mesh feet name meshes no test writes: each says in one warning line that its feet
# stand on default box soles (tests/test_foot_meshes.py asserts that line)
pytestmark = pytest.mark.filterwarnings("ignore:.*default box soles? used:UserWarning")

# the sweep's "combined" robot: every way of being built otherwise that a fix was needed for, at once
HARD = HumanoidSpec(waist="yp", torso_root=True, frames="pitch_z", arm="pr", extras=True, names="darwin",
                    hip="rpy", flip=0.5, limits="absent", root="j_tibia_l", robot_name="kid size #3", seed=29)
LEG_ROLES = ("hip_pitch", "knee", "ank_pitch", "hip_roll", "ank_roll")


def darwin(role: str, side: str) -> str:
    return CONVENTIONS["darwin"][role].format(s=side)


@pytest.fixture(scope="module")
def hard(tmp_path_factory):
    return load_robot(str(build_humanoid(tmp_path_factory.mktemp("hard") / "hard.urdf", HARD)), None)


def test_the_waist_above_the_legs_is_the_trunks_and_the_legs_start_at_the_hips(hard):
    # before: each leg's chain began at the waist, shared by both: the corrector's "legs" weighed the whole
    # robot twice and its step was NaN; the scenarios took the waist pitch for a hip pitch
    body = hard.body
    roles = joint_roles(body)
    assert {r: roles[f"{s}_{r}"] for s in "lr" for r in LEG_ROLES} == {r: darwin(r, s) for s in "lr"
                                                                       for r in LEG_ROLES}
    hips = {s: body.model.frames[f].name for s, f in body.correction.hips.items()}
    assert hips == {"left": darwin("hip_pitch", "l"), "right": darwin("hip_pitch", "r")}  # the pivot: the pitch
    assert roles["l_sho_pitch"] == darwin("sho_pitch", "l") and "l_el" not in roles  # a 2-joint arm


def test_turned_foot_frames_get_level_soles_under_the_feet(hard):
    # before: the default sole was a box in the foot link's own x-y plane: with the link turned so its z is the
    # pitch axis, the sole stood upright and no posture put the CoM over it
    body = hard.body
    model, data = body.model, body.model.createData()
    pin.framesForwardKinematics(model, data, np.zeros(model.nq))
    for foot in body.feet.values():
        m = data.oMf[foot.frame_id]
        corners = foot.sole_local @ m.rotation.T + m.translation
        assert np.ptp(corners[:, 2]) == pytest.approx(0.0, abs=1e-9)  # level
        spans = np.ptp(corners[:, :2], axis=0)
        assert spans[0] > spans[1] > 0  # longer forward than wide
        com = data.oMi[model.frames[foot.frame_id].parentJoint]
        centre = com.act(model.inertias[model.frames[foot.frame_id].parentJoint].lever)
        assert corners[:, :2].mean(axis=0) == pytest.approx(centre[:2], abs=1e-9)


def test_cleat_feet_stand_on_their_cleats_with_the_trunk_upright(tmp_path):
    # before: the lowest cleat was taken as the foot, under a level box sole (0.5 x 0.28 hip heights, centred under
    # the foot's centre of mass), and the standing posture kept the soles as the zero posture has them: the cleats,
    # on a plane 15° toes up (the right foot's also rolled 1.5°), were not the sole, and only the back pair touched
    body = load_robot(str(build_humanoid(tmp_path / "cleats.urdf", HumanoidSpec(cleats=np.radians(15), seed=40))),
                      None).body
    model, data = body.model, body.model.createData()
    joints = Poser(body).standing()
    base = BasePlacer(body).update(joints)
    pin.framesForwardKinematics(model, data, np.concatenate([base, joints]))
    soles = foot_soles(body, data)
    for side in ("left", "right"):
        cleats = np.array([data.oMf[f].translation for f in range(model.nframes)
                           if model.frames[f].name.startswith(f"{side[0]}_cleat_")
                           and model.frames[f].type == pin.FrameType.BODY])
        assert len(cleats) == 4
        np.testing.assert_allclose(cleats[:, 2], 0.0, atol=1e-9)  # all four on the floor
        np.testing.assert_allclose(sorted(map(tuple, soles[side])), sorted(map(tuple, cleats)), atol=1e-9)
    np.testing.assert_allclose(base[4:], 0.0, atol=1e-9)  # the trunk upright: no pitch, no roll


def test_a_two_joint_arm_hangs_down_by_its_shoulder_roll(hard):
    # before: scenarios needed an elbow on each arm, so every scenario refused a robot with 2-joint arms
    body = hard.body
    q = np.concatenate([np.zeros(6), Poser(body).standing(arm_out=0.1)])
    data = body.model.createData()
    pin.forwardKinematics(body.model, data, q)
    for side, sign in (("l", 1), ("r", -1)):
        roll = body.model.getJointId(darwin("sho_roll", side))
        arm = data.oMi[roll].act(body.model.inertias[roll].lever) - data.oMi[roll].translation
        assert np.arctan2(sign * arm[1], -arm[2]) == pytest.approx(0.1, abs=1e-6)  # 0.1 rad out from hanging


def test_continuous_and_unlimited_joints_are_one_angle_without_bounds(tmp_path):
    # before: a continuous joint was refused, and a revolute joint without <limit> was "not a valid URDF model"
    spec = HumanoidSpec(continuous=True, grippers=True, arm="prye", limits="absent")
    robot = load_robot(str(build_humanoid(tmp_path / "c.urdf", spec)), None)
    model = robot.body.model
    assert model.nq == model.nv  # one angle a joint, as a servo reports it
    assert np.all(np.isinf(model.lowerPositionLimit[6:])) and np.all(np.isinf(model.upperPositionLimit[6:]))
    assert [s.id for s in robot.config.servos.values()] == list(range(1, len(robot.body.joint_names) + 1))
    assert "l_finger1" in robot.body.joint_names  # the mimic finger: its own joint


def test_limits_with_no_range_are_no_limits(tmp_path):
    # before: every joint limited to [0, 0], as Z-Bot2's CAD export writes joints whose limits nobody set, and
    # every scenario refused ("standing with bent knees needs leg joint ... outside its limits")
    body = load_robot(str(build_humanoid(tmp_path / "z.urdf", HumanoidSpec(limits="zero", seed=48))), None).body
    model = body.model
    assert np.all(np.isinf(model.lowerPositionLimit[6:])) and np.all(np.isinf(model.upperPositionLimit[6:]))
    assert make_scenario("lean", body).name == "lean"


def _zero_pose_soles(body) -> dict[str, np.ndarray]:
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, np.zeros(body.model.nq))
    return foot_soles(body, data)


def test_a_foot_with_a_collision_box_stands_on_its_lowest_face(tmp_path):
    # before: the default box, 0.5 x 0.28 hip heights (240 x 134 mm here), whatever the foot's collision box (its
    # real 80 x 40 mm; Bez2's 170 x 90, Valkyrie's 270 x 160, the Berkeley Humanoid's 160 x 55 tilted 10°)
    spec = HumanoidSpec(frames="random", seed=49)  # the foot link's frame turned, its box written level in it
    soles = _zero_pose_soles(load_robot(str(build_humanoid(tmp_path / "b.urdf", spec)), None).body)
    for side in ("left", "right"):
        np.testing.assert_allclose(np.ptp(soles[side], axis=0), [0.16 * spec.height, 0.08 * spec.height, 0.0],
                                   atol=1e-6)  # the file's 9 digits
        # the box's bottom, 0.015 heights up, in the root's frame: at the torso's centre of mass
        np.testing.assert_allclose(soles[side][:, 2], (0.015 - spec.torso_com) * spec.height, atol=1e-6)


def test_a_foot_of_two_collision_boxes_on_one_plane_stands_on_both(tmp_path):
    # before: the lowest face alone, one box: half the foot (ergoCub's front and rear links, a 117 x 100 mm box
    # under each on one plane, stood on the front one, its CoM 84 mm behind it: every scenario refused)
    spec = HumanoidSpec(foot="split", frames="random", seed=52)
    soles = _zero_pose_soles(load_robot(str(build_humanoid(tmp_path / "s.urdf", spec)), None).body)
    for side in ("left", "right"):
        np.testing.assert_allclose(np.ptp(soles[side], axis=0), [0.16 * spec.height, 0.08 * spec.height, 0.0],
                                   atol=1e-6)
        np.testing.assert_allclose(soles[side][:, 0].mean(), 0.02 * spec.height, atol=1e-6)


def test_default_soles_keep_to_their_own_side_of_the_feet(tmp_path):
    # before: a foot without a collision box got a box 0.28 hip heights wide centred under its centre of mass; here
    # the two overlapped by 24 mm between the feet (Z-Bot2's by 18 mm, and its corrected push rolled the trunk 3.7°
    # over the foot the simulated feet's load jumped to, its true ZMP 0.44 m off the feet for moments)
    body = load_robot(str(build_humanoid(tmp_path / "m.urdf", HumanoidSpec(foot="mesh", seed=50))), None).body
    soles = _zero_pose_soles(body)
    assert soles["left"][:, 1].min() == pytest.approx(0.0, abs=1e-9)  # the mid-line between the feet
    assert soles["right"][:, 1].max() == pytest.approx(0.0, abs=1e-9)
    assert soles["left"][:, 1].max() > 0.055 * 0.5 > -soles["right"][:, 1].min() - 0.1  # the outer edges kept


def test_a_robot_upside_down_in_its_file_is_turned_onto_its_feet(tmp_path):
    # before: "no two feet" (its feet above its hips in the zero pose, as K-Scale's GPR file has them)
    spec = HumanoidSpec(upside_down=True, seed=51)
    body = load_robot(str(build_humanoid(tmp_path / "u.urdf", spec)), None).body
    model = body.model
    feet = {s: model.names[model.frames[f.frame_id].parentJoint] for s, f in body.feet.items()}
    assert feet == {"left": "l_ank_roll", "right": "r_ank_roll"}
    soles = _zero_pose_soles(body)
    assert soles["left"][:, 1].min() > 0 > soles["right"][:, 1].max()  # left on the left, facing +x
    assert all(soles[s][:, 2].max() < -0.5 * spec.height for s in soles)  # below the root
    assert make_scenario("lean", body).name == "lean"


@pytest.mark.parametrize("lying", ["x", "-x"])
def test_a_robot_lying_down_in_its_file_is_stood_on_its_feet(tmp_path, lying):
    # before: its feet and hips all at one height, the legs' height 0: default soles 1 mm long, every scenario
    # refused ("no forward lean up to 1 rad puts the CoM 4.0 mm past the toes"; WATonomous' humanoid V1)
    standing = load_robot(str(build_humanoid(tmp_path / "s.urdf", HumanoidSpec(seed=56))), None).body
    body = load_robot(str(build_humanoid(tmp_path / "l.urdf", HumanoidSpec(lying=lying, seed=56))), None).body
    for side, soles in _zero_pose_soles(body).items():
        np.testing.assert_allclose(soles - soles.mean(axis=0),
                                   _zero_pose_soles(standing)[side] - _zero_pose_soles(standing)[side].mean(axis=0),
                                   atol=1e-9)
    assert make_scenario("lean", body).name == "lean"


def test_a_link_named_as_a_joint_and_a_robot_named_in_words_load(tmp_path):
    # before: a traceback from Pinocchio ("Several frames match the filter"), and a refusal of the name
    spec = HumanoidSpec(root="l_knee", robot_name="My Humanoid v2")
    body = load_robot(str(build_humanoid(tmp_path / "n.urdf", spec)), None).body
    assert body.model.existFrame("l_knee_link") and joint_roles(body)["l_knee"] == "l_knee"


@pytest.mark.parametrize(("name", "options"), [("lean", {"hold_s": 1.0}), ("arm_swing", {"duration": 3.0}),
                                               ("push", {})])
def test_the_robot_built_otherwise_falls_uncorrected_and_stands_corrected(hard, name, options):
    # before: lean and push refused (no lean over the upright soles), arm_swing refused (no elbow)
    body = hard.body
    scenario = make_scenario(name, body, **options)
    off, s_off = balance(body, scenario, correct=False, foot_sensors=name == "push")
    on, s_on = balance(body, scenario, correct=True, foot_sensors=name == "push")
    print(f"{name}: uncorrected fell at {off.fallen and off.fallen.t:.2f} s, worst true margin "
          f"{1e3 * off.counters.worst_margin:.1f} mm; corrected: fell {on.fallen}, worst "
          f"{1e3 * on.counters.worst_margin:.1f} mm")
    assert off.fallen is not None and s_off["stopped_by"] == "fell"
    assert on.fallen is None and s_on["stopped_by"] == "duration"


PLAIN = HumanoidSpec(extras=True, grippers=True, seed=40)


@pytest.mark.parametrize("quirk", [{"placeholders": "zero_mass"}, {"placeholders": "point_mass"},
                                   {"fixed_axis_zero": True}, {"odd_inertias": True}, {"fixed_finger": True},
                                   {"foot_frames": True}, {"parallel_legs": True}, {"root_joint": "floating"}])
def test_quirks_of_published_urdfs_load_with_the_masses_and_legs_of_the_plain_robot(tmp_path, quirk):
    # before, refused: a link of mass 0 (Bolt's feet) or a point mass with a zero inertia (Talos', Wolfgang's
    # sensor frames), a fixed joint's <axis xyz="0 0 0"> (Unitree H1, NAO), a point-mass head with a 2.4e-35
    # product of inertia (iCub) or a torso breaking the triangle inequality (Darwin-OP, Romeo), a fixed finger
    # keeping its <mimic> (Talos' reduced model), a foot ending in several leaves at one height (JVRC-1's and
    # XBot-L's sensor and end-effector frames: both feet were taken on one leg), a massless copy of each leg
    # (NimbRo-OP2X's parallel linkage: its foot plane was taken for a foot), a floating joint from a massless root
    # link (HighTorque Hi's `world`: "type 'floating' not supported")
    plain = load_robot(str(build_humanoid(tmp_path / "plain.urdf", PLAIN)), None).body
    body = load_robot(str(build_humanoid(tmp_path / "odd.urdf", replace(PLAIN, **quirk))), None).body
    extra = 5 * 1e-4 if quirk.get("placeholders") == "point_mass" else 0.0  # 2 soles, camera, IMU, dummy root
    assert body.total_mass == pytest.approx(plain.total_mass + extra, rel=1e-9)
    roles = joint_roles(body)
    assert all(roles[f"{s}_{r}"] == plain_roles for s in "lr" for r in LEG_ROLES
               for plain_roles in [joint_roles(plain)[f"{s}_{r}"]])
    fingers = {"l_finger1", "r_finger1"}
    ghosts = {f"{s}_parallel_{r}" for s in "lr" for r in ("thigh", "shank", "foot")}
    assert set(body.joint_names) == (set(plain.joint_names) - (fingers if quirk.get("fixed_finger") else set())
                                     | (ghosts if quirk.get("parallel_legs") else set()))
    def foot_joints(b):
        return {s: b.model.names[b.model.frames[f.frame_id].parentJoint] for s, f in b.feet.items()}
    assert foot_joints(body) == foot_joints(plain)


@pytest.mark.parametrize("limits", ["tight", "wide"])
@pytest.mark.parametrize("facing", ["-y", "-x"])
def test_a_robot_facing_another_way_in_its_file_is_turned_to_face_x(tmp_path, facing, limits):
    # before: facing -y (Poppy), no leg joint turned about the lateral axis (refused: "found no l_hip_pitch");
    # facing -x (iCub), its right foot taken as the left and its knees bent against their limits to stand; with
    # limits that allow the stance both ways ("wide", Sigmaban's ±π) the way its toes point tells: before, the
    # foot at +y in the file was the left, and facing -x its knees bent backward
    spec = HumanoidSpec(limits=limits, seed=41)
    plain = load_robot(str(build_humanoid(tmp_path / "plain.urdf", spec)), None).body
    body = load_robot(str(build_humanoid(tmp_path / "turned.urdf", replace(spec, facing=facing))), None).body
    assert {s: body.model.names[body.model.frames[f.frame_id].parentJoint] for s, f in body.feet.items()} == \
        {"left": "l_ank_roll", "right": "r_ank_roll"}  # the feet's joints (their soles: their collision boxes)
    assert joint_roles(body) == joint_roles(plain)
    model = body.model
    for name in ("lean", "arm_swing", "push"):
        goals = make_scenario(name, body).goals(0.0)
        assert np.all(goals >= model.lowerPositionLimit[6:]) and np.all(goals <= model.upperPositionLimit[6:])
        assert np.allclose(goals, make_scenario(name, plain).goals(0.0), atol=1e-6)


def test_a_knee_bends_the_way_its_limits_let_it_and_an_arm_beyond_its_own_is_held_at_them(tmp_path):
    # before: every stance refused, "standing with bent knees needs leg joint 'l_knee' at 0.60 rad, outside its limits
    # [-1.40, 0.00]" (Poppy's file gives its left knee the right's range, their axes the same); earlier, the sim's
    # servos stopped the knee at its limit, the robot stood crooked and fell in 0.2 s corrected or not; the elbows'
    # goals were left outside their limits (NAO)
    spec = HumanoidSpec(limits="tight", odd_limits=True, seed=42)
    body = load_robot(str(build_humanoid(tmp_path / "odd.urdf", spec)), None).body
    goals = make_scenario("lean", body).goals(0.0)
    poser = Poser(body)
    assert poser.bends == {"l": -1.0, "r": 1.0}
    model = body.model
    assert np.all(goals >= model.lowerPositionLimit[6:]) and np.all(goals <= model.upperPositionLimit[6:])
    knees = [body.joint_names.index(f"{s}_knee") for s in "lr"]
    turned = [goals[i] / poser.unit(f"{s}_knee", 1)[i] for s, i in zip("lr", knees, strict=True)]  # about y, rad
    assert turned == pytest.approx([-0.6, 0.6])
    data = model.createData()
    pin.framesForwardKinematics(model, data, np.concatenate([BasePlacer(body).update(goals), goals]))
    soles = foot_soles(body, data)
    assert np.ptp(np.vstack(list(soles.values()))[:, 2]) < 1e-6  # both soles flat on the floor
    body = load_robot(str(build_humanoid(tmp_path / "arms.urdf", replace(spec, limits="wide"))), None).body
    goals = make_scenario("lean", body).goals(0.0)
    elbows = [body.joint_names.index(f"{s}_el") for s in "lr"]
    assert np.allclose(goals[elbows], -0.03)


def test_knees_that_bend_neither_way_stand_straight_legged(tmp_path):
    # before: refused, "standing with bent knees needs leg joint 'l_knee' at 0.60 rad, outside its limits"
    urdf = build_humanoid(tmp_path / "stiff.urdf", HumanoidSpec(seed=45))
    text = re.sub(r'(<joint name="[lr]_knee" type="revolute">.*?<limit) lower="[^"]*" upper="[^"]*"',
                  r'\1 lower="-0.01" upper="0.01"', urdf.read_text(), flags=re.S)
    urdf.write_text(text)
    body = load_robot(str(urdf), None).body
    goals = make_scenario("lean", body).goals(0.0)
    assert np.allclose(goals[[body.joint_names.index(f"{s}_knee") for s in "lr"]], 0.0, atol=1e-9)


def test_legs_without_an_ankle_pitch_are_refused_as_standing_on_points(tmp_path, capsys):
    # before: "found no l_hip_pitch in its kinematic tree" (Bolt: hip abduction, hip and knee flexion, a ball foot)
    urdf = build_humanoid(tmp_path / "bolt.urdf", HumanoidSpec(ankle="r", arm="", seed=46))
    rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "push", "--duration", "0.05"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1
    assert "left leg turns about the lateral axis at 2 joints (l_hip_pitch, l_knee), none at its ankle" in err[0]
    assert "cannot stand still" in err[0]


def test_an_arm_swing_too_light_to_move_the_zmp_is_refused_saying_how_far_it_gets(tmp_path, capsys):
    # before: "no arm swing of 0.6 rad between 0.1 and 3 Hz takes the ZMP 4.0 mm past the toes", not how near it came
    # (Atlas v5: 2.4 mm inside them at 3 Hz; a trunk 30 times as heavy here)
    urdf = build_humanoid(tmp_path / "heavy.urdf", HumanoidSpec(trunk_mass=30.0, seed=47))
    rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "arm_swing", "--duration", "0.05"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1
    assert re.search(r"at 3 Hz, 11\.3 rad/s at the shoulders, its ZMP reaches \d+\.\d mm inside them", err[0]), err


def test_a_link_inertia_no_link_of_the_robot_can_have_is_refused_in_one_line(tmp_path, capsys):
    # before: taken as written (Darwin-OP's file: a 1 kg body of 6.5 kg m^2), the true ZMP moved by metres; the
    # torso is the root link, named base_link
    for scale, refused in ((1e6, True), (100.0, False)):  # kg mm^2 written as kg m^2; a torso 10 times too wide
        urdf = build_humanoid(tmp_path / f"i{scale:g}.urdf", HumanoidSpec(inertia_scale=scale, seed=43))
        rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "lean", "--duration", "0.05",
                   "--quiet"])
        err = capsys.readouterr().err.splitlines()
        assert (rc, len(err)) == ((2, 1) if refused else (0, 0)), err
        assert not refused or ("link 'base_link' <inertia>" in err[0] and "more than the whole robot" in err[0])


def test_a_shoulder_pitch_mounted_off_the_lateral_axis_is_the_one_the_arms_swing_from(tmp_path):
    # before: a shoulder pitch 25 deg off the lateral axis (Unitree H1's) was passed over for the elbow: the arms
    # swung from their elbows (Unitree's H1, H1-2 and G1 then stood uncorrected and fell corrected)
    body = load_robot(str(build_humanoid(tmp_path / "t.urdf", HumanoidSpec(shoulder_tilt=0.44, seed=44))), None).body
    roles = joint_roles(body)
    assert [roles[f"{s}_{r}"] for s in "lr" for r in ("sho_pitch", "el")] == ["l_sho_pitch", "l_el", "r_sho_pitch",
                                                                              "r_el"]
    scenario = make_scenario("arm_swing", body, duration=3.0)
    off, _ = balance(body, scenario, correct=False)
    on, _ = balance(body, scenario, correct=True)
    assert off.fallen is not None and on.fallen is None


def test_arms_held_forward_in_the_zero_posture_are_brought_down_and_swung_from_the_shoulder(tmp_path):
    # before: with the arms forward in the zero posture (NAO's), the upper-arm twist at the elbow (NAO's elbow
    # yaw, about the forward axis) was taken for the shoulder roll: the arms stayed forward and NAO's arm swing
    # stood uncorrected
    body = load_robot(str(build_humanoid(tmp_path / "f.urdf", HumanoidSpec(arm="prye", arms_forward=True, seed=46))),
                      None).body
    roles = joint_roles(body)
    assert [roles[f"l_{r}"] for r in ("sho_pitch", "sho_roll", "el")] == ["l_sho_pitch", "l_sho_roll", "l_el"]
    poser = Poser(body)
    assert poser.standing()[poser.index("l_sho_pitch")] == pytest.approx(np.pi / 2, abs=0.01)  # arms down
    scenario = make_scenario("arm_swing", body, duration=3.0)
    off, _ = balance(body, scenario, correct=False)
    on, _ = balance(body, scenario, correct=True)
    assert off.fallen is not None and on.fallen is None


def test_a_lean_its_ankles_cannot_make_is_refused_in_one_line(tmp_path, capsys):
    # before: the loop held the ankles at their limits and the robot stood, short of its toes, uncorrected
    # (Romeo: 88 mm inside them; its default soles put the toes where 0.67 rad of ankle leans to them)
    urdf = build_humanoid(tmp_path / "a.urdf", HumanoidSpec(ankle_range=0.3, seed=45))
    rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "lean", "--duration", "0.1"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and "lean needs joint 'l_ank_pitch' at -0.30" in err[0], err
    assert "from every straighter stance down to 0.1 rad" in err[0]


def test_a_lean_its_ankles_cannot_make_from_the_knees_bent_stance_is_made_from_a_straighter_one(tmp_path):
    # before: refused ("lean needs joint 'l_ank_pitch' at -0.3657 rad", the knees-bent stance's -0.3 and the
    # lean's share of one ±0.365 range), as Fourier GR-Mini's three scenarios were (its ankles ±0.436 rad); and a
    # straighter stance's goals may not come within the loop's limit margin, which would cut them at t = 0 (GR-Mini's
    # push asked -0.4334 rad, the loop sent -0.426: its true ZMP 516 mm past its toes for 20 ms)
    body = load_robot(str(build_humanoid(tmp_path / "a.urdf", HumanoidSpec(ankle_range=0.365, seed=45))), None).body
    roles = joint_roles(body)
    legs = [body.joint_names.index(roles[f"{s}_{r}"]) for s in "lr" for r in LEG_ROLES]
    n, margin = len(body.joint_names), SafetyConfig().limit_margin_rad
    lower, upper = body.model.lowerPositionLimit[-n:][legs] + margin, body.model.upperPositionLimit[-n:][legs] - margin
    for name in ("lean", "push", "arm_swing"):
        scenario = make_scenario(name, body)
        goals = np.array([scenario.goals(t)[legs] for t in np.arange(0.0, scenario.duration, 0.05)])
        assert goals[0, legs.index(body.joint_names.index(roles["l_knee"]))] < 0.6 - 1e-6, name  # straighter
        assert np.all(goals >= lower) and np.all(goals <= upper), name
    lean = make_scenario("lean", body)
    off, _ = balance(body, lean, correct=False)
    on, _ = balance(body, lean, correct=True)
    assert off.fallen is not None and on.fallen is None


# legs only, a light trunk whose CoM lies just above the hips: its largest turn (15°) moves the CoM back 1-3 mm
LIGHT_TRUNK = {
    "lean": HumanoidSpec(names="nao", ankle="rp", arm="", trunk_mass=0.1, torso_com=0.56, height=0.4, mass=1.5,
                         flip=0.5, seed=62),
    "push": HumanoidSpec(names="darwin", hip="rpy", arm="", trunk_mass=0.15, torso_com=0.6, height=0.6, mass=5.0,
                         seed=60),
}


@pytest.mark.parametrize("name", ["lean", "push"])
def test_a_robot_whose_trunk_is_too_short_a_lever_is_carried_back_by_its_legs(tmp_path, name):
    # before: refused, "its trunk turned back by the corrector's largest 15° moves its CoM back only 0.8 mm, 8.0
    # needed" (lean; push: 2.4, 5.0; Alexbotmini's lean: 1.8, 8.0); built anyway, with the trunk alone each fell
    # corrected (lean at 2.32 s, push at 2.14 s); its legs now carry its pelvis back over its feet
    body = load_robot(str(build_humanoid(tmp_path / "a.urdf", LIGHT_TRUNK[name])), None).body
    scenario = make_scenario(name, body)
    off, _ = balance(body, scenario, correct=False, foot_sensors=name == "push")
    on, _ = balance(body, scenario, correct=True, foot_sensors=name == "push")
    assert off.fallen is not None and on.fallen is None
    assert on.counters.worst_margin > 0


def test_a_lean_neither_trunk_nor_legs_can_take_back_is_refused_in_one_line(tmp_path, capsys, monkeypatch):
    # no robot on hand is beyond its trunk and legs both: the light-trunk lean robot with its legs' help taken away
    # stands for one (with the trunk alone its CoM goes back 0.8 mm of the 8.0 needed, and it fell corrected)
    monkeypatch.setattr(scenarios_module, "uses_legs", lambda *args: False)
    urdf = build_humanoid(tmp_path / "a.urdf", LIGHT_TRUNK["lean"])
    rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "lean", "--duration", "0.1"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and "lean: its trunk turned back" in err[0], err
    assert "could not stand corrected" in err[0]


def test_a_tall_robot_near_its_side_edge_rolls_its_trunk_without_toppling_itself(tmp_path):
    # before: the trunk's acceleration was cut by its ZMP answer in pitch only; this 1.8 m robot (its upper body's
    # mass high, as in the push test above), leaning sideways 20 mm inside its feet's outer edge, 35 mm short of its
    # corrector's aim, had its trunk rolled at the full acceleration limit, whose answer moved its ZMP past that edge:
    # it fell at 0.29 s, before it was pushed
    spec = HumanoidSpec(height=1.8, mass=60.0, waist="yp", torso_com=0.95, seed=24)
    body = load_robot(str(build_humanoid(tmp_path / "a.urdf", spec)), None).body
    poser = Poser(body)
    stood = poser.standing(0.3)
    rolls = [poser.unit(f"{s}_{j}_roll", 0) for s in "lr" for j in ("ank", "hip")]

    def room(angle: float) -> float:  # m from the CoM to the left feet's outer edge, leaning sideways (parallelogram)
        com, polygon = standing_support(body, stood + angle * (rolls[0] - rolls[1] + rolls[2] - rolls[3]))
        return float(polygon[:, 1].max() - com[1])

    side = 1.0 if room(0.05) < room(0.0) else -1.0
    angle = side * brentq(lambda a: room(side * a) - 0.02, 0.0, 0.6)
    q0 = stood + angle * (rolls[0] - rolls[1] + rolls[2] - rolls[3])
    height = hip_height(body, q0)
    force = (0.0, (0.02 + 0.005) * body.total_mass * G / height)
    push = Scenario("push", lambda t: q0.copy(), 4.5, (Push(force, height, 1.0, 3.0, 1.0),))
    off, _ = balance(body, push, correct=False, foot_sensors=True)
    on, _ = balance(body, push, correct=True, foot_sensors=True)
    assert off.fallen is not None and on.fallen is None
    assert on.counters.worst_margin > 0


@pytest.mark.parametrize("tilt", [30, 45])
def test_a_hip_pitch_mounted_off_the_lateral_axis_bends_the_knees_by_the_legs_ik(tmp_path, tilt):
    # before: refused, "found no l_hip_pitch" (Unitree H2's and Fourier GR2's hip pitch turned 30° about the forward
    # axis, R1's 25°: every scenario of the three; AgiBot X1's 45°, until the hip pitch might be 46° off); the
    # corrector's pivot was the knee, the first joint within 8°
    spec = HumanoidSpec(hip="pry", hip_tilt=np.radians(tilt), seed=46)
    body = load_robot(str(build_humanoid(tmp_path / "t.urdf", spec)), None).body
    twin = load_robot(str(build_humanoid(tmp_path / "u.urdf", replace(spec, hip_tilt=0.0))), None).body
    assert joint_roles(body)["l_hip_pitch"] == "l_hip_pitch"
    assert {s: body.model.frames[f].name for s, f in body.correction.hips.items()} == {
        "left": "l_hip_pitch", "right": "r_hip_pitch"}
    tilted, untilted = (RootMover(b).feet_of(np.concatenate([np.zeros(len(b.base_channels)), Poser(b).standing()]))
                        for b in (body, twin))
    for side in ("left", "right"):  # each foot where the untilted twin's hip -θ, knee +2θ, ankle -θ puts it
        assert tilted[side][0].isApprox(untilted[side][0], 1e-8)
    scenario = make_scenario("lean", body, hold_s=1.0)
    off, _ = balance(body, scenario, correct=False)
    on, _ = balance(body, scenario, correct=True)
    assert off.fallen is not None and on.fallen is None


def test_a_hip_pitch_mounted_far_off_the_lateral_axis_is_refused_saying_how_far(tmp_path, capsys):
    # before: "found no l_hip_pitch" and what a leg needs, not which joint came near
    urdf = build_humanoid(tmp_path / "a.urdf", HumanoidSpec(hip_tilt=np.radians(50), seed=46))
    rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "lean", "--duration", "0.1"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and "found no l_hip_pitch" in err[0] and "l_hip_pitch 50°" in err[0], err


SAYS = {"one_leg": "two feet", "loop": "kinematic loop", "no_feet": "two feet", "no_axes": "found no l_hip_pitch",
        "floating": "type 'floating' not supported", "no_masses": "no <inertial>", "not_xml": "cannot read URDF",
        "missing_child": "no link 'ghost'"}


def test_a_urdf_that_is_no_humanoid_gets_one_line_and_exit_2(tmp_path, capsys):
    for path in malformed(tmp_path):
        for argv in (["demo", "--robot", path, "--link", "mock", "--scenario", "lean", "--duration", "0.1"],
                     ["sim", "--robot", path, "--link", "dynamixel", "--scenario", "lean"]):
            rc = main([str(a) for a in argv])
            err = capsys.readouterr().err.splitlines()
            assert rc == 2 and len(err) == 1, (path.stem, argv[0], err)
            assert path.name in err[0] or path.stem == "no_axes", err[0]
            assert re.search(SAYS[path.stem], err[0]), err[0]


def test_a_robot_without_arms_stands_but_is_told_it_cannot_swing_them(tmp_path, capsys):
    urdf = build_humanoid(tmp_path / "a.urdf", replace(HumanoidSpec(), arm=""))
    assert make_scenario("lean", load_robot(str(urdf), None).body).duration > 0
    rc = main(["demo", "--robot", str(urdf), "--link", "mock", "--scenario", "arm_swing", "--duration", "0.1"])
    err = capsys.readouterr().err.splitlines()
    assert rc == 2 and len(err) == 1 and "found no l_sho_pitch" in err[0] and "an arm on each side" in err[0]


def test_a_tall_light_robot_swinging_its_arms_is_held_by_a_gentler_trunk(tmp_path):
    # before: the trunk's 100 deg/s^2 swung this 1 m, 2 kg robot's ZMP past its toes by itself: corrected, it
    # fell at 0.27 s; the limit now scales as 0.3 m / CoM height (it stood too at (0.3 m / CoM height)^2)
    spec = HumanoidSpec(height=1.0, mass=2.0, foot="mesh", seed=25)  # a mesh foot: the default sole
    body = load_robot(str(build_humanoid(tmp_path / "t.urdf", spec)), None).body
    ground = (0.06 - 0.12 * (0.54 - 0.06)) * spec.height  # default soles: 0.12 hip heights below the ankle
    assert size_scaled_accel(body, 100.0) == pytest.approx(100.0 * 0.3 / (com_height(spec) - ground))
    scenario = make_scenario("arm_swing", body, duration=3.0)
    off, _ = balance(body, scenario, correct=False)
    on, _ = balance(body, scenario, correct=True)
    print(f"uncorrected fell at {off.fallen and off.fallen.t:.2f} s; corrected: fell {on.fallen}")
    assert off.fallen is not None and on.fallen is None


def test_a_taller_robot_leans_slower_so_the_lean_itself_does_not_shove_it(mini, tmp_path):
    # before: a 1.2 m robot leaned over the same 2 s as the mini: the lean's deceleration put its ZMP past the
    # toes before its CoM got there, and it fell at 2.3 s whether corrected or not
    assert make_scenario("lean", mini).duration == pytest.approx(8.0)  # 2 s ramps: unchanged
    spec = HumanoidSpec(height=1.2, mass=20.0, foot="mesh")  # the default sole, 0.5 hip heights long
    body = load_robot(str(build_humanoid(tmp_path / "k.urdf", spec)), None).body
    poser = Poser(body)
    q0 = poser.standing()
    dq = poser.ankles_lean(lean_angle(body, 0.004))
    ramp = lean_ramp(body, q0, dq)
    (c0, _), (c1, _) = standing_support(body, q0), standing_support(body, q0 + dq)
    # the half-cosine's peak acceleration D pi^2 / (2 T^2) times h / g is the lean's ZMP lead: LEAN_LEAD
    lead = (c1[0] - c0[0]) * np.pi ** 2 / (2 * ramp ** 2) * c0[2] / 9.81
    assert ramp > 4.0 and lead == pytest.approx(LEAN_LEAD, rel=0.01)


# the sweep's adult_1.8m_60kg on the default soles it had when these figures were measured (the sweep's now stands on
# its feet's collision boxes)
ADULT = HumanoidSpec(height=1.8, mass=60.0, waist="yp", foot="mesh", seed=24)


@pytest.mark.parametrize(("name", "until"), [("lean", 9.0), ("push", None)])
def test_a_tall_heavy_robot_turns_its_trunk_fast_enough_and_keeps_its_zmp_on_its_feet(tmp_path, name, until):
    # before: its trunk acceleration limit, 100 deg/s^2 x (0.3 m / 0.99 m)^2 = 9 deg/s^2, turned it 1.8 deg in the
    # 0.6 s its lean took to bring the ZMP from 15 mm inside its toes to them: it fell corrected at 6.67 s in the
    # lean, at 1.81 s in the push. Scaled as 0.3 m / h (dynamic similarity), 30 deg/s^2, it stands. Then, with the
    # corrector aiming 15 mm inside whatever the robot's size, its true ZMP still left its feet for moments
    # (-4.6 mm in the lean, -5.7 mm in the push); aimed 15 mm x h / 0.3 m = 49.5 mm inside, it stays on them
    body = load_robot(str(build_humanoid(tmp_path / "a.urdf", ADULT)), None).body
    assert size_scaled_accel(body, 100.0) == pytest.approx(30.3, abs=0.1)
    assert size_scaled_margin(body) == pytest.approx(0.0495, abs=0.0003)  # its CoM: 0.99 m above its soles
    scenario = make_scenario(name, body, hold_s=1.0) if name == "lean" else make_scenario(name, body)
    if until is not None:  # the lean's 6.7 s ramp and 1 s hold, where its ZMP left its feet; not the lean back
        scenario = replace(scenario, duration=until)
    sensors = name == "push"
    off, _ = balance(body, scenario, correct=False, foot_sensors=sensors)
    on, _ = balance(body, scenario, correct=True, foot_sensors=sensors)
    fixed, _ = balance(body, scenario, correct=True, foot_sensors=sensors, margin_m=MARGIN_M)
    print(f"{name}: uncorrected fell at {off.fallen and off.fallen.t:.2f} s; corrected: fell {on.fallen}, worst "
          f"true margin {1e3 * on.counters.worst_margin:.1f} mm; with a 15 mm margin: fell {fixed.fallen}, "
          f"{1e3 * fixed.counters.worst_margin:.1f} mm")
    assert off.fallen is not None and on.fallen is None
    assert on.counters.worst_margin > 0 and on.counters.unsupported_steps == 0
    assert fixed.counters.worst_margin < 0 and fixed.counters.unsupported_steps > 0


def test_a_tall_robot_nearer_its_toes_than_its_aim_turns_its_trunk_back_without_toppling_itself(tmp_path):
    # before: this 1.8 m robot, its upper body's mass high (as Atlas v5's), fell corrected in `push` at 0.29 s, before
    # it was pushed: standing 20 mm inside its toes, 35 mm short of its corrector's 54.8 mm aim, it had its trunk turned
    # back at the full acceleration limit, whose answer moved its ZMP 24.5 mm forward, past its toes for the 0.2 s the
    # trunk accelerated (Atlas: 24.8 mm, fell at 0.29 s); the acceleration is now cut to keep half its CoM's room
    spec = HumanoidSpec(height=1.8, mass=60.0, waist="yp", torso_com=0.95, seed=24)
    body = load_robot(str(build_humanoid(tmp_path / "a.urdf", spec)), None).body
    push = make_scenario("push", body)
    off, _ = balance(body, push, correct=False, foot_sensors=True)
    on, _ = balance(body, push, correct=True, foot_sensors=True)
    assert off.fallen is not None and on.fallen is None
    assert on.counters.worst_margin > 0


def test_a_slow_arm_swing_lasts_a_whole_period_at_full_swing(tmp_path):
    # before: 4 s whatever the swing: JAXON's 0.16 Hz swing grows over 6.3 s, its arms swung a quarter of the way
    # and it stood uncorrected; this robot's swing reached 87 % of its amplitude in 4 s
    body = load_robot(str(build_humanoid(tmp_path / "adult.urdf", ADULT)), None).body
    scenario, poser = make_scenario("arm_swing", body), Poser(body)
    name = poser.roles["l_sho_pitch"]
    i, along = poser.names.index(name), abs(float(poser.axis[name][1]))
    start = scenario.goals(0.0)[i]
    swing = [abs(scenario.goals(t)[i] - start) * along for t in np.arange(0.0, scenario.duration, 0.01)]
    full = [t for t, a in zip(np.arange(0.0, scenario.duration, 0.01), swing, strict=True) if a > 0.6 * 0.999]
    assert full and scenario.duration - full[0] >= 1.0  # full swing reached, and swung on at it


def test_the_margin_is_15_mm_for_robots_up_to_0_3_m_and_grows_with_the_com_height(mini, tmp_path):
    assert size_scaled_margin(mini) == MARGIN_M == 0.015  # the mini's CoM: 0.29 m above its soles
    spec = HumanoidSpec(height=1.2, mass=20.0, foot="mesh")  # a mesh foot: the default sole
    body = load_robot(str(build_humanoid(tmp_path / "k.urdf", spec)), None).body
    ground = (0.06 - 0.12 * (0.54 - 0.06)) * spec.height  # default soles: 0.12 hip heights below the ankle
    assert size_scaled_margin(body) == pytest.approx(MARGIN_M * (com_height(spec) - ground) / 0.3)


def test_a_small_light_robot_is_toppled_by_its_arm_swing(tmp_path):
    # before: light arms for its feet needed a 2.1 Hz swing to take its ZMP 4 mm past its toes from 8 mm inside
    # them; past them 0.15 s a swing (less with its shoulders clipped at the servos' speed), it never fell. It
    # now leans to 3.3 mm inside its toes and swings at 1.5 Hz, past them 0.25 s a swing
    body = load_robot(str(build_humanoid(tmp_path / "s.urdf", HumanoidSpec(height=0.3, mass=0.5, seed=22))),
                      None).body
    scenario = make_scenario("arm_swing", body, duration=3.0)
    _, poly = standing_support(body, scenario.goals(0.0))
    com, _ = standing_support(body, scenario.goals(0.0))
    assert poly[:, 0].max() - com[0] < 0.004  # it leans closer to its toes than the 8 mm asked
    off, _ = balance(body, scenario, correct=False)
    on, _ = balance(body, scenario, correct=True)
    print(f"uncorrected fell at {off.fallen and off.fallen.t:.2f} s; corrected: fell {on.fallen}")
    assert off.fallen is not None and on.fallen is None
