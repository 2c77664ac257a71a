"""Foot force sensors: which feet bear weight, and the measured centre of pressure (CoP)
in the world frame of an analysed frame, compared with the computed ZMP.

A link's :class:`~livezmp.links.base.FootSensors` gives, per foot, the vertical forces
(N) of its corner cells and the board's centre of pressure in the sole frame
(firmware_protocol SPEC §1: origin at the sole's reference point, x forward, y left,
metres). The reference point is taken as the mean of the foot's sole corners
(``body.feet[side].sole_local``), as the simulated board computes it, and the sole frame's
axes as the foot link's.

* :func:`sensor_contacts`: a foot is in contact when its cells carry more than
  ``fraction`` of the body's weight (:func:`contact_force`);
* :class:`CopLocator`: the board's per-foot CoPs placed on the soles of a
  :class:`~livezmp.balance.pipeline.FrameResult` (its estimated foot placements) and combined,
  weighted by each foot's load, into one point in that result's world frame (z up, m);
* :class:`CopVsZmp`: constant-memory statistics of the horizontal distance between that
  point and the result's computed ZMP.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from livezmp.errors import InputError
from livezmp.histogram import TimingHistogram
from livezmp.links.base import FootSensors

if TYPE_CHECKING:  # a type only: this module stays light for the command line's defaults
    from livezmp.model.body import BodyModel

GRAVITY = 9.81  # m/s²
CONTACT_FRACTION = 0.05  # of the body's weight: what a foot carries to count as down
SIDES = ("left", "right")


def contact_force(body: BodyModel, fraction: float = CONTACT_FRACTION) -> float:
    """The force (N) above which a foot's cells mean the foot bears weight: ``fraction`` of
    the body's weight. InputError unless 0 < fraction < 1."""
    if not (math.isfinite(fraction) and 0.0 < fraction < 1.0):
        raise InputError(f"contact fraction {fraction!r}: must be a share of the body weight in (0, 1)")
    return fraction * body.total_mass * GRAVITY


def sensor_contacts(feet: FootSensors | None, min_force: float) -> tuple[bool, bool] | None:
    """(left, right): whether each foot's cells carry more than ``min_force`` (N); None
    when there is no reading of both feet."""
    if feet is None:
        return None
    forces = feet.forces
    if "left" not in forces or "right" not in forces:
        return None
    return float(np.sum(forces["left"])) > min_force, float(np.sum(forces["right"])) > min_force


class CopLocator:
    """Places the board's per-foot CoPs in a result's world frame (see module docstring).

    Per foot, with the sole's local corners c_i (k, 3) and A = [c_ix, c_iy, 1] (k, 3),
    M = A (AᵀA)⁻¹ gives affine weights reproducing any point of the sole plane from the
    corners, so the world images of the sole frame's x and y unit vectors are
    M[:, 0] · corners_world and M[:, 1] · corners_world, and the CoP is
    mean(corners_world) + cop_x ex + cop_y ey: exact for any rigid placement of a flat
    sole, with no forward kinematics. ``min_force`` (N): below this total load the feet
    carry nothing measurable (flight) and there is no CoP."""

    def __init__(self, body: BodyModel, min_force: float):
        self.min_force = min_force
        self.axes: dict[str, np.ndarray] = {}  # side -> (2, k): rows give ex, ey from the world corners
        for side in SIDES:
            foot = body.feet.get(side)
            if foot is None or foot.sole_local is None:
                continue  # a skeleton's soles have no fixed corners: no CoP for it
            corners = np.asarray(foot.sole_local, dtype=float)
            a = np.column_stack([corners[:, :2], np.ones(len(corners))])
            gram = a.T @ a
            if abs(np.linalg.det(gram)) < 1e-18:
                raise InputError(f"foot '{side}': its sole corners are collinear; no centre of pressure can be placed")
            self.axes[side] = (a @ np.linalg.inv(gram))[:, :2].T.copy()

    def locate(self, feet: FootSensors, soles: dict[str, np.ndarray]) -> np.ndarray | None:
        """The measured CoP (3,) in the world frame of ``soles`` (side -> (k, 3) world
        corners, e.g. ``FrameResult.soles``), on the loaded soles' plane; None in flight,
        or when a loaded foot has no CoP reading or no placeable sole."""
        total = 0.0
        point = np.zeros(3)
        for side, forces in feet.forces.items():
            load = float(np.sum(forces))
            if load <= 0.0:
                continue
            cop = feet.cop.get(side)
            axes = self.axes.get(side)
            if cop is None or axes is None or side not in soles:
                return None
            corners = soles[side]
            ex, ey = axes @ corners
            point += load * (corners.mean(axis=0) + float(cop[0]) * ex + float(cop[1]) * ey)
            total += load
        if total <= self.min_force:
            return None
        return point / total


def _distance_stats(h: TimingHistogram) -> dict:
    """mean, p95 and max of a histogram of distances (m), in mm; None when empty."""
    if not h.count:
        return dict.fromkeys(("mean_mm", "p95_mm", "max_mm"))
    return {"mean_mm": 1e3 * h.mean, "p95_mm": 1e3 * h.quantile(0.95), "max_mm": 1e3 * h.max}


class CopVsZmp:
    """|measured CoP − computed ZMP| over a run, horizontally (m), in constant memory: a
    histogram in 0.1 mm bins up to 1 m (quantiles to within a bin), exact mean and max.
    The same against the ZMP clamped to the support polygon, which is what a CoP can
    show (it never leaves the feet)."""

    BIN_M = 1e-4
    SPAN_M = 1.0

    def __init__(self):
        self.to_zmp = TimingHistogram(self.BIN_M, self.SPAN_M)  # a histogram of any quantity, here metres
        self.to_clamped = TimingHistogram(self.BIN_M, self.SPAN_M)
        self.readings = 0  # analysed frames with a foot-sensor reading
        self.no_cop = 0  # ... whose reading had no CoP (flight, unloaded)
        self.no_zmp = 0  # ... whose analysis had no ZMP (flight)

    def add(self, cop: np.ndarray | None, zmp: np.ndarray | None, clamped: np.ndarray | None) -> float | None:
        """Count one analysed frame with a sensor reading; the distance (m) when both points exist."""
        self.readings += 1
        if cop is None:
            self.no_cop += 1
            return None
        if zmp is None:
            self.no_zmp += 1
            return None
        d = math.hypot(float(cop[0] - zmp[0]), float(cop[1] - zmp[1]))
        self.to_zmp.add(d)
        if clamped is not None:
            self.to_clamped.add(math.hypot(float(cop[0] - clamped[0]), float(cop[1] - clamped[1])))
        return d

    def summary(self) -> dict:
        """``frames`` compared and mean / p95 / max (mm) of the distance to the ZMP and,
        under ``clamped``, to the clamped ZMP; ``readings``, ``no_cop``, ``no_zmp`` as counted."""
        return {"frames": self.to_zmp.count, **_distance_stats(self.to_zmp), "readings": self.readings,
                "no_cop": self.no_cop, "no_zmp": self.no_zmp,
                "clamped": {"frames": self.to_clamped.count, **_distance_stats(self.to_clamped)}}
