"""Balance correction: the root mover, the offline sequence solver and the online corrector."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
from data_paths import BANDAI, OP3_URDF
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from test_body import make_bvh

from livezmp.balance.pipeline import FrameResult, Pipeline, default_config
from livezmp.cli import main
from livezmp.correct.limits import CORRECTION_CUTOFF_HZ, CorrectionLimits, rate_limit
from livezmp.correct.online import OnlineCorrector, hips_height
from livezmp.correct.root_motion import RootMover, euler_from_matrix, hip_axes
from livezmp.correct.solver import correct_bvh
from livezmp.model.base_placement import BasePlacer
from livezmp.model.bvh import parse_bvh, read_bvh
from livezmp.model.demo_robot import smooth_ramp

# rotations about world +y; the OP3's pitch axes are ±y per side (URDF), hence the signs
OP3_FLEX = (("l_hip_pitch", -1, 1), ("l_knee", 2, 1), ("l_ank_pitch", -1, -1),
            ("r_hip_pitch", -1, -1), ("r_knee", 2, -1), ("r_ank_pitch", -1, 1))


def op3_pose(body, bend: float = 0.35, lean: float = 0.0) -> np.ndarray:
    """Joint angles (rad) of the OP3 standing with bent knees, leaning forward at the ankles."""
    names = body.joint_names
    q = np.zeros(len(names))
    for joint, world, axis_y in OP3_FLEX:
        q[names.index(joint)] = world * axis_y * bend
    q[names.index("l_ank_pitch")] += lean
    q[names.index("r_ank_pitch")] -= lean
    return q


def full_q(body, joints: np.ndarray) -> np.ndarray:
    return np.concatenate([BasePlacer(body).update(joints), joints])


@pytest.mark.parametrize("w_left", [0.0, 0.5, 1.0])
def test_root_mover_keeps_robot_feet_exactly(op3_body, w_left):
    mover = RootMover(op3_body)
    q = full_q(op3_body, op3_pose(op3_body))
    data = op3_body.model.createData()
    pin.framesForwardKinematics(op3_body.model, data, q)
    feet = {s: data.oMf[f[0]].copy() for s, f in op3_body.correction.foot_frames.items()}
    root = data.oMf[op3_body.correction.root_frame_id].copy()
    hips = {s: data.oMf[f].translation.copy() for s, f in op3_body.correction.hips.items()}
    axes = hip_axes(hips["left"], hips["right"])
    rng = np.random.default_rng(1)
    for _ in range(5):
        delta = np.radians(rng.uniform(-8, 8, 3))
        q2 = mover.apply(q, delta, w_left)
        pin.framesForwardKinematics(op3_body.model, data, q2)
        for s, m in feet.items():
            err = pin.log6(data.oMf[op3_body.correction.foot_frames[s][0]].actInv(m)).vector
            assert np.abs(err).max() < 1e-6  # below a micrometre
        new_root = data.oMf[op3_body.correction.root_frame_id]
        np.testing.assert_allclose(new_root.rotation, pin.exp3(axes @ delta) @ root.rotation, atol=1e-10)
        # only the base and leg channels move
        legs = {c for cols in op3_body.correction.legs.values() for c in cols} | set(range(6))
        untouched = [i for i in range(op3_body.nq) if i not in legs]
        np.testing.assert_array_equal(q2[untouched], q[untouched])


@pytest.mark.parametrize("robot", ["op3", "mini"])
def test_the_trunk_pitched_about_the_hips_moves_no_leg_joint_below_them(op3_body, robot):
    """The root turns about the line through the hip pitch joints: a pitch of the trunk is a turn of the hip pitch
    joints alone. (About the first leg joints', the hip yaws 3 cm above them, 0.1 rad of pitch turned the mini's
    and the OP3's hip pitch 0.117 rad, their knees 0.005 and ankles 0.011; Wolfgang-OP's yaws, 4 cm above its hip
    pitch and 2 cm behind, turned its knees 0.24 rad for 0.2, where its legs' IK lost the feet by 17 mm and its
    corrected lean fell.)"""
    from livezmp.live.scenarios import Poser, joint_roles
    from livezmp.model.robot import load_robot
    body = op3_body if robot == "op3" else load_robot(None, None).body
    q = full_q(body, Poser(body).standing())
    moved = RootMover(body).apply(q, np.array([0.0, -0.1, 0.0]), 0.5) - q
    roles = joint_roles(body)
    index = {role: body.model.joints[body.model.getJointId(name)].idx_q for role, name in roles.items()}
    for side in "lr":
        assert abs(moved[index[f"{side}_hip_pitch"]]) == pytest.approx(0.1, abs=1e-6)
        others = [index[f"{side}_{role}"] for role in ("knee", "ank_pitch", "ank_roll", "hip_roll")]
        assert np.abs(moved[others]).max() < 1e-6


def test_root_mover_skeleton_keeps_stance_foot(bandai_walk):
    from livezmp.model.bvh_body import body_from_bvh

    body = body_from_bvh(bandai_walk)
    mover = RootMover(body)
    q = body.channels_to_q(bandai_walk.frames[40])
    data = body.model.createData()
    pin.framesForwardKinematics(body.model, data, q)
    before = {f: data.oMf[f].translation.copy() for fs in body.correction.foot_frames.values() for f in fs}
    for delta in (np.radians([3.0, 0, 0]), np.radians([0, 4.0, 0]), np.radians([1.5, -2.0, 2.0])):
        q2 = mover.apply(q, delta, 1.0)  # left stance: pivot at the left hip
        pin.framesForwardKinematics(body.model, data, q2)
        for f in body.correction.foot_frames["left"]:
            assert np.linalg.norm(data.oMf[f].translation - before[f]) < 2e-5
        changed = np.nonzero(np.abs(q2 - q) > 1e-12)[0]
        allowed = set(body.correction.root_channels) | {c for cs in body.correction.legs.values() for c in cs}
        assert set(changed) <= allowed


def test_rate_limit_projection():
    d = np.zeros((6, 3))
    d[3, 0] = 1.0
    out, changed = rate_limit(d, 0.25)
    assert np.abs(np.diff(out, axis=0)).max() <= 0.25 + 1e-12
    assert changed and np.abs(out).max() <= 1.0


def test_rate_limit_of_a_loop_wraps_from_its_last_frame_to_its_first():
    d = np.zeros((6, 3))
    d[:, 1] = [0.0, 0.25, 0.5, 0.75, 1.0, 1.0]  # within the rate frame to frame, but 1 rad from the last to the first
    assert np.array_equal(rate_limit(d, 0.25)[0], d)  # as a take: nothing to limit
    out, changed = rate_limit(d, 0.25, periodic=True)
    assert changed and np.abs(np.diff(np.vstack([out, out[:1]]), axis=0)).max() <= 0.25 + 1e-12


def test_correct_cli_on_a_bandai_walk(tmp_path):
    """walk_normal_002: the corrected BVH, re-analysed by `livezmp analyze`, is ≥ 99 % inside;
    the feet stay put; only root and thigh channels change; hierarchy and timing are kept."""
    src = BANDAI / "walk_normal_002.bvh"
    out, rep, summ = tmp_path / "c.bvh", tmp_path / "r.json", tmp_path / "s.json"
    assert main(["correct", str(src), "-o", str(out), "--report", str(rep)]) == 0
    report = json.loads(rep.read_text())
    for key in ("frames", "out_of_support_before", "out_of_support_after", "infeasible_frames",
                "max_root_rotation_deg", "rms_root_rotation_deg", "max_foot_displacement_mm", "solver_ms_per_frame"):
        assert key in report
    assert report["out_of_support_before"] > 50
    # judged with the correction's own estimator settings, which the report gives (README: correct)
    assert report["estimator"]["cutoff_hz"] == CORRECTION_CUTOFF_HZ
    assert main(["analyze", str(out), "--cutoff-hz", str(report["estimator"]["cutoff_hz"]),
                 "--summary-json", str(summ)]) == 0
    after = json.loads(summ.read_text())
    assert after["inside_fraction"] >= 0.99 and after["estimator"] == report["estimator"]
    assert after["out_of_support_frames"] == report["out_of_support_after"]
    a, b = read_bvh(src), read_bvh(out)
    assert [j.name for j in a.joints] == [j.name for j in b.joints]
    assert b.frames.shape == a.frames.shape and b.frame_time == pytest.approx(a.frame_time)
    labels = a.channel_labels()
    moved = {labels[c] for c in np.nonzero(np.abs(b.frames - a.frames).max(axis=0) > 1e-5)[0]}
    assert moved and all(m.split(".")[0] in ("Hips", "UpperLeg_L", "UpperLeg_R") for m in moved), moved
    # feet: ankle and toe joints of a foot bearing weight move ≤ 1 mm
    assert report["max_foot_displacement_mm"] <= 1.0
    limits = CorrectionLimits()
    assert report["max_root_rotation_deg"] <= max(limits.max_rotation_deg) + 1e-6
    assert report["max_root_rate_deg_s"] <= limits.max_rate_deg_s + 1e-3


def _closed_loop_lean(body, correct: bool, seconds: float = 6.0, rate: float = 100.0):
    """The OP3 leans forward at the ankles until its CoM is ~2 mm past the toes, holds,
    and comes back. The corrector's offsets are added to the command; the robot executes
    the command exactly and its base rests on the stance foot. Returns per-frame
    (time, inside, delta) of the analysed (lagged) frames and the sent offsets."""
    dt = 1.0 / rate
    pipe = Pipeline(body, default_config(body, rate), dt)
    corrector = OnlineCorrector(body, dt)
    cmd_base, robot_base = BasePlacer(body), BasePlacer(body)
    out, last = [], None
    for k in range(int(seconds * rate)):
        t = k * dt
        lean = 0.32 * (smooth_ramp(t, 0.5, 2.0) - smooth_ramp(t, 4.5, 5.5))
        joints = op3_pose(body, lean=lean)
        q_cmd = np.concatenate([cmd_base.update(joints), joints])
        sent = q_cmd
        delta = np.zeros(3)
        if correct and last is not None:
            c = corrector.step(last, q_cmd)
            sent = q_cmd + c.offsets
            delta = c.delta
        sensed = sent[6:]
        r = pipe.step(t, np.concatenate([robot_base.update(sensed), sensed]))
        if r is not None:
            last = r
            out.append((r.t, r.inside, delta))
    return out


def _upper_com_shift(body, q: np.ndarray, pivot: np.ndarray, rotation: np.ndarray, legs: list[int]) -> np.ndarray:
    """Whole-body CoM shift (m, world) when every body outside the leg subtrees ``legs`` turns by
    ``rotation`` about ``pivot``: summed body by body, without Pinocchio's subtree quantities."""
    model, data = body.model, body.model.createData()
    pin.forwardKinematics(model, data, q)
    shift, mass = np.zeros(3), 0.0
    for i in range(1, model.njoints):
        inertia = model.inertias[i]
        mass += inertia.mass
        if any(j in legs for j in model.supports[i]):
            continue
        p = data.oMi[i].act(inertia.lever) - pivot
        shift += inertia.mass * (rotation @ p - p)
    return shift / mass


