"""Scenarios for any humanoid: limbs found from the kinematic tree, disturbances sized by the robot's
own masses and inertias. Truth: the joint names the generated robots were given, the closed form of a
push's ZMP shift, and the simulated humanoid's exact whole-body dynamics (simulated time)."""

from __future__ import annotations

import numpy as np
import pytest
from humanoid_gen import generate_humanoid, joint_name
from test_live_loop_closed import balance

from livezmp.errors import InputError
from livezmp.live import scenarios as sc
from livezmp.live.scenarios import joint_roles, make_scenario
from livezmp.model.robot import load_robot
from sim_devices.humanoid import SimHumanoid
from sim_devices.scenario_player import ScenarioPlayer

ROLES = [f"{s}_{r}" for s in "lr"
         for r in ("hip_pitch", "knee", "ank_pitch", "hip_roll", "ank_roll", "sho_pitch", "sho_roll", "el")]
SMALL, BIG = (0.8, 0.9, 3), (1.4, 1.2, 2)  # scale, extra leg scale, seed of the joint order


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    out = tmp_path_factory.mktemp("humanoids")
    return {spec: load_robot(str(generate_humanoid(out / f"gen{spec[2]}.urdf", *spec)), None).body
            for spec in (SMALL, BIG)}


def test_the_limbs_of_the_built_in_robots_are_their_named_joints(mini, op3_body):
    for body in (mini, op3_body):
        assert joint_roles(body) == {role: role for role in ROLES}


def test_the_limbs_of_a_robot_named_otherwise_are_found_from_its_tree(generated):
    for body in generated.values():
        assert body.joint_names != list(sorted(body.joint_names))  # not the mini's order, not sorted either
        assert joint_roles(body) == {role: joint_name(role) for role in ROLES}  # e.g. l_knee -> l_knee_y


def test_the_arm_swing_is_sized_by_the_robots_inertia(mini, generated):
    # the frequency whose swing takes the ZMP 4 mm past the toes: the mini's is the 0.8 Hz its demo was tuned to
    poser = sc.Poser(mini)
    q0 = poser.standing() + poser.ankles_lean(sc.lean_angle(mini, -0.008))
    dq = poser.unit("l_sho_pitch", sc.Y) + poser.unit("r_sho_pitch", sc.Y)
    f_mini = sc.swing_frequency(mini, q0, dq, 0.6, 0.004)
    assert f_mini == pytest.approx(0.8, abs=0.02)
    assert sc.swing_zmp_beyond_toes(mini, q0, dq, 0.6, f_mini) == pytest.approx(0.004, abs=1e-6)
    freqs = {}
    for spec, body in generated.items():
        p = sc.Poser(body)
        q = p.standing() + p.ankles_lean(sc.lean_angle(body, -0.008))
        freqs[spec] = sc.swing_frequency(body, q, p.unit("l_sho_pitch", sc.Y) + p.unit("r_sho_pitch", sc.Y), 0.6,
                                         0.004)
    assert freqs[BIG] < f_mini < freqs[SMALL]  # a bigger robot is shaken over by a slower swing


def test_the_push_moves_the_zmp_the_stated_distance_past_the_toes(generated):
    body = generated[BIG]
    scenario = make_scenario("push", body)
    (push,) = scenario.pushes
    q0 = scenario.goals(0.0)
    # a push F at height h moves the ZMP by h F / (m g): F = (toe distance + 5 mm) m g / h
    assert push.force[0] == pytest.approx((sc.front_margin(body, q0) + 0.005) * body.total_mass * 9.81 / push.height)
    h = SimHumanoid(body, q0, fall_after_s=10.0)
    ScenarioPlayer(h, scenario).run(push.start + push.rise_s + 0.1)  # the player applies the scenario's pushes
    s = h.state()
    toe = s.polygon[:, 0].max()
    assert s.zmp[0] - toe == pytest.approx(0.005, abs=0.0015)


