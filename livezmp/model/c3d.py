"""Read a C3D gait trial (ezc3d): marker trajectories, force platforms, subject parameters, events.

Everything comes out in SI units in the file's own world frame (metres, newtons, N·m, seconds).
Unseen markers (negative residual, or a point at exactly (0, 0, 0) as older writers store
them) are NaN. Marker labels lose their subject prefix (``Subject:LASI`` -> ``LASI``). Force platforms are
taken from ezc3d's platform filter: per analog sample, the force the plate exerts on the
subject (N, world axes) and its moment (N·m) about the centre of the plate's top surface (the
mean of its four corners), plus the plate outline. Nothing here filters or zeroes; see
:mod:`livezmp.balance.plates` for that.

ezc3d's plate filter follows the C3D spec (c3d.org user guide, FORCE_PLATFORM): the plate's axes from its
corners, x = corner 1 − corner 2 and y = corner 1 − corner 4 (the corners are numbered by the plate's quadrants
+x+y, −x+y, −x−y, +x−y; its z then points down into the floor); moments moved to the surface centre as
M + F × ORIGIN, ORIGIN being the vector from the plate's measurement origin to that centre in plate axes (its z
negative; a positive z, the original AMTI convention, is negated, as Visual3D does); TYPE 3 from Kistler's
eight channels with ORIGIN's x, y the sensor offsets (kept positive where ezc3d negates them with a positive z:
:func:`_kistler_moment`); TYPE 1 from its CoP and free-moment channels (:func:`_cop_moment`: ezc3d's moment for it
has the wrong sign); TYPE 4 through CAL_MATRIX stored by columns; TYPE 5, which ezc3d refuses, here
(:func:`_calibrated_platforms`). The
synthetic labs of tests/test_c3d_lab_variants.py write every one of these and meet their true CoP. Its analog
scaling subtracts |ANALOG:OFFSET| where the spec's offset is signed: a negative offset on a plate channel of
signed data is refused.
"""

from __future__ import annotations

import math
import signal
import struct
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from livezmp.checks import MAX_COORDINATE_M, check_frame_period, check_input_file
from livezmp.errors import InputError
from livezmp.model.anthropometry import MAX_AGE_YEARS, MAX_BODY_MASS
from livezmp.model.plate_frame import plate_axes

LENGTH_UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}  # m per POINT:UNITS unit
_NEWTONS = {"n": 1.0, "newton": 1.0, "newtons": 1.0}  # FORCE_PLATFORM:UNITS


@dataclass
class PlateRecord:
    """One force platform at the analog rate, world frame of the file.

    ``force`` (S, 3) N on the subject; ``moment`` (S, 3) N·m about ``centre`` (3,) m, the centre of the
    top surface; ``corners`` (4, 3) m; ``zero`` the analog samples [start, stop) the file names unloaded
    (FORCE_PLATFORM:ZERO), or None; ``reading`` how its parameters were read where not as the spec says, else ''."""

    force: np.ndarray
    moment: np.ndarray
    centre: np.ndarray
    corners: np.ndarray
    zero: tuple[int, int] | None = None
    reading: str = ""


@dataclass
class C3dTrial:
    """A C3D trial. ``points`` (F, P, 3) m with NaN where a marker was not seen (negative residual,
    non-finite or all-zero coordinates); ``rate`` Hz of the
    points; ``analog_rate`` Hz of the plates; ``start_time`` s, the time of frame 0 in the
    capture (events are given on the same clock); ``parameters`` the subject's (``Bodymass`` kg,
    ``Height`` m, ``Age`` years, ``LKneeWidth``, ``LElbowWidth``, ``LShoulderOffset`` ... m) when the file has them."""

    source: str
    labels: list[str]
    points: np.ndarray
    rate: float
    analog_rate: float
    start_time: float
    plates: list[PlateRecord]
    mass_kg: float | None = None
    mass_field: str = ""
    height_m: float | None = None
    widths_m: dict[str, float] = field(default_factory=dict)
    events: list[tuple[str, str, float]] = field(default_factory=list)  # (context, label, time s)
    units: str = "m"
    age_years: float | None = None
    # landmarks carried from a static trial by their clusters (livezmp.model.static_trial): its file and
    # label -> "segment: cluster markers"; empty for a trial as read
    from_static: dict = field(default_factory=dict)

    def marker(self, label: str) -> np.ndarray | None:
        """(F, 3) trajectory of ``label`` (m), or None when the file has no such marker."""
        try:
            return self.points[:, self.labels.index(label)]
        except ValueError:
            return None

    def seen_labels(self) -> set[str]:
        """The labels of the markers seen in at least one frame (a label never seen is a marker the trial lacks)."""
        seen = np.isfinite(self.points).all(axis=2).any(axis=0)
        return {label for label, ok in zip(self.labels, seen, strict=True) if ok}