@pytest.mark.parametrize("robot", ["op3", "mini"])
def test_online_sensitivity_is_the_com_shift_of_the_turned_upper_body(op3_body, robot):
    """S δ, the corrector's quasi-static ZMP shift for a small δ, equals the CoM shift of the upper body turned
    by H δ about the hip pivot, summed body by body (with the legs' subtree CoMs taken mass-weighted twice, as
    they once were, S was off by 20-30 %)."""
    from livezmp.model.robot import load_robot
    body = op3_body if robot == "op3" else load_robot(None, None).body
    joints = np.random.default_rng(3).uniform(-0.3, 0.3, len(body.joint_names))
    q = full_q(body, joints)
    corrector = OnlineCorrector(body, 0.01)
    corrector.w_left = 0.7
    pin.framesForwardKinematics(body.model, corrector.data, q)
    s = corrector.sensitivity(q)
    h_left = corrector.data.oMf[body.correction.hips["left"]].translation.copy()
    h_right = corrector.data.oMf[body.correction.hips["right"]].translation.copy()
    axes = hip_axes(h_left, h_right)
    for delta in np.eye(3) * 1e-6:
        rotation = Rotation.from_rotvec(axes @ delta).as_matrix()
        truth = _upper_com_shift(body, q, 0.7 * h_left + 0.3 * h_right, rotation, corrector.leg_roots)[:2]
        assert s @ delta == pytest.approx(truth, abs=1e-11)


