"""The seed paper's correction, as a baseline for the solver: per frame, root rotations
searched on a fixed grid, holding the frame's velocities and accelerations."""

from __future__ import annotations

import numpy as np

from livezmp.balance.pipeline import FrameResult, PipelineConfig
from livezmp.balance.support import clamp_to_polygon
from livezmp.balance.zmp import compute_zmp
from livezmp.correct.limits import CorrectionLimits, stance_weights
from livezmp.correct.root_motion import RootMover
from livezmp.model.body import BodyModel


def seed_grid_search(body: BodyModel, config: PipelineConfig, results: list[FrameResult], frames_idx: list[int],
                     step_deg: float = 0.5, limits: CorrectionLimits | None = None) -> dict[int, np.ndarray]:
    """The seed paper's search, as a baseline: for each frame in ``frames_idx`` that is
    outside, try root rotations on a fixed grid (``step_deg``; roll and pitch, in square
    shells of growing size) holding the frame's velocities and accelerations, and keep
    the smallest that puts the ZMP inside. Returns δ (rad) per frame; frames where no
    grid point within the limits works are left out."""
    limits = limits or CorrectionLimits()
    model = body.model if config.mode == "full" else body.point_model
    data = model.createData()
    mover = RootMover(body)
    w = stance_weights(results, 1)
    n = [int(limits.max_rotation_deg[a] / step_deg) for a in range(2)]
    out: dict[int, np.ndarray] = {}
    for k in frames_idx:
        r = results[k]
        if r.inside is not False:
            continue
        found = None
        for shell in range(1, max(n) + 1):
            best = None
            for i in range(-min(shell, n[0]), min(shell, n[0]) + 1):
                for j in range(-min(shell, n[1]), min(shell, n[1]) + 1):
                    if max(abs(i), abs(j)) != shell:
                        continue
                    d = np.radians([i * step_deg, j * step_deg, 0.0])
                    q = mover.apply(r.q, d, w[k])
                    z = compute_zmp(model, data, q, r.v, r.a, r.ground_z).zmp
                    if z is not None and clamp_to_polygon(z[:2], r.polygon).inside:
                        if best is None or np.linalg.norm(d) < np.linalg.norm(best):
                            best = d
            if best is not None:
                found = best
                break
        if found is not None:
            out[k] = found
    return out
