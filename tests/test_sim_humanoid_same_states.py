"""The simulated humanoid's CPU cuts compute the states the straightforward code computed, bit for bit.

The humanoid is stepped twice over the same scenario on simulated time, the second time with the
straightforward code patched in (the reference, kept here), and every step's state is compared: the
configuration and its derivatives, the true ZMP, CoM, contact force, support, polygon, clamped ZMP and margin,
and the servos' positions, velocities and currents. The push scenario, uncorrected, pushes the robot until
it falls: the steps cover double support, the push's wrench, the ZMP leaving the polygon and the fall."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from data_paths import OP3_URDF
from humanoid_gen import HumanoidSpec, build_humanoid

import sim_devices.humanoid as humanoid_module
from livezmp.balance.support import clamp_to_polygon
from livezmp.live import scenarios as sc
from livezmp.model import base_placement
from livezmp.model.body import foot_soles
from livezmp.model.robot import load_robot
from sim_devices.humanoid import SimHumanoid
from sim_devices.scenario_player import ScenarioPlayer


def continued_in_numpy(angles, previous):
    """The base's angles continued as before, with numpy's ufuncs."""
    angles, previous = np.asarray(angles), np.asarray(previous)
    return previous + (angles - previous + np.pi) % (2 * np.pi) - np.pi


def clamp_checked_every_step(p_xy, vertices):
    """The clamp as it was: to the kept polygon's array, its vertices checked again each step."""
    return clamp_to_polygon(p_xy, np.array(vertices, dtype=float).reshape(-1, 2))


def stepped_states(seconds: float) -> list[tuple]:
    body = load_robot(None, None).body
    scenario = sc.make_scenario("push", body)
    h = SimHumanoid(body, scenario.goals(0.0))
    for push in scenario.pushes:
        h.push(push)
    states = []
    check_fall = h._check_fall

    def recorded(s):
        states.append((s.t, s.q, s.v, s.a, s.zmp, s.com, s.force, s.push, s.stance, s.support, s.polygon,
                       s.clamped, s.margin, h.servo.position.copy(), h.servo.velocity.copy(),
                       h.servo.current.copy()))
        check_fall(s)

    h._check_fall = recorded
    ScenarioPlayer(h, scenario, rate_hz=125.0).run(seconds)
    assert h.fallen is not None  # the run reached the fall
    return states


def same(a, b) -> bool:
    if a is None or b is None or isinstance(a, str):
        return a == b
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def soles_every_frame_placed(body, data, place=False):
    """The soles as the step found them: every frame of the model placed, the feet's read back."""
    pin.updateFramePlacements(body.model, data)
    return foot_soles(body, data)


class EveryFramePlaced:
    """Pinocchio as the base placer used it: forward kinematics placing every frame, the feet's read back."""

    forwardKinematics = staticmethod(pin.framesForwardKinematics)

    @staticmethod
    def updateFramePlacement(model, data, frame):
        return data.oMf[frame]

    def __getattr__(self, name):
        return getattr(pin, name)


def test_humanoid_states_bit_for_bit_as_before(monkeypatch):
    after = stepped_states(2.5)
    with monkeypatch.context() as m:
        m.setattr(humanoid_module, "clamp_to_vertices", clamp_checked_every_step)
        m.setattr(humanoid_module, "_continued", continued_in_numpy)
        m.setattr(humanoid_module, "foot_soles", soles_every_frame_placed)
        m.setattr(base_placement, "pin", EveryFramePlaced())
        before = stepped_states(2.5)
    assert len(after) == len(before) > 1000
    assert any(s[12] is not None and s[12] < 0 for s in after)  # the ZMP left the polygon
    for a, b in zip(after, before, strict=True):
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            assert same(x, y), f"t = {a[0]:.3f} s: state {k} differs: {x!r} != {y!r}"


def test_continued_angles_as_numpy_made_them():
    # the stance switch's re-placed base takes this path too, which the run above does not reach
    rng = np.random.default_rng(3)
    for _ in range(2000):
        scale = 10.0 ** rng.integers(-3, 2)
        angles, previous = rng.normal(size=3) * scale, rng.normal(size=3) * scale
        continued = humanoid_module._continued(angles.tolist(), previous.tolist())
        assert same(continued, continued_in_numpy(angles, previous))


@pytest.mark.parametrize("robot", ["livezmp_mini", "op3", "generated", "generated_cylinders"])
def test_feet_placed_alone_as_every_frame_placed(robot, tmp_path):
    # the feet's frames alone placed from the joints' placements: the soles and the base placement as before, on
    # random postures (the generated robots' link frames turned at random; cylinder feet: a sole from collisions)
    if robot == "op3":
        urdf = str(OP3_URDF)
    elif robot.startswith("generated"):
        spec = HumanoidSpec(frames="random", seed=31, foot="cylinders" if robot.endswith("cylinders") else "box")
        urdf = str(build_humanoid(tmp_path / f"{robot}.urdf", spec))
    else:
        urdf = None
    body = load_robot(urdf, None).body
    rng = np.random.default_rng(5)
    model = body.model
    placer, reference = base_placement.BasePlacer(body), base_placement.BasePlacer(body)
    data, every = model.createData(), model.createData()
    for _ in range(300):
        q = np.zeros(model.nq)
        q[6:] = rng.uniform(-0.4, 0.4, model.nq - 6)
        pin.forwardKinematics(model, data, q)
        pin.framesForwardKinematics(model, every, q)
        placed, all_placed = foot_soles(body, data, place=True), foot_soles(body, every)
        assert all(same(placed[s], all_placed[s]) for s in body.feet)
        base = placer.update(q[6:])
        with pytest.MonkeyPatch.context() as m:
            m.setattr(base_placement, "pin", EveryFramePlaced())
            assert same(base, reference.update(q[6:]))
