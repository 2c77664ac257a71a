"""A marker map: how a C3D's markers make the body when its labels are not the standard ones.

A TOML file (``livezmp analyze TRIAL.c3d --markers MAP.toml``) with either or both tables:

- ``[labels]``: standard role = the file's label, e.g. ``LTOE = "L.TO"``, ``SACR = "VSAC"``: the
  file's markers are renamed, then read as a Plug-in Gait / Helen Hayes set.
- ``[segments]``: a cluster set. Each of ``pelvis, thigh_l, shank_l, foot_l, thigh_r, shank_r, foot_r``
  lists 3 or more markers that move rigidly with it. ``[joints]`` gives the rule for each joint
  centre (``hip``, ``knee``, ``ankle``; or per side ``knee_l`` ...): ``"functional"`` (default), the
  point that stays fixed in both neighbouring segments' cluster frames over the take, by least
  squares (the SCoRE method, Ehrig et al. 2006, J Biomech 39:2798-2809), or ``["M1", "M2"]``, the
  mid-point of those markers (e.g. lateral and medial epicondyles). A hinge (knee, ankle in walking)
  leaves the point free along its axis: it is pinned there nearest the mid-point of the two clusters.
  Optional ``stature_m`` (else from the leg length).

Without a map, a file whose markers make no Plug-in Gait / Helen Hayes set but which carries Plug-in Gait's
segment outputs (``PELO PELA PELL PELP``, ``LFEO``..., ``LTIO``..., ``LFOO``...: every Vicon Nexus trial its model
ran on) is read as the cluster set they make, its joint centres the model's (:func:`segment_outputs_map`).

Segment frames of a cluster set: the pelvis' lateral axis joins the hip centres, its up axis is
the cluster's mean up direction carried by the cluster; a thigh or shank runs from its proximal to
its distal joint centre, turned about that line by its cluster; the foot runs from the ankle centre to
the foot marker furthest forward of it (taken as the toe). Errors are one line naming the file and field.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from livezmp.errors import InputError
from livezmp.model.c3d import C3dTrial
from livezmp.tomlfile import read_toml

CLUSTER_SEGMENTS = ("pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r")
JOINTS = {"hip": ("pelvis", "thigh"), "knee": ("thigh", "shank"), "ankle": ("shank", "foot")}
# Plug-in Gait's model outputs, which Vicon Nexus writes with each modelled trial whatever markers tracked the
# segments (its own set or a lab's clusters: fhstp/autoSIM's FH Campus Wien walks, a Cleveland set with thigh and
# shank clusters and no knee or ankle landmark): each segment's origin and its anterior, lateral and proximal axis
# tips, O A L P after the segment's name. Measured on the shared walk_plugingait and cgm24 trials: the femur's origin
# lies 58-59 mm medial of the knee marker (the knee centre) and its proximal tip a femur's length (364-414 mm) up it
# (the hip centre), the tibia's origin 37-43 mm medial of the ankle marker (the ankle centre), the foot's origin
# 28-31 mm from the toe marker; the foot's anterior tip points up the shank, not along the foot, and is not read
SEGMENT_OUTPUTS = {"pelvis": "PEL", "thigh": "FE", "shank": "TI", "foot": "FO"}
JOINT_OUTPUTS = {"hip": "FEP", "knee": "FEO", "ankle": "TIO"}
SEGMENT_OUTPUTS_SOURCE = "Plug-in Gait's segment outputs"
# a direction of the joint centre the relative rotation exercises less than this part of its main direction was
# not exercised (a hinge's axis): the prior decides there, not marker noise; below STILL rad RMS, none was
FREE_BELOW = 0.1
STILL = 1e-3


@dataclass(frozen=True)
class MarkerMap:
    """``labels`` role -> the file's label; ``segments`` segment -> its cluster's labels;
    ``joints`` 'knee_l' ... -> "functional" or a tuple of labels to average; ``stature_m`` or None."""

    source: str
    labels: tuple[tuple[str, str], ...] = ()
    segments: tuple[tuple[str, tuple[str, ...]], ...] = ()
    joints: tuple[tuple[str, str | tuple[str, ...]], ...] = field(default_factory=tuple)
    stature_m: float | None = None

    def joint_rule(self, joint: str, side: str) -> str | tuple[str, ...]:
        rules = dict(self.joints)
        return rules.get(f"{joint}_{side}", rules.get(joint, "functional"))


def _labels_list(value, where: str) -> tuple[str, ...]:
    if not (isinstance(value, list) and value and all(isinstance(v, str) and v.strip() for v in value)):
        raise InputError(f"{where} must be a list of marker labels, got {value!r}")
    return tuple(v.strip() for v in value)


def load_marker_map(path: str | Path) -> MarkerMap:
    """Read and check a marker map (see the module docstring)."""
    p = Path(path)
    doc = read_toml(p, "marker map")
    unknown = set(doc) - {"labels", "segments", "joints", "stature_m"}
    if unknown:
        raise InputError(f"{p}: unknown table(s) {', '.join(sorted(unknown))} (labels, segments, joints, stature_m)")
    labels = doc.get("labels", {})
    if not isinstance(labels, dict) or not all(isinstance(v, str) and v.strip() for v in labels.values()):
        raise InputError(f"{p}: [labels] must map roles to the file's labels (ROLE = \"LABEL\")")
    segs = doc.get("segments", {})
    if not isinstance(segs, dict):
        raise InputError(f"{p}: [segments] must be a table of segment = [markers]")
    seg_out = []
    if segs:
        missing = [s for s in CLUSTER_SEGMENTS if s not in segs]
        extra = [s for s in segs if s not in CLUSTER_SEGMENTS]
        if missing or extra:
            raise InputError(f"{p}: [segments] needs exactly {', '.join(CLUSTER_SEGMENTS)}"
                             + (f"; missing {', '.join(missing)}" if missing else "")
                             + (f"; unknown {', '.join(extra)}" if extra else ""))
        for s in CLUSTER_SEGMENTS:
            markers = _labels_list(segs[s], f"{p}: segments.{s}")
            if len(set(markers)) < 3:
                raise InputError(f"{p}: segments.{s} needs at least 3 different markers, got {len(set(markers))}")
            seg_out.append((s, markers))
    joints = doc.get("joints", {})
    if not isinstance(joints, dict):
        raise InputError(f"{p}: [joints] must be a table of joint = rule")
    joint_out = []
    for name, rule in joints.items():
        if name.split("_")[0] not in JOINTS or name not in (*JOINTS, *(f"{j}_{s}" for j in JOINTS for s in "lr")):
            raise InputError(f"{p}: joints.{name}: unknown joint (hip, knee, ankle, or with _l / _r)")
        if rule != "functional":
            rule = _labels_list(rule, f"{p}: joints.{name} (\"functional\" or a list of markers)")
        joint_out.append((name, rule))
    stature = doc.get("stature_m")
    if stature is not None and not (isinstance(stature, int | float) and 0.5 < stature < 2.5):
        raise InputError(f"{p}: stature_m must be a number between 0.5 and 2.5 m, got {stature!r}")
    if not labels and not seg_out:
        raise InputError(f"{p}: a marker map needs [labels] or [segments]")
    return MarkerMap(str(p), tuple((k, v.strip()) for k, v in labels.items()), tuple(seg_out), tuple(joint_out),
                     None if stature is None else float(stature))


def segment_outputs_map(trial: C3dTrial) -> MarkerMap | None:
    """The cluster set the file's Plug-in Gait segment outputs make (:data:`SEGMENT_OUTPUTS`), when it has all of
    them seen: each segment's origin and axis tips are its cluster, the hip centre the femur's proximal tip, the knee
    the femur's origin, the ankle the tibia's origin; None without them."""
    seen = trial.seen_labels()
    segments = [("pelvis", tuple(f"{SEGMENT_OUTPUTS['pelvis']}{k}" for k in "OALP"))]
    joints = []
    for side, t in (("L", "l"), ("R", "r")):
        segments += [(f"{seg}_{t}", tuple(f"{side}{SEGMENT_OUTPUTS[seg]}{k}" for k in tips))
                     for seg, tips in (("thigh", "OALP"), ("shank", "OALP"), ("foot", "OLP"))]
        joints += [(f"{joint}_{t}", (f"{side}{label}",)) for joint, label in JOINT_OUTPUTS.items()]
    if not all(label in seen for _, labels in segments for label in labels):
        return None
    order = {s: k for k, s in enumerate(CLUSTER_SEGMENTS)}
    return MarkerMap(SEGMENT_OUTPUTS_SOURCE, (), tuple(sorted(segments, key=lambda s: order[s[0]])), tuple(joints))


def renamed(trial: C3dTrial, mmap: MarkerMap) -> C3dTrial:
    """``trial`` with its labels renamed by the map's ``[labels]``."""
    if not mmap.labels:
        return trial
    labels = list(trial.labels)
    for role, label in mmap.labels:
        if label not in labels:
            raise InputError(f"{mmap.source}: labels.{role}: no marker {label!r} in {trial.source}")
        i = labels.index(label)
        # the file's own marker of that name, if another, is not the role: set apart
        labels = [f"{role}?" if lab == role and k != i else lab for k, lab in enumerate(labels)]
        labels[i] = role
    return replace(trial, labels=labels)