def test_online_corrector_saves_a_lean_that_fails_without_it(op3_body):
    off = _closed_loop_lean(op3_body, correct=False)
    on = _closed_loop_lean(op3_body, correct=True)
    lean_window = [k for k, (t, _, _) in enumerate(off) if 2.5 <= t <= 4.5]
    outside_off = sum(1 for k in lean_window if off[k][1] is False)
    outside_on = sum(1 for k in lean_window if on[k][1] is False)
    print(f"lean held 2.5-4.5 s: outside {outside_off}/{len(lean_window)} frames without correction, "
          f"{outside_on} with")
    assert outside_off == len(lean_window)  # without correction the ZMP stays out the whole hold
    assert outside_on == 0
    first_out = next(k for k, (_, inside, _) in enumerate(on) if inside is False)
    back_in = next(k for k in range(first_out, len(on)) if on[k][1])
    assert back_in - first_out <= 40, "inside again within 0.4 s of first leaving"
    deltas = np.array([d for _, _, d in on])
    limits = CorrectionLimits()
    assert np.abs(np.diff(deltas, axis=0)).max() <= np.radians(limits.max_rate_deg_s) / 100 + 1e-12
    assert np.abs(deltas).max(axis=0).max() <= np.radians(max(limits.max_rotation_deg)) + 1e-12


