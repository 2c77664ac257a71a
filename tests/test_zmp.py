"""ZMP against independent truth: closed forms, and Pinocchio's RNEA on the OP3."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from livezmp.balance.zmp import compute_zmp, zmp_from_wrench
from livezmp.estimate.estimator import EstimatorConfig, StreamingEstimator

G = 9.81


def point_mass_model(mass: float = 2.0) -> pin.Model:
    """A point mass on three world-aligned prismatic joints: q = its position."""
    m = pin.Model()
    j = 0
    for jm in (pin.JointModelPX(), pin.JointModelPY(), pin.JointModelPZ()):
        j = m.addJoint(j, jm, pin.SE3.Identity(), f"p{j}")
    m.appendBodyToJoint(j, pin.Inertia(mass, np.zeros(3), np.zeros((3, 3))), pin.SE3.Identity())
    return m


def trajectory(t):
    """Position, velocity, acceleration of a point mass swaying over the ground (m, s)."""
    w = 2 * np.pi * 0.8
    p = np.stack([0.05 * np.sin(w * t), 0.03 * np.cos(1.5 * w * t), 0.9 + 0.02 * np.sin(2 * w * t)], -1)
    v = np.stack([0.05 * w * np.cos(w * t), -0.045 * w * np.sin(1.5 * w * t), 0.04 * w * np.cos(2 * w * t)], -1)
    a = np.stack([-0.05 * w * w * np.sin(w * t), -0.0675 * w * w * np.cos(1.5 * w * t),
                  -0.08 * w * w * np.sin(2 * w * t)], -1)
    return p, v, a


def closed_form(p, a):
    """x_zmp = x − z ẍ / (z̈ + g), same for y: the seed paper's equation for one mass."""
    return np.stack([p[..., 0] - p[..., 2] * a[..., 0] / (a[..., 2] + G),
                     p[..., 1] - p[..., 2] * a[..., 1] / (a[..., 2] + G)], -1)


def test_point_mass_matches_closed_form():
    model = point_mass_model()
    data = model.createData()
    t = np.linspace(0, 3, 200)
    p, v, a = trajectory(t)
    want = closed_form(p, a)
    for k in range(len(t)):
        got = compute_zmp(model, data, p[k], v[k], a[k]).zmp
        np.testing.assert_allclose(got[:2], want[k], atol=1e-12)
        assert got[2] == 0.0


def test_point_mass_with_noise_error_is_bounded():
    """1 mm position noise at 200 Hz through the streaming estimator: report and bound the error."""
    model = point_mass_model()
    data = model.createData()
    rate = 200.0
    t = np.arange(0, 6, 1 / rate)
    p, _, a = trajectory(t)
    rng = np.random.default_rng(1)
    noisy = p + rng.normal(0, 0.001, p.shape)
    est = StreamingEstimator(3, np.zeros(3, bool), EstimatorConfig(rate_hz=rate))
    errs = []
    for k in range(len(t)):
        e = est.step(t[k], noisy[k])
        if e is None or e.t < 1.0:  # skip the estimator's warm-up second
            continue
        got = compute_zmp(model, data, e.q, e.qd, e.qdd).zmp[:2]
        errs.append(np.linalg.norm(got - closed_form(p[e.index], a[e.index])))
    errs = np.array(errs)
    rms = float(np.sqrt(np.mean(errs**2)))
    # baseline: plain second differences of the same noisy samples
    fd = (noisy[2:] - 2 * noisy[1:-1] + noisy[:-2]) * rate**2
    naive = np.linalg.norm(closed_form(noisy[1:-1], fd) - closed_form(p[1:-1], a[1:-1]), axis=-1)
    naive_rms = float(np.sqrt(np.mean(naive**2)))
    print(f"point mass, 1 mm noise at 200 Hz: ZMP error rms {1000 * rms:.1f} mm, max {1000 * errs.max():.1f} mm; "
          f"finite differences: rms {1000 * naive_rms:.0f} mm")
    # the noise-free ZMP sways about ±11 cm: the estimate must resolve it to about a centimetre,
    # and beat plain finite differences by two orders of magnitude
    assert rms < 0.02
    assert errs.max() < 0.05
    assert rms < naive_rms / 100


def test_static_pose_zmp_is_com_projection(op3_body):
    rng = np.random.default_rng(0)
    for model in (op3_body.model, op3_body.point_model):
        data = model.createData()
        for _ in range(5):
            q = rng.uniform(-0.5, 0.5, op3_body.nq)
            r = compute_zmp(model, data, q, np.zeros(op3_body.nq), np.zeros(op3_body.nq), ground_z=-0.1)
            np.testing.assert_allclose(r.zmp[:2], r.com[:2], atol=1e-12)
            assert r.zmp[2] == -0.1


