"""Landmarks of a cluster marker set from its static trial (``--static STATIC.c3d``).

Gait labs that track the legs with clusters (three or more markers on a rigid shell or on the skin of one
segment) put the anatomical landmarks (epicondyles, malleoli, sometimes the ASIS or the heel) on the subject only
for a standing static trial; the walks carry the clusters alone. The calibrated anatomical system technique
(CAST: Cappozzo, Catani, Croce & Leardini 1995, Clin Biomech 10:171-178) expresses each landmark in its
segment's cluster frame in the static trial and carries it with the cluster through the walk. Here:

- Which landmarks: the segment markers the static trial's standard set reads (:func:`markers.marker_roles`: ASIS,
  PSIS or sacrum, lateral and medial knee and ankle markers, wands, heel, toe) that the walk does not see, under
  the static trial's labels; the walk is then read as any trial carrying them.
- Which cluster: the segment a landmark belongs to is its role's (a knee marker the thigh's, a malleolus the
  shank's); its cluster, the largest group of markers both trials see, lying on that segment in the standing static
  trial (the thigh between the knee's height and the ASIS', the shank between the ankle's and the knee's, the foot
  below the ankle's, the pelvis within :data:`PELVIS_BAND_M` of the ASIS' height; a leg's markers on its side of the
  mid-pelvis), whose mutual distances stay within :data:`RIGID_SPREAD_M` (standard deviation) over the walk.
- The reference: the cluster's mean shape over the static frames seeing it and the segment's landmarks, each
  landmark's mean position in the cluster's frame; each walk frame's cluster pose is the least-squares rigid fit
  (Kabsch SVD) of that shape to the cluster markers the frame sees (3 or more; else the landmark is unseen there).
- Refused, in one line naming the static file and the segment: fewer than 3 such markers, or a cluster whose
  distances differ between the static trial and the walk (median) by more than :data:`MAX_SHAPE_CHANGE_M` (another
  subject, or the markers placed again). A rigid shell of the same make on another subject passes this check; the
  landmarks then are that subject's, which nothing in the walk can tell.
"""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from livezmp.errors import InputError
from livezmp.model.c3d import C3dTrial, read_c3d
from livezmp.model.marker_labels import standard_trial
from livezmp.model.marker_map import rigid_fit
from livezmp.model.markers import input_rotation, marker_roles

# a cluster's markers move rigidly: their distances' standard deviation over the walk below this (ISW's plate
# clusters 0.2-1.2 mm; a thigh marker against a shank or pelvis marker 10-27 mm, the forefoot against the heel 5-7)
RIGID_SPREAD_M = 0.003
# a cluster's distances in the static trial against the walk's (median): ISW's clusters differ by 0.0-1.3 mm
MAX_SHAPE_CHANGE_M = 0.005
PELVIS_BAND_M = 0.15  # pelvis markers within this height of the ASIS' in the standing static trial
MIN_FRAMES = 10  # walk frames seeing two markers together before their distance's spread is judged
_SEGMENT = {"ASI": "pelvis", "PSI": "pelvis", "SACR": "pelvis", "KNE": "thigh", "KNE_med": "thigh", "THI": "thigh",
            "ANK": "shank", "ANK_med": "shank", "TIB": "shank", "HEE": "foot", "TOE": "foot"}
_NAMES = {"pelvis": "pelvis", "thigh_l": "left thigh", "thigh_r": "right thigh", "shank_l": "left shank",
          "shank_r": "right shank", "foot_l": "left foot", "foot_r": "right foot"}


def _segment(role: str) -> str | None:
    """The segment (``pelvis``, ``thigh_l`` ...) a standard role's marker lies on, or None (trunk, arms, head)."""
    if role == "SACR":
        return "pelvis"
    part = _SEGMENT.get(role[1:])
    if part is None or role[0] not in "LR":
        return None
    return part if part == "pelvis" else f"{part}_{role[0].lower()}"