def map_labels(mmap: MarkerMap) -> list[str]:
    """Every label a cluster map reads: its segments' and its mid-point rules' markers."""
    out = [m for _, ms in mmap.segments for m in ms]
    out += [m for _, rule in mmap.joints if rule != "functional" for m in rule]
    return list(dict.fromkeys(out))


def cluster_frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A rigid cluster's pose per frame from its markers ``points`` (F, k, 3) m: origin (F, 3) at their
    centroid and rotation (F, 3, 3) that best carries the take's median shape onto each frame
    (Kabsch / Söderkvist-Wedin SVD fit)."""
    origin = points.mean(axis=1)
    centred = points - origin[:, None]
    ref = np.median(centred, axis=0)
    ref -= ref.mean(axis=0)
    return origin, _rotation(np.einsum("ki,fkj->fij", ref, centred))  # sum_k ref_k centred_k^T


def _rotation(h: np.ndarray) -> np.ndarray:
    """(F, 3, 3) the proper rotations R best carrying points onto others, from their covariances ``h`` (F, 3, 3)
    = sum_k p_k q_k^T of centred pairs (q_k ~ R p_k): V diag(1, 1, det(V U^T)) U^T of h's SVD (Kabsch)."""
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("fij,fjk->fik", vt.transpose(0, 2, 1), u.transpose(0, 2, 1))))
    fix = np.ones((len(h), 3))
    fix[:, 2] = d
    return np.einsum("fji,fj,fkj->fik", vt, fix, u)  # V diag(1, 1, d) U^T