def strip_prefix(label: str) -> str:
    """``Subject:LASI`` -> ``LASI``; surrounding blanks removed."""
    return label.split(":")[-1].strip()


def _param(groups: dict, group: str, name: str):
    try:
        return groups[group][name]["value"]
    except KeyError:
        return None


def _first_number(value) -> float | None:
    if value is None:
        return None
    a = np.asarray(value, dtype=float).ravel()
    return float(a[0]) if a.size and np.isfinite(a[0]) and a[0] > 0 else None


def _age(groups: dict) -> float | None:
    """The subject's age (years) when the file states one (PROCESSING:Age, SUBJECT:AGE or SUBJECTS:AGE)."""
    for g, n in (("PROCESSING", "Age"), ("SUBJECT", "AGE"), ("SUBJECTS", "AGE")):
        age = _first_number(_param(groups, g, n))
        if age is not None and age < MAX_AGE_YEARS:
            return age
    return None


def _subject(groups: dict) -> tuple[float | None, str, float | None, dict[str, float]]:
    """Mass (kg) and where it came from, height (m), knee/ankle widths (m) from PROCESSING (Vicon) or
    SUBJECT/SUBJECTS."""
    mass, where = None, ""
    for g, n in (("PROCESSING", "Bodymass"), ("SUBJECT", "WEIGHT"), ("SUBJECTS", "WEIGHT")):
        m = _first_number(_param(groups, g, n))
        if m is not None and m <= MAX_BODY_MASS:  # 1e30 kg: no subject's (the plates weigh one then)
            mass, where = m, f"{g}:{n}"
            break
    height = None
    for g, n in (("PROCESSING", "Height"), ("SUBJECT", "HEIGHT"), ("SUBJECTS", "HEIGHT")):
        h = _first_number(_param(groups, g, n))
        if h is not None:
            height = h / 1000.0 if h > 3.0 else h  # Vicon writes mm, others m
            break
    widths = {}
    # Plug-in Gait's subject measurements (mm): its model places joint centres with them
    for n in (f"{s}{what}" for s in "LR" for what in ("KneeWidth", "AnkleWidth", "ElbowWidth", "WristWidth",
                                                       "ShoulderOffset")):
        w = _first_number(_param(groups, "PROCESSING", n))
        if w is not None:
            widths[n] = w / 1000.0
    return mass, where, height, widths


def _events(groups: dict) -> list[tuple[str, str, float]]:
    """The EVENT group's (context, label, time s): TIMES is (2, USED) minutes and seconds, which ezc3d gives as a
    (2, n) array or flattened, pairs interleaved (Vicon Nexus files); USED, where given, counts the events, and a
    group whose fields disagree in length keeps the events all of them describe."""
    times = _param(groups, "EVENT", "TIMES")
    labels = _param(groups, "EVENT", "LABELS")
    if times is None or labels is None:
        return []
    contexts = _param(groups, "EVENT", "CONTEXTS") or [""] * len(labels)
    used = _first_number(_param(groups, "EVENT", "USED"))
    count = int(used) if used else len(labels)
    n = min(len(labels), len(contexts), count)
    t = np.asarray(times, dtype=float)
    if t.ndim == 2 and t.shape[0] == 2:
        t = t[0] * 60.0 + t[1]
    elif t.ndim == 1 and t.size == 2 * count:
        t = t[0::2] * 60.0 + t[1::2]
    else:
        t = t.ravel()
    n = min(n, len(t))
    return [(str(c).strip(), str(lab).strip(), float(s))
            for c, lab, s in zip(contexts[:n], labels[:n], t[:n], strict=True) if np.isfinite(s)]


def _check_plate_offsets(groups: dict, source: str) -> None:
    """Refuse a negative ANALOG:OFFSET on a force-plate channel of signed analog data. The C3D spec's value is
    (raw − OFFSET) × SCALE × GEN_SCALE with OFFSET signed; ezc3d subtracts |OFFSET| (right for the unsigned
    offsets above 32767 that an int16 parameter stores negative), which for signed data shifts that channel by
    2 OFFSET SCALE GEN_SCALE before its platform filter: the plate's force would be off by a constant."""
    try:
        offsets = np.asarray(_param(groups, "ANALOG", "OFFSET"), dtype=float).ravel()
        channels = np.asarray(_param(groups, "FORCE_PLATFORM", "CHANNEL"), dtype=float).ravel()
    except (TypeError, ValueError):  # not numbers: ezc3d's platform filter has read them as it could
        return
    fmt = _param(groups, "ANALOG", "FORMAT")
    unsigned = fmt is not None and len(fmt) > 0 and str(fmt[0]).strip().upper() == "UNSIGNED"
    bad = [int(c) for c in channels if 0 < c <= len(offsets) and offsets[int(c) - 1] < 0]
    if bad and not unsigned:
        raise InputError(f"{source}: ANALOG:OFFSET of force-plate channel {bad[0]} is negative "
                         f"({offsets[bad[0] - 1]:.0f}): ezc3d reads signed data with its magnitude, not supported")