def _fake_result(body, q, zmp_xy, support: str, poly: np.ndarray, margin: float) -> FrameResult:
    z = np.array([*zmp_xy, 0.0])
    inside = margin >= 0
    return FrameResult(0, 0.0, q, np.zeros_like(q), np.zeros_like(q), z, z + [0, 0, 0.2], support, poly,
                       {}, 0.0, inside, z if inside else np.array([*np.clip(zmp_xy, -0.05, 0.05), 0.0]), margin)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.sampled_from(["left", "right", "double"])),
                min_size=1, max_size=60),
       st.floats(1.0, 20.0), st.floats(5.0, 200.0))
def test_online_corrections_never_exceed_limits(op3_body, frames, max_rot, max_rate):
    """Whatever ZMP sequence comes in, δ stays within the rotation limit and steps within the rate limit."""
    limits = CorrectionLimits(max_rotation_deg=(max_rot, max_rot, max_rot), max_rate_deg_s=max_rate)
    dt = 0.01
    corrector = OnlineCorrector(op3_body, dt, limits)
    q = full_q(op3_body, op3_pose(op3_body))
    poly = np.array([[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05]])
    prev = np.zeros(3)
    for x, y, support in frames:
        inside = abs(x) <= 0.05 and abs(y) <= 0.05
        margin = min(0.05 - abs(x), 0.05 - abs(y)) if inside else -max(abs(x) - 0.05, abs(y) - 0.05)
        c = corrector.step(_fake_result(op3_body, q, (x, y), support, poly, margin), q)
        assert np.all(np.abs(c.delta) <= np.radians(max_rot) + 1e-12)
        assert np.all(np.abs(c.delta - prev) <= np.radians(max_rate) * dt + 1e-12)
        assert np.all(np.isfinite(c.offsets))
        prev = c.delta