def _missing(walk: C3dTrial, static: C3dTrial) -> dict[str, list[str]]:
    """Segment -> the static trial's labels of its landmarks that the walk does not see (under any of the names
    the label matcher reads for that role)."""
    try:
        roles = marker_roles(static)
    except InputError as e:
        raise InputError(f"static trial {e}") from None
    by_label = {lab: role for role, lab in standard_trial(static)[1].roles.items()}
    walk_std = standard_trial(walk)[0].seen_labels()
    walk_seen = walk.seen_labels()
    out: dict[str, list[str]] = {}
    for role, label in roles.items():
        seg = _segment(role)
        if seg is None or label is None or label not in static.labels:  # a toe stand-in is no marker of the file
            continue
        if label not in walk_seen and by_label.get(label, label) not in walk_std:
            out.setdefault(seg, []).append(label)
    return out


def _static_points(static: C3dTrial) -> tuple[dict[str, np.ndarray], dict[str, str | None]]:
    """The static trial's seen markers (F, 3) m in the internal z-up frame, and its roles -> labels."""
    _, r_in = input_rotation(static)
    return ({lab: static.marker(lab) @ r_in.T for lab in static.seen_labels()}, marker_roles(static))


def _candidates(seg: str, pts: dict[str, np.ndarray], roles: dict[str, str | None], common: list[str]) -> list[str]:
    """The markers of ``common`` lying on ``seg`` in the standing static trial (module docstring)."""
    at = {lab: np.nanmean(pts[lab], axis=0) for lab in common}
    asis = (np.nanmean(pts[roles["LASI"]], axis=0) + np.nanmean(pts[roles["RASI"]], axis=0)) / 2
    if seg == "pelvis":
        return [lab for lab in common if abs(at[lab][2] - asis[2]) < PELVIS_BAND_M]
    side = seg[-1].upper()
    lateral = np.nanmean(pts[roles["LASI"]] - pts[roles["RASI"]], axis=0)
    on_side = {lab for lab in common if np.sign((at[lab] - asis) @ lateral) == (1.0 if side == "L" else -1.0)}
    knee, ankle = (np.nanmean(pts[roles[side + m]], axis=0)[2] for m in ("KNE", "ANK"))
    low, high = {"thigh": (knee, asis[2]), "shank": (ankle, knee), "foot": (-np.inf, ankle)}[seg[:-2]]
    return [lab for lab in common if lab in on_side and low < at[lab][2] < high]


def _spread(walk: C3dTrial, labels: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(k, k) standard deviation and median of the walk's distances between ``labels`` (m; inf where fewer than
    :data:`MIN_FRAMES` frames see both)."""
    p = np.stack([walk.marker(lab) for lab in labels], axis=1)
    d = np.linalg.norm(p[:, :, None] - p[:, None], axis=3)
    ok = np.isfinite(d).sum(axis=0) >= MIN_FRAMES
    with warnings.catch_warnings():  # a pair never seen together: all-NaN, set to inf below
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.where(ok, np.nanstd(d, axis=0), np.inf), np.where(ok, np.nanmedian(d, axis=0), np.inf)


def _cliques(adjacent: np.ndarray) -> list[list[int]]:
    """The maximal cliques of the graph ``adjacent`` (k, k) bool (Bron-Kerbosch): groups of markers every two of
    which move rigidly together (a full-body set's static trial may put twenty markers near the pelvis' height, whose
    subsets are too many to try one by one)."""
    near = [{int(j) for j in np.flatnonzero(row)} - {i} for i, row in enumerate(adjacent)]
    out = []

    def grow(group: set[int], could: set[int], done: set[int]) -> None:
        if not could and not done:
            out.append(sorted(group))
            return
        pivot = max(could | done, key=lambda u: len(could & near[u]))  # its neighbours come with it: not tried apart
        for v in list(could - near[pivot]):
            grow(group | {v}, could & near[v], done & near[v])
            could, done = could - {v}, done | {v}

    grow(set(), set(range(len(adjacent))), set())
    return out


def _cluster(walk: C3dTrial, candidates: list[str]) -> list[str]:
    """The largest group of ``candidates`` moving rigidly together over the walk (ties: the stiffest), or []."""
    if len(candidates) < 3:
        return []
    spread, _ = _spread(walk, candidates)
    best = max(_cliques(spread < RIGID_SPREAD_M), key=lambda g: (len(g), -spread[np.ix_(g, g)].max()))
    return [candidates[i] for i in best] if len(best) >= 3 else []


def _check_shape(walk: C3dTrial, static: C3dTrial, seg: str, cluster: list[str], ref: np.ndarray) -> None:
    """Refuse a cluster whose distances in the static trial (``ref`` (k, 3) m) differ from the walk's."""
    _, walk_d = _spread(walk, cluster)
    static_d = np.linalg.norm(ref[:, None] - ref[None], axis=2)
    worst = float(np.max(np.abs(walk_d - static_d)))
    if worst > MAX_SHAPE_CHANGE_M:
        raise InputError(f"{static.source}: the {_NAMES[seg]}'s cluster {', '.join(cluster)} is not the shape it is in "
                         f"{walk.source} (distances {1000 * worst:.1f} mm apart, more than "
                         f"{1000 * MAX_SHAPE_CHANGE_M:g}): another subject, or the markers placed again")