def _zero_samples(groups: dict, samples: int, frames: int) -> tuple[int, int] | None:
    """FORCE_PLATFORM:ZERO as analog samples [start, stop): the spec's (c3d.org user guide, FORCE_PLATFORM:ZERO)
    range of 3D frames, first frame 1 (a 0 read as 1), over which the plates are unloaded, so that each channel's
    mean there is its baseline; (0, 0) or no parameter: none. ``samples`` analog samples over ``frames`` frames."""
    try:
        z = [int(v) for v in np.asarray(_param(groups, "FORCE_PLATFORM", "ZERO"), dtype=float).ravel()[:2]]
    except (TypeError, ValueError, OverflowError):  # text, NaN or an infinite float: no range named
        return None
    if len(z) < 2 or z[1] <= 0 or frames <= 0:
        return None
    per = samples // frames
    start, stop = (max(z[0], 1) - 1) * per, min(z[1] * per, samples)
    return (start, stop) if stop - start >= 2 else None


def _kistler_moment(p: dict) -> np.ndarray:
    """(3, S) the moment of ezc3d's TYPE-3 platform ``p`` (file units, world axes, about the surface centre) with
    Kistler's sensor offsets a, b (ORIGIN's x, y: distances, positive) as the file gives them. ezc3d negates the
    whole ORIGIN when its z is positive (the AMTI sign, right for az0) and so a and b too, which negates the
    sensors' part of the moment and mirrors the CoP through the plate's centre: AnyBody's GaitUniMiami sample
    (Vicon Workstation, four Kistler plates, az0 written +54 mm) had every plate's CoP 90-160 mm off the foot on
    it, walking backwards over the stance. ezc3d's moment is -S + F x (z0 ez), S the sensors' moment, z0 its
    negated az0 and ez the plate's z axis from its corners as ezc3d takes them (corner 1 - 2, corner 1 - 4); the
    moment meant is S + F x (z0 ez)."""
    moment = np.asarray(p["moment"], dtype=float)
    a, b, z0 = np.asarray(p["origin"], dtype=float).ravel()[:3]
    if not (a < 0 and b < 0):
        return moment
    c = np.asarray(p["corners"], dtype=float)
    ez = np.cross(c[:, 0] - c[:, 1], c[:, 0] - c[:, 3])
    lever = z0 * ez / np.linalg.norm(ez)
    return -moment + 2.0 * np.cross(np.asarray(p["force"], dtype=float).T, lever).T


def _cop_moment(p: dict) -> np.ndarray:
    """(3, S) the moment of ezc3d's TYPE-1 platform ``p`` (file units, world axes) about its surface centre, from
    the CoP and free moment the plate gives (channels Fx Fy Fz Px Py Mz; ezc3d's ``center_of_pressure`` and ``Tz``):
    (CoP - centre) x F + Tz. ezc3d's own moment for such a plate is that negated, which mirrors the CoP through the
    plate's centre: the BTS walks of RehabEngGroup/MOtoNMS (``TestData/InputData/Control1_UNIPD``, two Bertec
    plates: "plate 2: its CoP lies off the foot standing on it in 100 %", 236 mm off at the 95th percentile); so
    read, each CoP lies 56-87 mm (median) from the heel-to-toe mid-point of the foot on its plate."""
    centre = np.asarray(p["corners"], dtype=float).mean(axis=1)
    lever = np.asarray(p["center_of_pressure"], dtype=float).T - centre
    return np.cross(lever, np.asarray(p["force"], dtype=float).T).T + np.asarray(p["Tz"], dtype=float)


# the ORIGIN read the other way round must put the CoP on the plate in this share of its loaded samples, where the
# spec's reading puts it there in under half of them; a loaded sample carries this much across the plate (N); "on"
# spares a tenth of the plate's half-sizes (a foot at the edge, noise at light loads)
ON_PLATE_SHARE = 0.95
LOADED_N = 100.0
ON_PLATE_SPARE = 1.1


def _on_plate_share(p: dict, moment: np.ndarray) -> float:
    """The share of ``p``'s loaded samples (file units) whose CoP, from ``moment`` (3, S) about the surface centre,
    lies on the plate's top surface (its outline, :data:`ON_PLATE_SPARE` times its half-sizes)."""
    c = np.asarray(p["corners"], dtype=float)
    ex, ey = c[:, 0] - c[:, 1], c[:, 0] - c[:, 3]
    n = np.cross(ex, ey) / np.linalg.norm(np.cross(ex, ey))
    force = np.asarray(p["force"], dtype=float)
    fn = n @ force
    loaded = np.abs(fn) > LOADED_N * _NEWTONS.get(str(p["unit_force"]).strip().lower(), 1.0)
    if not loaded.any():
        return 1.0
    r = np.cross(n, moment[:, loaded].T) / fn[loaded, None]  # the CoP from the centre: M = r x F + t n, r . n = 0
    half = [np.linalg.norm(e) / 2 for e in (ex, ey)]
    return float(np.mean(np.all([np.abs(r @ e) / np.linalg.norm(e) <= ON_PLATE_SPARE * h for e, h in zip((ex, ey), half,
                                                                                              strict=True)], axis=0)))