# (BIG, "lean") fell corrected too while the lean took 2 s whatever the robot's size (its lean now takes 2.9 s)
@pytest.mark.parametrize(("spec", "name"), [(SMALL, "lean"), (SMALL, "arm_swing"), (BIG, "arm_swing"), (BIG, "lean")])
def test_a_robot_never_seen_falls_uncorrected_and_stands_corrected(generated, spec, name):
    body = generated[spec]
    scenario = make_scenario(name, body, **({"hold_s": 1.0} if name == "lean" else {"duration": 3.0}))
    off, s_off = balance(body, scenario, correct=False)
    assert off.fallen is not None and s_off["stopped_by"] == "fell"
    on, s_on = balance(body, scenario, correct=True)
    c = on.counters
    print(f"{spec} {name}: uncorrected fell at {off.fallen.t:.2f} s; corrected: true ZMP inside "
          f"{100 * (1 - c.unsupported_steps / c.steps):.2f} % of its steps")
    assert on.fallen is None and s_on["stopped_by"] == "duration"


@pytest.mark.parametrize("robot", ["livezmp_mini", "robotis_op3", "generated"])
def test_a_push_topples_the_uncorrected_robot_and_the_corrector_holds_it_with_foot_sensors(
        robot, mini, op3_body, generated):
    """The push scenario on the mini, the OP3 and a robot never seen: uncorrected it falls; corrected with the
    feet's measured CoP it stands; (the mini) corrected from the joints alone it falls too: a push does not move
    the joints."""
    body = {"livezmp_mini": mini, "robotis_op3": op3_body, "generated": generated.get(SMALL)}[robot]
    scenario = make_scenario("push", body)
    (push,) = scenario.pushes
    off, s_off = balance(body, scenario, correct=False, foot_sensors=True)
    blind, _ = balance(body, scenario, correct=True) if robot == "livezmp_mini" else (None, None)
    on, s_on = balance(body, scenario, correct=True, foot_sensors=True)
    impulse = push.force[0] * (push.duration - push.rise_s)  # each half-cosine ramp carries half its span
    blind_said = "" if blind is None else f"joints-only corrected fell at {blind.fallen and blind.fallen.t:.2f} s; "
    print(f"{robot}: push {push.force[0]:.2f} N at {push.height:.3f} m, impulse {impulse:.2f} N s; uncorrected "
          f"fell at {off.fallen and off.fallen.t:.2f} s; {blind_said}with the CoP: fell {on.fallen}, worst true "
          f"margin {1e3 * on.counters.worst_margin:.1f} mm")
    assert off.fallen is not None and s_off["stopped_by"] == "fell"
    assert blind is None or blind.fallen is not None
    assert on.fallen is None and s_on["stopped_by"] == "duration" and on.counters.unsupported_steps == 0


def test_a_push_grows_and_eases_off_as_half_cosines():
    p = sc.Push((2.0, 0.0), 0.2, start=1.0, duration=3.0, rise_s=1.0)
    shares = [p.share(t) for t in (0.99, 1.0, 1.5, 2.0, 3.0, 3.5, 4.0)]
    assert shares == pytest.approx([0.0, 0.0, 0.5, 1.0, 1.0, 0.5, 0.0])
    assert sc.Push((2.0, 0.0), 0.2, 1.0, 0.1).share(1.05) == 1.0  # no rise: a step
    with pytest.raises(InputError, match="rise_s within"):
        sc.Push((2.0, 0.0), 0.2, 1.0, 1.0, rise_s=0.6)


def test_the_arm_swing_starts_no_harder_than_it_swings(mini, generated):
    # before: it grew over a fixed 0.5 s; for a slow (big robot's) swing the growth itself accelerated the arms
    # several times harder than the swing does, and took the ZMP past the toes in its first 0.3 s
    for body in (mini, generated[BIG]):
        scenario = make_scenario("arm_swing", body)
        joint = body.joint_names.index(joint_roles(body)["l_sho_pitch"])
        dt = 1e-3
        q = np.array([scenario.goals(t)[joint] for t in np.arange(0.0, scenario.duration, dt)])
        accel = np.abs(np.diff(q, 2)) / dt ** 2
        steady = accel[len(q) // 2:].max()  # A w^2, once grown
        assert accel.max() <= 1.05 * steady, (body.model.name, accel.max(), steady)