def test_flight_gives_no_zmp():
    model = point_mass_model()
    data = model.createData()
    r = compute_zmp(model, data, np.array([0, 0, 1.0]), np.zeros(3), np.array([1.0, 0, -G]))
    assert r.zmp is None
    assert zmp_from_wrench(np.zeros(3), np.array([1.0, 0, float("nan")]), np.zeros(3), 0.0, 1.0) is None


def _op3_trajectory(nq: int, t: float, seed: int = 3):
    """Smooth random trajectory of the OP3's 26 coordinates with exact derivatives."""
    rng = np.random.default_rng(seed)
    amp = rng.uniform(0.05, 0.4, (3, nq))
    amp[:, :3] *= 0.1  # base translation in m
    freq = rng.uniform(0.3, 2.0, (3, nq)) * 2 * np.pi
    ph = rng.uniform(0, 2 * np.pi, (3, nq))
    s = np.sin(freq * t + ph)
    c = np.cos(freq * t + ph)
    q = (amp * s).sum(0)
    q[2] += 0.3
    return q, (amp * freq * c).sum(0), (-amp * freq**2 * s).sum(0)


def _rnea_zmp(model: pin.Model, data: pin.Data, q, v, a):
    """Reference: the wrench RNEA says the ground must apply at the base (world frame,
    about the origin), turned into a ZMP on z = 0: p = (−τ_y / F_z, τ_x / F_z)."""
    pin.rnea(model, data, q, v, a)
    f = data.liMi[1].act(data.f[1])  # joint 1 hangs from the universe: liMi[1] is its world pose
    return np.array([-f.angular[1] / f.linear[2], f.angular[0] / f.linear[2]])


def test_full_mode_matches_rnea_on_op3(op3_body):
    model = op3_body.model
    d1, d2 = model.createData(), model.createData()
    worst = 0.0
    for t in np.linspace(0, 4, 120):
        q, v, a = _op3_trajectory(model.nq, t)
        got = compute_zmp(model, d1, q, v, a).zmp[:2]
        worst = max(worst, float(np.linalg.norm(got - _rnea_zmp(model, d2, q, v, a))))
    print(f"full ZMP vs RNEA reference, OP3, exact derivatives: max error {worst * 1000:.2e} mm")
    assert worst <= 1e-3


def test_seed_and_full_differ_by_rotational_inertia(op3_body):
    """The seed mode drops segment rotational inertia: on a fast motion the two differ,
    and removing the OP3's inertias from the full model makes them agree."""
    q, v, a = _op3_trajectory(op3_body.nq, 1.3)
    full = compute_zmp(op3_body.model, op3_body.model.createData(), q, v, a).zmp
    seed = compute_zmp(op3_body.point_model, op3_body.point_model.createData(), q, v, a).zmp
    assert np.linalg.norm(full - seed) > 1e-4
    stripped = op3_body.model.copy()
    for i in range(len(stripped.inertias)):
        stripped.inertias[i] = pin.Inertia(stripped.inertias[i].mass, stripped.inertias[i].lever, np.zeros((3, 3)))
    np.testing.assert_allclose(compute_zmp(stripped, stripped.createData(), q, v, a).zmp, seed, atol=1e-12)


@pytest.mark.parametrize("noise_deg", [0.2])
def test_full_mode_with_joint_noise_through_estimator(op3_body, noise_deg):
    """0.2° joint noise at 200 Hz through the estimator: report the ZMP error against truth."""
    model = op3_body.model
    d1 = model.createData()
    rate = 200.0
    ts = np.arange(0, 5, 1 / rate)
    truth = [_op3_trajectory(model.nq, t) for t in ts]
    rng = np.random.default_rng(7)
    est = StreamingEstimator(model.nq, op3_body.angle_mask, EstimatorConfig(rate_hz=rate))
    errs = []
    for k, t in enumerate(ts):
        q = truth[k][0].copy()
        q[op3_body.angle_mask] += np.deg2rad(rng.normal(0, noise_deg, op3_body.angle_mask.sum()))
        e = est.step(t, q)
        if e is None or e.t < 1.0:
            continue
        got = compute_zmp(model, d1, e.q, e.qd, e.qdd).zmp[:2]
        want = compute_zmp(model, d1, *truth[e.index]).zmp[:2]
        errs.append(np.linalg.norm(got - want))
    errs = np.array(errs)
    rms = float(np.sqrt(np.mean(errs**2)))
    print(f"OP3 full ZMP with {noise_deg} deg joint noise at 200 Hz: error rms {rms * 1000:.1f} mm, "
          f"p95 {np.percentile(errs, 95) * 1000:.1f} mm")
    assert rms < 0.02  # the OP3's sole is 127 mm long: the estimate must resolve well inside it