def _origin_moment(p: dict) -> tuple[np.ndarray, str]:
    """(3, S) the moment of ezc3d's platform ``p`` about its surface centre, and how ORIGIN was read ('' as the
    spec says). The spec's ORIGIN runs from the measurement origin to the surface centre, and ezc3d moves the
    moment by F x ORIGIN. A plate measuring about a corner of its top (an instrumented treadmill's belt: the
    Vicon Nexus file in RealTimeBiomechanics/rtosim, ``data/ViconNexus/walking_1.c3d``, ORIGIN
    (-241.3, -819, 0) mm on a 483 x 1638 mm belt) may write it from the centre to that corner instead: the CoP
    then lies a whole plate off, outside the plate's own surface, where no CoP can be. ORIGIN's x, y are read
    the other way round when the spec's reading puts the CoP on the plate in under half of its loaded samples and
    the other reading in :data:`ON_PLATE_SHARE` of them; with a centred measurement origin (AMTI's few mm) both
    readings put it there and the spec's stands."""
    moment = np.asarray(p["moment"], dtype=float)
    ox, oy = np.asarray(p["origin"], dtype=float).ravel()[:2]
    c = np.asarray(p["corners"], dtype=float)
    ex, ey = c[:, 0] - c[:, 1], c[:, 0] - c[:, 3]
    lever = ox * ex / np.linalg.norm(ex) + oy * ey / np.linalg.norm(ey)
    if not np.any(lever):
        return moment, ""
    other = moment - 2.0 * np.cross(np.asarray(p["force"], dtype=float).T, lever).T
    spec, opposite = _on_plate_share(p, moment), _on_plate_share(p, other)
    if spec >= 0.5 or opposite < ON_PLATE_SHARE:
        return moment, ""
    return other, (f"ORIGIN's x, y read from the surface centre to the measurement origin (the spec's reading put "
                   f"the CoP on the plate in {100 * spec:.0f} % of its loaded samples, this one in "
                   f"{100 * opposite:.0f} %)")


def _plate_types(groups: dict) -> np.ndarray:
    """FORCE_PLATFORM:TYPE per plate (float; none, or text: empty)."""
    try:
        return np.asarray(_param(groups, "FORCE_PLATFORM", "TYPE"), dtype=float).ravel()
    except (TypeError, ValueError):  # none, or text
        return np.zeros(0)


_CHANNELS_OF_TYPE = {2: 6, 5: 8}  # the plate types read where ezc3d's filter refuses a TYPE-5 plate


