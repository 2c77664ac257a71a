"""Balance correction of a gait-lab C3D take: the marker body corrected as a chain, its markers moved.

The take is analysed as ``livezmp analyze`` analyses it (:func:`~livezmp.offline.gaitlab.analyse_lab_take`:
mass, floor, estimator), its free marker body turned into the chain of :mod:`livezmp.model.marker_chain`
and corrected by :func:`~livezmp.correct.solver.correct_motion` (the pelvis rotates about the stance hip,
carrying the trunk; each thigh is re-solved so its foot stays). Every marker is rigidly attached to
one segment and moved with it: the marker set's own markers by their role, any other position point
(model outputs such as joint centres) with the nearest of those markers; angle, force, moment and power
points are copied unchanged (they describe the motion before the correction). A placed HAT (lower-body
sets) has no markers: its corrected frame is written as virtual points (``HAT_POINTS``), which the
marker body reads back, so the corrected file analyses as it was corrected.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from livezmp.correct.limits import CorrectionLimits
from livezmp.correct.solver import CorrectionResult, correct_motion
from livezmp.model.body import BodyModel
from livezmp.model.c3d import C3dTrial
from livezmp.model.marker_chain import chain_body, chain_frames, chain_poses, segment_names, world_poses
from livezmp.model.marker_map import MarkerMap
from livezmp.model.markers import HAT_POINTS, marker_roles
from livezmp.offline.gaitlab import LabOptions, analyse_lab_take

HAT_AXIS_M = 0.1  # m from the HAT origin to each axis point
_SEGMENT_OF_ROLE = {"ASI": "pelvis", "PSI": "pelvis", "SACR": "pelvis", "THI": "thigh", "KNE": "thigh",
                    "TIB": "shank", "ANK": "shank", "TOE": "foot", "HEE": "foot", "C7": "thorax", "T10": "thorax",
                    "CLAV": "thorax", "CLA": "thorax", "STRN": "thorax", "SHO": "thorax", "FHD": "head", "BHD": "head",
                    "HEA": "head", "ELB": "upperarm", "WRA": "forearm", "WRB": "forearm", "WRI": "forearm",
                    "FIN": "hand"}
_SIDE = {"L": "_l", "R": "_r"}


@dataclass
class MarkerCorrection:
    """``result`` the correction of the chain ``body``; ``moved`` point index -> (N, 3) corrected positions
    (m, the file's frame) over the take's frames from ``first_frame``; ``added`` the HAT's virtual points;
    ``attached`` label -> segment; ``stance_marker_mm`` the largest move of a weight-bearing foot's
    markers; ``unchanged`` the points copied as they were."""

    result: CorrectionResult
    body: BodyModel  # the chain body corrected
    moved: dict[int, np.ndarray]
    added: dict[str, np.ndarray]
    first_frame: int
    attached: dict[str, str]
    stance_marker_mm: float
    unchanged: list[str]


def role_segment(role: str) -> str | None:
    """The segment a marker role belongs to: ``LKNE`` -> ``thigh_l``, ``LANK_med`` -> ``shank_l``,
    ``LASI`` -> ``pelvis``, ``HATO`` -> ``hat``; None for a role not in the table (a cluster set's)."""
    if role in HAT_POINTS:
        return "hat"
    base = role.removesuffix("_med")
    seg = _SEGMENT_OF_ROLE.get(base) or _SEGMENT_OF_ROLE.get(base[1:])
    if seg is None or seg in ("pelvis", "thorax", "head"):
        return seg
    return seg + _SIDE[base[0]] if base[0] in _SIDE else None


def attach(trial: C3dTrial, skip: set[str], segments: list[str], mmap: MarkerMap | None = None) -> dict[int, str]:
    """Point index -> segment (of ``segments``): the marker set's markers by role (through the marker map
    ``mmap``: a cluster set's by its segments); other position points (not in ``skip``, seen at least once, or
    markers whose role has no segment here) with the marker nearest to them (median distance over the frames)."""
    seen = np.isfinite(trial.points).all(axis=2).sum(axis=0)
    index = {}
    for i, label in enumerate(trial.labels):  # a label written twice: the copy with data (as the body reads it)
        if label not in index or seen[i] > seen[index[label]]:
            index[label] = i
    if mmap is not None and mmap.segments:
        by_label = {lab: seg for seg, labels in mmap.segments for lab in labels}
    else:
        by_label = {lab: role_segment(role) for role, lab in marker_roles(trial, mmap).items()
                    if lab is not None and role not in HAT_POINTS}
    out = {index[lab]: seg for lab, seg in by_label.items() if lab in index and seg in segments}
    known = list(out)
    for i, label in enumerate(trial.labels):
        if i in out or label in skip or label in HAT_POINTS or not np.isfinite(trial.points[:, i]).any():
            continue
        d = np.nanmedian(np.linalg.norm(trial.points[:, known] - trial.points[:, i:i + 1], axis=2), axis=0)
        if np.isfinite(d).any():
            out[i] = out[known[int(np.nanargmin(d))]]
    return out


def correct_marker_take(trial: C3dTrial, lab_options: LabOptions, limits: CorrectionLimits | None,
                        skip: set[str], progress: Callable[[str], None] | None = None) -> MarkerCorrection:
    """Correct ``trial`` (see the module docstring); ``skip`` the labels of points that are not positions."""
    lab = analyse_lab_take(trial, lab_options)
    free = lab.take
    names = segment_names(free.body)
    body = chain_body(free.body)
    result = correct_motion(body, lab.times, chain_frames(names, free.frames), lab.config, limits,
                            nominal_dt=1.0 / trial.rate, progress=progress)
    before, after = world_poses(names, free.frames), chain_poses(names, result.frames)
    r_in = free.body.world_from_input
    span = slice(free.first_frame, free.first_frame + len(free.frames))
    attached = attach(trial, skip, names, lab_options.markers.marker_map)
    moved = {}
    for i, seg in attached.items():
        (o0, r0), (o1, r1) = before[seg], after[seg]
        p = trial.points[span, i] @ r_in.T
        local = np.einsum("fji,fj->fi", r0, p - o0)
        moved[i] = (np.einsum("fij,fj->fi", r1, local) + o1) @ r_in
    added = {}
    if "hat" in after and not {"thorax", "head"} & set(names):
        o, r = after["hat"]
        added = {HAT_POINTS[0]: o @ r_in}
        added.update({p: (o + HAT_AXIS_M * r[:, :, k]) @ r_in for k, p in enumerate(HAT_POINTS[1:])})
    support = [r.support for r in result.before]
    worst = 0.0
    for i, seg in attached.items():
        side = {"foot_l": "left", "foot_r": "right"}.get(seg)
        if side:
            bearing = np.array([s in (side, "double") for s in support])
            d = np.linalg.norm(moved[i] - trial.points[span, i], axis=1)[bearing]
            worst = max(worst, float(np.nanmax(d, initial=0.0)))
    unchanged = [lab for i, lab in enumerate(trial.labels) if i not in attached and lab not in HAT_POINTS]
    return MarkerCorrection(result, body, moved, added, free.first_frame,
                            {trial.labels[i]: s for i, s in attached.items()}, 1000 * worst, unchanged)
