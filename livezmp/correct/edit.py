"""A correction applied to a motion: the corrected raw channels, and how far the feet moved."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from livezmp.correct.root_motion import RootMover
from livezmp.model.body import BodyModel


def apply_delta(mover: RootMover, body: BodyModel, frames: np.ndarray, delta: np.ndarray,
                w: np.ndarray, block: int = 1024) -> np.ndarray:
    """Corrected raw channels (F, nq): only the root and leg correction channels change; the
    frames with a correction go through the legs' solve ``block`` at a time."""
    out = frames.copy()
    cols = changed_channels(body)
    moved = np.nonzero(np.any(delta, axis=1))[0]
    for lo in range(0, len(moved), block):  # a block at a time: bounded memory
        ks = moved[lo:lo + block]
        q = mover.apply_many(np.array([body.channels_to_q(frames[k]) for k in ks]), delta[ks], w[ks])
        out[np.ix_(ks, cols)] = q[:, cols] / body.channel_scale[cols]
    return out


def hold_feet(mover: RootMover, body: BodyModel, frames: np.ndarray, delta: np.ndarray, w: np.ndarray,
              stance: list[str], tolerance: float, steps: int = 12) -> tuple[np.ndarray, list[int]]:
    """``delta`` (F, 3, rad) with each frame's rotation scaled down, where needed, until every
    foot bearing weight there (per the support labels ``stance``) moves at most ``tolerance``
    (m) once the legs are re-solved; and the frames scaled.

    The solver's rotation bounds come from a first-order model of how far a hip moves; this
    measures the feet themselves, with the same kinematics as :func:`foot_displacement`, so
    the promise holds on any skeleton the body model accepts whatever its joint layout,
    channel orders, axes, units or rate. Bisection on the scale, ``steps`` halvings."""
    out = delta.copy()
    held = []
    data_a, data_b = body.model.createData(), body.model.createData()
    for k in range(len(frames)):
        loaded = [s for s in ("left", "right") if stance[k] in (s, "double")]
        if not loaded or not np.any(delta[k]):
            continue
        q = body.channels_to_q(frames[k])
        pin.framesForwardKinematics(body.model, data_a, q)
        feet = [f for s in loaded for f in body.correction.foot_frames[s]]
        if _drift(mover, body, data_a, data_b, q, delta[k], w[k], feet) <= tolerance:
            continue
        lo, hi = 0.0, 1.0
        for _ in range(steps):
            mid = 0.5 * (lo + hi)
            if _drift(mover, body, data_a, data_b, q, mid * delta[k], w[k], feet) <= tolerance:
                lo = mid
            else:
                hi = mid
        out[k] = lo * delta[k]
        held.append(k)
    return out, held


def _drift(mover: RootMover, body: BodyModel, before: pin.Data, after: pin.Data, q: np.ndarray, delta: np.ndarray,
           w_left: float, feet: list[int]) -> float:
    """Largest displacement (m) of the frames ``feet`` (placed in ``before``) once ``delta`` is applied to ``q``."""
    pin.framesForwardKinematics(body.model, after, mover.apply(q, delta, w_left))
    return max(float(np.linalg.norm(before.oMf[f].translation - after.oMf[f].translation)) for f in feet)


def changed_channels(body: BodyModel) -> list[int]:
    """The raw channels a correction changes: the root's and each leg's correction channels."""
    corr = body.correction
    return sorted(set(corr.root_channels) | {c for cols in corr.legs.values() for c in cols})


def foot_displacement(body: BodyModel, a: np.ndarray, b: np.ndarray, stance: list[str]) -> dict[str, float]:
    """Largest world displacement (m) of the foot frames between two takes of raw channels,
    split into feet in stance (per the support labels) and feet in swing."""
    data_a, data_b = body.model.createData(), body.model.createData()

    worst = {"stance": 0.0, "swing": 0.0}
    for k in range(len(a)):
        pin.framesForwardKinematics(body.model, data_a, body.channels_to_q(a[k]))
        pin.framesForwardKinematics(body.model, data_b, body.channels_to_q(b[k]))
        for side, frames in body.correction.foot_frames.items():
            d = max(np.linalg.norm(data_a.oMf[f].translation - data_b.oMf[f].translation) for f in frames)
            key = "stance" if stance[k] in (side, "double") else "swing"
            worst[key] = max(worst[key], float(d))
    return worst