def _calibrated_platforms(c3d: dict, source: str) -> list[dict]:
    """The plates of a file with TYPE-5 plates, which ezc3d's plate filter refuses ("not supported yet"), as that
    filter gives a plate (force, moment about the surface centre, world axes; corners, ORIGIN). A TYPE-5 plate is a
    TYPE-3 one (Kistler's eight channels fx12 fx34 fy14 fy23 fz1-4) with a 6 x 8 FORCE_PLATFORM:CAL_MATRIX (c3d.org's
    user guide; BTK's ForcePlatformType5), which takes them to TYPE 2's six (Fx Fy Fz Mx My Mz about the measurement
    origin, plate axes), as pyCGM2's ``correctForcePlateType5`` reads the Qualisys files that write them: the
    qualisys/cgm2-web-report-uploader walk ``WithNewPafFields/Gait - CGM2 1`` so read gives the six channels its
    processed copy (``processed/Gait - CGM2 3``, re-written as TYPE 2) holds to 1 % RMS. TYPE-2 plates beside them are
    read too. From there as ezc3d's filter does (its ``ForcePlatforms.cpp``): axes from the corners (x = corner 1 - 2,
    y = corner 1 - 4, made orthogonal), the moment moved to the surface centre by F x ORIGIN, ORIGIN negated where its
    z is positive. Other types beside a TYPE-5 plate are refused in one line."""
    groups = c3d["parameters"]
    types = _plate_types(groups)
    try:
        channel = np.asarray(_param(groups, "FORCE_PLATFORM", "CHANNEL"), dtype=int).reshape(-1, len(types), order="F")
        corners = np.asarray(_param(groups, "FORCE_PLATFORM", "CORNERS"), dtype=float).reshape(3, 4, len(types),
                                                                                                order="F")
        origin = np.asarray(_param(groups, "FORCE_PLATFORM", "ORIGIN"), dtype=float).reshape(3, len(types), order="F")
        cal = np.asarray(_param(groups, "FORCE_PLATFORM", "CAL_MATRIX"), dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{source}: TYPE-5 force platforms without a CHANNEL, CORNERS or ORIGIN for each plate "
                         "(FORCE_PLATFORM)") from None
    analogs = np.asarray(c3d["data"]["analogs"], dtype=float)[0]  # (channels, samples), scaled
    units = _param(groups, "FORCE_PLATFORM", "UNITS")
    out = []
    for k, kind in enumerate(types):
        n = _CHANNELS_OF_TYPE.get(int(kind))
        if n is None:
            raise InputError(f"{source}: force platform {k + 1}: TYPE {kind:g} beside TYPE-5 plates is not read "
                             "(TYPE 2 and 5 are)")
        if kind == 5 and (cal.ndim != 3 or cal.shape[:2] != (6, 8) or cal.shape[2] <= k):
            raise InputError(f"{source}: force platform {k + 1}: TYPE 5 needs a 6 x 8 FORCE_PLATFORM:CAL_MATRIX "
                             f"(the file's is {' x '.join(map(str, cal.shape))})")
        index = channel[:n, k] - 1
        if len(index) < n or index.min() < 0 or index.max() >= len(analogs):
            raise InputError(f"{source}: force platform {k + 1}: FORCE_PLATFORM:CHANNEL names channels the file "
                             "does not have")
        six = cal[:, :, k] @ analogs[index] if kind == 5 else analogs[index]
        c = corners[:, :, k]
        rot, _ = plate_axes(c.T)
        o = -origin[:, k] if origin[2, k] > 0 else origin[:, k]
        moment = six[3:] + np.cross(six[:3].T, o).T
        out.append({"unit_force": str(units[0]) if units is not None and len(units) else "N", "corners": c,
                    "origin": o, "force": rot @ six[:3], "moment": rot @ moment})
    return out


MIN_PLATE_AREA_M2 = 0.01  # a 10 x 10 cm plate: the smallest gait-lab plates measure 0.3 x 0.4 m


def _check_plate_area(corners: np.ndarray, where: str) -> None:
    """Refuse a plate whose four corners (4, 3) m enclose less than :data:`MIN_PLATE_AREA_M2` (coincident or on a
    line): its axes and surface are undefined, and its CoP, never on a foot, left no frame complete without a word
    of why."""
    area = 0.5 * np.linalg.norm(np.cross(corners[2] - corners[0], corners[3] - corners[1]))  # a quadrilateral's
    if area < MIN_PLATE_AREA_M2:
        raise InputError(f"{where}: FORCE_PLATFORM:CORNERS enclose {area:.3g} m² (corners that coincide or lie on "
                         f"a line; a plate covers at least {MIN_PLATE_AREA_M2:g} m²)")


def _unread_as_zero(samples: np.ndarray) -> np.ndarray:
    """``samples`` with each NaN or infinite value (a dropped or saturated sample) read as zero, as an unloaded
    plate: an infinite one, kept, made every low-passed sample near it infinite."""
    return np.where(np.isfinite(samples), samples, 0.0)


def _plates(c3d: dict, source: str, unit: str) -> list[PlateRecord]:
    """The plates, their corners and moments (N·``unit``) in ``unit`` (POINT:UNITS): ezc3d only labels its
    numbers, and labels them m when POINT:UNITS is empty, where the points are taken as mm."""
    _check_plate_offsets(c3d["parameters"], source)
    out = []
    length = LENGTH_UNITS[unit]
    frames = int(np.shape(c3d["data"]["points"])[2])
    types = _plate_types(c3d["parameters"])  # none, or text: ezc3d has read the plates as it could
    for k, p in enumerate(c3d["data"].get("platform", [])):
        newtons = _NEWTONS.get(str(p["unit_force"]).strip().lower())
        if newtons is None:
            raise InputError(f"{source}: force platform {k + 1}: unknown force unit {p['unit_force']!r} "
                             "(FORCE_PLATFORM:UNITS)")
        moment = newtons * length
        for key in ("corners", "origin"):  # NaN too: every plate's geometry is used
            if not (np.abs(np.asarray(p[key], dtype=float)) * length <= MAX_COORDINATE_M).all():
                raise InputError(f"{source}: force platform {k + 1}: FORCE_PLATFORM:{key.upper()} not finite or "
                                 f"beyond {MAX_COORDINATE_M:g} m")
        corners = np.asarray(p["corners"], dtype=float).T * length
        _check_plate_area(corners, f"{source}: force platform {k + 1}")
        force = np.asarray(p["force"], dtype=float).T * newtons
        kind = types[k] if k < len(types) else 0
        mom, reading = (_kistler_moment(p), "") if kind == 3 else (_cop_moment(p), "") if kind == 1 else \
            _origin_moment(p)
        mom = mom.T * moment
        zero = _zero_samples(c3d["parameters"], len(force), frames)
        out.append(PlateRecord(_unread_as_zero(force), _unread_as_zero(mom), corners.mean(axis=0), corners, zero,
                               reading))
    return out