def _reference(static: C3dTrial, cluster: list[str], landmarks: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The cluster's mean shape (k, 3) m over the static frames seeing it and the landmarks, and each landmark's
    mean position (n, 3) m in the frame of that shape."""
    cl = np.stack([static.marker(lab) for lab in cluster], axis=1)
    lm = np.stack([static.marker(lab) for lab in landmarks], axis=1)
    use = np.isfinite(cl).all(axis=(1, 2)) & np.isfinite(lm).all(axis=(1, 2))
    if not use.any():
        raise InputError(f"{static.source}: no frame sees {', '.join(cluster + landmarks)} together")
    ref = cl[use].mean(axis=0)
    rot, shift = rigid_fit(ref, cl[use])
    local = np.einsum("fji,fnj->fni", rot, lm[use] - shift[:, None]).mean(axis=0)
    return ref, local


def carried(ref: np.ndarray, local: np.ndarray, cluster: np.ndarray) -> np.ndarray:
    """Points (F, n, 3) m fixed at ``local`` (n, 3) in the frame of the cluster shape ``ref`` (k, 3), carried by
    the cluster's markers ``cluster`` (F, k, 3) (NaN where unseen; a frame seeing fewer than 3: NaN)."""
    rot, shift = rigid_fit(ref, cluster)
    return np.einsum("fij,nj->fni", rot, local) + shift[:, None]


def with_static_landmarks(walk: C3dTrial, static: C3dTrial) -> C3dTrial:
    """``walk`` with the landmarks it lacks carried from ``static`` by their segments' clusters (module
    docstring), added under the static trial's labels; its ``from_static`` names them and their clusters."""
    missing = _missing(walk, static)
    if not missing:
        return walk
    pts, roles = _static_points(static)
    seen = walk.seen_labels()
    common = [lab for lab in walk.labels if lab in pts and lab in seen]
    labels, points = list(walk.labels), walk.points
    told = {}
    for seg, landmarks in missing.items():
        cluster = _cluster(walk, _candidates(seg, pts, roles, common))
        if len(cluster) < 3:
            raise InputError(f"{static.source}: no 3 markers it shares with {walk.source} move rigidly with the "
                             f"{_NAMES[seg]} (its landmarks {', '.join(landmarks)} need a cluster)")
        ref, local = _reference(static, cluster, landmarks)
        _check_shape(walk, static, seg, cluster, ref)
        xyz = carried(ref, local, np.stack([walk.marker(lab) for lab in cluster], axis=1))
        for k, lab in enumerate(landmarks):
            if lab in labels:  # a label the walk has but never sees
                points = points.copy()
                points[:, labels.index(lab)] = xyz[:, k]
            else:
                labels.append(lab)
                points = np.concatenate([points, xyz[:, k:k + 1]], axis=1)
            told[lab] = f"{seg}: {' '.join(cluster)}"
    return replace(walk, labels=labels, points=points,
                   from_static={"file": static.source, "landmarks": dict(sorted(told.items()))})


def read_walk(path: str | Path, static: str | Path | None = None) -> C3dTrial:
    """The C3D trial at ``path``, with the landmarks it lacks from the static trial at ``static`` when given."""
    trial = read_c3d(path)
    return trial if static is None else with_static_landmarks(trial, read_c3d(static))
