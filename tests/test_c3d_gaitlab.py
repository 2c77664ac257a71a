"""A synthetic gait lab: a subject swaying on two force plates, its exact ground reaction written
as plate channels into a C3D made with ezc3d (an unloaded third plate with offsets, prefixed
labels, a short and a long marker gap), then `livezmp analyze` on it; and the shared real trials."""

from __future__ import annotations

import functools
import json
import struct
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path

import ezc3d
import numpy as np
import pinocchio as pin
import pytest
from ezc3d import ezc3d as ezc3d_swig

from livezmp.balance import plates as plates_mod
from livezmp.balance.plates import unloaded_offset
from livezmp.cli import main
from livezmp.errors import InputError
from livezmp.estimate.estimator import EstimatorConfig
from livezmp.estimate.response import acceleration_response
from livezmp.model import c3d as c3d_mod
from livezmp.model.anthropometry import DE_LEVA_MALE
from livezmp.model.c3d import C3dTrial, read_c3d
from livezmp.model.markers import (
    ELBOW_WIDTH_OF_STATURE,
    SHOULDER_OFFSET,
    TRUNK_FOLLOW_HZ,
    WRIST_WIDTH_OF_STATURE,
    MarkerBodyOptions,
    _euler_zyx,
    _segments,
    body_from_markers,
    hat_sway,
    hat_table,
)
from livezmp.offline import calibrate as calibration
from livezmp.offline import gaitlab, validation
from livezmp.offline.gaitlab import LabOptions, analyse_lab_take, lateral_band
from livezmp.offline.validation import lag_with_halves, stance_gap
from tests.data_paths import DATA

C3D = DATA / "c3d"
RATE, ANALOG, SECONDS, MASS = 100, 1000, 4.0, 75.0
# standing marker positions (m, z up, facing +x); right side mirrors left in y
LEFT = {"ASI": (0.05, 0.12, 0.95), "PSI": (-0.10, 0.05, 0.98), "THI": (0.0, 0.16, 0.70), "KNE": (0.0, 0.14, 0.50),
        "TIB": (0.0, 0.13, 0.30), "ANK": (0.0, 0.12, 0.08), "HEE": (-0.06, 0.10, 0.04), "TOE": (0.15, 0.10, 0.03)}
FOOT = ("ANK", "HEE", "TOE")
UPPER_LEFT = {"FHD": (0.07, 0.06, 1.65), "BHD": (-0.08, 0.06, 1.64), "SHO": (0.0, 0.18, 1.43),
              "ELB": (-0.01, 0.22, 1.15), "WRA": (0.03, 0.23, 0.90), "WRB": (-0.02, 0.21, 0.90),
              "FIN": (0.02, 0.22, 0.80)}
HEAD3 = {"THEA": (0.0, 0.0, 1.757), "FHEA": (0.09, 0.0, 1.66), "RHEA": (-0.10, 0.0, 1.66)}  # top, front, rear
NECK = np.array([0.0, 0.0, 1.50])
TOP_ROLL = 0.15  # rad: the trunk-top set's trunk rolls this far over the hips
CENTRE = {"C7": (-0.08, 0.0, 1.45), "T10": (-0.10, 0.0, 1.20), "CLAV": (0.05, 0.0, 1.42), "STRN": (0.09, 0.0, 1.25)}
P95_WALK_MM = 86  # walk_plugingait's p95 with the default trunk sway (measured 83.2 mm; 101.7 without it)
PLATES = {"left": (0.05, 0.15), "right": (0.05, -0.15), "spare": (1.2, 0.0)}  # centres (m); 0.5 x 0.3 plates
WOBBLE_HZ = 5.0  # Hz: between half the estimator's 6 Hz cutoff and the cutoff
OFFSET = np.array([3.0, -2.0, 30.0, 4.0, -6.0, 1.0])  # N, N·m on the unloaded plate


def _markers(t: np.ndarray, full_body: bool = False, cluster: bool = False,
             trunk: bool | str = False) -> dict[str, np.ndarray]:
    """(F, 3) m per label: the body above the ankles sways fore-aft and sideways about the ankle line;
    ``full_body`` adds Plug-in Gait's trunk, head and arm markers (the arms also swing); ``cluster``
    gives instead a cluster set (CLUSTER: 3-4 markers a segment, no standard label) plus medial knee
    and ankle markers; ``trunk`` the lower body and the trunk's four markers only (C7 T10 CLAV STRN), or
    ``"top"``: only C7 and the clavicles' LCLA and RCLA, the trunk also rolling sideways over the hips by up
    to TOP_ROLL (as a trunk leaning over the stance leg does), or ``"shoulders"``: so, with LSHO and RSHO, or
    ``"arms"``: so, with the Helen Hayes upper body's ELB and WRI too (lateral epicondyle, wrist), the arms
    swinging, or ``"arms_head"``: so, with its head's three markers HEAD3 too, the head nodding, or ``"head"``: the
    trunk's four markers and Plug-in Gait's four head markers, the head nodding, no arm markers."""
    if cluster:
        return _cluster_markers(_markers(t))
    if trunk is True:
        return {k: v for k, v in _markers(t, full_body=True).items() if k in CENTRE or k[1:] in LEFT}
    pitch = 0.05 * np.sin(2 * np.pi * 0.4 * t)
    roll = 0.03 * np.sin(2 * np.pi * 0.3 * t + 1.0)
    rot = np.array([pin.utils.rpyToMatrix(r, p, 0.0) for r, p in zip(roll, pitch, strict=True)])
    pivot = np.array([0.0, 0.0, 0.08])
    out = {}
    for name, p in LEFT.items():
        for side, sign in (("L", 1.0), ("R", -1.0)):
            q = np.array([p[0], sign * p[1], p[2]])
            out[side + name] = np.repeat(q[None], len(t), 0) if name in FOOT else (rot @ (q - pivot)) + pivot
    if trunk in ("top", "shoulders", "arms", "arms_head"):  # carried by the sway, then rolled about the hips' middle
        hips = (out["LASI"] + out["RASI"] + out["LPSI"] + out["RPSI"]) / 4
        lean = np.array([pin.utils.rotate("x", a) for a in TOP_ROLL * np.sin(2 * np.pi * 0.5 * t)])
        top = ((("C7", CENTRE["C7"]), ("LCLA", (0.05, 0.07, 1.41)), ("RCLA", (0.05, -0.07, 1.41))) if trunk == "top"
               else (("LSHO", UPPER_LEFT["SHO"]), ("RSHO", (0.0, -0.18, 1.43))))
        if trunk.startswith("arms"):
            top += tuple((side + name, _swung(t, UPPER_LEFT[name] if name == "ELB" else (0.0, 0.22, 0.90), sign))
                         for name in ("ELB", "WRI") for side, sign in (("L", 1.0), ("R", -1.0)))
        if trunk == "arms_head":  # the head nodding about the neck
            nod = np.array([pin.utils.rotate("y", a) for a in 0.15 * np.sin(2 * np.pi * 0.7 * t)])
            top += tuple((name, nod @ (np.array(p) - NECK) + NECK) for name, p in HEAD3.items())
        for name, p in top:
            p = np.broadcast_to(np.array(p) - pivot, (len(t), 3))
            out[name] = hips + np.einsum("fij,fj->fi", lean, np.einsum("fij,fj->fi", rot, p) + pivot - hips)
    if trunk == "head":
        nod = np.array([pin.utils.rotate("y", a) for a in 0.15 * np.sin(2 * np.pi * 0.7 * t)])
        for name, p in CENTRE.items():
            out[name] = (rot @ (np.array(p) - pivot)) + pivot
        for name in ("FHD", "BHD"):
            for side, sign in (("L", 1.0), ("R", -1.0)):
                q = np.array([UPPER_LEFT[name][0], sign * UPPER_LEFT[name][1], UPPER_LEFT[name][2]])
                nodded = np.einsum("fij,j->fi", nod, q - NECK) + NECK
                out[side + name] = np.einsum("fij,fj->fi", rot, nodded - pivot) + pivot
    if full_body:
        for name, p in CENTRE.items():
            out[name] = (rot @ (np.array(p) - pivot)) + pivot
        for name, p in UPPER_LEFT.items():
            for side, sign in (("L", 1.0), ("R", -1.0)):
                q = np.array([p[0], sign * p[1], p[2]])
                if name in ("ELB", "WRA", "WRB", "FIN"):
                    out[side + name] = np.einsum("fij,fj->fi", rot, _swung(t, p, sign) - pivot) + pivot
                else:
                    out[side + name] = (rot @ (q - pivot)) + pivot
    return out


def _swung(t: np.ndarray, left: tuple, sign: float) -> np.ndarray:
    """(F, 3) m: the standing arm point ``left`` (mirrored to the right side for ``sign`` -1) swinging about the
    shoulder, the two sides in opposition."""
    q = np.array([left[0], sign * left[1], left[2]])
    shoulder = np.array([0.0, sign * 0.18, 1.39])
    a = 0.25 * sign * np.sin(2 * np.pi * 0.5 * t)
    return np.array([pin.utils.rotate("y", v) for v in a]) @ (q - shoulder) + shoulder


CLUSTER = {"pelvis": ("PV1", "PV2", "PV3", "PV4"), "thigh": ("TH1", "TH2", "TH3"), "shank": ("SK1", "SK2", "SK3"),
           "foot": ("FT1", "FT2", "FT3")}