def test_correct_cli_on_a_robot_csv(tmp_path, op3_body):
    """A joint-trajectory CSV of the OP3 leaning past its toes, corrected offline: the
    corrected CSV re-analysed is inside; only leg joints change; feet stay put."""
    names = op3_body.joint_names
    rate = 100.0
    t = np.arange(int(4 * rate)) / rate
    lean = 0.32 * (smooth_ramp(t, 0.3, 1.5) - smooth_ramp(t, 2.8, 3.8))
    q = np.array([op3_pose(op3_body, lean=x) for x in lean])
    src, out, rep, summ = (tmp_path / n for n in ("lean.csv", "fixed.csv", "r.json", "s.json"))
    np.savetxt(src, np.column_stack([t, q]), delimiter=",", header=",".join(["time", *names]), comments="")
    assert main(["analyze", str(src), "--robot", str(OP3_URDF), "--summary-json", str(summ)]) == 0
    assert json.loads(summ.read_text())["out_of_support_frames"] > 50
    # --cutoff-hz overrides the correction's own estimator cutoff too; the report says which was used
    assert main(["correct", str(src), "--robot", str(OP3_URDF), "--cutoff-hz", "5", "-o", str(out),
                 "--report", str(rep)]) == 0
    assert json.loads(rep.read_text())["estimator"]["cutoff_hz"] == 5.0
    assert main(["analyze", str(out), "--robot", str(OP3_URDF), "--cutoff-hz", "5", "--summary-json", str(summ)]) == 0
    after = json.loads(summ.read_text())
    assert after["inside_fraction"] >= 0.99
    fixed = np.loadtxt(out, delimiter=",", skiprows=1)
    assert fixed.shape == (len(t), 1 + len(names))
    moved = {names[c] for c in np.nonzero(np.abs(fixed[:, 1:] - q).max(axis=0) > 1e-9)[0]}
    legs = {names[c - 6] for cols in op3_body.correction.legs.values() for c in cols}
    assert moved and moved <= legs
    report = json.loads(rep.read_text())
    assert report["max_foot_displacement_mm"] < 0.01  # six-joint legs: the feet are exact


