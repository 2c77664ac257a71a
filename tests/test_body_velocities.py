"""Sole corner velocities against independent references: finite differences of the corners of a
robot foot, and the rigid-body formula v_o + ω × (p − o) at the frame origin for a skeleton foot."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from livezmp.model.body import foot_soles, lowest_sole_points, sole_velocities
from livezmp.model.bvh_body import body_from_bvh


def kinematics(body, q, v):
    data = body.model.createData()
    pin.forwardKinematics(body.model, data, q, v)
    pin.updateFramePlacements(body.model, data)
    return data


def test_robot_corner_velocities_are_the_time_derivative_of_the_corners(op3_body):
    rng = np.random.default_rng(0)
    h = 1e-6
    for _ in range(20):
        q, v = rng.normal(size=op3_body.nq) * 0.5, rng.normal(size=op3_body.nq)
        data = kinematics(op3_body, q, v)
        vel = sole_velocities(op3_body, op3_body.model, data, foot_soles(op3_body, data))
        ahead = foot_soles(op3_body, kinematics(op3_body, q + h * v, v))
        behind = foot_soles(op3_body, kinematics(op3_body, q - h * v, v))
        for side in vel:
            np.testing.assert_allclose(vel[side], (ahead[side] - behind[side]) / (2 * h), atol=1e-6)


def test_skeleton_heel_corners_move_with_the_ankle_and_toe_corners_with_the_toe(bandai_walk):
    body = body_from_bvh(bandai_walk)
    rng = np.random.default_rng(1)
    for _ in range(20):
        q, v = rng.normal(size=body.nq) * 0.3, rng.normal(size=body.nq)
        data = kinematics(body, q, v)
        soles = foot_soles(body, data)
        vel = sole_velocities(body, body.model, data, soles)
        for side, foot in body.feet.items():
            for rows, frame in (([0, 3], foot.frame_id), ([1, 2], foot.toe_frame_id)):
                m = pin.getFrameVelocity(body.model, data, frame, pin.LOCAL_WORLD_ALIGNED)
                expected = m.linear + np.cross(m.angular, soles[side][rows] - data.oMf[frame].translation)
                np.testing.assert_allclose(vel[side][rows], expected, rtol=1e-12, atol=1e-12)


def test_lowest_sole_points_are_the_lowest_rows_of_the_soles_and_their_velocities(op3_body, bandai_walk):
    rng = np.random.default_rng(2)
    for body in (op3_body, body_from_bvh(bandai_walk)):
        for _ in range(30):
            q, v = rng.normal(size=body.nq) * 0.4, rng.normal(size=body.nq)
            data = kinematics(body, q, v)
            soles = foot_soles(body, data)
            vel = sole_velocities(body, body.model, data, soles)
            low = lowest_sole_points(body, body.model, data, soles)
            for side in soles:
                i = int(np.argmin(soles[side][:, 2]))
                assert low[side] == (soles[side][i, 2], math.hypot(vel[side][i, 0], vel[side][i, 1]))
