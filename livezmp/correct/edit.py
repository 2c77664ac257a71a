"""A correction applied to a motion: the corrected raw channels, and how far the feet moved."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from livezmp.correct.root_motion import RootMover
from livezmp.model.body import BodyModel


def apply_delta(mover: RootMover, body: BodyModel, frames: np.ndarray, delta: np.ndarray,
                w: np.ndarray) -> np.ndarray:
    """Corrected raw channels (F, nq): only the root and leg correction channels change."""
    out = frames.copy()
    cols = changed_channels(body)
    for k in range(len(frames)):
        if np.any(delta[k]):
            q = mover.apply(body.channels_to_q(frames[k]), delta[k], w[k])
            out[k, cols] = q[cols] / body.channel_scale[cols]
    return out


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