@pytest.mark.parametrize("seq", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_euler_from_matrix_matches_scipy(seq):
    rng = np.random.default_rng(7)
    rotations = Rotation.random(300, random_state=rng)
    for r in [*rotations, Rotation.from_euler(seq, [1.0, -np.pi / 2 + 1e-3, 0.5])]:
        angles = euler_from_matrix(r.as_matrix(), seq)
        np.testing.assert_allclose(Rotation.from_euler(seq, angles).as_matrix(), r.as_matrix(), atol=1e-12)
        np.testing.assert_allclose(angles, r.as_euler(seq), atol=1e-9)
    # within 1e-6 of gimbal lock the angles are scipy's (which only keeps the rotation to ~1e-8)
    locked = Rotation.from_euler(seq, [0.3, np.pi / 2 - 1e-8, -0.2])
    with pytest.warns(UserWarning, match="Gimbal"):
        angles = euler_from_matrix(locked.as_matrix(), seq)
    np.testing.assert_allclose(Rotation.from_euler(seq, angles).as_matrix(), locked.as_matrix(), atol=1e-7)


def test_root_mover_warm_start_gives_the_same_legs(op3_body):
    # the live corrector starts the leg IK from its last solution: same answer, fewer iterations
    mover = RootMover(op3_body)
    q = full_q(op3_body, op3_pose(op3_body))
    cold = mover.apply(q, np.radians([2.0, -3.0, 0.5]), 0.5)
    mover.ik_iterations = 2  # from the previous solution for a nearby δ, two iterations suffice
    nearby = mover.apply(q, np.radians([2.1, -3.1, 0.5]), 0.5, leg_start=cold - q)
    assert mover.last_foot_error < 1e-9
    mover.ik_iterations = 10
    reference = mover.apply(q, np.radians([2.1, -3.1, 0.5]), 0.5)
    np.testing.assert_allclose(nearby, reference, atol=1e-6)
    # and without the warm start two iterations leave hundreds of times more: 7e-8 m (warm 2e-10; 3e-7 and 3e-10
    mover.ik_iterations = 2  # when the root turned about the hip yaws, not the hip pitch joints)
    mover.apply(q, np.radians([2.1, -3.1, 0.5]), 0.5)
    assert mover.last_foot_error > 1e-8


def test_root_mover_batch_matches_one_at_a_time(op3_body):
    # the offline solver moves many configurations at once (the steps of every configuration's legs stacked): each
    # must come out as alone, bit for bit, whatever the others need: δ = 0 is done before the first step, larger δ
    # take more iterations
    mover = RootMover(op3_body)
    rng = np.random.default_rng(3)
    q = np.array([full_q(op3_body, op3_pose(op3_body) + rng.normal(0, 0.05, op3_body.model.nq - 6)) for _ in range(6)])
    delta = np.radians(rng.uniform(-8, 8, (6, 3)) * np.array([[0], [1], [0.1], [1], [0.5], [1]]))
    w = np.array([0.0, 0.5, 1.0, 0.3, 1.0, 0.0])
    batch = mover.apply_many(q, delta, w)
    errors = []
    for n in range(6):
        assert np.array_equal(batch[n], mover.apply(q[n], delta[n], w[n]))
        errors.append(mover.last_foot_error)
    np.testing.assert_allclose(batch[0], q[0], atol=1e-12)  # δ = 0: nothing moves (the root channels round-trip)
    mover.apply_many(q, delta, w)
    assert mover.last_foot_error == max(errors) < 1e-7


def test_the_search_stops_on_a_take_it_cannot_correct():
    """A trunk swinging ±50° about the hips carries the ZMP out of the feet at 56 of 60 frames, beyond what 2° of
    root rotation can bring back: after ``patience`` iterations without fewer frames outside the search stops (it
    went on to 13 iterations, the contact re-detection phase and the easing, at 59 outside all along)."""
    motion = parse_bvh(make_bvh(frames=60), "swing.bvh")
    motion.frame_time = 1 / 30
    spine = next(j for j in motion.joints if j.name == "Spine")
    motion.frames[:, spine.first_channel + 1] = 50.0 * np.sin(2 * np.pi * np.arange(60) / 30)
    limits = CorrectionLimits(max_rotation_deg=(2.0, 2.0, 2.0))
    _, result = correct_bvh(motion, limits=limits)
    assert result.history == [59] * (limits.patience + 1)
    assert result.report()["out_of_support_after"] == 59


def test_a_take_with_nothing_to_move_skips_the_estimators_linear_maps(monkeypatch):
    """The solver built the estimator's linear maps (a Python pass over every frame per edge impulse) before
    asking whether any frame needed moving: a 5-frame looped cycle at 10 kHz, analysed with 1 s of its loop a
    side, took over 60 s to report 0 → 0 frames outside (the same take not looped, 4.5 s)."""
    motion = parse_bvh(make_bvh(frames=30), "still.bvh")
    motion.frames[:] = motion.frames[0]

    def refused(*args, **kwargs):
        raise AssertionError("the estimator's linear maps built with nothing to move")

    monkeypatch.setattr("livezmp.correct.solver.estimator_matrices", refused)
    _, result = correct_bvh(motion)
    assert result.history == [] and result.report()["out_of_support_after"] == 0


def test_the_pivot_sliding_to_one_hip_moves_a_turned_root_no_faster_than_the_pelvis_may(op3_body):
    """The root turned by δ about the pivot stands elsewhere when the pivot moves: (I − R(δ)) (h_left − h_right)
    per unit of the pivot's weight. AgiBot X1 on its foot meshes, its trunk turned 0.25 rad back and 0.11 rad
    rolled, was read as on one foot: the pivot slid to that hip within 50 ms (a first-order step from rest), its
    root dropped 9 mm, and its true ZMP left its feet by 562 mm for 31 ms. The root's move now keeps within the
    pelvis' acceleration (the trunk's × the hips' height), and the pivot still reaches the stance hip."""
    dt = 0.008
    corrector = OnlineCorrector(op3_body, dt)
    q = full_q(op3_body, op3_pose(op3_body))
    poly = np.array([[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05]])
    corrector.prepare(q)
    corrector.u[:3] = [0.11, 0.25, 0.0]  # held there: the ZMP comfortably inside, nothing to correct
    weights = []
    for k in range(150):
        corrector.update(_fake_result(op3_body, q, (0.0, 0.0), "double" if k < 5 else "right", poly, 0.05))
        weights.append(corrector.w_left)
    roots = np.array([corrector.mover.apply(q, corrector.delta, w)[:3] for w in weights])
    accel = np.linalg.norm(np.diff(roots, 2, axis=0), axis=1).max()  # m per frame^2
    allowed = hips_height(op3_body, q) * corrector.max_accel_step[1]
    print(f"root's largest acceleration {accel / dt**2:.2f} m/s^2, allowed {allowed / dt**2:.2f}")
    assert accel <= allowed * 1.05  # the lever is taken in the frame's posture, the root's move in the turned one
    assert weights[-1] < 0.05  # on the right hip within 1.2 s