def rigid_fit(ref: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (F, 3, 3) and shift (F, 3) m carrying the shape ``ref`` (k, 3) m onto each frame of ``points``
    (F, k, 3) m, ``points`` ~ R ref + shift by least squares over the markers each frame sees (NaN where unseen);
    NaN in a frame seeing fewer than 3."""
    seen = np.isfinite(points).all(axis=2)
    w = seen.astype(float)
    n = np.maximum(w.sum(axis=1), 1.0)[:, None]
    p = np.where(seen[..., None], points, 0.0)
    cp = p.sum(axis=1) / n
    cr = w @ ref / n
    h = np.einsum("fk,fki,fkj->fij", w, ref[None] - cr[:, None], p - cp[:, None])
    rot = _rotation(h)
    shift = cp - np.einsum("fij,fj->fi", rot, cr)
    few = seen.sum(axis=1) < 3
    rot[few], shift[few] = np.nan, np.nan
    return rot, shift


def functional_centre(o1: np.ndarray, r1: np.ndarray, o2: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """The joint centre (F, 3) m between two segments with poses (o, R) per frame: the point fixed in
    both frames, c1 in the first and c2 in the second, minimising sum |o1 + R1 c1 - o2 - R2 c2|²
    (SCoRE, Ehrig et al. 2006). Along directions the motion leaves free (a hinge's axis; see
    ``FREE_BELOW``) the point is the one nearest the mid-point of the two origins. Returned as the mean
    of both estimates."""
    n = len(o1)
    a = np.concatenate([r1, -r2], axis=2).reshape(3 * n, 6)
    b = (o2 - o1).reshape(3 * n)
    mid = (o1 + o2) / 2
    prior = np.concatenate([np.mean(np.einsum("fji,fj->fi", r1, mid - o1), axis=0),
                            np.mean(np.einsum("fji,fj->fi", r2, mid - o2), axis=0)])
    u, sv, vt = np.linalg.svd(a, full_matrices=False)
    # sv[:3]: the two estimates' difference, always seen (~sqrt(2n)); sv[3:]: set by the relative rotation
    seen = sv > max(FREE_BELOW * sv[3], STILL * np.sqrt(n))
    sol = vt[seen].T @ ((u[:, seen].T @ b) / sv[seen]) + vt[~seen].T @ (vt[~seen] @ prior)
    p1 = o1 + r1 @ sol[:3]
    p2 = o2 + r2 @ sol[3:]
    return (p1 + p2) / 2