def _byte_order(data: bytes) -> str:
    """The struct byte order of a C3D file's words: big-endian (">") where the parameter section's header (the
    block the file's first byte names) says processor type 84 + 2 (MIPS), else little-endian ("<")."""
    start = (data[0] - 1) * 512
    return ">" if 1 <= data[0] and start + 4 <= len(data) and data[start + 3] == 86 else "<"


def _check_parameter_section(p: Path, data: bytes) -> None:
    """Refuse, before ezc3d reads it, a parameter section that would make ezc3d allocate without
    bound: a description length byte above 127 (read as a negative count, then as an unsigned one:
    gigabytes) or dimensions claiming more values than the file holds bytes (also those before a zero
    dimension, which ezc3d loops over without reading anything), or a POINT:RATE or ANALOG:RATE that is not
    a finite number >= 0 (ezc3d sizes its frames by them: NaN ends in a C++ allocation message). The walk
    follows ezc3d's reader; where the structure breaks off, ezc3d's own check refuses the file."""
    size = len(data)
    if size < 512 or data[0] < 1:
        return
    start = (data[0] - 1) * 512
    if start + 4 > size:  # a section that begins inside the file is read even when the file ends in its block
        return
    order = _byte_order(data)
    # the first parameter follows the 4-byte section header: its first byte (the parameters' start, 0 in
    # Codamotion and Motion Analysis files) is read as 1 whatever it says, as ezc3d does
    pos = start + 4
    groups: dict[int, str] = {}
    while pos + 2 <= size:
        n, gid = struct.unpack_from("bb", data, pos)
        at = pos + 2 + abs(n)  # after the name
        if n == 0 or gid == 0 or at + 2 > size:
            return
        (offset,) = struct.unpack_from(order + "H", data, at)
        at += 2
        what = data[pos + 2 : pos + 2 + abs(n)].decode("ascii", "replace")
        if gid < 0:
            groups[-gid] = what.upper()
        if gid > 0:  # a parameter: type, dimensions, values
            if at + 2 > size:
                return
            kind, ndims = struct.unpack_from("bb", data, at)
            dims = data[at + 2 : at + 2 + max(ndims, 0)]
            claimed = abs(kind) * math.prod(dims)
            # ezc3d loops over the dimensions nested: the ones before a zero cost their product in loops
            loops = math.prod(dims[: dims.index(0)] if 0 in dims else dims)
            if max(claimed, loops) > size:
                raise InputError(f"{p}: parameter {what!r} claims {max(claimed, loops):.3g} values, more than "
                                 f"the file's {size} bytes")
            _check_rate(p, f"{groups.get(gid, '')}:{what.upper()}", kind, data, at + 2 + max(ndims, 0), order)
            at += 2 + max(ndims, 0) + claimed
        if at < size and data[at] > 127:
            raise InputError(f"{p}: {'parameter' if gid > 0 else 'group'} {what!r} has a description length of "
                             f"{data[at] - 256} bytes (a corrupt C3D parameter section)")
        if offset == 0:
            return
        pos = pos + 2 + abs(n) + offset


def _check_rate(p: Path, key: str, kind: int, data: bytes, at: int, order: str) -> None:
    """Refuse POINT:RATE or ANALOG:RATE (Hz, a 4-byte float at ``at``) when it is not a finite number >= 0."""
    if key in ("POINT:RATE", "ANALOG:RATE") and kind == 4 and at + 4 <= len(data):
        (rate,) = struct.unpack_from(order + "f", data, at)
        if not math.isfinite(rate) or rate < 0:
            raise InputError(f"{p}: {key} {rate:g} is not a rate in Hz (a finite number >= 0)")


READ_SECONDS = 20.0  # a trial read in the child gets this much CPU time, plus a second per 10 MB of file
READ_WALL_FACTOR = 10  # and this many times as long in wall time: on a loaded machine the child waits for
# a CPU (load 17 on 2 CPUs: a 1.2 MB walk's probe passed 20 s of wall time), but a read ezc3d loops on spends CPU


# the child caps its own CPU time (the kernel ends it with SIGXCPU): the read's limit, which also holds if this
# process is killed while the child reads a file ezc3d loops on (nobody is then left to stop it)
_PROBE = ("import resource, sys; n = int(sys.argv[3]); resource.setrlimit(resource.RLIMIT_CPU, (n, n + 1)); "
          "import ezc3d; "
          "ezc3d.c3d(sys.argv[1], extract_forceplat_data=sys.argv[2] == '1')")


