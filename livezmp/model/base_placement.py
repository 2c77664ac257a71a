"""Place a robot's floating base when only its joint angles are known.

The stance foot is held flat on the ground (z = 0) at the place and heading where it
touched down; the base follows from the leg's kinematics. The stance passes to the
other foot when, so placed, that foot's sole would go below the ground by more than
``switch_depth`` while, placed flat itself, it would leave the current stance foot above
that depth: then it is the lower foot and takes the weight (when both placements dip
below, as with a foot rolled on its edge, the stance stays: no chatter). At the first frame the
stance is the foot that leaves the other at or above the ground, its sole centred at
x = y = 0 (or, given ``stance``, that foot: a simulator that knows which foot stands flat).
Streaming: constant cost per frame, no history.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from livezmp.model.body import BodyModel


def _rz(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def base_coordinates(m: pin.SE3) -> np.ndarray:
    """(x, y, z, yaw, pitch, roll) of a base pose, R = Rz(yaw)·Ry(pitch)·Rx(roll)."""
    # one concatenation: unpacking the translation made three numpy scalars and a list to convert back
    return np.concatenate((m.translation, pin.rpy.matrixToRpy(m.rotation)[::-1]))


class BasePlacer:
    """Streaming base placement for a body with ``base_channels`` (a URDF robot)."""

    def __init__(self, body: BodyModel, switch_depth: float = 0.001, stance: str | None = None):
        if stance not in (None, "left", "right"):
            raise ValueError(f"BasePlacer: stance must be left, right or None, got {stance!r}")
        self.body = body
        self._first = stance
        self.data = body.model.createData()
        self.switch_depth = switch_depth
        self.stance: str | None = None
        self.anchor = pin.SE3.Identity()  # world pose of the stance foot frame (flat)
        self._q = np.zeros(body.nq)  # its base coordinates stay 0: the feet are placed relative to the base
        self._nb = len(body.base_channels)
        self._frames = {s: f.frame_id for s, f in body.feet.items()}
        self._sole_bottom = {s: float(f.sole_local[:, 2].min()) for s, f in body.feet.items()}

    def _sole_min_z(self, world_from_base: pin.SE3, side: str, base_from_foot: dict[str, pin.SE3]) -> float:
        m = world_from_base * base_from_foot[side]
        # the corners' heights as floats (the loop and the simulator place a base every cycle: a numpy reduction costs
        # more than the few floats); finite joint angles make finite corners, where min() finds what np.min would
        return min((self.body.feet[side].sole_local @ m.rotation.T + m.translation)[:, 2].tolist())

    def _anchor_flat(self, pose: pin.SE3, side: str, xy: np.ndarray | None = None) -> pin.SE3:
        yaw = float(np.arctan2(pose.rotation[1, 0], pose.rotation[0, 0]))
        p = pose.translation.copy() if xy is None else np.array([xy[0], xy[1], 0.0])
        p[2] = -self._sole_bottom[side]
        return pin.SE3(_rz(yaw), p)

    def update(self, q_joints: np.ndarray) -> np.ndarray:
        """Joint angles (rad, URDF order) → base (x, y, z, yaw, pitch, roll) in m, rad."""
        q = self._q
        q[self._nb:] = q_joints
        model, data = self.body.model, self.data
        pin.forwardKinematics(model, data, q)
        # the two feet's frames alone (the loop and the simulator place a base every cycle): the same products
        # framesForwardKinematics makes for every frame of the model, and reading data.oMf[i] back costs about 10
        # times a frame's placement
        bf = {s: pin.updateFramePlacement(model, data, frame) for s, frame in self._frames.items()}
        if self.stance is None:
            self._start(bf)
        other = "right" if self.stance == "left" else "left"
        wb = self.anchor * bf[self.stance].inverse()
        if self._sole_min_z(wb, other, bf) < -self.switch_depth:
            anchor = self._anchor_flat(wb * bf[other], other)
            wb_other = anchor * bf[other].inverse()
            if self._sole_min_z(wb_other, self.stance, bf) >= -self.switch_depth:
                self.anchor, self.stance, wb = anchor, other, wb_other
        return base_coordinates(wb)

    def _start(self, bf: dict[str, pin.SE3]) -> None:
        best = None
        for side in ("left", "right") if self._first is None else (self._first,):
            self.anchor = self._anchor_flat(bf[side], side, xy=np.zeros(2))
            other = "right" if side == "left" else "left"
            depth = self._sole_min_z(self.anchor * bf[side].inverse(), other, bf)
            if best is None or depth > best[0] + 1e-9:
                best = (depth, side, self.anchor)
        _, self.stance, self.anchor = best
        # centre the stance sole, not the foot frame, on the origin
        centre = self.body.feet[self.stance].sole_local.mean(axis=0)
        shift = self.anchor.rotation @ centre
        self.anchor = pin.SE3(self.anchor.rotation, self.anchor.translation - np.array([shift[0], shift[1], 0.0]))


def place_base(body: BodyModel, q_joints: np.ndarray, placer: BasePlacer | None = None) -> np.ndarray:
    """Base coordinates (F, 6) for joint angles (F, n) — :class:`BasePlacer` over a take, or, given
    ``placer``, over the take's next frames (a take read in pieces)."""
    placer = placer or BasePlacer(body)
    return np.array([placer.update(q) for q in q_joints])
