"""Zero Moment Point from the rigid-body dynamics of a body model.

Two modes:

- ``full``: the ground reaction wrench equals the rate of centroidal momentum minus
  gravity (Pinocchio's ``computeCentroidalMomentumTimeVariation``), so every segment's
  rate of angular momentum is included.
- ``seed``: the same with every segment a point mass at its centre of mass — exactly the
  point-mass formula of the seed paper (with its misprint corrected: the second sum is
  horizontal acceleration × height):
  x_zmp = [Σ m_i (z̈_i + g) x_i − Σ m_i ẍ_i (z_i − z_g)] / Σ m_i (z̈_i + g), same for y.

With F the contact force and τ its moment about the CoM c, the ZMP on the ground
plane z = z_g is p_x = c_x − (τ_y + h F_x)/F_z, p_y = c_y + (τ_x − h F_y)/F_z with
h = c_z − z_g. When F_z < ``flight_fraction`` × m g the body is (nearly) in flight: no
ZMP is reported (never a division by ~0, never NaN).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin


@dataclass
class ZmpResult:
    """ZMP and CoM in the internal frame (m); ``zmp`` is None in flight.

    ``force`` is the ground reaction force (N), ``com_acc`` the CoM acceleration (m/s²)."""

    zmp: np.ndarray | None
    com: np.ndarray
    com_acc: np.ndarray
    force: np.ndarray


def _zmp_xy(com: tuple, force: tuple, moment: tuple, ground_z: float, min_fz: float) -> tuple | None:
    """(x, y) of the ZMP on z = ground_z, plain floats (three-float tuples in); None if F_z < min_fz."""
    fz = force[2]
    if not fz >= min_fz:  # also catches NaN
        return None
    h = com[2] - ground_z
    return com[0] - (moment[1] + h * force[0]) / fz, com[1] + (moment[0] - h * force[1]) / fz


def zmp_from_wrench(com: np.ndarray, force: np.ndarray, moment: np.ndarray, ground_z: float,
                    min_fz: float) -> np.ndarray | None:
    """ZMP (3,) m on z = ``ground_z`` (m) of a contact wrench: ``force`` (3,) N, ``moment`` (3,) N·m about
    ``com`` (3,) m, all in the internal z-up frame; None if F_z < ``min_fz`` (N)."""
    xy = _zmp_xy(tuple(map(float, com)), tuple(map(float, force)), tuple(map(float, moment)), ground_z, min_fz)
    return None if xy is None else np.array((xy[0], xy[1], ground_z))


def compute_zmp(model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray, a: np.ndarray,
                ground_z: float = 0.0, flight_fraction: float = 0.05, gravity: np.ndarray | None = None) -> ZmpResult:
    """ZMP of ``model`` in state (q, v, a) (SI units, internal z-up frame).

    Pass the body's ``model`` for the full ZMP, its ``point_model`` for the seed's.
    ``gravity`` (3,) m/s²: gravity in this frame when it is not the model's (−z): in the
    frame of a sloped ground (its plane z = 0), the ZMP is the centre of pressure on that
    ground. Leaves ``data`` with kinematics of (q, v, a) computed (joint placements, CoM)."""
    pin.computeCentroidalMomentumTimeVariation(model, data, q, v, a)
    # Plain floats from here: a handful of 3-vectors, where numpy's per-call cost would dominate.
    mass = data.mass[0]
    lx, ly, lz, mx, my, mz = data.dhg.vector.tolist()  # linear, then angular
    gx, gy, gz = (model.gravity.linear if gravity is None else gravity).tolist()  # points down (−z) or nearly
    force = (lx - mass * gx, ly - mass * gy, lz - mass * gz)
    com = tuple(data.com[0].tolist())
    xy = _zmp_xy(com, force, (mx, my, mz), ground_z, flight_fraction * mass * -gz)
    zmp = None if xy is None else np.array((xy[0], xy[1], ground_z))
    return ZmpResult(zmp, np.array(com), np.array((lx / mass, ly / mass, lz / mass)), np.array(force))


def zmp_on_plane(zmp0: np.ndarray, force: np.ndarray, ground_z: float) -> np.ndarray:
    """Move a ZMP computed on z = 0 to the plane z = ground_z along the line of action of
    the contact force: p(h) = p(0) + h · F_xy / F_z (m, internal frame)."""
    fx, fy, fz = force.tolist()  # plain floats in one call each, not one indexing per value
    x0, y0, _ = zmp0.tolist()
    return np.array((x0 + ground_z * fx / fz, y0 + ground_z * fy / fz, ground_z))