def _spawned_read(p: Path, plates: bool, seconds: int) -> int | None:
    """ezc3d's read of ``p`` in a new interpreter given ``seconds`` of CPU time (its own cap: SIGXCPU past it) and
    READ_WALL_FACTOR times that in wall time: the signal that ended it, 0 if it ran out of wall time (then
    killed), None if it ended by itself."""
    try:
        r = subprocess.run([sys.executable, "-c", _PROBE, str(p), "1" if plates else "0", str(seconds)],
                           capture_output=True, timeout=READ_WALL_FACTOR * seconds)
    except subprocess.TimeoutExpired:
        return 0
    return -r.returncode if r.returncode < 0 else None


def _check_ezc3d_survives(p: Path, size: int, plates: bool) -> None:
    """Read ``p`` with ezc3d once in a child process first: some malformed files crash ezc3d's C++ reader
    (a segmentation fault, found by the fuzz suite) or keep it looping, which would end or hang this
    process without a word. A child killed by a signal or out of time refuses the file in one line;
    a child that merely raises leaves the message to the real read. The child is a new interpreter
    (0.2-0.5 s), not a fork: this process has threads (BLAS's, a live capture's clients), and a fork
    of a threaded process can itself crash in the child."""
    seconds = math.ceil(READ_SECONDS + size / 10e6)
    sig = _spawned_read(p, plates, seconds)
    if sig == signal.SIGXCPU:
        raise InputError(f"{p}: not a readable C3D file (ezc3d did not finish reading it in {seconds} s of CPU time)")
    if sig == 0:
        raise InputError(f"{p}: not a readable C3D file (ezc3d did not finish reading it in "
                         f"{READ_WALL_FACTOR * seconds} s)")
    if sig is not None:
        raise InputError(f"{p}: not a readable C3D file (ezc3d's reader crashed on it: {signal.Signals(sig).name})")


C3D_KEY = 0x50  # the second byte of every C3D file (the C3D specification's header, word 1)


def open_c3d(path: str | Path, plates: bool = False):
    """The ezc3d object of ``path`` (``plates``: with ezc3d's force-platform data). Raises InputError for
    files ezc3d cannot read."""
    import ezc3d  # imported here: only C3D input needs it

    p = check_input_file(path, "C3D file")  # the 1 GiB limit: ezc3d holds the whole trial (docs/archive.md)
    try:
        data = p.read_bytes()
    except OSError as e:
        raise InputError(f"{p}: cannot read ({e.strerror})") from None
    if len(data) < 512 or data[1] != C3D_KEY:  # read as one, a text's lines were parameters claiming 1e76 values
        raise InputError(f"{p}: not a readable C3D file (no C3D header: a 512-byte block whose second byte is 0x50)")
    _check_parameter_section(p, data)
    _check_ezc3d_survives(p, len(data), plates)
    try:
        c3d = ezc3d.c3d(str(p), extract_forceplat_data=plates)
    except Exception as e:  # ezc3d raises plain RuntimeError/ValueError with a C++ message  # noqa: BLE001
        raise InputError(f"{p}: not a readable C3D file ({str(e).splitlines()[0] if str(e) else type(e).__name__})") \
            from None
    _check_data_read_whole(p, data, c3d)
    return c3d


def _frames_held(data: bytes, order: str) -> tuple[int, int]:
    """(how many whole frames the data section of the C3D file ``data`` holds, from its header: words 2, 3, 7, 9,
    points, analog words a frame, POINT:SCALE whose sign says 4-byte floats or 2-byte integers, the data's first
    512-byte block; how many of those may be the last block's padding)."""
    points, analog_words = struct.unpack_from(order + "2H", data, 2)
    (scale,) = struct.unpack_from(order + "f", data, 12)
    (start,) = struct.unpack_from(order + "H", data, 16)
    size = (4 * points + analog_words) * (4 if scale < 0 else 2)
    if not size or not start:
        return 0, 0
    return max(0, len(data) - (start - 1) * 512) // size, 511 // size


