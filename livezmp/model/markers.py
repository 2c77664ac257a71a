"""A body model from gait-lab markers: marker set -> joint centres -> segment frames -> body.

Supported by their standard labels (prefixes already stripped): Vicon Plug-in Gait lower body
and its full-body superset (or the trunk's four markers C7 T10 CLAV STRN alone, or only its top, C7 with
CLAV or LCLA + RCLA, or the shoulders LSHO + RSHO: the thorax is tracked, head and arms placed on it; with the
Helen Hayes upper body's SHO, ELB and WRI on both sides the arms are tracked too, the head placed), Helen
Hayes / modified Helen Hayes (SACR or LPSI/RPSI), CGM 2.x lower limb.
Needed: LASI, RASI, LPSI+RPSI or SACR, and per side KNE, ANK, TOE; optional TIB wands (the ankle's chord
rule; THI wands are read but do not place the knee), medial knee/ankle markers, HEE. Other labels and
cluster sets: :mod:`livezmp.model.marker_map`; a cluster set's landmarks from its static trial:
:mod:`livezmp.model.static_trial`.

- Hip joint centres: Harrington et al. 2007 (J Biomech 40:595-602), the pelvic-width-only
  regression in the ASIS/PSIS pelvis frame (x anterior, z lateral, y superior; mm):
  x = -0.24 PD - 9.9, y = -0.30 PW - 10.9, z = ±(0.33 PW + 7.3).
- Knee / ankle centres: the mid-point of the lateral and medial markers when both exist; else
  half the knee (ankle) width plus a marker radius from the lateral marker: the knee medially along
  the pelvis' lateral axis (a THI wand's plane needs the static trial's thigh-rotation offset, which
  a walking trial lacks), the ankle by Plug-in Gait's chord rule, in the plane of the knee centre, the
  TIB wand and the marker, with the knee centre–ankle centre–marker angle 90° (without a wand,
  medially along the pelvis' lateral axis too).
- Segments: pelvis (lower trunk), thighs, shanks, feet, each a rigid body with six
  degrees of freedom (three prismatic, then yaw, pitch, roll) placed on its own markers every frame
  (no joint constraints: soft-tissue motion cannot break a chain). Masses, centres of mass and
  radii of gyration from de Leva (1996), or for a child that table with Jensen's mass proportions at the
  child's age (:mod:`livezmp.model.anthropometry`, chosen from the file's age or height, or ``bsp``), each
  centre of mass off its joint-centre line along the segment's forward axis by Dumas et al.'s (2007)
  fraction of its length (the thigh's 4.1 % behind); the foot's centre of mass at the middle of ankle centre
  to toe marker (Winter 2009, table 4.1).
- Head, arms and trunk (HAT) of a lower-body set are placed from the pelvis: de Leva's head,
  trunk and arm segments stacked upright above the mid-hip (arms hanging from the cervicale),
  their combined centre of mass above the mid-hip, 3 mm behind it for a 1.75 m subject (each part off its
  line as Dumas et al. measured). The HAT moves with the mid-hip and
  turns with the pelvis' heading but stays upright: the trunk does not follow the pelvis'
  obliquity and tilt in walking (the spine takes them up). ``hat_follows_pelvis`` rigidly
  attaches it to the pelvis instead (at the take's mean tilt), for comparison.

Short marker gaps (up to ``max_gap_s``) are filled by cubic interpolation; longer gaps are
reported and the take is cut to the longest stretch where every needed marker is present. A toe marker (or its
metatarsal stand-in) lost for longer is first placed from the heel and the two malleoli where a set has them
and they are seen (:func:`toe_from_heel_and_malleoli`): BTS' few cameras lose Padova's forefoot markers on most
frames (MOtoNMS' UNIPD walks: the right metatarsal heads seen together on 41-45 of 276-307 frames).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt

from livezmp.checks import MAX_COORDINATE_M
from livezmp.errors import InputError
from livezmp.model.anthropometry import ADULT, DE_LEVA_MALE, BspTable, SegmentParams, choose_table
from livezmp.model.body import BodyModel, CorrectionJoints, Foot, point_mass_copy, world_from_up_axis
from livezmp.model.bvh_body import DEFAULT_MASS, LEG_FRACTION_OF_STATURE
from livezmp.model.c3d import C3dTrial
from livezmp.model.euler import other_branch, wrapped
from livezmp.model.marker_labels import MEDIAL_ROLES, MIN_JOINT_WIDTH_M, LabelMatch, standard_trial
from livezmp.model.marker_map import (
    JOINTS,
    SEGMENT_OUTPUTS_SOURCE,
    MarkerMap,
    cluster_frames,
    functional_centre,
    map_labels,
    renamed,
    segment_outputs_map,
)

MARKER_RADIUS = 0.007  # m: Plug-in Gait's default 14 mm markers
KNEE_WIDTH_OF_STATURE = 0.064  # typical knee / ankle widths (m / m) when the file gives none
ANKLE_WIDTH_OF_STATURE = 0.040
FOOT_LENGTH_OF_STATURE = 258.1 / 1741  # de Leva foot length over stature
SOLE_WIDTH_OF_STATURE = 0.055
_LEGS = ("thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r")
# Plug-in Gait full body: trunk, head and arm markers (FIN optional); all present or the HAT is placed
_UPPER = ("C7", "T10", "CLAV", "STRN", "LFHD", "RFHD", "LBHD", "RBHD", "LSHO", "RSHO", "LELB", "RELB", "LWRA", "RWRA",
          "LWRB", "RWRB")
_TRUNK = ("C7", "T10", "CLAV", "STRN")
# the trunk's top alone: the cervicale and the sternal notch, or the two clavicles' markers (Helen Hayes sets), or
# the two acromia (the upper-body Helen Hayes sets Motion Analysis writes: SHO, ELB, WRI; c3d.org's Walk1, newwalk)
_TRUNK_TOPS = (("C7", "CLAV"), ("C7", "LCLA", "RCLA"), ("LSHO", "RSHO"))
# the cervicale (1 - de Leva's vertex-cervicale head length 242.9 / 1741 = 0.860 of stature high) above the
# acromia (0.818: Drillis & Contini 1966, as Winter 2009, Biomechanics and Motor Control, Fig. 4.1 gives them)
CERVICALE_ABOVE_ACROMIA = 1.0 - DE_LEVA_MALE["head"].length_fraction - 0.818
# the HAT's frame as virtual points (origin, anterior, left, proximal axis tips: Plug-in Gait's segment-axis
# convention), written by `livezmp correct` when it leans the HAT; when present they orient the placed HAT
HAT_POINTS = ("HATO", "HATA", "HATL", "HATP")
_ARM_DIMENSIONS = ("ShoulderOffset", "ElbowWidth", "WristWidth")  # Plug-in Gait's names, after the side letter
SHOULDER_OFFSET = 0.04  # m: shoulder joint centre below the acromion marker's centre when the file gives none (approx.)
ELBOW_WIDTH_OF_STATURE = 0.042  # typical elbow width (m / m)
WRIST_WIDTH_OF_STATURE = 0.032  # typical wrist width across the styloids (m / m; ~56 mm at 1.75 m, approximation)
# the Helen Hayes upper body (Motion Analysis: c3d.org's Walk1, newwalk): one marker at the acromion, the lateral
# epicondyle and the wrist per side; with both arms' three the arms are tracked, the head placed on the thorax
_ARMS = ("LSHO", "LELB", "LWRI", "RSHO", "RELB", "RWRI")
_HEAD3 = ("THEA", "FHEA", "RHEA")  # its head (Walk1): top, front and rear of the head
_HEAD4 = ("LFHD", "RFHD", "LBHD", "RBHD")  # Plug-in Gait's head; either set is tracked wherever the thorax is
# Plug-in Gait's TIB wand sits on the shank's lateral side (Vicon's Plug-in Gait reference: "lower lateral 1/3 surface
# of the shank"), so the chord rule's plane is the shank's frontal plane and the ankle centre lies across the line from
# the ankle marker to the knee centre from it. It is read so where it lies lateral of that line (along the pelvis'
# lateral axis) in this share of the frames; biomechZoo's subject HC036A has its right TIB 47 mm medial and 38 mm in
# front of the line, where the chord rule's two solutions swapped sides between frames (a 180 deg turn of the shank)
TIB_LATERAL_SHARE = 0.95
MAX_TURN_RAD = np.pi / 2  # between two frames: 78 rad/s at 50 Hz, beyond any segment in walking or running
_OPTIONAL = ("THI", "TIB", "HEE", "FIN", "KNE_med", "ANK_med")  # role suffixes the body can do without
_CHANNELS = ("x", "y", "z", "yaw", "pitch", "roll")
# Plausibility of marker-derived geometry: beyond these a file is corrupt, not a person
STATURE_RANGE_M = (0.5, 2.6)
SEGMENT_LENGTH_RANGE_M = (0.01, 1.5)  # joint centre to joint centre (median over the take)
# frames seeing a toe with the heel and both malleoli that place it where it is lost (toe_from_heel_and_malleoli)
RIGID_FILL_MIN_FRAMES = 10
_SIDES = {"left": ("L", 1.0, "l"), "right": ("R", -1.0, "r")}
# How far (fore-aft, lateral) the head-arms-trunk centre of mass sways about the walk's straight-line trend,
# as a fraction of the mid-hip's sway (:func:`hat_sway`): measured on the two trials whose trunk is tracked by
# markers (c3d.org samples 23 Vicon_analysis: 0.76 / 0.68, 32 vicon_zerowire: 0.71 / 0.98; their mean), never on
# the lower-body trials it is used for (docs/validation.md, `python benchmarks/bench_forceplates.py DIR`); the
# median over the four trials whose trunk is tracked (with 04 sub_labels and 09 PlugInC3D) is 0.74 / 0.83
TRUNK_SWAY_GAIN = (0.73, 0.83)
# The trunk is no rigid follower of the pelvis: it travels with it (the walk's slow changes of speed, below the
# step frequency) and damps its step-by-step sway, the more the higher the harmonic (the trunk attenuates the
# pelvis' accelerations: Menz, Lord & Fitzpatrick 2003, Gait Posture 18:35; Kavanagh et al. 2004, Gait Posture
# 20:291). On the four tracked trunks the sway gain per band (fore-aft) is 0.9-1.6 below 1.2 Hz, 0.53-0.75 at the
# step frequency, 0.40-0.67 at 2.5-4 Hz, 0.17-0.42 at 4-6 Hz; the constant gain above, fitted to positions (the
# fundamental), overstates the HAT's acceleration, which is what the ZMP uses, 1.5 times. A placed HAT in a whole
# take therefore follows the mid-hip's sway below TRUNK_FOLLOW_HZ and sways TRUNK_STEP_GAIN times it above: that
# gain is the four tracked trunks' median least-squares gain of the acceleration (6 Hz band; fore-aft 0.50, 0.58,
# 0.46, 0.46; lateral 0.61, 0.49, -0.59, 0.52), and this predicts their trunks' acceleration better than the constant
# in 7 of 8 axes (docs/validation.md, "Why the ZMP swung too far"). TRUNK_SWAY_GAIN remains the constant-gain
# model's (hat_follow_hz None); `calibrate` fits the follow model.
TRUNK_STEP_GAIN = (0.48, 0.50)
TRUNK_FOLLOW_HZ = 1.0  # below the step frequency of any walk (1.2-2.7 Hz on the plate trials), above its speed changes


@dataclass(frozen=True)
class MarkerBodyOptions:
    """``total_mass`` kg; ``hat_offset`` m, the HAT centre of mass in the pelvis' upright frame
    (forward, left, up from the mid-hip) replacing the table's (0, 0, h); ``hat_fraction`` of
    total mass replacing de Leva's; ``floor_z`` m (internal frame) where the soles are, None =
    from the lowest foot markers; ``max_gap_s`` s, the longest gap filled; ``hat_sway_gain`` (fore-aft,
    lateral) how far a placed HAT sways relative to the mid-hip over a whole take (:func:`hat_sway`; None:
    it moves with the mid-hip), above ``hat_follow_hz`` Hz, below which it follows the mid-hip (None: at every
    frequency); ``trunk_fraction`` of total mass and ``trunk_offset`` m, a tracked thorax' (middle + upper trunk)
    mass and centre of mass in its own frame (forward, left, up the trunk from its origin at the cervicale's level)
    replacing the table's (a full-body or trunk set's subject file; the hat_* are a placed HAT's, a lower-body
    set's: each kind is refused for the other)."""

    total_mass: float = DEFAULT_MASS
    hat_offset: tuple[float, float, float] | None = None
    hat_fraction: float | None = None
    trunk_fraction: float | None = None
    trunk_offset: tuple[float, float, float] | None = None
    floor_z: float | None = None
    max_gap_s: float = 0.1
    hat_follows_pelvis: bool = False
    hat_sway_gain: tuple[float, float] | None = TRUNK_STEP_GAIN
    hat_follow_hz: float | None = TRUNK_FOLLOW_HZ
    marker_map: MarkerMap | None = None  # labels renamed, or a cluster set (livezmp.model.marker_map)
    bsp: str = "auto"  # segment table: "auto" (from the file's age / height), "adult" or "child" (anthropometry)
    age_years: float | None = None  # the subject's age, replacing the file's


@dataclass
class MarkerTake:
    """A body and its frames (F, 6 per segment): x, y, z (m), yaw, pitch, roll (rad), internal frame."""

    body: BodyModel
    frames: np.ndarray
    first_frame: int  # index in the C3D of frames[0]
    notes: dict = field(default_factory=dict)
    centres: dict = field(default_factory=dict)  # joint -> side -> (F, 3) m, internal frame
    roles: dict = field(default_factory=dict)  # marker role -> label, as found in the trial
    subject: C3dTrial | None = None  # the trial the body was calibrated on (its widths, height, labels)
    # a label of ``roles`` that is the mean of several of the file's (the toe's metatarsal stand-in) -> those labels
    mean_of: dict = field(default_factory=dict)
    # the segments whose mass rides on another segment's markers (:func:`placed_segments`)
    placed: tuple[str, ...] = ()


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (F, 3) arrays: ``np.cross``'s arithmetic without its per-call
    overhead (a live stream converts one frame at a time)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    c0, c1, c2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    out = np.empty((*c0.shape, 3))
    out[..., 0], out[..., 1], out[..., 2] = c0, c1, c2
    return out


def _norm(v: np.ndarray) -> np.ndarray:
    """Row-wise length (..., 1) of (..., 3) vectors: ``np.linalg.norm``'s sum of squares without its checks."""
    return np.sqrt(np.add.reduce(v * v, axis=-1, keepdims=True))


def _columns(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotations whose columns are the (F, 3) axes ``x``, ``y``, ``z`` (``np.stack(axis=-1)``)."""
    out = np.empty((*x.shape, 3))
    out[..., 0], out[..., 1], out[..., 2] = x, y, z
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    n = _norm(v)  # a zero vector gives NaN (as 0 / 0 would, without its warning): refused by _check_turns
    return np.divide(v, n, out=np.full(v.shape, np.nan), where=n > 0)


def fill_gaps(x: np.ndarray, max_gap: int) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Fill runs of NaN rows in ``x`` (F, 3) of up to ``max_gap`` frames by a cubic spline through
    the seen samples; return the filled copy and the (first, last) frames of the gaps left open."""
    bad = ~np.isfinite(x).all(axis=1)
    if not bad.any():
        return x, []
    out = x.copy()
    good = np.flatnonzero(~bad)
    edges = np.flatnonzero(np.diff(np.r_[0, bad.astype(np.int8), 0]))
    spline = CubicSpline(good, x[good]) if len(good) >= 4 else None
    left_open = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        inner = a > 0 and b < len(x)
        if inner and b - a <= max_gap and spline is not None:
            out[a:b] = spline(np.arange(a, b))
        else:
            left_open.append((int(a), int(b - 1)))
    return out, left_open


def _foot_frames(heel: np.ndarray, lateral: np.ndarray, medial: np.ndarray) -> np.ndarray:
    """(F, 3, 3) frames of the heel and the two malleoli (F, 3): x from the heel to the lateral malleolus, z normal
    to the three (NaN where one is unseen)."""
    x = _unit(lateral - heel)
    z = _unit(np.cross(x, medial - heel))
    return _columns(x, np.cross(z, x), z)


def toe_from_heel_and_malleoli(toe: np.ndarray, heel: np.ndarray, lateral: np.ndarray, medial: np.ndarray,
                               max_gap: int) -> tuple[np.ndarray, int]:
    """``toe`` (F, 3) with its gaps longer than ``max_gap`` frames (those :func:`fill_gaps` leaves open) placed from
    the ``heel`` and the ``lateral`` and ``medial`` malleoli where those three are seen: at its median position in
    their frame over the frames seeing all four, at least :data:`RIGID_FILL_MIN_FRAMES` (else unchanged). The
    malleoli lie on the ankle's flexion axis, so the heel carries the foot's turn about it. Returns the filled toe
    and how many frames were placed."""
    _, open_gaps = fill_gaps(toe, max_gap)
    if not open_gaps:
        return toe, 0
    rot = _foot_frames(heel, lateral, medial)
    refs = np.isfinite(rot).all(axis=(1, 2))
    both = refs & np.isfinite(toe).all(axis=1)
    if both.sum() < RIGID_FILL_MIN_FRAMES:
        return toe, 0
    local = np.median(np.einsum("fji,fj->fi", rot[both], toe[both] - heel[both]), axis=0)
    gap = np.zeros(len(toe), dtype=bool)
    for a, b in open_gaps:
        gap[a:b + 1] = True
    fill = gap & refs
    out = toe.copy()
    out[fill] = heel[fill] + rot[fill] @ local
    return out, int(fill.sum())


def _need(trial: C3dTrial, match: LabelMatch, shown: list[str]) -> dict[str, str | None]:
    """Marker roles -> labels found; raises InputError naming what a usable set lacks (a role that several
    labels claim in ``match``: naming them; the file's labels ``shown`` as it writes them)."""
    have = trial.seen_labels()  # a label never seen is missing
    roles: dict[str, str | None] = {"LASI": "LASI", "RASI": "RASI"}
    missing = [m for m in ("LASI", "RASI") if m not in have]
    if {"LPSI", "RPSI"} <= have:
        roles.update(LPSI="LPSI", RPSI="RPSI")
    elif "SACR" in have:
        roles["SACR"] = "SACR"
    else:
        missing.append("LPSI+RPSI or SACR")
    for s in "LR":
        for m in ("KNE", "ANK", "TOE"):
            if s + m in have:
                roles[s + m] = s + m
            else:
                missing.append(s + m)
        for m in ("THI", "TIB", "HEE"):
            roles[s + m] = s + m if s + m in have else None
        for m, medial in MEDIAL_ROLES.items():
            roles[s + m + "_med"] = s + medial if s + medial in have else None
    roles.update({p: p for p in HAT_POINTS if set(HAT_POINTS) <= have})
    upper = [u for u in _UPPER if u in have]
    if len(upper) == len(_UPPER):
        roles.update({u: u for u in _UPPER})
        roles.update({s + "FIN": s + "FIN" for s in "LR" if s + "FIN" in have})
    else:
        if set(_TRUNK) <= have:  # the thorax is seen; head and arms are placed on it
            roles.update({u: u for u in _TRUNK})
        elif top := next((t for t in _TRUNK_TOPS if set(t) <= have), None):  # its top seen: the thorax leans
            roles.update({u: u for u in top})
        if set(_ARMS) <= have:  # and the arms are tracked
            roles.update({u: u for u in _ARMS})
        if _trunk_tracked(roles):  # and the head, on its own markers; else placed on the thorax
            roles.update({u: u for u in next((h for h in (_HEAD4, _HEAD3) if set(h) <= have), ())})
    if missing:
        ambiguous = match.ambiguous
        if all(m in ambiguous for m in missing):
            match.check(trial.source, missing)
        missing = [f"{m} (never seen)" if m in trial.labels else
                   f"{m} ({' and '.join(map(repr, ambiguous[m]))} claim it)" if m in ambiguous else m
                   for m in missing]
        seen = ", ".join(shown[:12]) + (" ..." if len(shown) > 12 else "")
        raise InputError(f"{trial.source}: no Plug-in Gait / Helen Hayes marker set: missing {', '.join(missing)} "
                         f"(markers in the file: {seen}){_static_hint(missing)}")
    return roles


def _static_hint(missing: list[str]) -> str:
    """For a set missing only knee and ankle markers (a cluster set's landmarks, which its static trial carries):
    how to give them."""
    if all(m[1:4] in ("KNE", "ANK") for m in missing):
        return "; a cluster set's knee and ankle landmarks come from its static trial: --static STATIC.c3d"
    return ""


# the mean pelvis-above-ankles vector within ~35 deg of a lab axis: that axis is up (a standing or walking
# subject leans far less; a lab's axes are level)
UPRIGHT_COS = 0.8


def _up_rotation(m: dict[str, np.ndarray], source: str) -> tuple[str, np.ndarray]:
    """The input's up axis (pelvis above the feet) and the rotation into the internal z-up frame."""
    return _up_from((m["LASI"] + m["RASI"]) / 2 - (m["LANK"] + m["RANK"]) / 2, source)


def _up_from(pelvis_above_feet: np.ndarray, source: str) -> tuple[str, np.ndarray]:
    """The lab axis, signed ("z", "y", "x", "-z" ...), along which the pelvis stands above the feet, and the
    rotation into the internal z-up frame; InputError when no axis carries most of that vector (a subject
    not upright: lying, or markers mislabelled)."""
    v = np.nanmean(pelvis_above_feet, axis=0)
    ax = int(np.argmax(np.abs(v)))
    if not np.isfinite(v).all() or abs(v[ax]) < UPRIGHT_COS * np.linalg.norm(v):
        raise InputError(f"{source}: cannot tell the up axis (pelvis-to-ankle vector {np.round(v, 3)} m)")
    up = ("-" if v[ax] < 0 else "") + "xyz"[ax]
    return up, world_from_up_axis(up)


def _standard(trial: C3dTrial, mmap: MarkerMap | None) -> tuple[C3dTrial, dict[str, str | None], LabelMatch]:
    """``trial`` with its markers under their roles' names (a map's [labels], then the built-in conventions of
    :mod:`livezmp.model.marker_labels`), the roles the body needs -> those names, and the match."""
    pinned = frozenset(role for role, _ in mmap.labels) if mmap is not None else frozenset()
    std, match = standard_trial(trial if mmap is None else renamed(trial, mmap), pinned)
    roles = _need(std, match, trial.labels)
    match.check(trial.source)
    return std, roles, match


def _map_for(trial: C3dTrial, mmap: MarkerMap | None) -> MarkerMap | None:
    """``mmap``; without one, the cluster set of the file's Plug-in Gait segment outputs where its markers make no
    standard set (:func:`livezmp.model.marker_map.segment_outputs_map`), else None."""
    implied = segment_outputs_map(trial) if mmap is None else None
    if implied is None:
        return mmap
    try:
        _standard(trial, None)
    except InputError:
        return implied
    return None


def _as_written(roles: dict[str, str | None], match: LabelMatch) -> dict[str, str | None]:
    """``roles`` (role -> the standard trial's label) with the file's own labels."""
    return {r: None if lab is None else match.roles.get(lab, lab) for r, lab in roles.items()}


def marker_roles(trial: C3dTrial, mmap: MarkerMap | None = None) -> dict[str, str | None]:
    """Role -> the label (as the file writes it) of each marker ``trial``'s marker body reads, through the marker
    map ``mmap``'s [labels] if given; None: absent."""
    _, roles, match = _standard(trial, mmap)
    original = dict(mmap.labels) if mmap is not None else {}  # a role the map names -> the file's label
    return {r: None if lab is None else original.get(lab, lab) for r, lab in _as_written(roles, match).items()}


def marker_labels(trial: C3dTrial, mmap: MarkerMap | None = None) -> list[str]:
    """The labels of ``trial``'s markers that its marker body (through the marker map ``mmap``, if any) is built
    from, as the file writes them."""
    mmap = _map_for(trial, mmap)
    if mmap is not None and mmap.segments:
        return _cluster_labels(trial, mmap)
    return [label for label in marker_roles(trial, mmap).values() if label is not None]


def input_rotation(trial: C3dTrial, mmap: MarkerMap | None = None) -> tuple[str, np.ndarray]:
    """The trial's up axis and the rotation (3, 3) from its world frame into the internal z-up one."""
    mmap = _map_for(trial, mmap)
    if mmap is not None and mmap.segments:
        return _up_from(_cluster_up_vector(_cluster_markers(renamed(trial, mmap), mmap), mmap), trial.source)
    trial, roles, match = _standard(trial, mmap)
    raw = {k: trial.marker(v) for k, v in roles.items() if v}
    _check_coordinates(raw, _as_written(roles, match), trial)
    return _up_rotation(raw, trial.source)


def _cluster_markers(trial: C3dTrial, mmap: MarkerMap) -> dict[str, np.ndarray]:
    """The cluster map's markers (F, 3) m, and the HAT points when the file has them all (a corrected take);
    InputError naming those the file does not have (or never sees)."""
    labels = _cluster_labels(trial, mmap)
    have = trial.seen_labels()
    missing = [label for label in labels if label not in have]
    if missing:
        raise InputError(f"{trial.source}: markers of the map {mmap.source} not in the file (or never seen): "
                         f"{', '.join(missing)}")
    return {label: trial.marker(label) for label in labels}


def _cluster_labels(trial: C3dTrial, mmap: MarkerMap) -> list[str]:
    """The labels a cluster set's body reads: the map's, and the HAT points when the file has them all."""
    return map_labels(mmap) + (list(HAT_POINTS) if set(HAT_POINTS) <= set(trial.labels) else [])


def _cluster_up_vector(m: dict[str, np.ndarray], mmap: MarkerMap) -> np.ndarray:
    seg = dict(mmap.segments)
    centroid = {s: np.mean([m[label] for label in seg[s]], axis=0) for s in ("pelvis", "foot_l", "foot_r")}
    return centroid["pelvis"] - (centroid["foot_l"] + centroid["foot_r"]) / 2


def _wand_side(proximal: np.ndarray, wand: np.ndarray, marker: np.ndarray, medial: np.ndarray) -> np.ndarray:
    """(F,) how far along ``medial`` (F, 3) the unit direction from the line ``marker``-``proximal`` to ``wand`` in
    their plane points: negative where the wand lies lateral of the line, as Plug-in Gait places it."""
    d = _unit(proximal - marker)
    w = wand - marker
    return np.add.reduce(_unit(w - np.add.reduce(w * d, axis=-1, keepdims=True) * d) * medial, axis=-1)


def _chord(proximal: np.ndarray, wand: np.ndarray, marker: np.ndarray, delta: float,
           medial: np.ndarray) -> np.ndarray:
    """Plug-in Gait's chord rule: the point J at ``delta`` from ``marker``, in the plane of the three
    points, with angle P-J-marker 90°; of the two such points, the one further along ``medial`` (F, 3)."""
    d = proximal - marker
    e1 = _unit(d)
    w = wand - marker
    e2 = _unit(w - np.add.reduce(w * e1, axis=-1, keepdims=True) * e1)
    c = np.minimum(np.maximum(delta / _norm(d), -1.0), 1.0)
    s = np.sqrt(1.0 - c * c) * np.sign(np.add.reduce(e2 * medial, axis=-1, keepdims=True))
    return marker + delta * (c * e1 + s * e2)


def _frame(z_dir: np.ndarray, y_ref: np.ndarray) -> np.ndarray:
    """(F, 3, 3) rotations with z along ``z_dir`` and y as close to ``y_ref`` as allowed; columns x, y, z."""
    z = _unit(z_dir)
    x = _unit(_cross(y_ref, z))
    return _columns(x, _cross(z, x), z)


def _foot_frame(x_dir: np.ndarray, y_ref: np.ndarray) -> np.ndarray:
    x = _unit(x_dir)
    z = _unit(_cross(x, y_ref))
    return _columns(x, _cross(z, x), z)


def _local(rot: np.ndarray, origin: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Median position (3,) of points ``p`` (F, 3) in the moving frames (rot, origin)."""
    return np.median(np.einsum("fji,fj->fi", rot, p - origin), axis=0)


def _euler_zyx(rot: np.ndarray, unwrap: bool = True) -> np.ndarray:
    """(F, 3) yaw, pitch, roll (rad) with R = Rz(yaw) Ry(pitch) Rx(roll), unwrapped over frames (else
    each within ±pi).

    Unwrapped, a frame passing over the angles' singularity (its x axis vertical, pitch ±90°) stays on the branch it
    came by: every rotation is also (yaw + pi, pi - pitch, roll + pi), and arcsin folds the pitch back at ±90°,
    where yaw and roll then jumped by pi each between two frames (a child's hand swung forward, biomechZoo's
    HC036A23: 170° in 10 ms, the ZMP 1.9 m off). Of the two, each frame takes the one nearer its predecessor's."""
    angles = np.empty((len(rot), 3))
    angles[:, 0] = np.arctan2(rot[:, 1, 0], rot[:, 0, 0])
    angles[:, 1] = np.arcsin(np.minimum(np.maximum(-rot[:, 2, 0], -1.0), 1.0))
    angles[:, 2] = np.arctan2(rot[:, 2, 1], rot[:, 2, 2])
    if not unwrap:
        return angles
    other = other_branch(angles)

    def apart(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return np.sum(wrapped(a - b) ** 2, axis=1)

    # the other branch is as far from the other branch before as this one from this one: a crossing is a frame whose
    # other branch lies nearer the frame before than its own; the branch changes at each crossing
    crossed = np.r_[False, apart(other[1:], angles[:-1]) < apart(angles[1:], angles[:-1])]
    on_other = (np.cumsum(crossed) % 2).astype(bool)
    return np.unwrap(np.where(on_other[:, None], other, angles), axis=0)


def hat_table(stature: float, part: str = "hat",
              table: dict[str, SegmentParams] = DE_LEVA_MALE) -> tuple[float, np.ndarray, np.ndarray]:
    """Head-arms-trunk above the lower trunk, from de Leva (1996) (masses from ``table``, a segment table of
    :mod:`livezmp.model.anthropometry`): mass fraction, centre of mass (3,) m from the mid-hip
    (x forward, y left, z up; forward each part's ``anterior_fraction`` of its length, Dumas et al. 2007), and
    its inertia (3, 3) per kg of HAT about that point. Segments stacked upright: lower, middle, upper trunk, head;
    each arm hangs from the cervicale (the top of the upper trunk) along the body's side. ``part``: ``"hat"`` all
    of it; ``"head_and_arms"`` without the middle and upper trunk, ``"arms"`` the two arms alone, the centre then
    measured from the cervicale."""
    t = table
    h = stature / 1741.0  # de Leva lengths are mm for a 1741 mm man
    parts = []  # (mass fraction, CoM (3,) m, segment, length m)

    def at(name: str, z: float, length: float) -> tuple[float, np.ndarray, str, float]:
        return t[name].mass_fraction, np.array([t[name].anterior_fraction * length, 0.0, z]), name, length

    base = 145.7 * h  # omphalion above the mid-hip: the lower trunk's length
    for name, length_mm in (("middle_trunk", 215.5), ("upper_trunk", 170.7)):
        top = base + length_mm * h  # proximal end is the top
        parts.append(at(name, top - t[name].com_fraction * length_mm * h, length_mm * h))
        base = top
    head_len = 242.9 * h
    parts.append(at("head", base + head_len * (1 - t["head"].com_fraction), head_len))
    joint = joint_top = base  # shoulders at the cervicale
    for name in ("upper_arm", "forearm", "hand"):
        length = t[name].length_fraction * stature
        parts += [at(name, joint - t[name].com_fraction * length, length)] * 2
        joint -= length
    if part != "hat":
        left_out = ("middle_trunk", "upper_trunk") + (("head",) if part == "arms" else ())
        parts = [(f, c - [0.0, 0.0, joint_top], n, length) for f, c, n, length in parts if n not in left_out]
    mass = sum(p[0] for p in parts)
    com = sum(p[0] * p[1] for p in parts) / mass
    inertia = np.zeros((3, 3))
    for frac, c, name, length in parts:
        rs, rt, rl = (g * length for g in t[name].gyration)
        # parallel axes along the vertical only, as for the arms' spread across (the parts' forward offsets, under
        # 20 mm, are left out: a HAT that turns only about the vertical then has no horizontal angular momentum)
        inertia += frac / mass * (np.diag([rs * rs, rt * rt, rl * rl]) + (c[2] - com[2]) ** 2 * np.diag([1, 1, 0.0]))
    return mass, com, inertia


def _trim(markers: dict[str, np.ndarray], max_gap: int, rate: float) -> tuple[slice, list[dict]]:
    """Fill short gaps in place; the longest stretch of frames where every marker is present, and
    the gaps left open (label, first and last time s)."""
    open_gaps = []
    ok = np.ones(len(next(iter(markers.values()))), dtype=bool)
    for label, x in markers.items():
        markers[label], gaps = fill_gaps(x, max_gap)
        for a, b in gaps:
            ok[a:b + 1] = False
            open_gaps.append({"marker": label, "from_s": round(a / rate, 4), "to_s": round(b / rate, 4)})
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
    if len(edges) == 0:
        raise InputError("no frame has every needed marker")
    runs = list(zip(edges[::2], edges[1::2], strict=True))
    a, b = max(runs, key=lambda r: r[1] - r[0])
    return slice(int(a), int(b)), open_gaps


def body_from_markers(trial: C3dTrial, opts: MarkerBodyOptions | None = None) -> MarkerTake:
    """Build the body and its frames from ``trial``'s markers (see the module docstring)."""
    opts = opts or MarkerBodyOptions()
    if not opts.total_mass > 0:
        raise InputError(f"total mass must be positive, got {opts.total_mass}")
    mmap = _map_for(trial, opts.marker_map)
    if mmap is not None and mmap.segments:
        take = _cluster_take(renamed(trial, mmap), opts, mmap)
    else:
        take = _standard_take(trial, opts)
    if trial.from_static:  # which landmarks a static trial gave (livezmp.model.static_trial)
        take.notes["from_static_trial"] = trial.from_static
    _check_subject_kind(take, opts, trial.source)
    return take


def _check_subject_kind(take: MarkerTake, opts: MarkerBodyOptions, source: str) -> None:
    """Refuse a subject's parameters for the other kind of marker set: a placed HAT's (``hat_*``, calibrated on a
    lower-body set) for a set that tracks the trunk, a tracked thorax' (``trunk_*``) for one that places the HAT."""
    placed = "hat" in take.placed
    if placed and (opts.trunk_fraction is not None or opts.trunk_offset is not None):
        raise InputError(f"{source}: the subject is a tracked trunk's (trunk_fraction, calibrated on a full-body or "
                         "trunk marker set) but this set places the head, arms and trunk on the pelvis: calibrate on "
                         "a trial of this marker set")
    if not placed and (opts.hat_fraction is not None or opts.hat_offset is not None):
        raise InputError(f"{source}: the subject is a placed HAT's (hat_fraction, calibrated on a lower-body marker "
                         "set) but this set tracks the trunk: calibrate on a trial of this marker set")


def _standard_take(trial: C3dTrial, opts: MarkerBodyOptions) -> MarkerTake:
    """The body of a Plug-in Gait / Helen Hayes set (see the module docstring)."""
    trial, roles, match = _standard(trial, opts.marker_map)
    raw = {role: trial.marker(label) for role, label in roles.items() if label is not None}
    _check_coordinates(raw, _as_written(roles, match), trial)
    max_gap = max(1, round(opts.max_gap_s * trial.rate))
    placed_toes = {}
    for s in "LR":  # a toe lost for long, placed from the heel and the malleoli where they are seen
        if all(s + k in raw for k in ("TOE", "HEE", "ANK", "ANK_med")):
            raw[s + "TOE"], n = toe_from_heel_and_malleoli(raw[s + "TOE"], raw[s + "HEE"], raw[s + "ANK"],
                                                          raw[s + "ANK_med"], max_gap)
            if n:
                placed_toes[match.roles.get(roles[s + "TOE"], roles[s + "TOE"])] = n
    optional = {k: raw.pop(k) for k in list(raw) if k[1:] in _OPTIONAL}
    try:
        keep, open_gaps = _trim(raw, max_gap, trial.rate)
    except InputError as e:
        raise InputError(f"{trial.source}: {e}") from None
    # an optional marker (wand, heel, medial, finger) is used only where it covers the needed markers' stretch
    dropped = []
    for role, x in optional.items():
        filled, _ = fill_gaps(x, max_gap)
        if np.isfinite(filled[keep]).all():
            raw[role] = filled
        else:
            dropped.append(roles[role])
            roles[role] = None  # so that live frames leave it out too
    copies = _medial_copies(raw, roles, keep, match)
    if keep.stop - keep.start < 4:
        raise InputError(f"{trial.source}: only {keep.stop - keep.start} frames have every needed marker")
    up, r_in = _up_rotation(raw, trial.source)
    m = {k: v[keep] @ r_in.T for k, v in raw.items()}
    seg, centres, notes = _segments(m, trial)
    for role, why in copies.items():
        side, joint = ("left" if role[0] == "L" else "right"), ("knee" if role[1:4] == "KNE" else "ankle")
        notes["joint_centres"][f"{side}_{joint}"] += f"; {why}"
    _check_stature(notes["stature_m"], trial)
    _check_turns(seg, keep.start, trial.source)
    lengths = _check_lengths(seg, m, trial)
    body, frames = _build(_swayed(seg, opts, m, trial.rate), m, opts, up, r_in, notes, lengths,
                          _table(opts, trial, notes))
    open_gaps = [{**g, "marker": match.roles.get(g["marker"], g["marker"])} for g in open_gaps]
    notes.update(marker_gaps_open=open_gaps, frames_used=[keep.start, keep.stop - 1])
    if dropped:
        notes["optional_markers_not_used"] = sorted(match.roles.get(d, d) for d in dropped)
    if placed_toes:
        notes["toe_placed_from_heel_and_malleoli"] = {k: f"{n} frames" for k, n in placed_toes.items()}
    if match.aliases or match.toe:
        notes["labels"] = match.summary()
    if match.conventions:
        notes["marker_set"] = notes["marker_set"].replace(
            "(standard labels)", f"(labels read as {', '.join(match.conventions)})")
    # the roles' labels as the file (or a live stream of the same set) writes them
    return MarkerTake(body, frames, keep.start, notes, centres, _as_written(roles, match), trial,
                      {match.roles[r]: labs for r, labs in match.midpoints.items()}, placed_segments(seg, m))


def _medial_copies(raw: dict[str, np.ndarray], roles: dict[str, str | None], keep: slice,
                   match: LabelMatch) -> dict[str, str]:
    """Leave out (from ``raw`` and ``roles``) each medial knee or ankle marker lying on its lateral one: less than
    :data:`MIN_JOINT_WIDTH_M` from it over the frames ``keep`` (median). A joint's medial marker lies the joint's
    width across from its lateral one; one on top of it is a copy of the lateral marker, and the mid-point of the
    two would put the joint centre on the skin (pyCGM2 writes each marker's model-fitted copy as ``RKNE_m``, which
    reads as ``RKNEM``, the medial knee: the qualisys/cgm2-web-report-uploader test trials; the knee's frame then
    turned 127 deg between two frames). Returns lateral role -> why (the file's labels: ``match``), for each one
    left out."""
    out = {}
    for role in [r for r in raw if r.endswith("_med")]:
        lateral = role.removesuffix("_med")
        apart = float(np.nanmedian(np.linalg.norm(raw[role][keep] - raw[lateral][keep], axis=1)))
        if apart < MIN_JOINT_WIDTH_M:
            label, lateral_label = (match.roles.get(roles[r], roles[r]) for r in (role, lateral))
            out[lateral] = (f"{label} not read as the medial marker: {1000 * apart:.0f} mm from {lateral_label} "
                            "(a medial marker lies the joint's width across)")
            del raw[role]
            roles[role] = None  # so that live frames leave it out too
    return out


def _check_coordinates(raw: dict[str, np.ndarray], roles: dict[str, str | None], trial: C3dTrial) -> None:
    """Refuse a coordinate of the markers ``raw`` (role -> (F, 3) m) beyond :data:`MAX_COORDINATE_M`
    (a corrupt value), naming the file's label and the frame."""
    for role, x in raw.items():
        far = np.flatnonzero(np.nanmax(np.abs(x), axis=1, initial=0.0) > MAX_COORDINATE_M)
        if far.size:
            f = int(far[0])
            raise InputError(f"{trial.source}: marker {roles[role]} at frame {f} ({f / trial.rate:.3f} s): coordinate "
                             f"{np.nanmax(np.abs(x[f])):.3g} m is beyond {MAX_COORDINATE_M:g} m of the origin")


def _segment_lengths(seg: dict, m: dict) -> dict[str, float]:
    """Median segment lengths (m): joint centre to the next one down the chain; a foot's from the
    ankle centre to its toe marker, a hand's from the wrist centre to its FIN marker when there is one."""
    chain = (("thigh", "shank"), ("shank", "foot"), ("upperarm", "forearm"), ("forearm", "hand"))
    out = {f"{a}_{t}": float(np.median(np.linalg.norm(seg[f"{a}_{t}"][0] - seg[f"{b}_{t}"][0], axis=1)))
           for a, b in chain for t in "lr" if f"{a}_{t}" in seg}
    for kind, marker in (("foot", "TOE"), ("hand", "FIN")):
        for t in "lr":
            name, label = f"{kind}_{t}", t.upper() + marker
            if name in seg and label in m:
                out[name] = float(np.median(np.linalg.norm(m[label] - seg[name][0], axis=1)))
    return out


def _check_stature(stature: float, trial: C3dTrial) -> None:
    """Refuse a stature (m) outside :data:`STATURE_RANGE_M`: it sizes the joint centres."""
    lo, hi = STATURE_RANGE_M
    if not lo <= stature <= hi:
        where = "the file's height" if trial.height_m else "estimated from the leg markers"
        raise InputError(f"{trial.source}: stature {stature:.3g} m ({where}) is outside {lo:g}-{hi:g} m")


def _check_marker_size(leg_stature: float, trial: C3dTrial) -> None:
    """Refuse markers whose legs make no person (``leg_stature`` m, estimated from the hip centre to the ankle
    marker, outside :data:`STATURE_RANGE_M`) where the file's height sizes the body: the points are then in
    another unit than POINT:UNITS says (a walk in metres labelled mm had been analysed as a 0.3 mm pelvis under
    a 1.64 m body's table: every frame inside, "plausible for walking", exit 0)."""
    lo, hi = STATURE_RANGE_M
    if not lo <= leg_stature <= hi:
        raise InputError(f"{trial.source}: the leg markers make a stature of {leg_stature:.3g} m (hip centre to "
                         f"ankle marker), outside {lo:g}-{hi:g} m, where the file's height is {trial.height_m:g} m: "
                         f"are the points in another unit than POINT:UNITS ({trial.units})?")


def _check_lengths(seg: dict, m: dict, trial: C3dTrial) -> dict[str, float]:
    """The segment lengths (m); one outside :data:`SEGMENT_LENGTH_RANGE_M` is refused naming it."""
    lengths = _segment_lengths(seg, m)
    lo, hi = SEGMENT_LENGTH_RANGE_M
    for name, length in lengths.items():
        if not lo <= length <= hi:
            raise InputError(f"{trial.source}: segment {name} is {1000 * length:.4g} mm long (median over the "
                             f"frames used); a plausible one is {1000 * lo:g}-{1000 * hi:g} mm")
    return lengths


def marker_channels(take: MarkerTake, markers: dict[str, np.ndarray]) -> np.ndarray:
    """The body's channels (F, nq) of new frames of markers: ``markers`` role -> (F, 3) m in the internal
    frame (every role of ``take.roles``; NaN where unseen gives NaN channels). The subject's dimensions
    (pelvis width and depth, stature) stay those measured when ``take`` was built, so frames of the take
    itself give back ``take.frames`` (angles each within ±pi instead of unwrapped over frames)."""
    seg, _, _ = _segments(markers, take.subject, take.notes["dimensions"])
    return segment_channels(seg, unwrap=False)


def segment_channels(seg: dict, unwrap: bool = True) -> np.ndarray:
    """(F, 6 per segment) x, y, z (m), yaw, pitch, roll (rad) of segment frames ``seg`` (see _segments),
    angles unwrapped over the frames (else each within ±pi)."""
    return np.concatenate([part for origin, rot in seg.values() for part in (origin, _euler_zyx(rot, unwrap))],
                          axis=1)


def _segments(m: dict[str, np.ndarray], trial: C3dTrial, dims: dict | None = None) -> tuple[dict, dict, dict]:
    """Segment frames: name -> (origin (F, 3), rotation (F, 3, 3)); joint centres; notes. ``dims`` the
    subject's pelvis width, depth and stature (m) as in ``notes["dimensions"]``; None: measured on ``m``."""
    mid_asis = (m["LASI"] + m["RASI"]) / 2
    back = (m["LPSI"] + m["RPSI"]) / 2 if "LPSI" in m else m["SACR"]
    y = _unit(m["LASI"] - m["RASI"])
    fwd = mid_asis - back
    x = _unit(fwd - np.add.reduce(fwd * y, axis=1, keepdims=True) * y)
    z = _cross(x, y)
    if dims is None:
        pw = float(np.median(np.linalg.norm(m["LASI"] - m["RASI"], axis=1)))
        pd = float(np.median(np.linalg.norm(fwd, axis=1)))
    else:
        pw, pd = dims["pelvis_width_m"], dims["pelvis_depth_m"]
    hjc = {side: mid_asis + (-0.24 * pd - 0.0099) * x + (-0.30 * pw - 0.0109) * z + sign * (0.33 * pw + 0.0073) * y
           for side, (_, sign, _) in _SIDES.items()}
    # stature: the file's, else from the leg (hip centre to the lateral ankle marker)
    # over the frames with a pelvis frame and an ankle marker (a frame without one is refused later, naming it)
    leg = np.linalg.norm(hjc["left"] - m["LANK"], axis=1)
    leg = leg[np.isfinite(leg)]
    leg_stature = float(np.median(leg)) / LEG_FRACTION_OF_STATURE if leg.size else math.nan
    if dims is None and trial.height_m and leg.size:
        _check_marker_size(leg_stature, trial)
    stature = dims["stature_m"] if dims else trial.height_m or leg_stature
    centres = {"hip": hjc, "knee": {}, "ankle": {}}
    rules = {}
    # the share of the take's frames each TIB wand lies lateral (LTIB_lateral_share ...): read as Plug-in Gait's
    # lateral wand from TIB_LATERAL_SHARE on; new frames of the take keep the take's decision
    wands: dict[str, float] = {}
    for side, (s, sign, _) in _SIDES.items():
        # the knee's chord rule takes no THI wand: without the static trial's thigh-rotation offset its plane
        # is not the knee's frontal plane (the Plug-in Gait walk's knees came out 36 mm forward and 16 mm
        # lateral of the lab's own knee centres; medially along the pelvis' lateral axis, within 5 mm)
        for joint, mk, wand, prox, frac in (("knee", "KNE", None, "hip", KNEE_WIDTH_OF_STATURE),
                                            ("ankle", "ANK", "TIB", "knee", ANKLE_WIDTH_OF_STATURE)):
            lateral = m[s + mk]
            medial = m.get(s + mk + "_med")
            if medial is not None:
                centres[joint][side] = (lateral + medial) / 2
                rules[f"{side}_{joint}"] = "mid-point of lateral and medial markers"
                continue
            width = trial.widths_m.get(f"{s}{joint.capitalize()}Width") or frac * stature
            delta = width / 2 + MARKER_RADIUS
            share = f"{s}{wand}_lateral_share" if wand else ""
            if wand and s + wand in m:
                wands[share] = (dims or {}).get(share, float(np.mean(
                    _wand_side(centres[prox][side], m[s + wand], lateral, -sign * y) < 0)))
            if wands.get(share, 0.0) >= TIB_LATERAL_SHARE:
                centres[joint][side] = _chord(centres[prox][side], m[s + wand], lateral, delta, -sign * y)
                rules[f"{side}_{joint}"] = f"chord rule ({s}{wand} wand, width {1000 * width:.0f} mm)"
            else:
                why = (f"; {s}{wand} not read as a lateral wand: lateral of the shank's line in "
                       f"{100 * wands[share]:.0f} % of the frames") if share in wands else ""
                centres[joint][side] = lateral - sign * delta * y
                rules[f"{side}_{joint}"] = (f"{s}{mk} moved medially along the pelvis axis ({1000 * width:.0f} mm "
                                            f"width){why}")
    pelvis_origin = (hjc["left"] + hjc["right"]) / 2
    seg = {"pelvis": (pelvis_origin, _columns(x, y, z))}
    full = "LWRA" in m
    if full or "LWRI" in m:
        arms = {s: arm_dimensions(trial.widths_m, s, stature) for s in "LR"}
        upper, hands = _upper_segments(m, pelvis_origin, stature, arms, dims)
        seg.update(upper)
        wands.update(hands)
        for k in (k for k, stable in hands.items() if not stable):
            rules[f"{'left' if k[0] == 'L' else 'right'}_hand"] = (
                f"along the forearm: {k[:4]} gives no stable hand frame (it turns over 90 deg between frames)")
        told = [_arm_told(trial.widths_m, arms, i) for i in range(3)]
        rules["shoulders"] = f"SHO moved down the thorax axis (offset {told[0]}, plus a marker radius)"
        rules["elbows"] = (f"chord rule (wrist centre, width {told[1]})" if full
                           else f"ELB moved medially along the thorax axis (width {told[1]})")
        if not full:
            rules["wrists"] = f"WRI moved medially along the thorax axis (width {told[2]})"
    elif _trunk_tracked(m) and _head_labels(m):  # the head on its markers, the arms placed on the thorax
        seg["thorax"] = seg["arms"] = _thorax(m, pelvis_origin, stature)
        seg["head"] = _head(m, *seg["thorax"])
    elif _trunk_tracked(m):
        seg["thorax"] = seg["headarms"] = _thorax(m, pelvis_origin, stature)
    else:
        seg["hat"] = _hat_frame(m, pelvis_origin, x)
    for side, (s, sign, t) in _SIDES.items():
        hip, knee, ankle = centres["hip"][side], centres["knee"][side], centres["ankle"][side]
        thigh = _frame(hip - knee, sign * (m[s + "KNE"] - knee))
        shank = _frame(knee - ankle, sign * (m[s + "ANK"] - ankle))
        heel = m.get(s + "HEE", ankle)
        foot = _foot_frame(m[s + "TOE"] - heel, shank[:, :, 1])
        seg[f"thigh_{t}"], seg[f"shank_{t}"], seg[f"foot_{t}"] = (hip, thigh), (knee, shank), (ankle, foot)
    notes = {"marker_set": "Plug-in Gait full body (standard labels)" if full else
             "Plug-in Gait / Helen Hayes lower body (standard labels)" + _upper_note(m, trial)
             + (f"; thorax from {_trunk_labels(m)}" if _trunk_tracked(m) else "")
             + ("; arms from " + " ".join(_ARMS) if "LWRI" in m else "")
             + ("; head from " + _head_labels(m) if _head_labels(m) else ""),
             "hip_joint_centre": "Harrington et al. 2007, pelvic-width regression",
             "joint_centres": rules, "stature_m": round(stature, 4),
             "dimensions": {"pelvis_width_m": pw, "pelvis_depth_m": pd, "stature_m": stature, **wands}}
    return seg, centres, notes


def _turns(rot: np.ndarray) -> np.ndarray:
    """(F - 1,) rad: how far a frame ``rot`` (F, 3, 3) turns from each frame to the next."""
    cos = (np.einsum("fij,fij->f", rot[:-1], rot[1:]) - 1.0) / 2.0  # trace(R_k^T R_k+1) = sum R_k * R_k+1
    return np.arccos(np.clip(cos, -1.0, 1.0))


def _check_turns(seg: dict, first: int, source: str) -> None:
    """Refuse a segment without a frame somewhere (markers on top of each other or in line, or far out of
    range) or whose frame turns more than ``MAX_TURN_RAD`` between two frames: its axes flipped (markers
    nearly in line, or a joint-centre rule switching sides), not a motion."""
    for name, (origin, rot) in seg.items():
        bad = ~(np.isfinite(origin).all(axis=1) & np.isfinite(rot).all(axis=(1, 2)))
        if bad.any():
            raise InputError(f"{source}: segment {name} has no frame at frame {first + int(np.argmax(bad))}: "
                             "its markers coincide, lie in line or are out of range there")
        turn = _turns(rot)
        if len(turn) and turn.max() > MAX_TURN_RAD:
            k = int(np.argmax(turn))
            raise InputError(f"{source}: segment {name} turns {np.degrees(turn[k]):.0f} deg between frames "
                             f"{first + k} and {first + k + 1}: its markers give no stable frame there")


def sway_basis(origin: np.ndarray, facing: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The straight-line trend (F, 3) m of a walking take's point ``origin`` (F, 3) (least squares over
    frames: the steady progression), and the walk's fore-aft and lateral unit axes (3,) (the trend's
    horizontal travel; when it travels less than 0.1 m, ``facing`` (horizontal, internal frame: the way the
    subject faces, so that the lab's axes do not matter), else +x)."""
    k = np.arange(len(origin), dtype=float)
    slope, icpt = np.polyfit(k, origin, 1)
    trend = np.outer(k, slope) + icpt
    return (trend, *travel_axes(trend[-1, :2] - trend[0, :2], facing))


def travel_axes(travel: np.ndarray, facing: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Unit horizontal fore-aft and lateral (left of it) axes (3,) of a walk that travels ``travel`` (2,) m:
    along it; when it is under 0.1 m, ``facing`` (horizontal: the way the subject faces, so that the lab's
    axes do not matter), else +x."""
    d = travel
    if np.linalg.norm(d) <= 0.1:
        d = np.array([1.0, 0.0]) if facing is None else np.asarray(facing, dtype=float)[:2]
    fwd = d / np.linalg.norm(d)
    return np.array([fwd[0], fwd[1], 0.0]), np.array([-fwd[1], fwd[0], 0.0])


def hat_sway(origin: np.ndarray, gain: tuple[float, float], facing: np.ndarray | None = None,
             rate: float | None = None, follow_hz: float | None = None) -> np.ndarray:
    """The HAT's base (F, 3) m when the trunk sways ``gain`` (fore-aft, lateral) times as far as the
    mid-hip ``origin`` (F, 3) about the walk's straight-line trend (:func:`sway_basis`); height
    unchanged. With ``follow_hz`` (Hz; frames at ``rate`` Hz) only the sway above it is scaled, the slower
    part followed as it is (zero-phase low-pass, 4th order); without, the HAT's acceleration is the gain
    times the mid-hip's along each axis (the trend has none).
    Whole takes only: a live stream has no trend, and :func:`marker_channels` does not sway."""
    trend, fwd, left = sway_basis(origin, facing)
    sway = origin - trend
    out = origin.copy()
    for axis, k in zip((fwd, left), gain, strict=True):
        along = sway @ axis
        slow = 0.0
        if follow_hz is not None and rate is not None and follow_hz < rate / 2:
            # padded by one period of the corner (in time, so that any frame rate gives the same ends)
            pad = min(round(rate / follow_hz), len(along) - 1)
            slow = sosfiltfilt(butter(2, follow_hz, fs=rate, output="sos"), along, padlen=pad)
        out += np.outer((k - 1.0) * (along - slow), axis)
    return out


def _swayed(seg: dict, opts: MarkerBodyOptions, m: dict, rate: float) -> dict:
    """``seg`` with its placed HAT swayed by ``opts.hat_sway_gain``; a HAT given by the file's HAT points
    (a corrected take) is where they say."""
    if opts.hat_sway_gain is None or "hat" not in seg or HAT_POINTS[0] in m:
        return seg
    origin, rot = seg["hat"]
    facing = np.nanmean(rot[:, :, 0], axis=0)  # the upright HAT's forward axis: the way the subject faces
    return {**seg, "hat": (hat_sway(origin, opts.hat_sway_gain, facing, rate, opts.hat_follow_hz), rot)}


def _hat_frame(m: dict[str, np.ndarray], mid_hip: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A placed HAT's origin and frame: where the file's HAT points say (a corrected take), else at the mid-hip
    ``mid_hip``, upright and turned to the pelvis' forward axes ``x`` (F, 3)."""
    if "HATO" not in m:
        return mid_hip, _upright(x)
    return m["HATO"], np.stack([_unit(m[p] - m["HATO"]) for p in HAT_POINTS[1:]], axis=-1)


def _upright(x: np.ndarray) -> np.ndarray:
    """(F, 3, 3) upright frames turned to the heading of the forward axes ``x`` (F, 3)."""
    heading = np.arctan2(x[:, 1], x[:, 0])
    c, sn, zero, one = np.cos(heading), np.sin(heading), np.zeros_like(heading), np.ones_like(heading)
    return np.stack([np.stack([c, -sn, zero], -1), np.stack([sn, c, zero], -1), np.stack([zero, zero, one], -1)], 1)


def _cluster_take(trial: C3dTrial, opts: MarkerBodyOptions, mmap: MarkerMap) -> MarkerTake:
    """The body of a cluster set (see :mod:`livezmp.model.marker_map`)."""
    raw = _cluster_markers(trial, mmap)
    _check_coordinates(raw, {k: k for k in raw}, trial)
    try:
        keep, open_gaps = _trim(raw, max(1, round(opts.max_gap_s * trial.rate)), trial.rate)
    except InputError as e:
        raise InputError(f"{trial.source}: {e}") from None
    if keep.stop - keep.start < 4:
        raise InputError(f"{trial.source}: only {keep.stop - keep.start} frames have every mapped marker")
    up, r_in = _up_from(_cluster_up_vector(raw, mmap), trial.source)
    m = {k: v[keep] @ r_in.T for k, v in raw.items()}
    seg, centres, notes = _cluster_segments(m, mmap, trial)
    _check_stature(notes["stature_m"], trial)
    _check_turns(seg, keep.start, trial.source)
    lengths = _check_lengths(seg, m, trial)
    body, frames = _build(_swayed(seg, opts, m, trial.rate), m, opts, up, r_in, notes, lengths,
                          _table(opts, trial, notes))
    notes.update(marker_gaps_open=open_gaps, frames_used=[keep.start, keep.stop - 1])
    return MarkerTake(body, frames, keep.start, notes, centres, placed=placed_segments(seg, m))


def _carried(rot: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """``direction`` (F, 3) as a cluster with rotations ``rot`` (F, 3, 3) carries it: its mean in the
    cluster frame, turned back by each frame's rotation."""
    local = _unit(np.mean(np.einsum("fji,fj->fi", rot, direction), axis=0))
    return rot @ local


def _cluster_segments(m: dict[str, np.ndarray], mmap: MarkerMap, trial: C3dTrial) -> tuple[dict, dict, dict]:
    """Segment frames, joint centres and notes of a cluster set; adds each foot's toe (its marker furthest
    forward of the ankle centre along the pelvis' forward axis) to ``m`` as LTOE / RTOE."""
    poses = {s: cluster_frames(np.stack([m[label] for label in labels], axis=1)) for s, labels in mmap.segments}
    centres: dict = {j: {} for j in JOINTS}
    rules = {}
    for side, (_, _, t) in _SIDES.items():
        for joint, (a, b) in JOINTS.items():
            rule = mmap.joint_rule(joint, t)
            if rule == "functional":
                pa = poses["pelvis" if a == "pelvis" else f"{a}_{t}"]
                centres[joint][side] = functional_centre(*pa, *poses[f"{b}_{t}"])
                rules[f"{side}_{joint}"] = "functional (SCoRE, Ehrig et al. 2006)"
            else:
                centres[joint][side] = np.mean([m[label] for label in rule], axis=0)
                rules[f"{side}_{joint}"] = f"mid-point of {', '.join(rule)}"
    hip_l, hip_r = centres["hip"]["left"], centres["hip"]["right"]
    _, r_pelvis = poses["pelvis"]
    y = _unit(hip_l - hip_r)
    x = _unit(np.cross(y, _carried(r_pelvis, np.tile([0.0, 0.0, 1.0], (len(y), 1)))))
    pelvis_origin = (hip_l + hip_r) / 2
    seg = {"pelvis": (pelvis_origin, np.stack([x, y, np.cross(x, y)], axis=-1)), "hat": _hat_frame(m, pelvis_origin, x)}
    stature = mmap.stature_m or trial.height_m or float(
        np.median(np.linalg.norm(hip_l - centres["ankle"]["left"], axis=1)) / LEG_FRACTION_OF_STATURE)
    for side, (s, _, t) in _SIDES.items():
        hip, knee, ankle = centres["hip"][side], centres["knee"][side], centres["ankle"][side]
        thigh = _frame(hip - knee, _carried(poses[f"thigh_{t}"][1], y))
        shank = _frame(knee - ankle, _carried(poses[f"shank_{t}"][1], y))
        foot_labels = dict(mmap.segments)[f"foot_{t}"]
        toe = max(foot_labels, key=lambda label: float(np.median(np.sum((m[label] - ankle) * x, axis=1))))
        m[s + "TOE"] = m[toe]
        seg[f"thigh_{t}"], seg[f"shank_{t}"] = (hip, thigh), (knee, shank)
        seg[f"foot_{t}"] = (ankle, _foot_frame(m[toe] - ankle, shank[:, :, 1]))
        rules[f"{side}_toe"] = toe
    notes = {"marker_set": f"cluster set ({mmap.source})" if mmap.source == SEGMENT_OUTPUTS_SOURCE else
             f"cluster set (marker map {Path(mmap.source).name})",
             "hip_joint_centre": rules["left_hip"], "joint_centres": rules, "stature_m": round(stature, 4)}
    return seg, centres, notes


def _upper_note(m: dict, trial: C3dTrial) -> str:
    """Why the file's Plug-in Gait upper-body labels, if any, are not used: those missing or never seen."""
    have = [u for u in _UPPER if u in trial.labels]
    if not have or _trunk_tracked(m):
        return ""
    unseen = [u for u in have if not np.isfinite(trial.marker(u)).all(axis=1).any()]
    if len(unseen) == len(have):
        return "; upper-body markers labelled but never seen: not used"
    missing = [u for u in _UPPER if u not in have] + [f"{u} (never seen)" for u in unseen]
    return f"; upper-body markers incomplete (missing {', '.join(missing)}): not used"


def placed_segments(seg: dict, m: dict) -> tuple[str, ...]:
    """The segments of ``seg`` whose mass is placed from another segment's markers (``m`` the markers): the
    head, arms and trunk on the pelvis (``hat``), head and arms or arms on the thorax, a head without head
    markers on the thorax. Empty: every segment is tracked by its own markers."""
    return tuple(s for s in seg if s in ("hat", "headarms", "arms") or (s == "head" and not _head_labels(m)))


def _head_labels(m: dict) -> str:
    """The head markers in ``m`` the head is tracked by ('' for none)."""
    return " ".join(next((h for h in (_HEAD4, _HEAD3) if h[0] in m), ()))


def _trunk_tracked(m: dict[str, np.ndarray]) -> bool:
    """Whether the markers ``m`` track the thorax (C7 with the sternal notch or clavicles, or both shoulders)."""
    return "C7" in m or "LSHO" in m


def _trunk_labels(m: dict[str, np.ndarray]) -> str:
    """The trunk markers the thorax is tracked by, and where its axis starts without T10 and STRN."""
    used = " ".join(u for u in (*_TRUNK, "LCLA", "RCLA", "LSHO", "RSHO") if u in m)
    return used if "T10" in m else used + " (its axis from the mid-hip)"


def _thorax(m: dict[str, np.ndarray], mid_hip: np.ndarray | None,
            stature: float) -> tuple[np.ndarray, np.ndarray]:
    """The thorax' origin (between C7 and CLAV, or the clavicles' mid-point) and frame (z up the trunk,
    x forward). Its axis runs from the mid-point of T10 and STRN, or, with the trunk's top markers alone,
    from the mid-hip ``mid_hip`` (F, 3; m): the trunk then leans as the line from the hips to its top. With the
    shoulders alone, y points to the left one and the origin is raised from between them to the cervicale's
    height, where head and arms are placed (:data:`CERVICALE_ABOVE_ACROMIA` of ``stature``, m)."""
    if "C7" not in m:
        up = _unit((m["LSHO"] + m["RSHO"]) / 2 - mid_hip)
        top = (m["LSHO"] + m["RSHO"]) / 2 + CERVICALE_ABOVE_ACROMIA * stature * up
        return top, _frame(up, m["LSHO"] - m["RSHO"])
    front = m["CLAV"] if "CLAV" in m else (m["LCLA"] + m["RCLA"]) / 2
    top = (m["C7"] + front) / 2
    if "T10" in m:
        bottom, fwd = (m["T10"] + m["STRN"]) / 2, (front + m["STRN"]) / 2 - (m["C7"] + m["T10"]) / 2
    else:
        bottom, fwd = mid_hip, front - m["C7"]
    return top, _frame(top - bottom, _cross(top - bottom, fwd))


def arm_dimensions(widths_m: dict[str, float], side: str, stature: float) -> tuple[float, float, float]:
    """Side ``side``'s ("L", "R") shoulder offset, elbow width and wrist width (m): the file's Plug-in Gait
    subject measurements (``LShoulderOffset``, ``LElbowWidth``, ``LWristWidth``) where given, else
    :data:`SHOULDER_OFFSET` and the fractions of ``stature`` (m)."""
    default = (SHOULDER_OFFSET, ELBOW_WIDTH_OF_STATURE * stature, WRIST_WIDTH_OF_STATURE * stature)
    return tuple(widths_m.get(side + name) or d for name, d in zip(_ARM_DIMENSIONS, default, strict=True))


def _arm_told(widths_m: dict[str, float], arms: dict[str, tuple[float, float, float]], i: int) -> str:
    """The left / right value ``i`` of :func:`arm_dimensions` in mm, and whether the file gave it."""
    given = all(f"{s}{_ARM_DIMENSIONS[i]}" in widths_m for s in "LR")
    return " / ".join(f"{1000 * arms[s][i]:.0f}" for s in "LR") + (" mm, the file's" if given else " mm")


def _head(m: dict[str, np.ndarray], top: np.ndarray, thorax: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The head's origin (F, 3; m) and frame (F, 3, 3): with Plug-in Gait's four head markers the origin at their
    centre, x forward; with the Helen Hayes head's three (top, front, rear) the origin at the vertex (a marker
    radius below THEA), z towards THEA from between the other two, x forward; without, the thorax' ``top`` and
    ``thorax`` frame (:func:`_upper_inertia` then puts its mass above the cervicale)."""
    if "LFHD" in m:
        front, back = (m["LFHD"] + m["RFHD"]) / 2, (m["LBHD"] + m["RBHD"]) / 2
        return (front + back) / 2, _foot_frame(front - back, (m["LFHD"] + m["LBHD"]) / 2 - (m["RFHD"] + m["RBHD"]) / 2)
    if "THEA" in m:
        up = m["THEA"] - (m["FHEA"] + m["RHEA"]) / 2
        head = _frame(up, _cross(up, m["FHEA"] - m["RHEA"]))
        return m["THEA"] - MARKER_RADIUS * head[:, :, 2], head
    return top, thorax


def _upper_segments(m: dict[str, np.ndarray], mid_hip: np.ndarray, stature: float,
                    arms: dict[str, tuple[float, float, float]], dims: dict | None = None) -> tuple[dict, dict]:
    """Thorax (:func:`_thorax`; origin at the cervicale's level, z up the trunk), head (:func:`_head`) and each
    arm. Each arm: shoulder centre its shoulder offset plus a marker radius below SHO along the thorax
    (Plug-in Gait's rule); with Plug-in Gait's wrist bar the wrist centre between WRA and WRB and the elbow
    centre by the chord rule, hand towards FIN (else along the forearm); with the Helen Hayes single markers ELB
    and WRI (lateral epicondyle, wrist) each centre half the elbow / wrist width (plus a marker radius) medial of
    its marker along the thorax' lateral axis, as the knees are placed from KNE, the hand along the forearm.
    ``mid_hip`` (F, 3; m) where the thorax' axis starts without T10 and STRN; ``stature`` m; ``arms`` side ->
    :func:`arm_dimensions`. A FIN marker whose hand frame turns more than ``MAX_TURN_RAD`` between two frames (a
    finger marker not where Plug-in Gait puts it: biomechZoo's HC040A14, 61-121 deg off the forearm) gives no hand
    frame: that hand lies along the forearm as without FIN; the decision per side (``LFIN_stable`` ...: 1.0 / 0.0)
    is returned beside the segments, and taken from ``dims`` when given (a stream keeps its calibration's)."""
    top, thorax = _thorax(m, mid_hip, stature)
    out = {"thorax": (top, thorax), "head": _head(m, top, thorax)}
    hands: dict[str, float] = {}
    ty, tz = thorax[:, :, 1], thorax[:, :, 2]
    for s, sign, t in _SIDES.values():
        shoulder, elbow, wrist = arms[s]
        sjc = m[s + "SHO"] - (shoulder + MARKER_RADIUS) * tz
        if s + "WRA" in m:
            wjc = (m[s + "WRA"] + m[s + "WRB"]) / 2
            ejc = _chord(sjc, wjc, m[s + "ELB"], elbow / 2 + MARKER_RADIUS, -sign * ty)
        else:
            ejc = m[s + "ELB"] - sign * (elbow / 2 + MARKER_RADIUS) * ty
            wjc = m[s + "WRI"] - sign * (wrist / 2 + MARKER_RADIUS) * ty
        hand = _frame(ejc - wjc, ty)
        if s + "FIN" in m:
            with_fin = _frame(wjc - m[s + "FIN"], ty)
            turn = _turns(with_fin)
            hands[f"{s}FIN_stable"] = (dims or {}).get(f"{s}FIN_stable",
                                                       float(not len(turn) or turn.max() <= MAX_TURN_RAD))
            hand = with_fin if hands[f"{s}FIN_stable"] else hand
        out[f"upperarm_{t}"] = (sjc, _frame(sjc - ejc, ty))
        out[f"forearm_{t}"] = (ejc, _frame(ejc - wjc, ty))
        out[f"hand_{t}"] = (wjc, hand)
    return out, hands


def thorax_table(stature: float, t: dict[str, SegmentParams] = DE_LEVA_MALE) -> tuple[float, np.ndarray]:
    """A tracked thorax' (middle + upper trunk) mass fraction and centre of mass (m, its own frame, x forward: below
    the cervicale, :func:`trunk_com_below_cervicale`, and behind its axis by the table's ``anterior_fraction`` of its
    length, as Dumas et al.'s torso lies behind its lumbar-to-cervical line) from the segment table ``t``."""
    length = (170.7 + 215.5) * stature / 1741.0
    return (t["middle_trunk"].mass_fraction + t["upper_trunk"].mass_fraction,
            np.array([t["upper_trunk"].anterior_fraction * length, 0.0, -trunk_com_below_cervicale(stature, t)]))


def trunk_com_below_cervicale(stature: float, t: dict[str, SegmentParams] = DE_LEVA_MALE) -> float:
    """Depth (m) of the middle + upper trunk's combined centre of mass below the cervicale (de Leva:
    the upper trunk from the cervicale down to the xiphion, the middle trunk on to the omphalion; masses from
    the segment table ``t``)."""
    h = stature / 1741.0
    upt, mpt = 170.7 * h, 215.5 * h
    mu, mm = t["upper_trunk"].mass_fraction, t["middle_trunk"].mass_fraction
    return (mu * t["upper_trunk"].com_fraction * upt + mm * (upt + t["middle_trunk"].com_fraction * mpt)) / (mu + mm)


def _table(opts: MarkerBodyOptions, trial: C3dTrial, notes: dict) -> BspTable:
    """The segment table ``opts.bsp`` asks for, given the subject's age (``opts``' or the file's) and height; said in
    ``notes["bsp"]``."""
    given = opts.age_years is not None  # --age or the subject file's, over the C3D's
    age = opts.age_years if given else trial.age_years
    table = choose_table(opts.bsp, age, trial.height_m, notes["stature_m"], "the given" if given else "the file's")
    notes["bsp"] = table.summary()
    return table


def _build(seg: dict, m: dict, opts: MarkerBodyOptions, up: str, r_in: np.ndarray,
           notes: dict, lengths: dict[str, float], table: BspTable = ADULT) -> tuple[BodyModel, np.ndarray]:
    t = table.segments
    stature = notes["stature_m"]
    hat_mass, hat_com, hat_inertia = hat_table(stature, table=t)
    full = "hat" not in seg
    hat_fraction = hat_mass if full or opts.hat_fraction is None else opts.hat_fraction
    # the segment a subject file weighs (the placed HAT, or the tracked thorax) and its table fraction
    weighed, weighed_table = (opts.trunk_fraction, thorax_table(stature, t)[0]) if full else (hat_fraction, hat_mass)
    weighed = weighed_table if weighed is None else weighed
    lower = t["lower_trunk"]
    pelvis_len = 145.7 / 1741 * stature
    # the pelvis' mean tilt about its lateral axis, for a HAT riding on the pelvis
    rot_p = seg["pelvis"][1]
    tilt = float(np.median(np.arctan2(rot_p[:, 2, 0], rot_p[:, 2, 2])))  # forward lean of the pelvis z axis
    upright = pin.utils.rotate("y", tilt) if opts.hat_follows_pelvis else np.eye(3)
    hat_up = np.array(opts.hat_offset) if opts.hat_offset is not None else hat_com
    scale_rest = (1.0 - weighed) / (1.0 - weighed_table)  # keep the total at 1 when the fraction is set
    model = pin.Model()
    model.name = "markers"
    body_frame = {}
    for name, (origin, rot) in seg.items():
        parent = 0
        for ch, jm in zip(_CHANNELS, (pin.JointModelPX, pin.JointModelPY, pin.JointModelPZ, pin.JointModelRZ,
                                      pin.JointModelRY, pin.JointModelRX), strict=True):
            parent = model.addJoint(parent, jm(), pin.SE3.Identity(), f"{name}.{ch}")
        body_frame[name] = model.addFrame(pin.Frame(name, parent, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
        kind = name.split("_")[0]
        if name == "hat":
            hat_m = opts.total_mass * hat_fraction
            inertia = pin.Inertia(hat_m, upright @ hat_up, hat_m * upright @ hat_inertia @ upright.T)
            model.appendBodyToJoint(body_frame["pelvis_joint"] if opts.hat_follows_pelvis else parent, inertia,
                                    pin.SE3.Identity())
            continue
        if name == "pelvis":
            mass = opts.total_mass * lower.mass_fraction * scale_rest
            r = [g * pelvis_len for g in lower.gyration]
            com = np.array([lower.anterior_fraction * pelvis_len, 0.0, (1 - lower.com_fraction) * pelvis_len])
            model.appendBodyToJoint(parent, pin.Inertia(mass, com, mass * np.diag(np.square(r))), pin.SE3.Identity())
            body_frame["pelvis_joint"] = parent
            continue
        if kind in ("headarms", "arms"):  # placed on the tracked thorax, whose origin is at the cervicale
            frac, com, inertia = hat_table(stature, "head_and_arms" if kind == "headarms" else "arms", table=t)
            mass = opts.total_mass * frac * scale_rest
            model.appendBodyToJoint(parent, pin.Inertia(mass, com, mass * inertia), pin.SE3.Identity())
            continue
        if kind in ("thorax", "head", "hand"):
            mass, com, inertia = _upper_inertia(kind, name, seg, m, stature, t)
            scale = weighed / mass if kind == "thorax" else scale_rest
            if kind == "thorax" and opts.trunk_offset is not None:
                com = np.array(opts.trunk_offset)
            model.appendBodyToJoint(parent, pin.Inertia(opts.total_mass * mass * scale, com,
                                                        opts.total_mass * inertia * scale), pin.SE3.Identity())
            continue
        p = t[{"upperarm": "upper_arm"}.get(kind, kind)]
        mass = opts.total_mass * p.mass_fraction * scale_rest
        if kind == "foot":
            side = name[-1].upper()
            toe = _local(rot, origin, m[side + "TOE"])
            length = float(np.linalg.norm(toe))
            com = toe / 2  # Winter: half-way from the ankle to the 2nd metatarsal head
            rot_in = pin.utils.rotate("y", -np.arctan2(toe[2], toe[0]))  # long axis along ankle -> toe
        else:
            length = lengths[name]
            com = np.array([p.anterior_fraction * length, 0.0, -p.com_fraction * length])
            rot_in = np.eye(3)
        r = np.array([g * length for g in p.gyration])
        model.appendBodyToJoint(parent, pin.Inertia(mass, com, mass * rot_in @ np.diag(r * r) @ rot_in.T),
                                pin.SE3.Identity())
    feet, named = _feet(model, body_frame, seg, m, opts, stature)
    nq = model.nq
    correction = CorrectionJoints(
        root_channels=list(range(6)), root_frame_id=body_frame["pelvis"],
        legs={s: [6 * list(seg).index(f"thigh_{s[0]}") + k for k in (3, 4, 5)] for s in ("left", "right")},
        hips={"left": body_frame["thigh_l"], "right": body_frame["thigh_r"]},
        foot_frames={s: [named[f"{s}_ankle"], named[f"{s}_toe"]] for s in ("left", "right")}, full_foot_pose=False)
    notes["hat"] = _tracked_note(seg, m, "de Leva" if table.name == "adult" else "child table") + (
        "" if opts.trunk_fraction is None else f"; thorax {100 * weighed:.1f} % of the mass (subject file)" + (
            "" if opts.trunk_offset is None else ", its centre of mass {:+.0f} mm forward, {:+.0f} mm left, {:+.0f} mm "
            "up from its origin".format(*(1000 * np.array(opts.trunk_offset))))) if full else (
        f"head, arms and trunk ({100 * hat_fraction:.1f} % of the mass) placed from the pelvis: "
        f"centre of mass {1000 * hat_up[2]:.0f} mm above the mid-hip, {1000 * hat_up[0]:.0f} mm forward"
        + (" (Dumas et al. 2007)" if opts.hat_offset is None else " (subject file)")
        + ("; oriented by the file's HAT points (" + ", ".join(HAT_POINTS) + ")" if "HATO" in m else
           "; upright, turning with the pelvis" if not opts.hat_follows_pelvis else
           f"; rigid on the pelvis, its mean anterior tilt {np.degrees(-tilt):.1f} deg removed")
        + ("" if opts.hat_sway_gain is None or "HATO" in m else
           "; swaying {:.2f} (fore-aft) and {:.2f} (lateral) times the mid-hip{}{}".format(
               *opts.hat_sway_gain, "" if opts.hat_follow_hz is None else
               f" above {opts.hat_follow_hz:g} Hz, following it below",
               " (trunk-marker trials)" if opts.hat_sway_gain in (TRUNK_SWAY_GAIN, TRUNK_STEP_GAIN) else "")))
    names = [f"{s}.{c}" for s in seg for c in _CHANNELS]
    body = BodyModel(
        kind="markers", model=model, point_model=point_mass_copy(model), channel_names=names,
        channel_scale=np.ones(nq), angle_mask=np.array([c in ("yaw", "pitch", "roll") for c in _CHANNELS] * len(seg)),
        feet=feet, world_from_input=r_in, up_axis=up, units="m", total_mass=opts.total_mass,
        correction=correction, named_points=named)
    return body, segment_channels(seg)


def _tracked_note(seg: dict, m: dict, table: str) -> str:
    """What tracks the head, arms and trunk of a body with a thorax (``seg`` its segments, ``m`` its markers),
    and what segment table (``table``) places the rest on the thorax."""
    if "LWRA" in m:
        return "head, arms and trunk tracked by their own markers"
    head = _head_labels(m)
    if "LWRI" in m:
        return (f"trunk tracked by {_trunk_labels(m)}, arms by " + " ".join(_ARMS) + "; head "
                + (f"by {head}" if head else f"({table}) placed on the thorax"))
    if "arms" in seg:
        return f"trunk tracked by {_trunk_labels(m)}, head by {head}; arms ({table}) placed on it, hanging"
    return f"trunk tracked by {_trunk_labels(m)}; head and arms ({table}) placed on it, arms hanging"


def _upper_inertia(kind: str, name: str, seg: dict, m: dict, stature: float,
                   t: dict[str, SegmentParams]) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass fraction, centre of mass (segment frame, m) and inertia per kg of body mass (3, 3) of the
    thorax (middle + upper trunk), head or hand, from the segment table ``t`` (de Leva 1996's layout)."""
    h = stature / 1741.0
    if kind == "thorax":
        frac, com = thorax_table(stature, t)
        length = (170.7 + 215.5) * h
        gyr = t["middle_trunk"].gyration
    elif kind == "head":  # at its four markers' centre; from the vertex or above the cervicale by de Leva's fraction
        length = 242.9 * h
        fwd = t["head"].anterior_fraction * length
        com = (np.zeros(3) if "LFHD" in m else np.array([fwd, 0.0, -t["head"].com_fraction * length]) if "THEA" in m
               else np.array([fwd, 0.0, (1 - t["head"].com_fraction) * length]))
        frac, gyr = t["head"].mass_fraction, t["head"].gyration
    else:
        s = name[-1].upper()
        origin, rot = seg[name]
        length = float(np.linalg.norm(_local(rot, origin, m[s + "FIN"]))) if s + "FIN" in m else 86.2 * h
        frac, gyr = t["hand"].mass_fraction, t["hand"].gyration
        com = np.array([t["hand"].anterior_fraction * length, 0.0, -t["hand"].com_fraction * length])
    r = np.array(gyr) * length
    return frac, com, frac * np.diag(r * r)


def _feet(model: pin.Model, body_frame: dict, seg: dict, m: dict, opts: MarkerBodyOptions,
          stature: float) -> tuple[dict[str, Foot], dict[str, int]]:
    """Heel-to-toe soles: ankle frame at the ankle centre, toe frame at the toe marker; heel behind the
    heel marker's surface, toe tip a foot length from the heel; heights above the floor from the
    take's lowest ankle and toe positions."""
    foot_len = FOOT_LENGTH_OF_STATURE * stature
    lows = []
    for s, _, _ in _SIDES.values():
        lows += [np.percentile(m[s + "HEE"][:, 2] if s + "HEE" in m else m[s + "TOE"][:, 2], 2),
                 np.percentile(m[s + "TOE"][:, 2], 2)]
    floor = opts.floor_z if opts.floor_z is not None else float(min(lows)) - MARKER_RADIUS - 0.005
    feet, named = {}, {}
    for side, (s, _, t) in _SIDES.items():
        origin, rot = seg[f"foot_{t}"]
        fid = body_frame[f"foot_{t}"]
        toe_local = _local(rot, origin, m[s + "TOE"])
        heel_back = (-_local(rot, origin, m[s + "HEE"])[0] + MARKER_RADIUS) if s + "HEE" in m else 0.25 * foot_len
        toe_frame = model.addFrame(pin.Frame(f"{side}_toe", model.frames[fid].parentJoint,
                                             pin.SE3(np.eye(3), toe_local), pin.FrameType.OP_FRAME))
        feet[side] = Foot(side, fid, toe_frame_id=toe_frame, heel_back=max(heel_back, 0.02),
                          toe_front=max(foot_len - heel_back - toe_local[0], 0.01),
                          width=SOLE_WIDTH_OF_STATURE * stature,
                          ankle_height=max(float(np.percentile(origin[:, 2], 2)) - floor, 0.0),
                          toe_height=max(float(np.percentile(m[s + "TOE"][:, 2], 2)) - floor, 0.0))
        named[f"{side}_ankle"] = fid
        named[f"{side}_toe"] = toe_frame
    return feet, named
