"""Batch kinematics and centroidal dynamics against Pinocchio, frame by frame, on random states."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from livezmp.model.body import foot_soles, point_mass_copy, sole_velocities
from livezmp.model.bvh_body import body_from_bvh
from livezmp.offline.kinematics import (
    BatchKinematics,
    UnsupportedModel,
    batch_sole_velocities,
    batch_soles,
    body_frame_ids,
)

FRAMES = 12


def random_states(model: pin.Model, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(nq, FRAMES) channel-major positions, velocities, accelerations."""
    return (rng.uniform(-2, 2, (model.nq, FRAMES)), rng.normal(size=(model.nv, FRAMES)),
            rng.normal(size=(model.nv, FRAMES)))


def close(got: np.ndarray, want: np.ndarray, what: str) -> None:
    """Equal to rounding: 1e-10 relative to the quantity's size."""
    scale = max(1.0, float(np.max(np.abs(want))))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-10 * scale, err_msg=what)


def check_dynamics(model: pin.Model, frame_ids: list[int], rng: np.random.Generator) -> None:
    kin = BatchKinematics(model, frame_ids)
    q, v, a = random_states(model, rng)
    dyn = kin.dynamics(q, v, a)
    origin_velocity = {f: dyn.frames[f].point_velocity(dyn.frames[f].position[:, None])[:, 0] for f in frame_ids}
    data = model.createData()
    for c in range(FRAMES):
        pin.computeCentroidalMomentumTimeVariation(model, data, q[:, c], v[:, c], a[:, c])
        pin.updateFramePlacements(model, data)
        close(dyn.com[c], data.com[0], "com")
        close(dyn.momentum_rate[c], data.dhg.linear, "dhg linear")
        close(dyn.moment[c], data.dhg.angular, "dhg angular")
        for f in frame_ids:
            fm = dyn.frames[f]
            close(fm.position[c], data.oMf[f].translation, "frame position")
            close(fm.rotation[c], data.oMf[f].rotation, "frame rotation")
            twist = pin.getFrameVelocity(model, data, f, pin.LOCAL_WORLD_ALIGNED)
            close(fm.omega[c], twist.angular, "frame angular velocity")
            close(origin_velocity[f][c], twist.linear, "frame origin velocity")
    assert kin.mass == pytest.approx(data.mass[0], rel=1e-14)


@pytest.mark.parametrize("which", ["model", "point_model"])
def test_skeleton_matches_pinocchio(bandai_walk, which):
    body = body_from_bvh(bandai_walk)
    check_dynamics(getattr(body, which), body_frame_ids(body), np.random.default_rng(1))


@pytest.mark.parametrize("which", ["model", "point_model"])
def test_robot_matches_pinocchio(op3_body, which):
    check_dynamics(getattr(op3_body, which), body_frame_ids(op3_body), np.random.default_rng(2))


def test_any_axis_and_placement_match_pinocchio():
    """Revolute and prismatic joints along x/y/z and along unaligned axes, rotated and offset placements,
    a branching tree, bodies with full inertia: what URDF robots can contain."""
    rng = np.random.default_rng(3)
    model = pin.Model()

    def place() -> pin.SE3:
        return pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-1, 1, 3)), rng.uniform(-0.3, 0.3, 3))

    def axis() -> np.ndarray:
        u = rng.normal(size=3)
        return u / np.linalg.norm(u)

    kinds = [pin.JointModelPX(), pin.JointModelRevoluteUnaligned(axis()), pin.JointModelRY(),
             pin.JointModelPrismaticUnaligned(axis()), pin.JointModelRZ(), pin.JointModelRevoluteUnaligned(0, 0, -1),
             pin.JointModelPZ(), pin.JointModelRX()]
    parents = [0, 1, 2, 2, 4, 3, 6, 5]  # two branches from joint 2
    frames = []
    for i, (jm, parent) in enumerate(zip(kinds, parents, strict=True)):
        j = model.addJoint(parent, jm, place(), f"j{i}")
        inertia = pin.Inertia.Random()
        model.appendBodyToJoint(j, inertia, pin.SE3.Identity())
        frames.append(model.addFrame(pin.Frame(f"f{i}", j, place(), pin.FrameType.OP_FRAME)))
    check_dynamics(model, frames, rng)
    check_dynamics(point_mass_copy(model), frames, rng)


def test_soles_and_their_velocities_match_the_per_frame_code(bandai_walk, op3_body):
    rng = np.random.default_rng(4)
    for body in (body_from_bvh(bandai_walk), op3_body):
        model, data = body.model, body.model.createData()
        q, v, a = random_states(model, rng)
        q[:3] *= 0.1  # keep skeleton positions (m) plausible
        dyn = BatchKinematics(model, body_frame_ids(body)).dynamics(q, v, a)
        soles = batch_soles(body, dyn.frames)
        vel = batch_sole_velocities(body, dyn.frames, soles)
        for c in range(FRAMES):
            pin.forwardKinematics(model, data, q[:, c], v[:, c])
            pin.updateFramePlacements(model, data)
            want = foot_soles(body, data)
            want_v = sole_velocities(body, model, data, want)
            for side in want:
                close(soles[side][c], want[side], f"{body.kind} {side} sole")
                close(vel[side][c], want_v[side], f"{body.kind} {side} sole velocity")


def test_a_joint_outside_the_chain_kinds_is_refused():
    model = pin.Model()
    j = model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    model.appendBodyToJoint(j, pin.Inertia.Random(), pin.SE3.Identity())
    with pytest.raises(UnsupportedModel, match="JointModelFreeFlyer"):
        BatchKinematics(model, [])