def _cluster_markers(std: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The standard markers' motion carried by a cluster set: the pelvis' four, three per leg segment
    (affine combinations of markers of the same rigid body, so they move rigidly), lateral and medial
    knee and ankle markers (KNE, KNM, ANK, ANM)."""
    out = {f"PV{k + 1}": std[m] for k, m in enumerate(("LASI", "RASI", "LPSI", "RPSI"))}
    for s, o in (("L", "R"), ("R", "L")):
        fwd = 0.3 * (std[s + "ASI"] - std[s + "PSI"])
        across = (std[o + "KNE"] - std[s + "KNE"]) / 0.28  # unit medial (the knees are 0.28 m apart)
        out |= {s + "TH1": std[s + "THI"], s + "TH2": 0.8 * std[s + "KNE"] + 0.2 * std[s + "ASI"],
                s + "TH3": std[s + "THI"] + fwd, s + "SK1": std[s + "TIB"], s + "SK2": std[s + "TIB"] + fwd,
                s + "SK3": (std[s + "KNE"] + std[s + "TIB"]) / 2, s + "FT1": std[s + "TOE"], s + "FT2": std[s + "HEE"],
                s + "FT3": std[s + "ANK"], s + "KNE": std[s + "KNE"], s + "KNM": std[s + "KNE"] + 0.10 * across,
                s + "ANK": std[s + "ANK"], s + "ANM": std[s + "ANK"] + 0.07 * _medial(s)}  # the feet stand still
    return out


def _medial(side: str) -> np.ndarray:
    """Unit medial direction (m) of a foot standing still, facing +x."""
    return np.array([0.0, -1.0 if side == "L" else 1.0, 0.0])


def _trial(t: np.ndarray, rate: float, full_body: bool = False, cluster: bool = False,
           trunk: bool | str = False, height: float = 1.75) -> C3dTrial:
    m = _markers(t, full_body, cluster, trunk)
    return C3dTrial("synthetic", list(m), np.stack(list(m.values()), axis=1), rate, rate, 0.0, [], MASS,
                    "PROCESSING:Bodymass", height)


@functools.lru_cache(maxsize=4)  # variants of one lab share it (the arrays are not modified)
def _true_wrench(body: MarkerBodyOptions, full_body: bool = False, cluster: bool = False,
                 trunk: bool | str = False, analog: float = ANALOG, seconds: float = SECONDS,
                 height: float = 1.75) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Force (S, 3) N, moment about the world origin (S, 3) N·m and CoP (S, 2) m at the analog rate, from the
    marker body's own rigid-body dynamics driven by the motion sampled at >= 10 kHz (central differences), for
    a subject of ``height`` m (the file's Height: it sizes the placed segments and chooses the segment table)."""
    fine = int(np.ceil(10_000 / analog))
    t = np.arange(int(seconds * analog) * fine + 2 * fine) / (analog * fine) - 1.0 / analog
    take = body_from_markers(_trial(t, analog * fine, full_body, cluster, trunk, height),
                             replace(body, total_mass=MASS))
    q = take.frames
    h = 1.0 / (analog * fine)
    model, data = take.body.model, take.body.model.createData()
    force, moment = [], []
    for k in range(fine, len(t) - fine, fine):
        v = (q[k + 1] - q[k - 1]) / (2 * h)
        a = (q[k + 1] - 2 * q[k] + q[k - 1]) / (h * h)
        pin.computeCentroidalMomentumTimeVariation(model, data, q[k], v, a)
        f = data.dhg.linear - MASS * model.gravity.linear
        force.append(f)
        moment.append(data.dhg.angular + np.cross(data.com[0], f))
    force, moment = np.array(force)[: int(seconds * analog)], np.array(moment)[: int(seconds * analog)]
    cop = np.column_stack([-moment[:, 1] / force[:, 2], moment[:, 0] / force[:, 2]])
    return force, moment, cop


def _add_int(c3d, group: str, name: str, value) -> None:
    v = np.asarray(value)
    c3d.add_parameter(group, name, v.astype(float))
    c3d["parameters"][group][name]["type"] = ezc3d_swig.INT
    c3d["parameters"][group][name]["value"] = v.astype(int)


IDENTITY = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
PER_METRE = {"mm": 1000.0, "cm": 100.0, "m": 1.0}
KISTLER_AB = (0.21, 0.12)  # m: a Kistler plate's half sensor spacings along its x and y (ORIGIN(1), ORIGIN(2))


@dataclass(frozen=True)
class Lab:
    """How a lab writes the synthetic trial; the defaults are the reference (z up, mm, 100 / 1000 Hz, TYPE-2
    plates whose axes are the lab's).

    ``rot`` (3, 3) and ``origin`` (3,) m place the reference in the lab (p_lab = rot @ p_ref + origin): a y-up lab,
    walking along -x, a far origin; ``units`` POINT:UNITS (``units_given`` False: left empty, the data in
    ``units``); ``rate``, ``analog`` Hz; ``plate_type`` 1 (CoP channels Px Py and the free moment), 2, 3 (Kistler,
    8 channels), 4 (CAL_MATRIX) or 5 (8 channels, 6 x 8 CAL_MATRIX);
    ``spec_plates``: the plates as the C3D spec has them (z axis down, corner 1 in the plate's +x +y quadrant, then
    -x +y, -x -y, +x -y; ORIGIN the vector from the transducer origin to the surface centre, plate axes, its z
    negative); ``origin_sign`` -1 writes that vector negated (z positive, the original AMTI convention; TYPE 3:
    only its z, az0, Kistler's sensor offsets a, b staying positive);
    ``plate_turn`` deg the plates turned in the floor; ``scale`` (ANALOG:SCALE, OFFSET, GEN_SCALE) the channels
    are stored with; ``integer``: POINT:SCALE (> 0, POINT:UNITS per count) of an integer file, None: floating
    point (POINT:SCALE -1); ``prefix`` of the labels; ``mass``: whether the file gives the subject's mass and
    height; ``zero`` FORCE_PLATFORM:ZERO (3D frames, 1-based; 0 in the second: no baseline range);
    ``corner_origin``: the transducer origin at the plate's -x -y corner of its top surface and ORIGIN's x, y
    written from the centre to it, the spec's the other way round (an instrumented treadmill's belt as
    RealTimeBiomechanics/rtosim's ``walking_1.c3d`` writes it)."""

    rot: tuple = IDENTITY
    origin: tuple = (0.0, 0.0, 0.0)
    units: str = "mm"
    units_given: bool = True
    rate: int = RATE
    analog: int = ANALOG
    seconds: float = SECONDS
    plate_type: int = 2
    spec_plates: bool = False
    origin_sign: float = 1.0
    plate_turn: float = 0.0
    scale: tuple = (1.0, 0, 1.0)
    integer: float | None = None
    prefix: str = "Sub01:"
    mass: bool = True
    height_m: float = 1.75  # PROCESSING:Height, written with the mass
    subject: tuple = ()  # (name, mm) more PROCESSING measurements, written with the mass (LElbowWidth ...)
    zero: tuple = (1, 0)
    corner_origin: bool = False


def _plate_axes(lab: Lab) -> np.ndarray:
    """(3, 3) the plates' axes (columns x, y, z) in reference coordinates."""
    c, s = np.cos(np.radians(lab.plate_turn)), np.sin(np.radians(lab.plate_turn))
    ux, uy = np.array([c, s, 0.0]), np.array([-s, c, 0.0])
    return np.column_stack([ux, -uy, [0.0, 0.0, -1.0]] if lab.spec_plates else [ux, uy, [0.0, 0.0, 1.0]])


def _plate_origin(lab: Lab) -> np.ndarray:
    """(3,) m: FORCE_PLATFORM:ORIGIN as meant (transducer origin to surface centre, plate axes)."""
    if lab.plate_type == 3:
        return np.array([*KISTLER_AB, -0.045])
    if lab.corner_origin:
        return np.array([0.25, 0.15, 0.0])
    if lab.plate_type == 1:  # its CoP channels are from the surface centre
        return np.zeros(3)
    return np.array([0.002, -0.001, -0.04]) if lab.spec_plates else np.zeros(3)


CAL = np.eye(6) + 0.02 * np.sin(np.arange(36).reshape(6, 6))  # a TYPE-4 plate's calibration matrix (cross-talk)
# a TYPE-5 plate's: Kistler's eight channels (fx12 fx34 fy14 fy23 fz1..fz4, volts) to TYPE 2's six, with cross-talk
CAL5 = np.hstack([np.eye(6), np.zeros((6, 2))]) * 50.0 + np.cos(np.arange(48).reshape(6, 8))


def _channels(force: np.ndarray, moment: np.ndarray, lab: Lab) -> np.ndarray:
    """(S, 6 or 8) a plate's channels for force (S, 3) N and moment (S, 3) N·m about its surface centre, both in
    plate axes: forces and moments (N·POINT:UNITS) about the transducer origin, through the inverse CAL_MATRIX for
    TYPE 4, the 6 x 8 one for TYPE 5 (eight channels); TYPE 3: Kistler's eight forces (fx12 fx34 fy14 fy23 fz1..fz4,
    sensors k at (±a, ±b) in the corners' quadrant order), which give back the wrench through the C3D spec's TYPE-3
    formulae."""
    o = _plate_origin(lab)
    if lab.plate_type == 1:  # Fx Fy Fz, the CoP Px Py from the centre and the free moment Tz: M = (Px, Py, 0) x F + Tz
        fz = force[:, 2]
        loaded = np.abs(fz) > 1e-9
        px = np.where(loaded, -moment[:, 1] / np.where(loaded, fz, 1.0), 0.0)
        py = np.where(loaded, moment[:, 0] / np.where(loaded, fz, 1.0), 0.0)
        tz = moment[:, 2] - (px * force[:, 1] - py * force[:, 0])
        return np.column_stack([force, PER_METRE[lab.units] * np.column_stack([px, py, tz])])
    if lab.plate_type == 3:
        (a, b), (fx, fy, fz) = KISTLER_AB, force.T
        mx, my, mz = (moment - np.cross(force, [0.0, 0.0, o[2]])).T
        return np.column_stack([fx / 2 - mz / (4 * b), fx / 2 + mz / (4 * b),
                                fy / 2 + mz / (4 * a), fy / 2 - mz / (4 * a),
                                fz / 4 + mx / (4 * b) - my / (4 * a), fz / 4 + mx / (4 * b) + my / (4 * a),
                                fz / 4 - mx / (4 * b) + my / (4 * a), fz / 4 - mx / (4 * b) - my / (4 * a)])
    w = np.hstack([force, PER_METRE[lab.units] * (moment - np.cross(force, o))])
    return w @ np.linalg.inv(CAL).T if lab.plate_type == 4 else w @ np.linalg.pinv(CAL5).T if lab.plate_type == 5 else w


def _write_plates(c3d, lab: Lab, plates: dict[str, tuple[float, float]], wrenches: list) -> None:
    """FORCE_PLATFORM and ANALOG for ``wrenches`` [(force (S, 3) N, moment (S, 3) N·m about the plate's surface
    centre)] in reference axes, one per plate of ``plates`` (centres, m, reference frame; 0.5 x 0.3 m)."""
    rot, axes, per_m = np.asarray(lab.rot), _plate_axes(lab), PER_METRE[lab.units]
    n = 8 if lab.plate_type in (3, 5) else 6
    channels = np.hstack([_channels(f @ axes, m @ axes, lab) for f, m in wrenches])
    scale, offset, gen = lab.scale
    names = ("Fx12", "Fx34", "Fy14", "Fy23", "Fz1", "Fz2", "Fz3", "Fz4") if n == 8 else \
        ("Fx", "Fy", "Fz", "Px", "Py", "Mz") if lab.plate_type == 1 else ("Fx", "Fy", "Fz", "Mx", "My", "Mz")
    c3d["parameters"]["ANALOG"]["RATE"]["value"] = [lab.analog]
    c3d["parameters"]["ANALOG"]["LABELS"]["value"] = [f"{c}{k + 1}" for k in range(len(plates)) for c in names]
    c3d["data"]["analogs"] = channels.T[None]
    if lab.integer:  # counts, offset included, fit int16
        scale = np.maximum(np.abs(channels).max(axis=0), 1.0) / (30_000 - abs(offset)) / gen
    c3d.add_parameter("ANALOG", "SCALE", np.broadcast_to(scale, channels.shape[1]).astype(float))
    c3d["parameters"]["ANALOG"]["GEN_SCALE"]["value"] = [gen]
    _add_int(c3d, "FORCE_PLATFORM", "USED", [len(plates)])
    _add_int(c3d, "FORCE_PLATFORM", "TYPE", [lab.plate_type] * len(plates))
    _add_int(c3d, "FORCE_PLATFORM", "ZERO", list(lab.zero))
    quadrants = ((1, 1), (-1, 1), (-1, -1), (1, -1))
    corners = np.array([[rot @ (np.array([x, y, 0.0]) + axes[:, 0] * 0.25 * sx + axes[:, 1] * 0.15 * sy)
                         + lab.origin for sx, sy in quadrants] for x, y in plates.values()])
    c3d.add_parameter("FORCE_PLATFORM", "CORNERS", per_m * corners.transpose(2, 1, 0))
    sign = [1.0, 1.0, lab.origin_sign] if lab.plate_type == 3 else lab.origin_sign  # Kistler's a, b: distances
    sign = np.multiply(sign, [-1.0, -1.0, 1.0] if lab.corner_origin else 1.0)
    origin = np.tile(sign * _plate_origin(lab) * per_m, (len(plates), 1))
    c3d.add_parameter("FORCE_PLATFORM", "ORIGIN", origin.T)
    _add_int(c3d, "FORCE_PLATFORM", "CHANNEL", np.arange(1, n * len(plates) + 1).reshape(len(plates), n).T)
    if lab.plate_type == 4:
        c3d.add_parameter("FORCE_PLATFORM", "CAL_MATRIX", np.repeat(CAL[:, :, None], len(plates), axis=2))
    if lab.plate_type == 5:
        c3d.add_parameter("FORCE_PLATFORM", "CAL_MATRIX", np.repeat(CAL5[:, :, None], len(plates), axis=2))


def write_lab_c3d(path, plates: dict[str, tuple[float, float]], with_offsets: bool = True,
                  delay_samples: int = 0, body: MarkerBodyOptions | None = None, full_body: bool = False,
                  cluster: bool = False, spare_drift_n: float = 0.0, trunk: bool | str = False,
                  lab: Lab | None = None, pelvis_wobble_m: float = 0.0, right_free_s: float = 0.0,
                  right_bias_n: float = 0.0) -> np.ndarray:
    """The synthetic trial as a C3D at ``path``, written as ``lab`` does, its plates ``delay_samples`` analog samples
    late; returns the true CoP (S, 2) m at the analog rate (reference frame). ``cluster``: the cluster set (its
    body from ``body``'s map); ``spare_drift_n``: the unloaded plate's vertical force drifts by this much over the
    second half; ``pelvis_wobble_m``: the pelvis markers (not the body, nor its plates) shake sideways this far
    at WOBBLE_HZ (skin on the pelvis); ``right_free_s``: the left foot carries the whole body this long at first,
    then hands the right plate its share over 0.2 s; ``right_bias_n``: the right plate's channels carry a constant
    vertical force (N, up; an amplifier's DC offset)."""
    lab = lab or Lab()
    force, moment, cop = _true_wrench(body or MarkerBodyOptions(), full_body, cluster, trunk, lab.analog, lab.seconds,
                                      lab.height_m)
    if delay_samples:
        force, moment = (np.vstack([np.repeat(x[:1], delay_samples, 0), x[:-delay_samples]]) for x in (force, moment))
    t = np.arange(int(lab.seconds * lab.rate)) / lab.rate
    m = _markers(t, full_body, cluster, trunk)
    for k in ("LASI", "RASI", "LPSI", "RPSI") if pelvis_wobble_m else ():
        m[k][:, 1] += pelvis_wobble_m * np.sin(2 * np.pi * WOBBLE_HZ * t)
    m["LTH1" if cluster else "LTHI"][round(1.5 * lab.rate):round(1.55 * lab.rate)] = np.nan  # a short gap (filled)
    m["RFT1" if cluster else "RTOE"][:round(0.3 * lab.rate)] = np.nan  # a long gap at the start (the take is cut)
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [lab.rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = [f"{lab.prefix}{k}" for k in m]
    c3d.add_parameter("POINT", "UNITS", [lab.units] if lab.units_given else [])
    pts = np.ones((4, len(m), len(t)))
    xyz = np.stack(list(m.values()), axis=1) @ np.asarray(lab.rot).T + lab.origin  # (F, P, 3) m, lab frame
    pts[:3] = xyz.transpose(2, 1, 0) * PER_METRE[lab.units]
    c3d["data"]["points"] = pts
    residual = np.where(np.isnan(pts[0]), -1.0, 1.0)[None]
    c3d["data"]["meta_points"] = {"residuals": residual}
    ta = np.arange(len(force))[:, None] / lab.analog
    share = 0.5 + 0.2 * np.sin(2 * np.pi * 0.25 * ta)
    ramp = np.clip((ta - right_free_s) / 0.2, 0.0, 1.0) if right_free_s else np.ones_like(ta)
    ramp = ramp * ramp * (3 - 2 * ramp)  # smoothstep: no ringing in the low-pass
    share = 1.0 + (share - 1.0) * ramp
    centres = {k: np.array([x, y, 0.0]) for k, (x, y) in plates.items()}
    cop3 = np.column_stack([cop, np.zeros(len(cop))])
    # the left foot's force acts 2 cm behind its sole centre, nearer where a standing foot's CoP lies (the right
    # plate's share then stays on it as the subject sways back); alone, at the CoP (the right plate carries nothing)
    at = cop3 + ([0.03, 0.11, 0.0] - cop3) * ramp
    f1 = share * force
    m1 = np.cross(at - centres["left"], f1)
    f2 = force - f1
    m2 = moment - (m1 + np.cross(centres["left"], f1)) - np.cross(centres["right"], f2)
    axes = _plate_axes(lab)
    spare = np.tile(OFFSET * with_offsets, (len(force), 1))  # in the plate's own axes
    drift = spare_drift_n * np.clip(np.linspace(-1.0, 1.0, len(force)), 0.0, None)
    spare[:, :3] += np.outer(drift, axes[2])  # along the vertical
    f2 = f2 + [0.0, 0.0, right_bias_n]  # at the plate's centre: no moment about it
    _write_plates(c3d, lab, plates, [(f1, m1), (f2, m2), (spare[:, :3] @ axes.T, spare[:, 3:] @ axes.T)])
    if lab.mass:
        c3d.add_parameter("PROCESSING", "Bodymass", [MASS])
        c3d.add_parameter("PROCESSING", "Height", [1000.0 * lab.height_m])
        for name, mm in lab.subject:
            c3d.add_parameter("PROCESSING", name, [mm])
    c3d.write(str(path))
    if lab.integer or lab.scale[1]:  # ezc3d writes floats and zeroes ANALOG:OFFSET: rewrite its data section
        _store(path, pts, c3d["data"]["analogs"][0].T, lab)
    return cop


def parameter_at(data: bytes) -> dict[tuple[str, str], int]:
    """Byte position of each parameter's values in a little-endian C3D, by (group, name)."""
    pos = (data[0] - 1) * 512 + 4
    groups, params = {}, {}
    while (n := struct.unpack_from("b", data, pos)[0]) != 0:
        gid = struct.unpack_from("b", data, pos + 1)[0]
        name = data[pos + 2:pos + 2 + abs(n)].decode()
        (step,) = struct.unpack_from("<H", data, pos + 2 + abs(n))
        if gid < 0:
            groups[-gid] = name
        else:
            at = pos + 4 + abs(n)
            ndims = data[at + 1]
            params[(gid, name)] = at + 2 + ndims
        if step == 0:
            break
        pos += 2 + abs(n) + step
    return {(groups[g], name): at for (g, name), at in params.items()}


def _store(path, points: np.ndarray, analogs: np.ndarray, lab: Lab) -> None:
    """Rewrite the data section of ezc3d's float file ``path`` as ``lab`` stores it: int16 counts of
    POINT:SCALE (x, y, z; a fourth word of -1 for an unseen point, the spec's invalid mark) and of ANALOG:SCALE x
    GEN_SCALE offset by ANALOG:OFFSET (raw = value / (SCALE GEN_SCALE) + OFFSET, the spec's ANALOG:OFFSET
    read backwards), or floats with that OFFSET. ``points`` (4, P, F) in POINT:UNITS, ``analogs`` (S, C) values."""
    data = bytearray(Path(path).read_bytes())
    at = parameter_at(bytes(data))
    c = analogs.shape[1]
    scale = np.frombuffer(data, "<f4", c, at[("ANALOG", "SCALE")]) * lab.scale[2]
    raw = analogs / scale + lab.scale[1]
    struct.pack_into(f"<{c}h", data, at[("ANALOG", "OFFSET")], *[lab.scale[1]] * c)
    xyz = points[:3].transpose(2, 1, 0)  # (F, P, 3)
    unseen = np.isnan(xyz).any(axis=2)
    if lab.integer:
        struct.pack_into("<f", data, at[("POINT", "SCALE")], lab.integer)
        struct.pack_into("<f", data, 12, lab.integer)  # the header's copy
        counts = np.concatenate([np.rint(np.nan_to_num(xyz) / lab.integer), np.where(unseen, -1, 0)[..., None]], 2)
        frames, kind = [counts.reshape(len(xyz), -1), np.rint(raw).reshape(len(xyz), -1)], "<i2"
    else:
        w4 = np.where(unseen, -1.0, 0.0)[..., None]
        frames, kind = [np.concatenate([xyz, w4], 2).reshape(len(xyz), -1), raw.reshape(len(xyz), -1)], "<f4"
    block = np.hstack(frames)
    assert np.abs(block).max() < 32_000 or kind == "<f4"
    start = (struct.unpack_from("<H", data, 16)[0] - 1) * 512
    Path(path).write_bytes(bytes(data[:start]) + block.astype(kind).tobytes())


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    d = tmp_path_factory.mktemp("lab")
    cop = write_lab_c3d(d / "on.c3d", PLATES)
    write_lab_c3d(d / "raw.c3d", PLATES, with_offsets=False)
    write_lab_c3d(d / "off.c3d", {**PLATES, "right": (0.6, -0.15)})
    write_lab_c3d(d / "late.c3d", PLATES, delay_samples=25)
    return d, cop


def _analyze(path, tmp_path, *extra) -> tuple[int, dict]:
    out = tmp_path / "s.json"
    rc = main(["analyze", str(path), "--summary-json", str(out), "--out", str(tmp_path / "z.csv"), *extra])
    return rc, json.loads(out.read_text()) if rc == 0 else {}


def test_plate_cop_is_the_true_cop_and_the_zmp_agrees_within_a_millimetre(lab, tmp_path):
    d, true_cop = lab
    trial = read_c3d(d / "on.c3d")
    assert trial.labels[0] == "LASI"  # prefix stripped
    a = analyse_lab_take(trial)
    rows = a.complete & (a.times > 0.5) & (a.times < SECONDS - 0.5)  # clear of the low-pass' end transients
    k = np.rint(a.times[rows] * ANALOG).astype(int)
    # plates through ezc3d, offsets removed, low-passed: the true CoP to well under a millimetre
    assert np.abs(a.plates.cop[rows, :2] - true_cop[k]).max() < 2e-4
    cv = a.summary["cop_vs_zmp"]
    assert cv["frames"] > 250 and cv["max_mm"] < 1.0 and cv["rms_mm"] < 0.5
    assert abs(a.summary["time_alignment"]["plate_delay_measured_ms"]) < 1.0
    assert a.summary["markers"]["frames_used"][0] == 30  # the long RTOE gap cut the start
    assert a.summary["markers"]["marker_gaps_open"] == [{"marker": "RTOE", "from_s": 0.0, "to_s": 0.29}]
    offsets = a.summary["plates"]["offsets_removed_n"]
    assert offsets[2] == pytest.approx(OFFSET[:3].tolist(), abs=1e-3)


def test_offset_removal_gives_the_unoffset_cop_and_without_it_the_cop_moves(lab, monkeypatch):
    d, _ = lab
    frames = np.arange(50, 350)

    def cop(name):
        trial = read_c3d(d / name)
        return plates_mod.plate_frames(trial.plates, ANALOG, RATE, frames, np.eye(3), 6.0).cop[:, :2]

    with_offsets, without = cop("on.c3d"), cop("raw.c3d")
    assert np.abs(with_offsets - without).max() < 1e-6
    monkeypatch.setattr(plates_mod, "unloaded_offset", lambda plate, rate, up: None)
    assert np.linalg.norm(cop("on.c3d") - without, axis=1).min() > 0.01  # the spare plate's 30 N pulls it


def test_full_body_set_tracks_trunk_head_and_arms(tmp_path):
    """Plug-in Gait full body with swinging arms: every upper segment is a body of its own, and the ZMP
    matches the plates (written from that body's exact dynamics) to a millimetre."""
    path = tmp_path / "full.c3d"
    write_lab_c3d(path, PLATES, full_body=True)
    a = analyse_lab_take(read_c3d(path))
    names = {n.split(".")[0] for n in a.take.body.channel_names}
    assert {"thorax", "head", "upperarm_l", "forearm_r", "hand_l"} <= names and "hat" not in names
    assert a.summary["markers"]["marker_set"].startswith("Plug-in Gait full body")
    assert a.take.body.total_mass == pytest.approx(sum(i.mass for i in a.take.body.model.inertias))
    assert a.summary["cop_vs_zmp"]["max_mm"] < 1.0
    # every segment on its own markers: no lateral band (docs/validation.md, "... where every segment is tracked")
    assert a.take.placed == () and a.summary["lateral_band_hz"] is None


def test_why_upper_body_labels_are_not_used_is_said():
    """A full-body file whose upper-body markers are labelled but never seen (BTK's FunctionalWalk sample), or
    whose C7, a shoulder and a wrist marker are never seen, places the HAT from the pelvis and says why: which
    labels are missing or never seen (it listed none before)."""
    t = np.arange(0.0, 1.0, 1 / RATE)
    trial = _trial(t, RATE, full_body=True)
    upper = [i for i, lab in enumerate(trial.labels) if lab in ("C7", "T10", "CLAV", "STRN", "LFHD", "RFHD",
                                                                  "LBHD", "RBHD", "LSHO", "RSHO", "LELB", "RELB",
                                                                  "LWRA", "RWRA", "LWRB", "RWRB")]
    assert len(upper) == 16
    points = trial.points.copy()
    points[:, upper] = np.nan
    notes = body_from_markers(replace(trial, points=points)).notes
    assert notes["marker_set"].endswith("; upper-body markers labelled but never seen: not used")
    points = trial.points.copy()
    points[:, [trial.labels.index(lab) for lab in ("C7", "LSHO", "LWRB")]] = np.nan  # no trunk top is complete
    notes = body_from_markers(replace(trial, points=points)).notes
    assert notes["marker_set"].endswith("(missing C7 (never seen), LSHO (never seen), LWRB (never seen)): not used")
    assert notes["hat"].startswith("head, arms and trunk")


def test_a_plate_pulling_down_is_set_aside(lab, tmp_path, monkeypatch):
    """The unloaded plate drifts by -120 N: past its offset it reads a pull, which a plate cannot exert, so it
    is set aside and the ZMP still meets the true CoP; summed in, its drift would move the CoP by centimetres."""
    d, _ = lab
    path = tmp_path / "drift.c3d"
    write_lab_c3d(path, PLATES, spare_drift_n=-120.0)
    a = analyse_lab_take(read_c3d(path))
    [aside] = a.summary["plates"]["set_aside"]
    assert aside["plate"] == 3 and aside["min_fz_n"] < -plates_mod.PULL_N
    assert a.summary["cop_vs_zmp"]["max_mm"] < 1.0
    monkeypatch.setattr(plates_mod, "PULL_N", np.inf)
    assert analyse_lab_take(read_c3d(path)).summary["cop_vs_zmp"]["max_mm"] > 10.0


def test_a_plate_reading_more_than_a_person_can_load_is_set_aside_and_said(lab, tmp_path):
    """A plate's channels a million times too large (a scale or unit wrong): read as given, its offset then counted as
    load (channels 1e30 times too large: CoP vs ZMP RMS 0.09 -> 55 mm, a stance mass of 7.8e31 kg, no word; audit 9).
    Now set aside as a pulling plate is, its reason in the summary."""
    c3d = ezc3d.c3d(str(lab[0] / "on.c3d"))
    analogs = np.array(c3d["data"]["analogs"])
    analogs[0, 6:12] *= 1e6  # the second plate's six channels
    c3d["data"]["analogs"] = analogs
    c3d.write(str(tmp_path / "big.c3d"))
    [aside] = analyse_lab_take(read_c3d(tmp_path / "big.c3d")).summary["plates"]["set_aside"]
    assert aside["plate"] == 2 and aside["max_fz_n"] > plates_mod.OVERLOAD_N
    assert "more than any person's 20000 N" in aside["reason"]


def test_a_plate_read_turned_round_puts_its_cop_off_the_foot_and_is_reported(lab, tmp_path):
    """The left plate's corners numbered from the opposite corner (its axes read turned by 180 degrees, a classic
    set-up error): its CoP lands off the left foot standing on it, every frame, and the summary says so; read
    right, it lies under the foot every frame. (The right plate carries the synthetic remainder, no foot's CoP.)"""
    d, _ = lab
    c3d = ezc3d.c3d(str(d / "on.c3d"))
    corners = np.array(c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"])
    corners[:, :, 0] = np.roll(corners[:, :, 0], 2, axis=1)
    c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"] = corners
    c3d.write(str(tmp_path / "turned.c3d"))
    right = analyse_lab_take(read_c3d(d / "on.c3d")).summary["cop_under_foot"]
    turned = analyse_lab_take(read_c3d(tmp_path / "turned.c3d")).summary["cop_under_foot"]
    assert right["plates"][0]["plate"] == 1 and right["plates"][0]["frames"] > 300
    assert right["plates"][0]["on_foot"] == 1.0 and not any(w.startswith("plate 1:") for w in right["warnings"])
    assert turned["plates"][0]["on_foot"] == 0.0 and turned["plates"][0]["off_p95_mm"] > 40
    assert any(w.startswith("plate 1: its CoP lies off the foot") for w in turned["warnings"])


def test_trunk_markers_alone_track_the_thorax(tmp_path):
    """A lower-body set with the trunk's four markers (C7 T10 CLAV STRN) but no head or arm markers: the
    thorax is a segment of its own, head and arms ride on it (no placed HAT), and the ZMP matches the plates
    written from that body's dynamics to a millimetre. Its mass adds up to the body's."""
    path = tmp_path / "trunk.c3d"
    write_lab_c3d(path, PLATES, trunk=True)
    a = analyse_lab_take(read_c3d(path))
    names = {n.split(".")[0] for n in a.take.body.channel_names}
    assert {"thorax", "headarms"} <= names and not {"hat", "head", "upperarm_l"} & names
    assert "thorax from C7 T10 CLAV STRN" in a.summary["markers"]["marker_set"]
    assert a.take.body.total_mass == pytest.approx(sum(i.mass for i in a.take.body.model.inertias))
    assert a.summary["cop_vs_zmp"]["max_mm"] < 1.0
    # head and arms placed on the thorax: de Leva's head above the cervicale, both arms hanging from it
    t, stature = DE_LEVA_MALE, 1.75
    head_len = 242.9 * stature / 1741
    # (mass fraction, forward, up): forward by Dumas et al.'s fractions of each part's length (head +2.0 %, upper
    # arm +1.7 %, forearm +1.0 %, hand +3.5 %)
    parts = [(t["head"].mass_fraction, 0.020 * head_len, head_len * (1 - t["head"].com_fraction))]
    joint = 0.0
    for name, fwd in (("upper_arm", 0.017), ("forearm", 0.010), ("hand", 0.035)):
        length = t[name].length_fraction * stature
        parts.append((2 * t[name].mass_fraction, fwd * length, joint - t[name].com_fraction * length))
        joint -= length
    ha, ha_com, _ = hat_table(stature, "head_and_arms")
    assert ha == pytest.approx(sum(f for f, _, _ in parts))
    assert ha_com[2] == pytest.approx(sum(f * z for f, _, z in parts) / ha)  # ~0.14 m below: arms outweigh the head
    assert ha_com[0] == pytest.approx(sum(f * x for f, x, _ in parts) / ha) and ha_com[1] == 0.0


@pytest.mark.parametrize("trunk, labels", [("top", "C7 LCLA RCLA"), ("shoulders", "LSHO RSHO")])
def test_trunk_top_markers_track_a_leaning_thorax(tmp_path, trunk, labels):
    """A lower-body set with only the trunk's top (C7 and the clavicles' LCLA, RCLA, or their ISB name LSC, RSC;
    or the shoulders' LSHO, RSHO), the trunk rolling over the hips on its own: the thorax is tracked, its axis
    from the mid-hip, and the ZMP matches the plates written from that body's dynamics to a millimetre. Without
    C7 (LSHO) the HAT is placed upright on the mid-hip and misses the lean by centimetres."""
    path = tmp_path / "top.c3d"
    write_lab_c3d(path, PLATES, trunk=trunk)
    trial = read_c3d(path)
    a = analyse_lab_take(trial)
    assert {"thorax", "headarms"} <= {n.split(".")[0] for n in a.take.body.channel_names}
    assert f"thorax from {labels} (its axis from the mid-hip)" in a.summary["markers"]["marker_set"]
    assert a.summary["cop_vs_zmp"]["max_mm"] < 1.0
    if trunk == "top":  # the clavicles' sternal ends under their ISB name (c3d.org's 2198928: LSC, RSC)
        isb = replace(trial, labels=[{"LCLA": "LSC", "RCLA": "RSC"}.get(v, v) for v in trial.labels])
        assert analyse_lab_take(isb).summary["cop_vs_zmp"]["rms_mm"] == a.summary["cop_vs_zmp"]["rms_mm"]
    trial.labels[trial.labels.index(labels.split()[0])] = "unused"
    placed = analyse_lab_take(trial)
    assert "hat" in {n.split(".")[0] for n in placed.take.body.channel_names}
    assert placed.summary["cop_vs_zmp"]["rms_mm"] > 10.0


def test_the_plates_cop_leaves_its_force_line_as_far_as_the_trunk_rolls(tmp_path):
    """The trunk rolling over the hips (the trunk-top lab) moves the plates' CoP off the line of their force
    through the CoM by the body's roll (Newton-Euler), 7 mm RMS across the walk: the body whose thorax is tracked
    reproduces that to 0.2 mm (its ZMP off its own force line as far), the same lab with its HAT placed (C7 not
    read) does not roll (0.5 mm) and its misplaced CoM leaves the plates' CoP 24 mm off; without the roll, the
    plates' CoP and the ZMP both stay within 1.5 mm of their force lines."""
    path = tmp_path / "top.c3d"
    write_lab_c3d(path, PLATES, trunk="top")
    trial = read_c3d(path)
    tracked = analyse_lab_take(trial).summary["cop_vs_force_line"]
    assert tracked["frames"] > 250 and tracked["single_support_frames"] == 0 and tracked["plates_stance_gap_mm"] is None
    assert tracked["plates_rms_mm"][1] > 5.0
    assert abs(tracked["zmp_rms_mm"][1] - tracked["plates_rms_mm"][1]) < 0.5
    trial.labels[trial.labels.index("C7")] = "unused"
    placed = analyse_lab_take(trial).summary["cop_vs_force_line"]
    assert placed["zmp_rms_mm"][1] < 1.0 and placed["plates_rms_mm"][1] > 3 * tracked["plates_rms_mm"][1]
    write_lab_c3d(path, PLATES)
    still = analyse_lab_take(read_c3d(path)).summary["cop_vs_force_line"]
    assert max(still["plates_rms_mm"] + still["zmp_rms_mm"]) < 2.0


def test_a_stance_gap_is_half_the_left_minus_right_offset():
    """An offset out towards the stance foot by 30 mm in every stance (left stance +y, right stance -y, walking
    along +x) on top of a constant one: the stance gap is 30 mm laterally and 0 fore-aft, whichever constant; frames
    in double support do not count; a side with too few frames gives none."""
    axes = (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    stance = np.repeat([0, 2, 1, 2, 0, 1], 12)
    offset = np.column_stack([np.full(len(stance), 0.02), np.where(stance == 0, 0.03, -0.03) + 0.011])
    offset[stance == 2] = 5.0  # double support: left out
    assert stance_gap(offset, stance, axes, 10) == pytest.approx([0.0, 0.03])
    assert stance_gap(offset, stance, (np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0])), 10) == \
        pytest.approx([0.03, 0.0])  # the same offsets with the walk along +y: their world-y gap is now along it
    assert stance_gap(offset, stance, axes, 25) is None


@pytest.mark.parametrize("trunk", ["arms", "arms_head"])
def test_helen_hayes_arm_markers_track_the_arms(tmp_path, trunk):
    """The Helen Hayes upper body as Motion Analysis writes it (SHO, ELB, WRI a side; with or without the head's
    THEA FHEA RHEA), the trunk rolling over the hips, the arms swinging and the head nodding: each arm is tracked
    (upper arm, forearm, hand), its elbow and wrist centres medial of ELB and WRI (the segments' lengths from the
    standing markers), the head on its markers or else placed on the thorax, de Leva's centre of mass from the
    vertex or the cervicale; the masses add up to the body's, and the ZMP matches the plates written from that
    body's dynamics to a millimetre. With the wrists unread the arms hang on the thorax: the ZMP then misses the
    plates by up to 3 mm, over ten times the tracked arms' largest miss (the arms swing in opposition, so most of
    their momentum cancels; what is left is where their mass is); with THEA unread the head is placed on the
    thorax and its nod missed (5.5 mm)."""
    path = tmp_path / "arms.c3d"
    write_lab_c3d(path, PLATES, trunk=trunk)
    trial = read_c3d(path)
    a = analyse_lab_take(trial)
    names = {n.split(".")[0] for n in a.take.body.channel_names}
    assert {"thorax", "head", "upperarm_l", "forearm_r", "hand_l", "hand_r"} <= names
    assert not {"hat", "headarms"} & names
    marker_set = a.summary["markers"]["marker_set"]
    assert "arms from LSHO LELB LWRI RSHO RELB RWRI" in marker_set
    assert ("head from THEA FHEA RHEA" in marker_set) == (trunk == "arms_head")
    assert a.take.body.total_mass == pytest.approx(sum(i.mass for i in a.take.body.model.inertias))
    assert a.summary["cop_vs_zmp"]["max_mm"] < 1.0
    _assert_arm_centres(a, SHOULDER_OFFSET, ELBOW_WIDTH_OF_STATURE * 1.75, WRIST_WIDTH_OF_STATURE * 1.75)
    com = functools.partial(_segment_com, a.take.body.model)
    head, head_len = DE_LEVA_MALE["head"], 242.9 * 1.75 / 1741
    below_vertex = trunk == "arms_head"  # else above the cervicale, the thorax' origin
    assert com("head")[2] == pytest.approx(-head.com_fraction * head_len if below_vertex else
                                           (1 - head.com_fraction) * head_len)
    frames = a.take.frames
    head_pitch, thorax_pitch = (frames[:, a.take.body.channel_names.index(f"{s}.pitch")] for s in ("head", "thorax"))
    assert (np.ptp(head_pitch - thorax_pitch) > 0.2) == below_vertex  # the nod is tracked (0.3 rad peak to peak)
    trial.labels[trial.labels.index("THEA" if below_vertex else "LWRI")] = "unused"
    placed = analyse_lab_take(trial)
    assert "head from" not in placed.summary["markers"]["marker_set"]
    assert ("headarms" in {n.split(".")[0] for n in placed.take.body.channel_names}) != below_vertex
    assert placed.summary["cop_vs_zmp"]["max_mm"] > max(2.0, 10 * a.summary["cop_vs_zmp"]["max_mm"])


def _segment_com(model, seg: str) -> np.ndarray:
    """(3,) m: segment ``seg``'s centre of mass in its joint's frame."""
    return model.inertias[model.frames[model.getFrameId(seg)].parentJoint].lever


def test_centres_of_mass_lie_behind_the_joint_lines_as_the_body_scans_put_them(monkeypatch):
    """De Leva's table puts each centre of mass on its segment's joint-centre line; 3-D scans of the body (Dumas,
    Cheze & Verriest 2007, table 2, men) put the thigh's and the shank's 4.1 and 4.8 % of their length behind it,
    the torso's 3.6 % behind its axis. On the synthetic lab's subject standing upright (facing +x) the marker body's
    whole centre of mass, which the plates' CoP of a still subject is, then lies 7-10 mm further back than on the
    lines, for the lower-body set (its HAT placed) and the one tracking its thorax."""
    t = np.arange(RATE) / RATE
    moved = []
    for trunk in (False, True):
        take = body_from_markers(_trial(t, RATE, trunk=trunk))
        model = take.body.model
        for seg, behind, along in (("thigh", 0.041, 0.4095), ("shank", 0.048, 0.4459)):
            for side in "lr":
                com = _segment_com(model, f"{seg}_{side}")  # x forward, z up the segment
                assert com[0] == pytest.approx(-behind * -com[2] / along, abs=1e-9)
        if trunk:
            assert _segment_com(model, "thorax")[0] == pytest.approx(-0.036 * (170.7 + 215.5) * 1.75 / 1741)
        data = model.createData()
        now = pin.centerOfMass(model, data, take.frames[0])[0]
        for kind, params in DE_LEVA_MALE.items():  # the same table with every centre of mass on its line
            monkeypatch.setitem(DE_LEVA_MALE, kind, replace(params, anterior_fraction=0.0))
        lines = body_from_markers(_trial(t, RATE, trunk=trunk)).body.model
        moved.append(pin.centerOfMass(lines, lines.createData(), take.frames[0])[0] - now)
        monkeypatch.undo()
    assert all(0.006 < m < 0.012 for m in moved)  # 7.2 mm (placed HAT), 9.5 mm (tracked thorax)


def _assert_arm_centres(a, shoulder: float, elbow: float, wrist: float) -> None:
    """The arms' centres from the standing markers: the shoulder ``shoulder`` plus a marker radius below SHO, elbow
    and wrist half their widths ``elbow``, ``wrist`` plus a marker radius medial of ELB, WRI (m); each segment's
    CoM de Leva's fraction down its length."""
    sjc = np.array(UPPER_LEFT["SHO"]) - [0.0, 0.0, shoulder + 0.007]
    ejc = np.array(UPPER_LEFT["ELB"]) - [0.0, elbow / 2 + 0.007, 0.0]
    wjc = np.array([0.0, 0.22, 0.90]) - [0.0, wrist / 2 + 0.007, 0.0]
    for side in "lr":
        for seg, table, length in (("upperarm", "upper_arm", sjc - ejc), ("forearm", "forearm", ejc - wjc)):
            assert -_segment_com(a.take.body.model, f"{seg}_{side}")[2] == pytest.approx(
                DE_LEVA_MALE[table].com_fraction * np.linalg.norm(length), abs=1e-3)


def test_head_markers_track_the_head_without_arm_markers(tmp_path):
    """The trunk's four markers and Plug-in Gait's four head markers, no arm markers, the head nodding: the head is
    tracked on its markers and the arms (de Leva's, hanging) placed on the thorax; the masses add up and the ZMP
    matches the plates written from that body's dynamics to a millimetre. With a head marker unread the head is
    placed on the thorax (as before), its nod missed: 8 mm at most, over ten times the tracked head's largest miss."""
    path = tmp_path / "head.c3d"
    write_lab_c3d(path, PLATES, trunk="head")
    trial = read_c3d(path)
    a = analyse_lab_take(trial)
    names = {n.split(".")[0] for n in a.take.body.channel_names}
    assert {"thorax", "head", "arms"} <= names and not {"hat", "headarms", "upperarm_l"} & names
    assert a.summary["markers"]["marker_set"].endswith("; head from LFHD RFHD LBHD RBHD")
    assert a.summary["markers"]["hat"] == ("trunk tracked by C7 T10 CLAV STRN, head by LFHD RFHD LBHD RBHD; arms "
                                           "(de Leva) placed on it, hanging")
    assert a.take.body.total_mass == pytest.approx(sum(i.mass for i in a.take.body.model.inertias))
    assert a.summary["cop_vs_zmp"]["max_mm"] < 1.0
    assert a.take.placed == ("arms",) and a.summary["lateral_band_hz"] == 3.0  # arms ride on the thorax markers
    trial.labels[trial.labels.index("LBHD")] = "unused"
    placed = analyse_lab_take(trial)
    assert {"thorax", "headarms"} <= {n.split(".")[0] for n in placed.take.body.channel_names}
    assert placed.take.placed == ("headarms",)
    assert placed.summary["cop_vs_zmp"]["max_mm"] > max(2.0, 10 * a.summary["cop_vs_zmp"]["max_mm"])


def test_the_files_arm_measurements_place_the_arm_centres(tmp_path):
    """Plug-in Gait's subject measurements in PROCESSING (LShoulderOffset, LElbowWidth, LWristWidth and the right
    side's, mm; c3d.org's vicon_zerowire writes them) are read in m and place the shoulder, elbow and wrist centres
    in place of the defaults; the summary says they are the file's. The defaults' lengths then do not fit."""
    given = {"ShoulderOffset": 25.0, "ElbowWidth": 90.0, "WristWidth": 70.0}
    path = tmp_path / "arms.c3d"
    write_lab_c3d(path, PLATES, trunk="arms", lab=Lab(subject=tuple((s + k, v) for k, v in given.items()
                                                                   for s in "LR")))
    trial = read_c3d(path)
    assert trial.widths_m == {s + k: pytest.approx(v / 1000) for k, v in given.items() for s in "LR"}
    a = analyse_lab_take(trial)
    _assert_arm_centres(a, *(v / 1000 for v in given.values()))
    rules = a.summary["markers"]["joint_centres"]
    assert rules["elbows"].endswith("(width 90 / 90 mm, the file's)")
    assert "offset 25 / 25 mm, the file's" in rules["shoulders"]
    with pytest.raises(AssertionError):
        _assert_arm_centres(a, SHOULDER_OFFSET, ELBOW_WIDTH_OF_STATURE * 1.75, WRIST_WIDTH_OF_STATURE * 1.75)


def test_late_plates_are_measured_and_realigned(lab):
    """Plates 25 ms behind the markers: measured from the CoM acceleration and undone; left in, the ZMP
    would seem to lead the CoP by 25 ms."""
    d, _ = lab
    trial = read_c3d(d / "late.c3d")
    a = analyse_lab_take(trial)
    assert a.summary["time_alignment"]["plate_delay_measured_ms"] == pytest.approx(25.0, abs=2.0)
    assert a.summary["cop_vs_zmp"]["max_mm"] < 1.0
    assert a.summary["time_alignment"]["plate_delay_determined"]
    raw = analyse_lab_take(trial, LabOptions(plate_delay_s=0.0))
    assert raw.summary["cop_vs_zmp"]["lag_ms"] == pytest.approx(-25.0, abs=3.0)
    assert raw.summary["cop_vs_zmp"]["lag_halves_ms"] == pytest.approx([-25.0, -25.0], abs=3.0)
    assert raw.summary["cop_vs_zmp"]["max_mm"] > 2.0
    # the applied delay's own uncertainty is part of the lag's: the lag is measured against the shifted plates
    ta, cv = a.summary["time_alignment"], a.summary["cop_vs_zmp"]
    assert 0 < ta["plate_delay_uncertainty_ms"] <= cv["lag_uncertainty_ms"] < 5.0


def test_a_plate_delay_its_halves_do_not_pin_down_is_not_applied(lab, monkeypatch):
    """A measured plate delay of +30 ms whose halves give 0 and +60 ms is the body model's timing as much as the
    clock's: the plates stay where the file has them (ISW's +18 ms, halves +6 / +28, put its ZMP 17 ms late). The
    same delay determined is applied."""
    d, _ = lab
    trial = read_c3d(d / "on.c3d")
    for determined, applied in ((False, 0.0), (True, 30.0)):
        monkeypatch.setattr(gaitlab, "plate_delay", lambda *_, ok=determined: (0.03, ok, [0.0, 0.06], 0.03))
        s = analyse_lab_take(trial).summary
        assert s["time_alignment"]["plate_delay_applied_ms"] == applied
        assert s["cop_vs_zmp"]["lag_ms"] == pytest.approx(applied, abs=2.0)


def test_lateral_band_keeps_the_stride_harmonics_across_the_walk_and_leaves_the_rest():
    """Across a walk heading 30 deg off x: a 1 Hz sway (the stride's) and a 0.9 Hz sway of a second segment are
    kept, a 5 Hz wobble (between half the 6 Hz cutoff and the cutoff: soft tissue, not the CoM's lateral
    motion) is removed; along the walk the same 5 Hz is kept, and height and angles are untouched."""
    t = np.arange(0, 6, 1 / RATE)
    fwd, left = np.array([np.cos(0.5), np.sin(0.5), 0.0]), np.array([-np.sin(0.5), np.cos(0.5), 0.0])
    sway, wobble = 0.02 * np.sin(2 * np.pi * t), 0.004 * np.sin(2 * np.pi * 5 * t)
    frames = np.zeros((len(t), 12))
    frames[:, :3] = np.outer(1.2 * t + wobble, fwd) + np.outer(sway + wobble, left) + [0, 0, 0.95]
    frames[:, 3:6] = np.c_[0.5 + 0.1 * wobble, wobble, -wobble]
    frames[:, 6:9] = np.outer(1.2 * t, fwd) + np.outer(0.01 * np.sin(2 * np.pi * 0.9 * t), left) + [0, 0, 0.5]
    out = lateral_band(frames, RATE, 3.0)
    inner = slice(RATE, -RATE)
    np.testing.assert_allclose(out[inner, :3] @ left, sway[inner], atol=0.0008)  # wobble 4 mm -> < 0.8 mm
    np.testing.assert_allclose(out[:, :3] @ fwd, frames[:, :3] @ fwd, atol=1e-4)  # heading: 0.4 deg
    np.testing.assert_allclose(out[:, 2], frames[:, 2], atol=1e-12)
    np.testing.assert_allclose(out[:, 3:6], frames[:, 3:6], atol=0)
    np.testing.assert_allclose(out[inner, 6:9], frames[inner, 6:9], atol=0.0005)  # 0.9 Hz: gain > 0.95
    assert np.abs(frames[inner, :3] @ left - sway[inner]).max() > 0.0039  # the wobble was there


def test_lateral_band_follows_a_turning_walk():
    """A walk at 1.2 m/s turning 90 deg to the left over 2 s, with a 5 Hz wobble along the walk (a step's harmonic)
    and across it: across is removed, along kept, before, in and after the turn. Across the take's straight-line
    trend instead (half-way between the two legs), half of the along-walk wobble went on both legs."""
    t = np.arange(0, 8, 1 / RATE)
    heading = 0.5 * np.pi * np.clip((t - 3.0) / 2.0, 0.0, 1.0)
    heading = 0.5 * np.pi * (1 - np.cos(np.pi * heading / (0.5 * np.pi))) / 2  # smooth in and out of the turn
    fwd = np.column_stack([np.cos(heading), np.sin(heading), 0 * t])
    left = np.column_stack([-np.sin(heading), np.cos(heading), 0 * t])
    path = np.cumsum(1.2 * fwd / RATE, axis=0)
    wobble = 0.004 * np.sin(2 * np.pi * 5 * t)
    frames = np.zeros((len(t), 6))
    frames[:, :3] = path + wobble[:, None] * (fwd + left) + [0, 0, 0.95]
    out = lateral_band(frames, RATE, 3.0)
    inner = slice(RATE, -RATE)
    along = np.einsum("ij,ij->i", out[:, :3] - path, fwd)
    across = np.einsum("ij,ij->i", out[:, :3] - path, left)
    np.testing.assert_allclose(along[inner], wobble[inner], atol=0.0008)
    assert np.abs(across[inner]).max() < 0.0008


@pytest.mark.parametrize("turn_deg", [0.0, 90.0, 180.0])
def test_a_turning_walks_bias_is_split_along_its_path(turn_deg):
    """A walk at 1.2 m/s turning ``turn_deg`` to the left over 2 s (180: it walks back), its ZMP 15 mm ahead of the
    CoP and 5 mm to its left at every frame, both with a stride's sway: the bias is 15 mm fore-aft and 5 mm lateral
    before, in and after the turn, and the lag (a distance's, so no axis's) the straight walk's. Along the net
    travel instead (half-way between the legs of a 90 deg turn, across those of a U-turn) 15 mm went half or wholly
    into the lateral."""
    def scored(turn: float) -> dict:
        t = np.arange(0, 8, 1 / RATE)
        s = np.clip((t - 3.0) / 2.0, 0.0, 1.0)
        heading = np.radians(turn) * (1 - np.cos(np.pi * s)) / 2  # smooth in and out of the turn
        fwd = np.column_stack([np.cos(heading), np.sin(heading), 0 * t])
        left = np.column_stack([-np.sin(heading), np.cos(heading), 0 * t])
        com = np.cumsum(1.2 * fwd / RATE, axis=0) + 0.02 * np.sin(np.pi * t)[:, None] * left + [0, 0, 0.95]
        cop = com + 0.06 * np.sin(2 * np.pi * t)[:, None] * fwd  # through each step and back
        every = np.ones(len(t), dtype=bool)
        return validation.cop_vs_zmp(cop + 0.015 * fwd + 0.005 * left, every, cop[:, :2], every, com, 1 / RATE)

    cv = scored(turn_deg)
    assert cv["bias_mm"] == pytest.approx([15.0, 5.0], abs=1.0)
    assert cv["lag_ms"] == pytest.approx(scored(0.0)["lag_ms"], abs=1.0)


def test_pelvis_markers_shaking_sideways_are_kept_out_of_the_zmp(tmp_path):
    """The pelvis markers shake 2 mm sideways at 5 Hz (skin, not the body: the plates see none of it). The
    segments' lateral positions in the lateral band (3 Hz) keep the ZMP on the CoP; at the estimator's 6 Hz
    the shake, through the pelvis, hip centres and placed HAT, moves the ZMP ~50 mm."""
    write_lab_c3d(tmp_path / "shake.c3d", PLATES, pelvis_wobble_m=0.002)
    trial = read_c3d(tmp_path / "shake.c3d")
    banded = analyse_lab_take(trial).summary["cop_vs_zmp"]
    assert banded["rms_mm"] < 2.0 and banded["max_mm"] < 3.0
    unbanded = analyse_lab_take(trial, LabOptions(lateral_cutoff_fraction=None)).summary["cop_vs_zmp"]
    assert unbanded["rms_mm"] > 30


def test_a_lag_is_determined_only_when_both_halves_agree():
    """A signal 30 ms behind its reference over the whole take: lag +30 ms, determined. The same with the second
    half 30 ms ahead instead: each half finds its own shift, the whole a compromise, not determined."""
    dt = 0.01
    t = np.arange(400) * dt
    ref = np.column_stack([np.sin(2 * np.pi * 0.9 * t), np.cos(2 * np.pi * 1.3 * t)])
    late = np.column_stack([np.sin(2 * np.pi * 0.9 * (t - 0.03)), np.cos(2 * np.pi * 1.3 * (t - 0.03))])
    early = np.column_stack([np.sin(2 * np.pi * 0.9 * (t + 0.03)), np.cos(2 * np.pi * 1.3 * (t + 0.03))])
    rows = (t > 0.5) & (t < 3.5)
    lag, ok, halves = lag_with_halves(late, ref, rows, dt)
    assert ok and lag == pytest.approx(0.03, abs=1e-3) and halves == pytest.approx([0.03, 0.03], abs=1e-3)
    mixed = np.where((t < 2.0)[:, None], late, early)
    lag, ok, halves = lag_with_halves(mixed, ref, rows, dt)
    assert not ok and halves == pytest.approx([0.03, -0.03], abs=2e-3)


def test_a_lags_uncertainty_covers_its_error_and_widens_where_the_take_wants_two_shifts():
    """Two noisy signals 30 ms apart (3 s at 100 Hz): the lag's 95 % interval is a few ms wide and holds 30 ms.
    The second half 30 ms ahead instead (a single stance's early and late parts wanting opposite shifts): the
    interval, the mean shift's, widens more than 40-fold, to over 10 ms (and the halves mark the lag not
    determined). Under two 0.2 s blocks of frames there is none."""
    dt = 0.01
    t = np.arange(400) * dt
    rng = np.random.default_rng(3)

    def shifted(s: float) -> np.ndarray:
        return np.column_stack([np.sin(2 * np.pi * 0.9 * (t - s)), np.cos(2 * np.pi * 1.3 * (t - s))])

    ref = shifted(0.0)
    late = shifted(0.03) + 0.02 * rng.standard_normal(ref.shape)
    rows = (t > 0.5) & (t < 3.5)
    u = validation.lag_uncertainty(late, ref, rows, dt)
    assert 0 < u < 0.005 and abs(validation.best_lag(late, ref, rows, dt) - 0.03) < u
    mixed = np.where((t < 2.0)[:, None], late, shifted(-0.03))
    assert validation.lag_uncertainty(mixed, ref, rows, dt) > max(0.01, 40 * u)
    assert validation.lag_uncertainty(late, ref, (t > 0.5) & (t < 0.64), dt) is None


def test_frames_next_to_load_off_the_plates_are_not_complete(lab, monkeypatch):
    """The right plate reads nothing for 0.6 s (its foot's load off the plates): those frames are not complete,
    and neither are the frames within the plates' low-pass reach of them (0.078 s at the lab's 4.93 Hz band):
    there the low-passed plates mix in the missing load (enough to pass the 75 % force test on the first frame of
    the gap), and their CoP lies up to 66 mm off the true one; kept out, the plates' CoP stays within 3 mm of the
    true CoP and the ZMP within 3 mm of it."""
    d, true_cop = lab
    errors, default = {}, gaitlab.PLATE_LEAK
    for leak in (default, 0.5):  # 0.5: the filter's reach is zero, the margin off
        monkeypatch.setattr(gaitlab, "PLATE_LEAK", leak)
        trial = read_c3d(d / "raw.c3d")
        gap = slice(int(1.6 * ANALOG), int(2.2 * ANALOG))
        trial.plates[1].force[gap] = 0.0
        trial.plates[1].moment[gap] = 0.0
        a = analyse_lab_take(trial)
        rows = a.complete & (a.times > 0.5) & (a.times < SECONDS - 0.5)
        k = np.rint(a.times[rows] * ANALOG).astype(int)
        errors[leak] = (1000 * np.abs(a.plates.cop[rows, :2] - true_cop[k]).max(), a.summary)
        if leak == default:
            # 8 frames clear of the first and last frame the plates' low-passed load falls below 75 %
            assert not a.complete[(a.times > 1.6 - 0.06) & (a.times < 2.2 + 0.06)].any()
    (kept, s), (off, s_off) = errors[default], errors[0.5]
    assert s["plates"]["complete_margin_s"] == pytest.approx(0.078, abs=0.002)
    assert kept < 3.0 and s["cop_vs_zmp"]["max_mm"] < 3.0
    assert off > 30.0 and s_off["cop_vs_zmp"]["max_mm"] > 30.0
    assert s_off["cop_vs_zmp"]["frames"] - s["cop_vs_zmp"]["frames"] == 2 * 8  # 8 frames at 100 Hz a side


def test_no_frame_clear_of_load_off_the_plates_says_so(lab, monkeypatch):
    """The right plate reading nothing from 1.6 to 2.2 s of the 4 s take, and a low-pass reaching 1.5 s: every frame
    with the load on the plates lies within that reach of the gap, none is complete, and the summary says why."""
    d, _ = lab
    trial = read_c3d(d / "raw.c3d")
    gap = slice(int(1.6 * ANALOG), int(2.2 * ANALOG))
    trial.plates[1].force[gap] = 0.0
    trial.plates[1].moment[gap] = 0.0
    monkeypatch.setattr(gaitlab, "lowpass_reach_s", lambda cutoff, outside: 1.5)
    a = analyse_lab_take(trial, LabOptions(mass=MASS))
    assert not a.complete.any()
    assert "within their low-pass reach (150 frames)" in a.summary["plates"]["no_complete_frame"]


def test_a_margin_keeps_the_frames_whose_neighbours_are_all_in():
    mask = np.array([0, 1, 1, 1, 0, 1, 1, 1, 1, 1, 1, 1, 0], dtype=bool)
    assert gaitlab.clear_of(mask, 2).astype(int).tolist() == [0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 0, 0, 0]
    assert gaitlab.clear_of(mask, 0).tolist() == mask.tolist()
    assert gaitlab.clear_of(np.ones(5, dtype=bool), 3).all()  # the take's own ends are no missing load


def test_the_low_pass_reach_is_where_its_impulse_response_has_5_percent_left_a_side():
    """lowpass_reach_s against the impulse response of the plates' low-pass itself, at a rate of its own."""
    rate, cutoff = 1000.0, 4.93
    impulse = np.zeros(8001)
    impulse[4000] = 1.0
    weight = np.abs(plates_mod.lowpass(impulse, rate, cutoff))
    reach = plates_mod.lowpass_reach_s(cutoff)
    k = round(reach * rate)
    assert weight[4000 + k + 1:].sum() / weight.sum() < 0.05 < weight[4000 + k - 1:].sum() / weight.sum()
    assert plates_mod.lowpass_reach_s(2 * cutoff) == pytest.approx(reach / 2, abs=0.002)  # it scales with 1 / cutoff


def test_a_foot_off_the_plates_leaves_no_complete_frame(lab, tmp_path):
    d, _ = lab
    rc, s = _analyze(d / "off.c3d", tmp_path)
    assert rc == 0
    assert s["plates"]["complete_frames"] == 0 and s["cop_vs_zmp"]["frames"] == 0
    assert "has every foot that may bear weight on a plate" in s["plates"]["no_complete_frame"]


def test_plates_carrying_less_than_the_mass_needs_say_so(lab):
    """newwalk's case: no mass in the file, its plates carry ~55 kg, the default 70 kg leaves no complete frame."""
    d, _ = lab
    s = analyse_lab_take(read_c3d(d / "on.c3d"), LabOptions(mass=1.5 * MASS)).summary
    assert s["plates"]["complete_frames"] == 0
    why = s["plates"]["no_complete_frame"]
    carried = int(why.split("at most ")[1].split(" %")[0])
    assert abs(carried - 100 / 1.5) <= 3 and "lighter subject" in why


def test_a_step_on_the_plates_without_a_file_mass_weighs_the_subject(tmp_path, monkeypatch):
    """No mass in the file, no whole gait cycle and too short to be a standing take: the plates weigh the subject
    over the frames where every loaded foot is on them, F_z / (g + a_z) with the kinematics' a_z (75 kg true)."""
    path = tmp_path / "short.c3d"
    write_lab_c3d(path, PLATES, lab=Lab(mass=False, seconds=1.6))
    trial = read_c3d(path)
    m = analyse_lab_take(trial).summary["mass"]
    assert m["source"] == "plates (stance)" and m["used_kg"] == pytest.approx(MASS, rel=0.005)
    assert m["stance_kept"] == 1.0 and m["stance_rule"].startswith("sum F_z / sum (g + a_z) over the ")
    monkeypatch.setattr(gaitlab, "stance_mass", lambda *a: (None, 0, 0))
    assert analyse_lab_take(trial).summary["mass"]["source"] == "default"  # the 70 kg default without it


def test_plates_weighing_the_subject_as_no_person_say_so(tmp_path):
    """Open3DMotion's Codamotion export weighs its subject at 1174 kg: plates whose channels all read 16 times too
    much weigh the lab's 75 kg subject (no mass in the file) at 1200 kg or so, a body-mass index near 400, and it is
    said. The true scale says nothing."""
    write_lab_c3d(tmp_path / "on.c3d", PLATES, lab=Lab(mass=False))
    c3d = ezc3d.c3d(str(tmp_path / "on.c3d"))
    c3d["data"]["analogs"] = c3d["data"]["analogs"] * 16.0  # written back through the file's unchanged SCALE
    c3d.write(str(tmp_path / "x16.c3d"))
    ref, s = (analyse_lab_take(read_c3d(tmp_path / n)).summary for n in ("on.c3d", "x16.c3d"))
    assert s["mass"]["used_kg"] == pytest.approx(16 * ref["mass"]["used_kg"], rel=0.1)  # weighed over other frames
    assert "no person's: their ANALOG:SCALE or FORCE_PLATFORM:UNITS may be wrong" in s["mass"]["note"]
    assert "no person" not in ref["mass"].get("note", "")


def test_stance_mass_sums_over_the_frames_the_plates_carry_whole():
    """Two seconds on the plates at 2 steps/s: F_z = m (g + a) with a the CoM's vertical acceleration (3 m/s²), while
    the kinematics' a_z keeps half of it and lags 40 ms (a smoothed second derivative). Frame by frame F_z / (g + a_z)
    scatters (IQR 19 % of the median, sub_labels' and sample14's case: refused before); Σ F_z / Σ (g + a_z) over
    whole steps is m. A step where 40 % of the load stands off the plates (a foot or an aid the markers do not see)
    is left out, as the complete frames leave it out; when most frames carry too little there is no mass."""
    rate, m, G = 100.0, 63.0, plates_mod.G
    t = np.arange(0, 2.0, 1 / rate)
    a = 3.0 * np.sin(2 * np.pi * 2.0 * t)
    a_kin = 1.5 * np.sin(2 * np.pi * 2.0 * (t - 0.04))
    fz = m * (G + a)
    on = np.ones(len(t), dtype=bool)
    per = np.percentile(fz / (G + a_kin), [25, 50, 75])
    assert (per[2] - per[0]) / per[1] > 0.15  # the old rule's limit
    assert plates_mod.stance_mass(fz, a_kin, on, gaitlab.FORCE_SEEN) == (pytest.approx(m, rel=1e-3), 200, 200)
    aid = (t >= 0.5) & (t < 1.0)  # one whole step
    fz_aid = np.where(aid, 0.6 * fz, fz)
    assert fz_aid.sum() / (G + a_kin).sum() < 0.92 * m  # summed over every frame: 10 % light
    assert plates_mod.stance_mass(fz_aid, a_kin, on, gaitlab.FORCE_SEEN) == (pytest.approx(m, rel=1e-3), 150, 200)
    most = (t >= 0.5) & (t < 1.5)  # half the frames miss load: kept half, still weighed
    assert plates_mod.stance_mass(np.where(most, 0.6 * fz, fz), a_kin, on, gaitlab.FORCE_SEEN)[0] == \
        pytest.approx(m, rel=1e-3)
    # 60 % of the frames carry 15 % of the load (gait-pig-nz's run on a plate set aside: 11 kg of 64): the plates do
    # not carry the body in most frames, no mass
    assert plates_mod.stance_mass(np.where(t >= 0.8, 0.15 * fz, fz), a_kin, on, gaitlab.FORCE_SEEN) == (None, 80, 200)


def test_the_plates_get_the_estimators_band():
    """Both sides of ZMP vs CoP must keep the same part of each frequency: the plates' low-pass at
    ``plates_band_hz`` keeps what the lab estimator keeps of an acceleration (measured on sinusoids through it) within
    0.01 from 1 to 4 Hz, at 60 and 120 Hz; the low-pass at the estimator's own cutoff (before) kept 0.84 of 4 Hz
    where the estimator keeps 0.70."""
    for rate in (60.0, 120.0):
        est = EstimatorConfig(rate_hz=rate, **gaitlab.LAB_ESTIMATOR)
        band = gaitlab.plates_band_hz(est)
        t = np.arange(int(8 * rate)) / rate
        for f in (1.0, 2.0, 3.0, 4.0):
            x = np.sin(2 * np.pi * f * t)
            mid = slice(len(t) // 4, 3 * len(t) // 4)  # clear of the filter's ends
            kept = np.std(plates_mod.lowpass(x, rate, band)[mid]) / np.std(x[mid])
            assert kept == pytest.approx(acceleration_response(est, f)[0], abs=0.01)
        old = np.std(plates_mod.lowpass(x, rate, est.cutoff_hz)[mid]) / np.std(x[mid])
        assert old - acceleration_response(est, 4.0)[0] > 0.1


def test_a_standing_take_without_a_file_mass_is_weighed_over_its_standing_span(tmp_path):
    """The synthetic subject stands 4 s on the plates, no mass in the file, no foot strike: the plates' mean vertical
    force over the unbroken complete frames is the weight (75 kg true)."""
    path = tmp_path / "stand.c3d"
    write_lab_c3d(path, PLATES, lab=Lab(mass=False))
    m = analyse_lab_take(read_c3d(path)).summary["mass"]
    assert m["source"] == "plates (standing)" and m["used_kg"] == pytest.approx(MASS, rel=0.005)


def test_a_standing_span_is_an_unbroken_run_of_complete_frames():
    """Two 1 s steps on the plates with a step off between them span 3 s but are not standing; a 2 s unbroken run
    is, and only that run counts (its mean vertical force is the weight), unless a foot strikes inside it."""
    t = np.arange(0, 6, 0.01)
    steps = ((t >= 0.5) & (t < 1.5)) | ((t >= 2.5) & (t < 3.5))
    assert plates_mod.standing_span(t, steps) == []
    stand = steps | ((t >= 4.0) & (t < 6.0))
    (a, b), = plates_mod.standing_span(t, stand)
    assert a == pytest.approx(4.0) and b == pytest.approx(5.99)
    # a walk over adjoining plates: unbroken, but a foot strikes inside it
    assert plates_mod.standing_span(t, stand, [0.5, 2.5, 4.0, 4.8]) == []
    assert plates_mod.standing_span(t, stand, [0.5, 2.5, 4.0]) == [(a, b)]  # stepping on, then standing


def test_analyze_c3d_writes_cop_columns_and_validation(lab, tmp_path):
    d, _ = lab
    rc, s = _analyze(d / "on.c3d", tmp_path, "--plot", str(tmp_path / "zmp.png"))
    assert (tmp_path / "zmp.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert rc == 0
    assert s["cop_vs_zmp"]["rms_mm"] < 0.5 and s["mass"]["used_kg"] == MASS and s["mass"]["source"] == "file"
    header = (tmp_path / "z.csv").read_text().splitlines()[0].split(",")
    assert header[-5:] == ["cop_x", "cop_y", "cop_z", "plate_fz", "complete"]
    assert "HAT" in s["markers"]["hat"] or "head, arms and trunk" in s["markers"]["hat"]


def test_placed_hat_follows_the_mid_hips_slow_sway_and_damps_its_steps():
    """A mid-hip walking at 1.2 m/s that sways slowly (0.2 Hz, 50 mm) and step by step (2 Hz, 10 mm) fore-aft, 1 Hz
    laterally: the placed HAT follows the slow sway whole and sways the gain plus the rest of the follow filter's
    gain at the step frequency (zero-phase 4th-order Butterworth at 1 Hz: |H|² at 100 Hz, bilinear), on either
    axis; its step-frequency acceleration is that part of the mid-hip's. A constant gain would scale both."""
    rate, gain = 100.0, (0.48, 0.5)
    t = np.arange(0, 10, 1 / rate)
    fwd, left = np.array([0.6, 0.8, 0.0]), np.array([-0.8, 0.6, 0.0])  # a walk heading 53 deg off x
    slow, step, side = (np.cos(2 * np.pi * f * t) for f in (0.2, 2.0, 1.0))
    origin = (np.outer(1.2 * t + 0.05 * slow + 0.01 * step, fwd) + np.outer(0.03 * side, left)
              + np.array([1.0, 2.0, 0.9]))
    hat = hat_sway(origin, gain, None, rate, 1.0)
    warp = lambda f: np.tan(np.pi * f / rate)  # noqa: E731
    passed = lambda f: 1.0 / (1.0 + (warp(f) / warp(1.0)) ** 4)  # noqa: E731
    inner = slice(int(2 * rate), -int(2 * rate))  # clear of the filter's ends
    sway = hat - np.outer(1.2 * t, fwd) - np.array([1.0, 2.0, 0.9])
    basis = np.column_stack([slow, step, side])[inner]
    (a_slow, a_step, _), *_ = np.linalg.lstsq(basis, sway[inner] @ fwd, rcond=None)
    (_, _, a_side), *_ = np.linalg.lstsq(basis, sway[inner] @ left, rcond=None)
    assert a_slow / 0.05 == pytest.approx(gain[0] + (1 - gain[0]) * passed(0.2), abs=2e-3)  # 0.9992: followed
    assert a_step / 0.01 == pytest.approx(gain[0] + (1 - gain[0]) * passed(2.0), abs=2e-3)  # 0.51: damped
    assert a_side / 0.03 == pytest.approx(gain[1] + (1 - gain[1]) * passed(1.0), abs=2e-3)  # 0.75 at the corner
    assert np.abs(hat[:, 2] - origin[:, 2]).max() < 1e-12  # height unchanged
    # without the follow filter: one gain at every frequency (the model calibrate fits)
    flat = hat_sway(origin, gain, None) - np.outer(1.2 * t, fwd) - np.array([1.0, 2.0, 0.9])
    (b_slow, b_step, _), *_ = np.linalg.lstsq(basis, flat[inner] @ fwd, rcond=None)
    assert b_slow / 0.05 == pytest.approx(gain[0], abs=2e-3) and b_step / 0.01 == pytest.approx(gain[0], abs=2e-3)


# ---- the shared real trials ----

def test_real_plugin_gait_walk(tmp_path):
    rc, s = _analyze(C3D / "walk_plugingait_forceplates.c3d", tmp_path)
    assert rc == 0
    assert s["mass"]["plates_kg"] == pytest.approx(82.6, abs=1.0) and s["mass"]["source"] == "plates"
    assert "73.4 kg" in s["mass"]["note"]
    # Newton frame by frame over the complete frames agrees with the mean force over its gait cycle (82.2 / 82.5 kg)
    assert s["mass"]["stance_kg"] == pytest.approx(s["mass"]["plates_kg"], rel=0.01)
    # its plates run ~20-24 ms behind its markers (measured, undone); then lag and fore-aft bias are small
    assert 18 < s["time_alignment"]["plate_delay_measured_ms"] < 30
    cv = s["cop_vs_zmp"]
    # the placed HAT swaying TRUNK_SWAY_GAIN times the mid-hip (measured on other trials): 50.8 -> 38.9 mm; knee
    # centres without the THI wands: 36.7 mm, lag -8.5 -> -3.3 ms; the lateral band (3 Hz): 33.4 mm; the plates at the
    # estimator's band: 32.0 mm (33.4 with the plates at the estimator's cutoff); the HAT following the mid-hip below
    # 1 Hz and swaying TRUNK_STEP_GAIN above (the tracked trunks' acceleration): 27.9 mm
    # (129 frames: 8 fewer, within the plates' low-pass reach of a foot off the plates; 27.9 mm either way)
    assert cv["frames"] >= 125 and cv["rms_mm"] < 29.5 and cv["p95_mm"] < P95_WALK_MM
    # lag -3.9 ms, -8.4 with the step-gain sway; the centres of mass off the joint lines (Dumas et al. 2007): lag
    # -8.1 -> -1.5 ms, fore-aft bias +2.4 -> -6.9 mm
    assert abs(cv["lag_ms"]) < 5 and abs(cv["bias_mm"][0]) < 10
    assert s["lateral_band_hz"] == 3.0
    # its plates' CoP lies off their force line outwards in both stances (+10.9 mm: its trunk, placed here, leans
    # over the stance leg); the placed HAT's body shows less of it (+6.4 mm)
    fl = s["cop_vs_force_line"]
    assert fl["single_support_frames"] >= 100 and 5 < fl["plates_stance_gap_mm"][1] < 20
    assert 0 < fl["zmp_stance_gap_mm"][1] < fl["plates_stance_gap_mm"][1]
    acc = s["com_acc_vs_plates"]
    assert acc["r"][0] > 0.85  # lateral CoM acceleration follows the plates
    trial = read_c3d(C3D / "walk_plugingait_forceplates.c3d")
    unswayed = analyse_lab_take(trial, LabOptions(markers=MarkerBodyOptions(hat_sway_gain=None)))
    assert unswayed.summary["cop_vs_zmp"]["rms_mm"] > 42  # the HAT moving with the mid-hip, as before (45.1)
    unbanded = analyse_lab_take(trial, LabOptions(lateral_cutoff_fraction=None))
    # lateral positions at the estimator's 6 Hz: 29.6 mm against the band's 27.9 (35.6 / 32.0 with the
    # constant HAT sway; 36.7 / 33.4, plates at 6 Hz)
    assert unbanded.summary["cop_vs_zmp"]["rms_mm"] > cv["rms_mm"] + 1


def test_real_cgm24_walk(tmp_path):
    rc, s = _analyze(C3D / "cgm24_walking01_forceplate.c3d", tmp_path)
    assert rc == 0
    # one stance on its plate: weighed frame by frame, the subject is the file's 77.6 kg (77.3)
    assert s["mass"]["source"] == "file" and s["mass"]["stance_kg"] == pytest.approx(s["mass"]["file_kg"], rel=0.01)
    cv = s["cop_vs_zmp"]
    # this subject's trunk follows its mid-hip fore-aft (calibrated gain ~1): the population sway costs it
    # 41.7 -> 45.2 mm and lag +7.1 -> +11.0 ms (knee centres without the THI wands: 46.9 -> 45.2 mm; the lateral
    # band: 39.6 mm); the population's smaller step-frequency sway (TRUNK_STEP_GAIN, above 1 Hz) more: 52.9 mm over
    # 44 frames; without the 8 frames a side within the plates' low-pass reach of its other foot's steps off the
    # plate: 20.8 mm over 28 (bias +5.6 mm)
    assert cv["frames"] >= 25 and cv["rms_mm"] < 23 and abs(cv["bias_mm"][0]) < 10
    # one stance: its halves' lags (+11 / -50 ms) disagree, so the lag is reported as not determined
    assert cv["lag_ms"] is None and abs(cv["lag_halves_ms"][0] - cv["lag_halves_ms"][1]) > 40
    assert s["time_alignment"]["plate_delay_determined"]  # its plate delay (-2 ms) is: both halves -3 / -1 ms


def test_knee_and_ankle_centres_agree_with_the_files_own_model_outputs():
    """Our knee and ankle centres against the joint centres the lab's software wrote (pyCGM2 CGM 2.4 femur
    and tibia origins; Plug-in Gait's femur origins and LAJC). The Plug-in Gait walk's knees by the chord
    rule through its THI wands came out ~40 mm off (36 mm forward, 16 mm lateral): the wands' plane is not
    the knee's frontal plane without the static trial's thigh-rotation offset."""
    cgm = read_c3d(C3D / "cgm24_walking01_forceplate.c3d")
    pig = read_c3d(C3D / "walk_plugingait_forceplates.c3d")
    cases = [(cgm, "knee", "FEO"), (cgm, "ankle", "TIO"), (pig, "knee", "FEO"), (pig, "ankle", "AJC")]
    for trial, joint, label in cases:
        take = body_from_markers(trial)
        for side in ("left", "right"):
            ref = trial.marker(side[0].upper() + label)
            err = np.linalg.norm(take.centres[joint][side] - ref, axis=1)
            assert np.median(err) < 0.015, (trial.source, joint, side, np.median(err))


def test_cluster_marker_set_is_refused_naming_what_is_missing(capsys):
    rc = main(["analyze", str(C3D / "sample01_gait_forceplates.c3d")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    assert "missing LASI" in err and "RFT1" in err


def test_unzeroed_plates_of_sample01_have_their_offsets_found():
    trial = read_c3d(C3D / "sample01_gait_forceplates.c3d")
    fz = [unloaded_offset(p, trial.analog_rate)[0][2] for p in trial.plates]
    assert fz == pytest.approx([22.0, 31.0], abs=3.0)


def test_a_segment_flipping_between_frames_is_refused():
    """LASI and RASI swapped for one frame (a labelling slip) turn the pelvis 180 degrees in 10 ms: refused
    naming the segment and frame, instead of a ZMP kilometres away; LASI on top of RASI leaves the pelvis
    without a frame (before: a pinocchio traceback)."""
    t = np.arange(int(SECONDS * RATE)) / RATE
    trial = _trial(t, RATE)
    a, b = trial.labels.index("LASI"), trial.labels.index("RASI")
    trial.points[100, [a, b]] = trial.points[100, [b, a]]
    with pytest.raises(InputError, match="segment pelvis turns 1[0-9][0-9] deg between frames 99 and 100"):
        body_from_markers(trial)
    body_from_markers(_trial(t, RATE))  # unswapped: fine
    trial.points[100, a] = trial.points[100, b]  # LASI on RASI: no pelvis frame there
    with pytest.raises(InputError, match="segment pelvis has no frame at frame 100"):
        body_from_markers(trial)


def test_a_tib_wand_medial_of_the_shank_is_not_read_as_plug_in_gaits_lateral_wand():
    """Plug-in Gait's TIB sits on the shank's lateral side; one lying medial of the line from the ankle marker to the
    knee centre (biomechZoo's HC036A, right side: 47 mm medial, 38 mm in front) puts the chord rule's plane off the
    shank's frontal plane, and its two solutions swapped sides between frames (the right shank turned 180 deg in
    10 ms: refused). Such a wand is left out, the ankle centre placed as without one, and the rule says why."""
    t = np.arange(int(SECONDS * RATE)) / RATE
    trial, bare = _trial(t, RATE), _trial(t, RATE)
    tib, lasi, rasi = (trial.labels.index(k) for k in ("RTIB", "LASI", "RASI"))
    left = trial.points[:, lasi] - trial.points[:, rasi]
    trial.points[:, tib] += 0.12 * left / np.linalg.norm(left, axis=1, keepdims=True)  # across to the medial side
    bare.points[:, tib] = np.nan  # no right wand at all
    take, ref = body_from_markers(trial), body_from_markers(bare)
    rules = take.notes["joint_centres"]
    assert "RTIB not read as a lateral wand: lateral of the shank's line in 0 % of the frames" in rules["right_ankle"]
    assert rules["left_ankle"].startswith("chord rule (LTIB wand")
    np.testing.assert_array_equal(take.centres["ankle"]["right"], ref.centres["ankle"]["right"])
    np.testing.assert_array_equal(take.frames, ref.frames)


def test_a_medial_marker_on_top_of_its_lateral_one_is_a_copy_and_not_read():
    """pyCGM2 writes each marker's model-fitted copy beside it (``RKNE_m``, ``RANK_m``), which reads as ``RKNEM`` /
    ``RANKM``, the medial knee and ankle: the mid-point of the two put the knee centre on the lateral marker and the
    thigh's frame turned 127 deg between two frames (qualisys/cgm2-web-report-uploader's ForMeasurementSectionTest
    walk, refused). A medial marker within a joint's width of its lateral one is left out and the rule says why."""
    t = np.arange(int(SECONDS * RATE)) / RATE
    bare = _trial(t, RATE)
    copies = ["LKNE", "RKNE", "LANK", "RANK"]
    noise = 0.002 * np.random.default_rng(0).standard_normal((len(t), len(copies), 3))
    trial = replace(bare, labels=bare.labels + [k + "_m" for k in copies],
                    points=np.concatenate([bare.points, bare.points[:, [bare.labels.index(k) for k in copies]] + noise],
                                          axis=1))
    take, ref = body_from_markers(trial), body_from_markers(bare)
    rules = take.notes["joint_centres"]
    assert rules["right_knee"].endswith("RKNE_m not read as the medial marker: 3 mm from RKNE (a medial marker lies "
                                        "the joint's width across)")
    assert "LANK_m not read as the medial marker" in rules["left_ankle"]
    for joint in ("knee", "ankle"):
        for side in ("left", "right"):
            np.testing.assert_array_equal(take.centres[joint][side], ref.centres[joint][side])
    np.testing.assert_array_equal(take.frames, ref.frames)


def test_a_segment_swinging_over_its_angles_singularity_keeps_continuous_angles():
    """A segment pitching over 90 degrees (its x axis through the vertical: a child's hand swung forward,
    biomechZoo's HC036A23) stays on the yaw-pitch-roll branch it came by; before, arcsin folded the pitch back at 90
    and yaw and roll each jumped by pi between two frames (170 deg in 10 ms; the ZMP ran 1.9 m off)."""
    def rz(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def ry(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])

    def rx(a):
        c, s = np.cos(a), np.sin(a)
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])

    pitch = np.radians(np.linspace(60.0, 110.0, 101))
    yaw, roll = 0.3 + 0.2 * np.sin(pitch), -0.4 + 0.1 * pitch
    rot = np.stack([rz(a) @ ry(b) @ rx(c) for a, b, c in zip(yaw, pitch, roll, strict=True)])
    ang = _euler_zyx(rot)
    assert np.abs(np.diff(ang, axis=0)).max() < 0.02
    np.testing.assert_allclose(ang, np.column_stack([yaw, pitch, roll]), atol=1e-9)
    short = rot[:40]  # short of the singularity: as before
    np.testing.assert_array_equal(_euler_zyx(short), np.unwrap(_euler_zyx(short, unwrap=False), axis=0))


def test_not_a_c3d_is_one_line(tmp_path, capsys):
    bad = tmp_path / "bad.c3d"
    bad.write_bytes(b"not a c3d file at all" * 10)
    assert main(["analyze", str(bad)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


# ---- calibration ----

def test_calibration_model_reproduces_the_pipelines_zmp_exactly():
    """The fit's model at the table's parameters is analyze's default ZMP; at other sway gains (the HAT following
    the mid-hip below TRUNK_FOLLOW_HZ, swaying the gains above) the ZMP of the pipeline run on a body built with
    them."""
    trial = read_c3d(C3D / "walk_plugingait_forceplates.c3d")
    lab = analyse_lab_take(trial)
    rows = lab.complete & lab.result.has_zmp
    terms = calibration._terms(trial, lab, rows, LabOptions())
    fraction, com, _ = hat_table(lab.summary["markers"]["stature_m"])
    zmp, _ = calibration._model(terms, np.array([fraction, *com, *calibration.TRUNK_STEP_GAIN]))
    assert np.abs(zmp - lab.result.zmp[rows, :2]).max() < 1e-9
    for gains in ((1.0, 1.0), (0.6, 0.4)):  # (1, 1): the HAT moving with the mid-hip
        swayed = analyse_lab_take(trial, LabOptions(markers=MarkerBodyOptions(hat_sway_gain=gains)))
        zmp, _ = calibration._model(terms, np.array([fraction, *com, *gains]))
        # equal but for the walk's axes, the model's from the estimated HAT path, the body's from the markers'
        # and the lateral band's following the walk's heading (0.10 and 0.22 mm)
        assert np.abs(zmp - swayed.result.zmp[rows, :2]).max() < 3e-4
        assert np.abs(swayed.result.zmp[rows, :2] - lab.result.zmp[rows, :2]).max() > 0.01  # the gains matter


def test_calibration_finds_a_subjects_hat_and_analyze_uses_it(tmp_path, monkeypatch):
    """The synthetic subject's HAT sits 40 mm forward and weighs 45 %: the table is off by ~18 mm; the fit
    (prior off) finds the truth within its jackknife standard errors, `analyze --subject` then agrees with the plates
    to a millimetre."""
    path = tmp_path / "hat.c3d"
    write_lab_c3d(path, PLATES, body=MarkerBodyOptions(hat_offset=(0.04, 0.0, 0.33), hat_fraction=0.45,
                                                       hat_sway_gain=None))
    trial = read_c3d(path)
    subject, report = calibration.calibrate([trial])
    assert report["rms_table_mm"] > 15 and report["rms_held_out_fitted_mm"] < report["rms_held_out_table_mm"] / 2
    assert report["rms_fitted_unconstrained_mm"] < 1.0  # the true HAT is among the parameters: the floor is ~0
    # its offset alone: mass fraction and sway stay the table's (not the true 0.45), so the truth is out of reach
    part, partial = calibration.calibrate([trial], fit=("forward", "left"))
    assert part.fraction == pytest.approx(hat_table(1.75)[0], abs=1e-12) and part.fraction > 0.47
    assert part.hat_sway_gain == calibration.TRUNK_STEP_GAIN
    assert partial["rms_fitted_unconstrained_mm"] > 5 * report["rms_fitted_unconstrained_mm"]
    with pytest.raises(ValueError, match="fit takes some of"):
        calibration.calibrate([trial], fit=("knee",))
    monkeypatch.setattr(calibration, "PRIOR_MM", 0.0)
    assert main(["calibrate", str(path), "-o", str(tmp_path / "s.toml")]) == 0
    exact = calibration.load_subject(tmp_path / "s.toml")
    assert exact.offset[0] == pytest.approx(0.04, abs=0.002)
    # the report in the subject file is TOML; the truth lies within 3 jackknife standard errors of the fit
    cal = tomllib.loads((tmp_path / "s.toml").read_text())["calibration"]
    assert cal["parameters"] == list(calibration.PARAMETERS) and cal["table_kept"] is False
    fit = np.array([exact.fraction, *exact.offset, *exact.hat_sway_gain])
    truth = np.array([0.45, 0.04, 0.0, 0.33, 1.0, 1.0])
    sd = np.array(cal["parameter_sd"])
    assert np.all(np.abs(fit - truth)[[0, 1, 3]] < 3 * sd[[0, 1, 3]]) and np.all(sd[:4] < calibration.PRIOR_SD[:4] / 10)
    assert abs(exact.offset[1]) < 1e-4  # left: found to 0.1 mm (its SD rounds to 0 in the file)
    rc, s = _analyze(path, tmp_path, "--subject", str(tmp_path / "s.toml"))
    assert rc == 0 and s["cop_vs_zmp"]["rms_mm"] < 1.0


TRUNK_TRUTH = (0.38, (0.04, 0.0, -0.20))  # the synthetic thorax: fraction, CoM fwd, left, up (m; table 0.323, -0.162)


def test_calibration_finds_a_tracked_trunks_thorax_and_analyze_uses_it(tmp_path, monkeypatch):
    """A full-body subject whose tracked thorax weighs 38 % (the table 32.3 %) with its centre of mass 40 mm forward
    and 200 mm below its origin (the table: 0, 162 mm): the table is off by mm; the fit's model at the truth is the
    plates' (exact), calibrate (prior off) finds fraction and offset within 0.01 / 3 mm, the subject file writes
    them as trunk_* keys, and `analyze --subject` agrees with the plates to < 1 mm. The thorax turns in 3-D (pitch
    and roll), so its acceleration and spin terms are exercised."""
    fraction, offset = TRUNK_TRUTH
    path = tmp_path / "trunk.c3d"
    write_lab_c3d(path, PLATES, full_body=True, body=MarkerBodyOptions(trunk_fraction=fraction, trunk_offset=offset))
    trial = read_c3d(path)
    rc, table = _analyze(path, tmp_path)
    assert rc == 0 and table["cop_vs_zmp"]["rms_mm"] > 3
    lab = analyse_lab_take(trial)
    rows = lab.complete & lab.result.has_zmp
    terms = calibration._terms(trial, lab, rows, LabOptions(), calibration.THORAX_SEGMENT)
    zmp, _ = calibration._model(terms, np.array([fraction, *offset, 0.0, 0.0]))
    assert np.abs(zmp - lab.plates.cop[rows, :2]).max() < 1e-3
    monkeypatch.setattr(calibration, "PRIOR_MM", 0.0)
    assert main(["calibrate", str(path), "-o", str(tmp_path / "s.toml")]) == 0
    subject = calibration.load_subject(tmp_path / "s.toml")
    assert subject.segment == "thorax" and subject.fraction == pytest.approx(fraction, abs=0.01)
    assert np.abs(np.array(subject.offset) - offset).max() < 0.003
    text = (tmp_path / "s.toml").read_text()
    assert "trunk_fraction" in text and "hat_" not in text.split("[calibration]")[0]
    assert tomllib.loads(text)["calibration"]["parameters"] == list(calibration.TRUNK_PARAMETERS)
    rc, s = _analyze(path, tmp_path, "--subject", str(tmp_path / "s.toml"))
    assert rc == 0 and s["cop_vs_zmp"]["rms_mm"] < 1.0 and "thorax 3" in s["markers"]["hat"]


def test_a_subject_file_for_the_other_kind_of_marker_set_is_refused(tmp_path, capsys):
    """A placed HAT's subject file (lower-body set) with a full-body take, a tracked trunk's with a lower-body take,
    or one file with both kinds of keys: each refused in one line, exit 2."""
    full, lower = tmp_path / "full.c3d", tmp_path / "lower.c3d"
    write_lab_c3d(full, PLATES, full_body=True)
    write_lab_c3d(lower, PLATES)
    hat, trunk, both = tmp_path / "hat.toml", tmp_path / "trunk.toml", tmp_path / "both.toml"
    hat.write_text("[subject]\nhat_fraction = 0.45\nhat_offset_m = [0.04, 0, 0.33]\n")
    trunk.write_text("[subject]\ntrunk_fraction = 0.35\ntrunk_offset_m = [0.02, 0, -0.18]\n")
    both.write_text("[subject]\ntrunk_fraction = 0.35\ntrunk_offset_m = [0.02, 0, -0.18]\nhat_fraction = 0.45\n")
    for take, subject, why in ((full, hat, "placed HAT's"), (lower, trunk, "tracked trunk's"),
                               (full, both, "not both")):
        assert main(["analyze", str(take), "--subject", str(subject)]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and why in err
    for take, subject in ((full, trunk), (lower, hat)):  # each with its own kind of set
        assert main(["analyze", str(take), "--subject", str(subject)]) == 0
    capsys.readouterr()
    assert main(["monitor", str(full), "--speed", "0", "--subject", str(hat)]) == 2
    assert "placed HAT's" in capsys.readouterr().err


def test_calibration_of_frames_within_one_block_keeps_the_table(tmp_path):
    """Complete frames that all lie in one cross-validation block (a short trial: AMMR's S3_Gait_Shod_1 has 23 at
    120 Hz, under 0.2 s) leave one fold with nothing to fit and the other with nothing to score: calibrate keeps
    the table and says so (it raised an IndexError from an empty fold before)."""
    path = tmp_path / "short.c3d"
    write_lab_c3d(path, PLATES, body=MarkerBodyOptions(hat_offset=(0.04, 0.0, 0.33), hat_fraction=0.45,
                                                       hat_sway_gain=None))
    trial = read_c3d(path)
    subject, report = calibration.calibrate([trial], block_s=1e3)  # every frame in the first block
    assert report["table_kept"] and report["rms_held_out_fitted_mm"] == report["rms_held_out_table_mm"]
    assert subject.fraction == pytest.approx(hat_table(1.75)[0], abs=1e-12)


def test_calibrated_sway_gains_bring_a_swaying_trunk_to_its_plates(tmp_path, monkeypatch):
    """The synthetic subject's trunk follows its mid-hip below 0.1 Hz and sways half as far fore-aft and 0.7 times as
    far sideways above (its sway is at 0.3-0.4 Hz, below TRUNK_FOLLOW_HZ, so the follow frequency is lowered to see
    it): the table (gains TRUNK_STEP_GAIN) is off by 4.1 mm; calibrated (prior on) the held-out folds halve that (1.8);
    with the prior off they and `analyze --subject` (the subject file carrying the follow frequency) agree with the
    plates to 0.7 mm. (A rigid sway about the ankles cannot tell a lighter, higher HAT from a heavier, lower, less
    swaying one, so the parameters themselves are not asserted here.)"""
    path = tmp_path / "sway.c3d"
    body = MarkerBodyOptions(hat_sway_gain=(0.5, 0.7), hat_follow_hz=0.1)
    write_lab_c3d(path, PLATES, body=body)
    opts = LabOptions(markers=MarkerBodyOptions(hat_follow_hz=0.1))
    _, report = calibration.calibrate([read_c3d(path)], opts)
    assert report["rms_table_mm"] > 3 and report["rms_held_out_fitted_mm"] < report["rms_held_out_table_mm"] / 2
    monkeypatch.setattr(calibration, "PRIOR_MM", 0.0)
    subject, report = calibration.calibrate([read_c3d(path)], opts)
    assert report["rms_held_out_fitted_mm"] < 1.0 and subject.hat_follow_hz == 0.1
    calibration.write_subject(subject, tmp_path / "s.toml", report)
    assert calibration.load_subject(tmp_path / "s.toml").hat_follow_hz == 0.1
    rc, s = _analyze(path, tmp_path, "--subject", str(tmp_path / "s.toml"))
    assert rc == 0 and s["cop_vs_zmp"]["rms_mm"] < 1.0 and "above 0.1 Hz" in s["markers"]["hat"]
    with pytest.raises(ValueError, match="follow frequency"):
        calibration.calibrate([read_c3d(path)], LabOptions(markers=MarkerBodyOptions(hat_follow_hz=None)))


def test_real_walk_calibrated_and_held_out():
    """The Plug-in Gait walk, cross-validated on every other 0.2 s block of its complete frames: its table is
    analyze's default (28.0 mm). A light prior's fit scores 27.3 mm pooled (weight 0.3) but does not beat the table
    both ways round, over the whole trial nor within either fold, so the table is kept and held out the calibration
    scores the table's; unconstrained and scored on its own frames the HAT reaches 25.1 mm."""
    trial = read_c3d(C3D / "walk_plugingait_forceplates.c3d")
    subject, report = calibration.calibrate([trial])
    default = analyse_lab_take(trial).summary["cop_vs_zmp"]
    assert report["rms_table_mm"] == pytest.approx(default["rms_mm"], abs=0.01)
    assert report["frames"] == default["frames"]
    assert report["table_kept"] and report["held_out_prior_weights"] == [None, None]
    assert report["rms_held_out_fitted_mm"] == pytest.approx(report["rms_held_out_table_mm"], abs=0.01)
    assert report["rms_held_out_table_mm"] < 29.5
    assert min(report["prior_weight_scores_mm"][:-1]) < report["rms_held_out_table_mm"] - 0.5
    assert report["rms_fitted_unconstrained_mm"] < report["rms_table_mm"] - 1
    assert subject.hat_follow_hz == TRUNK_FOLLOW_HZ


def test_calibration_rejects_a_fit_that_chases_one_folds_noise(monkeypatch):
    """cgm24 has one stance on its plate; scored with the frames next to its other foot's steps off the plate kept
    (the plates' low-pass margin off: 44 frames, whose edges carry load the plate misses). Fitted on one fold of its
    0.2 s blocks (prior weight 10), the HAT scores 59.6 mm on the other against the table's 72.1; fitted on that
    other fold, it scores 36.7 mm on the first against the table's 17.5: it chased the second fold's noise. A weight
    must beat the table both ways round; within either fold none does, so held out the calibration is the table's
    53.5 mm. The guard is conservative here: with the prior weight fixed at 10 instead (no cross-validation), held
    out it is 50.0 mm (before the centres of mass left the joint lines: 55.2 / 69.7, 32.0 / 23.3, 52.9, 45.6 mm)."""
    monkeypatch.setattr(gaitlab, "PLATE_LEAK", 0.5)  # its reach 0: no margin
    trial = read_c3d(C3D / "cgm24_walking01_forceplate.c3d")
    _, report = calibration.calibrate([trial])
    assert report["held_out_prior_weights"] == [None, None]
    assert report["rms_held_out_fitted_mm"] == pytest.approx(report["rms_held_out_table_mm"], abs=0.01)
    lab = analyse_lab_take(trial)
    assert report["rms_table_mm"] == pytest.approx(lab.summary["cop_vs_zmp"]["rms_mm"], abs=0.01)
    fraction, com, _ = hat_table(lab.summary["markers"]["stature_m"])
    # the folds themselves: one way round the fit helps, the other way it is far worse than the table
    rows = lab.complete & lab.result.has_zmp & np.isfinite(lab.plates.cop).all(axis=1)
    terms = calibration._terms(trial, lab, rows, LabOptions())
    prior = np.array([fraction, *com, *calibration.TRUNK_STEP_GAIN])
    (fit_a, held_a), (fit_b, held_b) = calibration._folds([terms], calibration.BLOCK_S)
    free = np.ones(6, bool)
    ab = calibration._rms_mm(calibration._fit(fit_a, prior, 10.0, free), held_a)
    ba = calibration._rms_mm(calibration._fit(fit_b, prior, 10.0, free), held_b)
    assert ab < calibration._rms_mm(prior, held_a) - 10 and ba > calibration._rms_mm(prior, held_b) + 5
    monkeypatch.setattr(calibration, "_cross_validated", lambda terms, prior, free, block_s: (10.0, []))
    _, fixed = calibration.calibrate([trial])
    assert fixed["rms_held_out_fitted_mm"] < fixed["rms_held_out_table_mm"] - 3


def test_calibration_refuses_plates_against_the_motion(lab):
    """A plate whose lateral force runs against the body's lateral acceleration (a sign or axis error in the
    plate set-up) would pull the fit wherever it makes up for it: refused in one line."""
    d, _ = lab
    trial = read_c3d(d / "on.c3d")
    calibration.calibrate([trial])  # the trial as written is calibrated
    for p in trial.plates:
        p.force[:, 1] *= -1.0
    with pytest.raises(InputError, match="lateral force runs against the markers' motion"):
        calibration.calibrate([trial])


def test_bad_subject_file_is_one_line(tmp_path, capsys):
    bad = tmp_path / "s.toml"
    bad.write_text("[subject]\nhat_fraction = 2\nhat_offset_m = [0, 0, 0.3]\n")
    rc = main(["analyze", str(C3D / "cgm24_walking01_forceplate.c3d"), "--subject", str(bad)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "hat_fraction" in err


def test_monitor_replays_a_c3d_and_its_recording_replays_the_same(tmp_path, capsys):
    path = tmp_path / "c3d.mcap"
    assert main(["monitor", str(C3D / "cgm24_walking01_forceplate.c3d"), "--speed", "0", "--record", str(path)]) == 0
    assert "493 frames in, 493 analysed" in capsys.readouterr().out
    assert main(["replay", str(path)]) == 0
    out = capsys.readouterr().out
    assert "493 results compared" in out and "same analysis" in out


# -- degenerate marker geometry (issue 12: the fuzz run reached Pinocchio with NaN or huge inertias) --------


def _synthetic() -> C3dTrial:
    return _trial(np.arange(200) / RATE, RATE)


def test_a_corrupt_marker_coordinate_is_refused_naming_marker_and_frame():
    trial = _synthetic()
    trial.points[57, trial.labels.index("RKNE"), 1] = 2.6e35
    with pytest.raises(InputError, match=r"synthetic: marker RKNE at frame 57 \(0\.570 s\): coordinate 2\.6e\+35 m"):
        body_from_markers(trial)


def test_implausible_stature_and_segment_length_are_refused():
    trial = _synthetic()
    trial.height_m = 17.5  # cm read as m
    with pytest.raises(InputError, match=r"stature 17\.5 m \(the file's height\) is outside 0\.5-2\.6 m"):
        body_from_markers(trial)
    trial = _synthetic()
    trial.points[:, trial.labels.index("LTOE"), 0] += 2.0  # the toe marker 2 m ahead of the foot
    with pytest.raises(InputError, match=r"segment foot_l is 2\d\d\d mm long"):
        body_from_markers(trial)


def _points_c3d(path, m: dict[str, np.ndarray]):
    """A C3D of markers ``m`` (label -> (F, 3) m), every point seen (residual 1)."""
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [RATE]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = list(m)
    c3d.add_parameter("POINT", "UNITS", ["m"])
    frames = len(next(iter(m.values())))
    pts = np.ones((4, len(m), frames))
    pts[:3] = np.stack(list(m.values()), axis=1).transpose(2, 1, 0)
    c3d["data"]["points"] = pts
    c3d["data"]["meta_points"] = {"residuals": np.ones((1, len(m), frames))}
    c3d.write(str(path))
    return path


def test_a_negative_description_length_is_refused_before_ezc3d_reads_it(tmp_path):
    """ezc3d reads a description length byte above 127 as a negative count, then as an unsigned one,
    and allocates gigabytes (found by the long fuzz run; it took half a minute and 3 GB to fail)."""
    data = bytearray(_points_c3d(tmp_path / "ok.c3d", _markers(np.arange(20) / RATE)).read_bytes())
    at = data.index(b"RATE") + 4 + 2 + 2 + 4  # POINT:RATE: offset, type, no dimensions (a scalar), a float
    assert data[at] == 0  # its description's length
    data[at] = 0xF0
    (tmp_path / "bad.c3d").write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"bad\.c3d: parameter 'RATE' has a description length of -16 bytes"):
        read_c3d(tmp_path / "bad.c3d")


def test_a_zero_parameter_start_byte_is_read_as_ezc3d_reads_it(tmp_path):
    """Codamotion and Motion Analysis files write 0 where the parameter section's first byte says 1: ezc3d
    ignores it; the check before ezc3d must walk the same parameters (it read them a byte early and refused
    the files with garbled parameter names)."""
    path = _points_c3d(tmp_path / "ok.c3d", _markers(np.arange(20) / RATE))
    data = bytearray(path.read_bytes())
    start = (data[0] - 1) * 512
    assert data[start] == 1
    data[start] = 0
    (tmp_path / "zero.c3d").write_bytes(bytes(data))
    ok, zero = read_c3d(path), read_c3d(tmp_path / "zero.c3d")
    assert zero.labels == ok.labels and np.array_equal(zero.points, ok.points, equal_nan=True)


def test_parameter_dimensions_beyond_the_file_are_refused(tmp_path):
    """A parameter of dimensions 255 x 255 x 255 x 255 x 0 holds no value, but ezc3d loops 255^4 times
    over it (the long fuzz run's C3D child hung there)."""
    block = bytearray(512)
    block[:4] = (1, 0x50, 1, 84)  # first parameter at byte 4, one block, Intel
    group = bytes([5, 0xFF]) + b"POINT" + (3).to_bytes(2, "little") + bytes([0])
    param = bytes([4, 1]) + b"DIMS" + (12).to_bytes(2, "little") + bytes([1, 5, 255, 255, 255, 255, 0, 0])
    block[4 : 4 + len(group) + len(param)] = group + param
    header = bytearray(512)
    header[:2] = (2, 0x50)
    (tmp_path / "dims.c3d").write_bytes(bytes(header + block))
    with pytest.raises(InputError, match=r"dims\.c3d: parameter 'DIMS' claims 4\.23e\+09 values"):
        read_c3d(tmp_path / "dims.c3d")


def test_all_zero_points_are_gaps_and_are_filled(tmp_path):
    """Some writers put (0, 0, 0) with a valid residual in a gap: read as a gap (filled), not as a
    marker at the lab origin."""
    t = np.arange(200) / RATE
    m = _markers(t)
    m["LASI"][100:103] = 0.0
    trial = read_c3d(_points_c3d(tmp_path / "zeros.c3d", m))
    assert np.isnan(trial.marker("LASI")[100:103]).all() and np.isfinite(trial.marker("LASI")[99]).all()
    take = body_from_markers(trial)
    assert take.frames.shape[0] == 200  # the gap is filled, nothing cut
    pelvis_x = take.frames[100:103, 0]  # the pelvis origin, from the filled LASI: near the true motion
    reference = body_from_markers(_trial(t, RATE)).frames[100:103, 0]
    assert np.abs(pelvis_x - reference).max() < 1e-3, (pelvis_x, reference)


def test_a_finger_marker_giving_no_stable_hand_frame_leaves_that_hand_along_the_forearm():
    """A FIN marker that jumps about the wrist (not where Plug-in Gait puts it: biomechZoo's HC040A14, 61-121 deg
    off the forearm) turns its hand frame by half a turn between frames: that hand is placed along the forearm, as
    without FIN, and said; the take is read (before: refused, "segment hand_l turns 170 deg"). The other hand keeps
    its FIN, and a stream built from the take's dimensions keeps the decision."""
    t = np.arange(int(SECONDS * RATE)) / RATE
    trial = _trial(t, RATE, full_body=True)
    fin = trial.labels.index("LFIN")
    wrist = (trial.points[:, trial.labels.index("LWRA")] + trial.points[:, trial.labels.index("LWRB")]) / 2
    flip = (np.arange(len(t)) // 50) % 2 == 1  # every half second the marker sits above the wrist instead of below
    trial.points[flip, fin] = 2 * wrist[flip] - trial.points[flip, fin]
    take = body_from_markers(trial)
    rules = take.notes["joint_centres"]
    assert rules["left_hand"].startswith("along the forearm: LFIN") and "right_hand" not in rules
    assert take.notes["dimensions"]["LFIN_stable"] == 0.0 and take.notes["dimensions"]["RFIN_stable"] == 1.0
    seg, _, _ = _segments({k: trial.points[:1, i] for i, k in enumerate(trial.labels)}, trial,
                                       take.notes["dimensions"])
    forearm, hand = seg["forearm_l"][1][0], seg["hand_l"][1][0]
    np.testing.assert_allclose(hand, forearm, atol=1e-12)  # one frame, as a stream's: the take's decision


def test_a_toe_lost_for_long_is_placed_from_the_heel_and_the_malleoli():
    """MOtoNMS' Padova walks (BTS) lose the right foot's metatarsal heads, the toe's stand-in, on all but 41-45 of
    276-307 frames, and the take was cut to the 36-43 frames seeing every needed marker: no complete frame. A toe
    lost for longer than a short gap is placed from the heel and the two malleoli where those are seen. Here the
    feet turn 0.3 rad about the malleoli's line (the ankle's flexion axis) and the left toe is lost for 1 s in the
    middle: the whole take is kept, the placed toe is the true one to 1e-9 m and the body's frames the unbroken
    take's."""
    t = np.arange(int(SECONDS * RATE)) / RATE
    trial = _trial(t, RATE)
    m = {label: trial.marker(label).copy() for label in trial.labels}
    for s, sign in (("L", 1.0), ("R", -1.0)):
        m[s + "MED"] = m[s + "ANK"] + [0.0, -sign * 0.07, 0.0]  # the medial malleolus, 70 mm inside
        axis = (m[s + "MED"] - m[s + "ANK"]) / 0.07
        for k in ("HEE", "TOE"):  # the foot turning about the malleoli's line
            turn = np.array([pin.exp3(a * v) for a, v in zip(0.3 * np.sin(2 * np.pi * 0.8 * t), axis, strict=True)])
            m[s + k] = m[s + "ANK"] + np.einsum("fij,fj->fi", turn, m[s + k] - m[s + "ANK"])
    whole = replace(trial, labels=list(m), points=np.stack(list(m.values()), axis=1))
    lost = whole.points.copy()
    gap = slice(len(t) // 2 - int(RATE // 2), len(t) // 2 + int(RATE // 2))
    lost[gap, whole.labels.index("LTOE")] = np.nan
    ref, take = body_from_markers(whole), body_from_markers(replace(whole, points=lost))
    assert take.notes["toe_placed_from_heel_and_malleoli"] == {"LTOE": f"{gap.stop - gap.start} frames"}
    assert take.notes["frames_used"] == ref.notes["frames_used"]
    assert np.abs(take.frames - ref.frames).max() < 1e-9


def test_a_rate_outside_the_frame_periods_read_is_refused(tmp_path):
    """POINT:RATE was not checked against the frame periods every input keeps to (a 3 Hz file was refused
    as "only 1 frames have every needed marker", a 1e9 Hz one as a pelvis turning 179 deg a frame)."""
    c3d = ezc3d.c3d(str(_points_c3d(tmp_path / "ok.c3d", _markers(np.arange(20) / RATE))))
    c3d["parameters"]["POINT"]["RATE"]["value"] = [5.0]
    c3d.write(str(tmp_path / "slow.c3d"))
    with pytest.raises(InputError, match=r"slow\.c3d: POINT:RATE 5: frame period 0.2 s is outside"):
        read_c3d(tmp_path / "slow.c3d")


def test_a_file_cut_short_or_read_at_another_analog_rate_is_refused(lab, tmp_path):
    """ezc3d reads a C3D cut short as the frames that are left (half the Plug-in Gait walk was analysed, exit 0),
    and steps through the data by ANALOG:RATE / POINT:RATE whatever the header says (1050 Hz against its 20 samples
    a frame was refused as "only 1 frames have every needed marker", 150 Hz as a pelvis turning 179 deg)."""
    data = (lab[0] / "on.c3d").read_bytes()
    (tmp_path / "cut.c3d").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match=r"cut\.c3d: truncated: the header says \d+ frames \(1\.\.\d+\), the file"):
        read_c3d(tmp_path / "cut.c3d")
    odd = bytearray(data)
    struct.pack_into("<f", odd, parameter_at(data)[("ANALOG", "RATE")], 1500.0)
    (tmp_path / "odd.c3d").write_bytes(bytes(odd))
    with pytest.raises(InputError, match=r"odd\.c3d: ANALOG:RATE 1500 is not POINT:RATE \d+ times the header's \d+"):
        read_c3d(tmp_path / "odd.c3d")


@pytest.mark.parametrize(("key", "value"), [("POINT", float("nan")), ("POINT", -100.0), ("ANALOG", float("nan"))])
def test_a_rate_that_is_no_number_is_refused_before_ezc3d_reads_it(lab, tmp_path, key, value):
    """ezc3d sizes its frames by POINT:RATE and ANALOG:RATE: NaN or a negative rate ended in its C++ allocation
    message ("not a readable C3D file (vector::_M_default_append)"), naming neither the parameter nor its value."""
    data = bytearray((lab[0] / "on.c3d").read_bytes())
    struct.pack_into("<f", data, parameter_at(data)[(key, "RATE")], value)
    (tmp_path / "rate.c3d").write_bytes(bytes(data))
    with pytest.raises(InputError, match=rf"rate\.c3d: {key}:RATE {value:g} is not a rate in Hz \(a finite number"):
        read_c3d(tmp_path / "rate.c3d")


def test_a_read_waiting_for_a_cpu_is_not_refused_as_one_ezc3d_loops_on(lab, monkeypatch):
    """The probe read before each C3D read was timed by the wall clock: at load 17 on 2 CPUs a valid 1.2 MB walk's
    probe passed its 20 s and the walk was refused as "not a readable C3D file". A probe that waits (here it
    sleeps 3 s, as a child waiting for a CPU does) with 1 s of CPU time allowed is now read; its CPU time is its
    limit."""
    monkeypatch.setattr(c3d_mod, "READ_SECONDS", 1.0)
    monkeypatch.setattr(c3d_mod, "_PROBE", "import time; time.sleep(3); " + c3d_mod._PROBE)
    assert read_c3d(lab[0] / "on.c3d").points.shape[0] > 0


def test_a_read_that_spends_its_cpu_time_is_refused_in_one_line(lab, monkeypatch):
    """A read ezc3d loops on (here the probe spins after importing ezc3d) is ended by its CPU cap and refused in
    one line naming it (the wall clock's limit, ten times as long, is raised here so that a loaded machine does
    not reach it first)."""
    monkeypatch.setattr(c3d_mod, "READ_SECONDS", 0.5)
    monkeypatch.setattr(c3d_mod, "READ_WALL_FACTOR", 60)
    spin = c3d_mod._PROBE.replace("import ezc3d; ", "import ezc3d; any(iter(int, 1)); ")
    monkeypatch.setattr(c3d_mod, "_PROBE", spin)
    with pytest.raises(InputError, match=r"on\.c3d: not a readable C3D file \(ezc3d did not finish reading it in 1 s "
                       r"of CPU time\)"):
        read_c3d(lab[0] / "on.c3d")


@pytest.mark.parametrize("key", ["CORNERS", "ORIGIN"])
def test_a_plate_geometry_not_finite_is_refused_naming_the_parameter(lab, tmp_path, key):
    """NaN corners had reached the ground's height and were refused as "GroundConfig.override: ... nan"; an
    ORIGIN of 1e30 mm put the CoP 1e30 mm off the foot, exit 0."""
    c3d = ezc3d.c3d(str(lab[0] / "on.c3d"))
    values = np.array(c3d["parameters"]["FORCE_PLATFORM"][key]["value"], dtype=float)
    values[...] = np.nan if key == "CORNERS" else 1e30
    c3d["parameters"]["FORCE_PLATFORM"][key]["value"] = values
    c3d.write(str(tmp_path / "bad.c3d"))
    with pytest.raises(InputError, match=rf"bad\.c3d: force platform 1: FORCE_PLATFORM:{key} not finite or beyond"):
        read_c3d(tmp_path / "bad.c3d")


@pytest.mark.parametrize("shape", ["point", "line"])
def test_a_plate_whose_corners_enclose_no_area_is_refused_naming_it(lab, tmp_path, shape):
    """Corners that coincide or line up had been read: the plate's CoP was never under a foot, and the analysis
    ended "no frame has every foot that may bear weight on a plate", exit 0, not saying why (audit 9)."""
    c3d = ezc3d.c3d(str(lab[0] / "on.c3d"))
    corners = np.array(c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"], dtype=float)  # (3, 4, plates)
    corners[:, 2:, 0] = corners[:, :2, 0] if shape == "line" else corners[:, :1, 0]
    corners[:, 1, 0] = corners[:, 1, 0] if shape == "line" else corners[:, 0, 0]
    c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"] = corners
    c3d.write(str(tmp_path / "flat.c3d"))
    with pytest.raises(InputError, match=r"flat\.c3d: force platform 1: FORCE_PLATFORM:CORNERS enclose 0 m²"):
        read_c3d(tmp_path / "flat.c3d")


def test_an_infinite_plate_sample_is_read_as_unloaded_and_a_file_mass_of_no_person_is_ignored(lab, tmp_path):
    """One infinite analog sample (a saturated channel) had made the low-passed plates infinite: exit 2, "field
    com_acc_vs_plates.rms_mps2[2] is not finite" (the output's field, not the input's); a PROCESSING:Bodymass of
    1e30 kg had been used as the subject's mass (no plate frame then complete, exit 0). Now the sample reads as a
    NaN one does (unloaded) and the file's mass as none: the plates weigh the subject and meet the ZMP as before."""
    c3d = ezc3d.c3d(str(lab[0] / "on.c3d"))
    analogs = np.array(c3d["data"]["analogs"])
    analogs[0, 2, 1000] = np.inf  # the first plate's vertical force, 1 s in
    c3d["data"]["analogs"] = analogs
    c3d["parameters"]["PROCESSING"]["Bodymass"]["value"] = [1e30]
    c3d.write(str(tmp_path / "odd.c3d"))
    assert read_c3d(tmp_path / "odd.c3d").mass_kg is None
    rc, s = _analyze(tmp_path / "odd.c3d", tmp_path)
    assert rc == 0 and s["mass"]["source"] != "file" and abs(s["mass"]["used_kg"] - MASS) < 1.0
    assert s["cop_vs_zmp"]["frames"] > 250 and s["cop_vs_zmp"]["max_mm"] < 5.0


def test_a_take_longer_than_the_16_bit_frame_count_is_refused_not_cut(tmp_path):
    """70000 frames (11.7 min at 100 Hz): the header's count stops at 65535 and ezc3d reads that many, with
    TRIAL:ACTUAL_END_FIELD or without; an hour at 100 Hz had been analysed as its first 11 min, exit 0 (audit 9)."""
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["LASI"]
    c3d["data"]["points"] = np.ones((4, 1, 70_000))
    c3d.write(str(tmp_path / "long.c3d"))
    with pytest.raises(InputError, match=r"long\.c3d: the data holds about 700\d\d frames \(12 min\), ezc3d reads "
                                         r"the first 65535"):
        read_c3d(tmp_path / "long.c3d")


def test_a_mass_the_plates_contradict_is_used_as_told_and_said(lab, tmp_path, capsys):
    """`--mass` 10 % light on the 75 kg synthetic subject: used as told, but the plates' weight is said, by
    `analyze` and by `calibrate` (whose subject file stays TOML with the note's text); the true mass says nothing."""
    d, _ = lab
    told = analyse_lab_take(read_c3d(d / "on.c3d"), LabOptions(mass=0.9 * MASS)).summary["mass"]
    assert told["source"] == "--mass" and told["used_kg"] == pytest.approx(0.9 * MASS)
    assert f"--mass says {0.9 * MASS:.1f} kg, the plates weigh {MASS:.1f} kg" in told["note"]
    assert told["note"].endswith("(-10.0 %); using --mass as told")
    right = analyse_lab_take(read_c3d(d / "on.c3d"), LabOptions(mass=MASS)).summary["mass"]
    assert "note" not in right
    out = tmp_path / "s.toml"
    assert main(["calibrate", str(d / "on.c3d"), "--mass", str(0.9 * MASS), "-o", str(out)]) == 0
    assert f"  mass: {d / 'on.c3d'}: --mass says" in capsys.readouterr().out
    assert tomllib.loads(out.read_text())["calibration"]["mass_notes"] == [f"{d / 'on.c3d'}: {told['note']}"]