def _check_data_read_whole(p: Path, data: bytes, c3d) -> None:
    """Refuse a file whose POINT:RATE is no frame rate read (:func:`check_frame_period`), or whose data ezc3d read
    otherwise than its header lays it out: analog samples a frame other than the header's (ezc3d steps through the
    data by ANALOG:RATE / POINT:RATE: one that is not the header's count reads markers from the analog words, refused
    later as an up axis or a pelvis it could not make out, or runs out of file), or fewer frames than the header's
    first..last (a file cut short: ezc3d reads what is there without a word), or, where the header's last frame is
    the 16-bit count's cap (0xFFFF), fewer frames than the data holds (ezc3d reads 65535 frames, TRIAL:ACTUAL_END_FIELD
    or not: an hour at 100 Hz was analysed as its first 11 min, exit 0)."""
    rate = _first_number(_param(c3d["parameters"], "POINT", "RATE"))
    if rate is None:
        raise InputError(f"{p}: POINT:RATE is missing or not a positive number")
    check_frame_period(1.0 / rate, f"{p}: POINT:RATE {rate:g}")
    order = _byte_order(data)
    analog_words, first, last = struct.unpack_from(order + "3H", data, 4)  # header words 3-5
    (per_frame,) = struct.unpack_from(order + "H", data, 18)  # word 10
    frames = c3d["data"]["points"].shape[2]
    samples = c3d["data"]["analogs"].shape[2]
    if analog_words and samples != frames * per_frame:
        analog_rate = _first_number(_param(c3d["parameters"], "ANALOG", "RATE")) or 0.0
        raise InputError(f"{p}: ANALOG:RATE {analog_rate:g} is not POINT:RATE {rate:g} times the header's "
                         f"{per_frame} analog samples a frame: the frames cannot be told apart")
    if first <= last < 0xFFFF and frames < last - first + 1:  # 0xFFFF: a longer trial's count is in TRIAL
        raise InputError(f"{p}: truncated: the header says {last - first + 1} frames ({first}..{last}), "
                         f"the file holds {frames}")
    held, padding = _frames_held(data, order)
    if last == 0xFFFF and held > frames + padding:  # the 16-bit count's cap: ezc3d reads 65535 frames and stops
        raise InputError(f"{p}: the data holds about {held} frames ({held / rate / 60:.0f} min), ezc3d reads the "
                         f"first {frames} (its 16-bit frame count's limit): split the take")


def told_apart(labels: list[str], descriptions: list[str]) -> list[str]:
    """``labels`` with each repeat of a label that POINT:DESCRIPTIONS describes otherwise than its first copy
    renamed to its description: Motion Analysis' Helen Hayes template writes the medial knee and ankle markers as
    a second ``RKNE`` / ``RANK`` described ``R.Knee.Medial`` / ``R.Ankle.Medial`` (c3d.org's Walk1 and newwalk,
    BTK's Gait sample). A repeat with no other description stays (and is refused where it is used)."""
    out, first = list(labels), {}
    for i, (lab, desc) in enumerate(zip(labels, descriptions, strict=False)):
        if lab not in first:
            first[lab] = desc
        elif desc and desc != first[lab] and desc not in labels:
            out[i] = desc
    return out


def read_c3d(path: str | Path) -> C3dTrial:
    """Read ``path`` (see module docstring). Raises InputError for files ezc3d cannot read."""
    p = Path(path)
    try:
        c3d = open_c3d(p, plates=True)
    except InputError as refused:  # ezc3d's plate filter refuses TYPE-5 plates: read here
        c3d = open_c3d(p)
        if 5 not in _plate_types(c3d["parameters"]):
            raise refused from None
        c3d["data"]["platform"] = _calibrated_platforms(c3d, str(p))
    groups = c3d["parameters"]
    units = _param(groups, "POINT", "UNITS")
    # missing or empty: mm, the unit nearly every writer uses (a metre file is then refused by its stature)
    unit = (str(units[0]).strip().lower() if units is not None and len(units) else "") or "mm"
    if unit not in LENGTH_UNITS:
        raise InputError(f"{p}: POINT:UNITS {unit!r} is not a length unit (mm, cm, m)")
    rate = _first_number(_param(groups, "POINT", "RATE"))  # checked by open_c3d
    pts = np.asarray(c3d["data"]["points"][:3], dtype=float)  # (3, P, F)
    labels = [strip_prefix(s) for s in (_param(groups, "POINT", "LABELS") or [])][: pts.shape[1]]
    labels += [f"point{i + 1}" for i in range(len(labels), pts.shape[1])]
    labels = told_apart(labels, [str(d).strip() for d in _param(groups, "POINT", "DESCRIPTIONS") or []])
    residual = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=float)[0]  # (P, F); < 0: not seen
    # a gap: a negative residual, a non-finite coordinate, or the all-zero point some writers put in gaps
    unseen = (residual < 0) | ~np.isfinite(pts).all(axis=0) | (pts == 0).all(axis=0)
    pts = np.where(unseen[None], np.nan, pts) * LENGTH_UNITS[unit]
    first = _first_number(_param(groups, "TRIAL", "ACTUAL_START_FIELD"))
    mass, where, height, widths = _subject(groups)
    return C3dTrial(
        source=str(p), labels=labels, points=pts.transpose(2, 1, 0), rate=rate,
        analog_rate=_first_number(_param(groups, "ANALOG", "RATE")) or rate,
        start_time=((first or 1.0) - 1.0) / rate, plates=_plates(c3d, str(p), unit), mass_kg=mass, mass_field=where,
        height_m=height, age_years=_age(groups), widths_m=widths, events=_events(groups), units=unit,
    )
