"""A gait-lab take analysed against its force plates: body mass, the pipeline over the marker body,
the plates at the marker frames, the frames they saw whole, and the comparison.

Mass: ``--mass`` when given; else the plates' (mean vertical force over whole gait cycles ÷ g) when
they cover a cycle, said when the file's differs by more than ``MASS_DISAGREE``; else the file's;
else the plates' mean vertical force ÷ g over a standing take (complete frames without a break or a foot
strike, over at least ``STANDING_S``); else the plates' over the frames where every loaded foot is on one and
they carry the load, Σ F_z / Σ (g + a_z) with the kinematics' vertical CoM acceleration
(:func:`livezmp.balance.plates.stance_mass`: a trial with a step or two on the plates and no mass in the file);
else 70 kg. The ZMP does not depend on the total mass
(every segment scales with it); the flight threshold, the complete frames and the plate-side CoM acceleration
(so the measured plate delay) do.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import pinocchio as pin

from livezmp.balance.pipeline import Pipeline, PipelineConfig, default_config
from livezmp.balance.plates import (
    STANCE_MIN_FRAMES,
    STANCE_MIN_KEPT,
    G,
    PlateFrames,
    complete_frames,
    cop_on_feet,
    cutoff_for_gain,
    gait_cycles,
    lowpass,
    lowpass_reach_s,
    plate_frames,
    plate_mass,
    plates_floor,
    raised_by,
    stance_mass,
    standing_span,
)
from livezmp.balance.support import SUPPORT_LABELS
from livezmp.estimate.estimator import EstimatorConfig
from livezmp.estimate.response import acceleration_response
from livezmp.model.bvh_body import DEFAULT_MASS
from livezmp.model.c3d import C3dTrial
from livezmp.model.markers import HAT_POINTS, MarkerBodyOptions, MarkerTake, body_from_markers
from livezmp.offline.batch import BatchResult, run_batch
from livezmp.offline.treadmill import SIDES, Treadmill, find_treadmill, given_treadmill
from livezmp.offline.validation import (
    HEADING_HZ,
    com_acc_vs_plates,
    cop_vs_force_line,
    cop_vs_zmp,
    ms,
    plate_delay,
    walk_heading,
    walking_axes,
)

MASS_DISAGREE = 0.03
# a body-mass index (kg/m^2) outside this no walking subject has: WHO's classes run from severe thinness (under 16)
# to obese class III (40 and over); the plates that weighed someone so are scaled wrongly (ANALOG:SCALE,
# FORCE_PLATFORM:UNITS): Open3DMotion's Codamotion export gait-bilateral-2005-amtix2 weighs its subject at 1174 kg
PERSON_BMI = (10.0, 80.0)
LOADED_HEIGHT_M = 0.04  # m: a sole corner this low ...
LOADED_SPEED_MPS = 1.0  # m/s: ... and this slow may carry load (completeness check)
# A whole take needs no low latency: a symmetric spline window (look as far ahead as back). The live
# default (0.4 s window, 0.1 s ahead) delays a 6 Hz-smoothed acceleration by up to ~20 ms at gait
# frequencies and bends its gain; this one has no delay (docs/validation.md). Its 6 Hz cutoff, not the
# per-rate default (a noise rule: 3.9 Hz at 100 Hz), is the one kept after comparing cutoffs against
# force plates on marker data at 50-240 Hz (docs/validation.md, "Cutoff for marker data").
LAB_ESTIMATOR = {"window_s": 0.8, "lag_s": 0.4, "cutoff_hz": 6.0}
# Walking's lateral motion repeats once a stride, its fore-aft and vertical motion once a step (twice a stride:
# Smidt et al. 1971; the harmonic ratios of Menz, Lord & Fitzpatrick 2003, Gait Posture 18:35): the same
# harmonics of the lateral motion lie below half the frequency. The segments' lateral positions are low-passed at
# this part of the estimator's cutoff (whole takes; docs/validation.md, "The lateral band").
LATERAL_CUTOFF_FRACTION = 0.5
# The plates are matched to the estimator's acceleration gain at this part of its cutoff: the estimator's response
# falls off faster than the plates' 4th-order low-pass, so they can agree over the band below it, not everywhere
PLATE_BAND_MATCH = 2 / 3
# A complete frame's low-passed plate reading takes at most this part of its filter's weight from beyond the
# complete frames on either side (lowpass_reach_s: 0.078 s at the lab's 4.93 Hz): a foot carrying W off the plates
# there moves the CoP at most this part of W / body weight times its distance from the plates' CoP (15 mm for half
# the weight 0.6 m away)
PLATE_LEAK = 0.05
FORCE_SEEN = 0.75  # complete frames: the plates carry at least this part of m (g + CoM vertical acceleration)
# The CoP-under-the-foot check: a plate's CoP is its moment over its force, so a moment error of 1 N·m (offsets,
# cross-talk) moves it 6 mm at a quarter of a 70 kg subject's weight, and further below; frames where a plate carries
# less are left out. A plate whose CoP lies off the foot on it in more than half of its frames is reported.
COP_CHECK_WEIGHT = 0.25
COP_OFF_FOOT = 0.5


@dataclass
class LabAnalysis:
    """``result`` the pipeline's; ``plates`` at its frames (None without plates); ``complete`` (N,)."""

    take: MarkerTake
    rate: float  # Hz of the marker frames
    times: np.ndarray
    config: PipelineConfig
    result: BatchResult
    plates: PlateFrames | None
    complete: np.ndarray
    summary: dict = field(default_factory=dict)
    treadmill: Treadmill | None = None  # the belts the feet's contacts were judged on (None: a floor at rest)


@dataclass(frozen=True)
class LabOptions:
    """``mass`` kg (None: decide, see module docstring); ``mode`` ZMP mode; ``plate_cutoff_hz``: the
    plates' zero-phase low-pass (None: :func:`plates_band_hz`, so both sides see the same band);
    ``plate_delay_s``: the plates' delay behind the markers (s; they are sampled that much later), None =
    measured from the CoM acceleration and applied when determined and at least half a frame; ``markers``: body options
    (mass is set here); ``estimator`` settings replacing the pipeline's (None: defaults);
    ``lateral_cutoff_fraction``: the segments' positions across the walk are low-passed at this part of the
    estimator's cutoff before it (None: not; :func:`lateral_band`); ``treadmill``: "auto" (found from the feet,
    :func:`livezmp.offline.treadmill.find_treadmill`), "off" (a floor at rest) or the (left, right) belt speeds, m/s.
    """

    mass: float | None = None
    mode: str = "full"
    plate_cutoff_hz: float | None = None
    plate_delay_s: float | None = None
    markers: MarkerBodyOptions = MarkerBodyOptions()
    estimator: dict | None = None
    lateral_cutoff_fraction: float | None = LATERAL_CUTOFF_FRACTION
    treadmill: str | tuple[float, float] = "auto"


def _strikes(trial: C3dTrial, result: BatchResult) -> dict[str, list[float]]:
    """Foot-strike times (s, from C3D frame 0) per side: the file's events, else contact onsets."""
    out: dict[str, list[float]] = {"left": [], "right": []}
    for context, label, t in trial.events:
        side = context.lower()
        if side in out and label.lower().replace("-", " ") == "foot strike":
            out[side].append(t - trial.start_time)
    if any(out.values()):
        return out
    labels = np.asarray(SUPPORT_LABELS)[result.support]
    for side in out:
        on = np.isin(labels, (side, "double"))
        out[side] = result.t[1:][on[1:] & ~on[:-1]].tolist()
    return out


def run_take(trial: C3dTrial, opts: LabOptions, mass: float, floor: float | None, treadmill: Treadmill | None = None):
    """The marker body of ``trial`` (``mass`` kg, soles at ``floor``, the plates' surface; its feet's contacts judged
    on the ``treadmill``'s belts, if any) through the lab pipeline: the take, its frame times (s), the pipeline's
    settings and its result. Plates raised above the floor the feet
    stand on off them (:func:`livezmp.balance.plates.raised_by`): the soles' heights are measured from that floor,
    the ZMP and the contacts kept on the plates' surface, where the complete frames stand; ``take.notes["floor"]``
    says so."""
    take = body_from_markers(trial, replace(opts.markers, total_mass=mass, floor_z=floor))
    raised = 0.0 if floor is None or "ankle" not in take.centres else raised_by(
        list(take.centres["ankle"].values()), [p.corners @ take.body.world_from_input.T for p in trial.plates],
        trial.rate)
    if raised:
        take = body_from_markers(trial, replace(opts.markers, total_mass=mass, floor_z=floor - raised))
        take.notes["floor"] = {"below_plates_mm": round(1000 * raised, 1), "why": (
            f"the feet stand {1000 * raised:.0f} mm higher on the plates than off them: plates raised above the "
            "floor (a step onto them); the soles' heights from the floor, the ZMP on the plates' surface, compared "
            "where every loaded foot is on them")}
    times = (take.first_frame + np.arange(len(take.frames))) / trial.rate
    cfg = default_config(take.body, trial.rate, opts.mode, floor)
    cfg = replace(cfg, estimator=replace(cfg.estimator, **{**LAB_ESTIMATOR, **(opts.estimator or {})}),
                  belt=None if treadmill is None else treadmill.belt)
    band = lateral_band_hz(opts, take, cfg)
    frames = take.frames if band is None else lateral_band(take.frames, trial.rate, band, facing(take))
    result = run_batch(Pipeline(take.body, cfg, nominal_dt=1.0 / trial.rate), times, frames, keep_states=True)
    return take, times, cfg, result


def plates_band_hz(estimator: EstimatorConfig) -> float:
    """The plates' low-pass cutoff (Hz) that gives them the estimator's band: :func:`livezmp.balance.plates.lowpass`
    keeps there what the estimator keeps of an acceleration at ``PLATE_BAND_MATCH`` of its cutoff. The lab estimator
    at 6 Hz: 4.93 Hz, whose gain is the estimator's within 0.01 from 1 to 4 Hz, where a walk's CoM acceleration lies
    (at the estimator's own cutoff the plates kept 0.84 of a 4 Hz acceleration, the markers 0.70; docs/validation.md).
    """
    f = PLATE_BAND_MATCH * estimator.cutoff_hz
    return cutoff_for_gain(f, acceleration_response(estimator, f)[0])


def lateral_band_hz(opts: LabOptions, take: MarkerTake, cfg: PipelineConfig) -> float | None:
    """The cutoff (Hz) of :func:`lateral_band` for ``take``, or None: not asked; every segment tracked by its
    own markers (no mass rides on another segment's markers to carry their shake into the ZMP, and the band
    would only take real motion out: docs/validation.md, "The lateral band where every segment is tracked");
    or a corrected take (livezmp's own output, its HAT given by HAT points), which is analysed as written."""
    if opts.lateral_cutoff_fraction is None or not take.placed or HAT_POINTS[0] in take.roles:
        return None
    return opts.lateral_cutoff_fraction * cfg.estimator.cutoff_hz


def lateral_band(frames: np.ndarray, rate: float, cutoff_hz: float, facing: np.ndarray | None = None) -> np.ndarray:
    """``frames`` (F, 6 per segment: x, y, z m, yaw, pitch, roll rad, internal frame) with every segment's
    position across the walk low-passed at ``cutoff_hz`` (zero phase); along the walk, height and angles
    unchanged. Across the walk is square to :func:`walk_heading` at each frame, so that a turning walk's
    fore-aft motion is not taken for lateral. Whole takes only (zero phase needs the future)."""
    left = walk_heading(frames[:, :3], rate, facing) @ np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    out = frames.copy()
    for k in range(0, frames.shape[1], 6):
        pos = frames[:, k:k + 3]
        # about the segment's own slow path, so that a turning heading does not sweep its distance from the origin in
        across = np.einsum("ij,ij->i", pos - lowpass(pos, rate, HEADING_HZ), left)
        out[:, k:k + 3] = pos + (lowpass(across, rate, cutoff_hz) - across)[:, None] * left
    return out


def may_bear_weight(sole: np.ndarray, floor: float, dt: float, belt: tuple[float, float] | None = None) -> np.ndarray:
    """(F,) whether a foot (sole corners (F, k, 3), m) may carry load: some corner lower than
    ``LOADED_HEIGHT_M`` above the floor and slower than ``LOADED_SPEED_MPS`` (relative to the ``belt`` (vx, vy) m/s
    under it, if any). Looser than contact detection, which is late at toe-off: a complete frame must not miss a
    loaded foot."""
    vel = np.gradient(sole[:, :, :2], dt, axis=0)
    speed = np.linalg.norm(vel if belt is None else vel - belt, axis=2)
    return (((sole[:, :, 2] - floor) < LOADED_HEIGHT_M) & (speed < LOADED_SPEED_MPS)).any(axis=1)


def com_accelerations(take: MarkerTake, result: BatchResult) -> np.ndarray:
    """(N, 3) CoM acceleration (m/s², internal frame) from the estimated q, v, a."""
    model = take.body.model
    data = model.createData()
    out = np.empty((len(result), 3))
    for i in range(len(result)):
        pin.centerOfMass(model, data, result.q[i], result.v[i], result.a[i])
        out[i] = data.acom[0]
    return out


def plates_at(trial: C3dTrial, take: MarkerTake, times: np.ndarray, cutoff: float | None, shift: float) -> PlateFrames:
    """The plates at the marker frames ``times`` (s), low-passed at ``cutoff`` Hz (None: raw), ``shift`` s later."""
    frames = np.rint(times * trial.rate).astype(int)
    return plate_frames(trial.plates, trial.analog_rate, trial.rate, frames, take.body.world_from_input, cutoff,
                        shift_s=shift)


def _complete(trial: C3dTrial, result: BatchResult, times: np.ndarray, cfg: PipelineConfig, floor: float,
              plates: PlateFrames, com_acc: np.ndarray, mass: float,
              margin: int = 0) -> tuple[np.ndarray, np.ndarray, str | None]:
    """The complete frames (``margin`` frames or more from any frame that is not, but for the take's ends), the
    frames with every foot that may bear weight on a plate (whatever the plates carry) and, when there is no
    complete frame, why (one line)."""
    contact = {s: may_bear_weight(sole, floor, 1.0 / trial.rate, _belt_under(cfg, s))
               for s, sole in result.soles.items()}
    # half a spline window from either end of the take the estimate is one-sided (and the plates' filter too);
    # at least the lab window's, so that estimator settings are compared on the same frames
    edge = max(cfg.estimator.window_s, LAB_ESTIMATOR["window_s"]) / 2
    inner = (times >= times[0] + edge) & (times <= times[-1] - edge)
    feet = complete_frames(result.soles, contact, plates.outlines, np.ones(len(times), dtype=bool))
    feet_on = feet & inner
    # the plates must also carry what the motion needs: a foot bearing weight off them is missed otherwise
    needed = mass * (G + com_acc[:, 2])
    seen = feet & (plates.force[:, 2] > FORCE_SEEN * needed)
    complete = clear_of(seen, margin) & inner
    why = None
    if not feet_on.any():
        why = f"no frame ({edge:g} s or more from the take's ends) has every foot that may bear weight on a plate"
    elif not complete.any() and (seen & inner).any():
        why = (f"every frame with the load on the plates lies within their low-pass reach ({margin} frames) of one "
               "without: the low-passed plates there mix in load they do not carry")
    elif not complete.any():
        carried = np.max(plates.force[feet_on, 2] / np.maximum(needed[feet_on], 1e-9))
        why = (f"where the feet are on the plates, these carry at most {100 * carried:.0f} % of m (g + a_z) with "
               f"m = {mass:.1f} kg (complete: {100 * FORCE_SEEN:.0f} %): "
               + ("a lighter subject? (--mass)" if carried > 0.5 else
                  "the plates do not read the feet on them (plate corners or channels wrong?)"))
    return complete, feet_on, why


def clear_of(mask: np.ndarray, k: int) -> np.ndarray:
    """(N,) the frames of ``mask`` (N,) bool whose ``k`` neighbours on either side (within the take) are in it too."""
    if k <= 0:
        return mask
    c = np.concatenate([[0], np.cumsum(~mask)])
    i = np.arange(len(mask))
    return mask & (c[np.minimum(i + k + 1, len(mask))] == c[np.maximum(i - k, 0)])


def _belt_under(cfg: PipelineConfig, side: str) -> tuple[float, float] | None:
    """The belt velocity (vx, vy) m/s under the ``side`` foot in ``cfg``, or None (a floor at rest)."""
    return None if cfg.belt is None else cfg.belt[SIDES.index(side)]


def _cop_under_foot(trial: C3dTrial, result: BatchResult, plates: PlateFrames, floor: float, mass: float,
                    cfg: PipelineConfig) -> dict:
    """Each plate's CoP against the foot standing on it (:func:`livezmp.balance.plates.cop_on_feet`, over frames
    where the plate carries ``COP_CHECK_WEIGHT`` of the weight or more) and a warning per plate whose CoP lies off
    the foot in more than ``COP_OFF_FOOT`` of them (``STANCE_MIN_FRAMES`` or more)."""
    contact = {s: may_bear_weight(sole, floor, 1.0 / trial.rate, _belt_under(cfg, s))
               for s, sole in result.soles.items()}
    per_plate = cop_on_feet(plates, result.soles, contact, COP_CHECK_WEIGHT * mass * G)
    warnings = [f"plate {p['plate']}: its CoP lies off the foot standing on it in {100 * (1 - p['on_foot']):.0f} % "
                f"of {p['frames']} frames ({p['off_p95_mm']:.0f} mm off at the 95th percentile): its corners, ORIGIN, "
                "axes or channels may be wrong" for p in per_plate
                if 1 - p["on_foot"] > COP_OFF_FOOT and p["frames"] >= STANCE_MIN_FRAMES]
    return {"plates": per_plate, "warnings": warnings}


def _stance_rule(stance: tuple[float | None, int, int]) -> str:
    """One line: how the plates weighed the subject over the frames with every loaded foot on them, or why not."""
    m_stance, kept, feet_on = stance
    seen = f"carry {100 * FORCE_SEEN:.0f} % of m (g + a_z)"
    if m_stance is not None:
        return (f"sum F_z / sum (g + a_z) over the {kept} of {feet_on} frames with every loaded foot on a plate "
                f"that {seen} at that mass")
    if feet_on < STANCE_MIN_FRAMES:
        return f"not weighed: {feet_on} frames with every loaded foot on a plate (need {STANCE_MIN_FRAMES})"
    return (f"not weighed: only {kept} of the {feet_on} frames with every loaded foot on a plate {seen} at the mass "
            f"they give (need {STANCE_MIN_FRAMES} and {100 * STANCE_MIN_KEPT:.0f} %): the plates miss load")


def _decide_mass(trial: C3dTrial, opts: LabOptions, m_plates: float | None, cycles: int, first: float,
                 m_standing: float | None = None, stance: tuple[float | None, int, int] = (None, 0, 0)) -> dict:
    m_stance, kept, feet_on = stance
    info = {"file_kg": trial.mass_kg, "file_field": trial.mass_field or None,
            "plates_kg": None if m_plates is None else round(m_plates, 2), "plate_cycles": cycles,
            "stance_kg": None if m_stance is None else round(m_stance, 2),
            "stance_kept": round(kept / feet_on, 3) if feet_on else None, "stance_rule": _stance_rule(stance)}
    if opts.mass:
        used, source = opts.mass, "--mass"
    elif m_plates is not None:
        used, source = m_plates, "plates"
    elif not trial.mass_kg and m_standing is not None:
        used, source = m_standing, "plates (standing)"
    elif not trial.mass_kg and m_stance is not None:
        used, source = m_stance, "plates (stance)"
    else:
        used, source = first, "file" if trial.mass_kg else "default"
    info.update(used_kg=round(used, 2), source=source)
    notes = []
    if trial.mass_kg and m_plates and abs(m_plates - trial.mass_kg) > MASS_DISAGREE * m_plates:
        notes.append(f"the file says {trial.mass_kg:.1f} kg, the plates {m_plates:.1f} kg "
                     f"({100 * (trial.mass_kg / m_plates - 1):+.1f} %); using the {source}")
    # a mass given on the command line is used as told, but a plate weight that contradicts it is said: a typo
    # (5 for 75 kg) scales every force the ZMP is computed from
    weighed = next(((m, how) for m, how in ((m_plates, "over whole gait cycles"), (m_standing, "standing"),
                                            (m_stance, "in stance")) if m is not None), None)
    if opts.mass and weighed and abs(weighed[0] - opts.mass) > MASS_DISAGREE * weighed[0]:
        notes.append(f"--mass says {opts.mass:.1f} kg, the plates weigh {weighed[0]:.1f} kg {weighed[1]} "
                     f"({100 * (opts.mass / weighed[0] - 1):+.1f} %); using --mass as told")
    if notes:
        info["note"] = "; ".join(notes)
    return info


def _weighed_as_no_person(info: dict, stature_m: float | None) -> None:
    """Add to the mass ``info`` (:func:`_decide_mass`) a note where the plates weighed the subject at a body-mass
    index outside :data:`PERSON_BMI` at the markers' stature (m): their scale is wrong. Their mass stays in use: a
    scale common to a plate's channels leaves its CoP (a ratio) where it is, and the thresholds scale with it."""
    if not info["source"].startswith("plates") or not stature_m:
        return
    bmi = info["used_kg"] / stature_m**2
    if PERSON_BMI[0] <= bmi <= PERSON_BMI[1]:
        return
    note = (f"the plates weigh the subject at {info['used_kg']:.0f} kg, a body-mass index of {bmi:.0f} kg/m^2 at the "
            f"markers' stature of {stature_m:.2f} m, no person's: their ANALOG:SCALE or FORCE_PLATFORM:UNITS may be "
            "wrong (a scale common to a plate's channels leaves its CoP where it is; --mass gives the mass)")
    info["note"] = f"{info['note']}; {note}" if "note" in info else note


def take_treadmill(asked: str | tuple[float, float], take: MarkerTake, soles: dict[str, np.ndarray],
                   path: np.ndarray, rate: float) -> Treadmill | None:
    """The treadmill ``take`` walks on (its ``soles`` {side: (F, k, 3)} and body point's ``path`` (F, 3), m,
    internal frame, at ``rate`` Hz): found from its feet ("auto"), none ("off"), or the given (left, right) belt
    speeds (m/s) against the way the subject faces."""
    if asked == "off":
        return None
    if asked == "auto":
        return find_treadmill(soles, path, 1.0 / rate)
    return given_treadmill(asked, facing(take), path, 1.0 / rate)


def facing(take: MarkerTake) -> np.ndarray:
    """(2,) the horizontal way the pelvis faces on average (internal frame)."""
    yaw = take.frames[:, take.body.channel_names.index("pelvis.yaw")]
    return np.array([np.nanmean(np.cos(yaw)), np.nanmean(np.sin(yaw))])


def _input(trial: C3dTrial, take: MarkerTake) -> dict:
    """How the file was written: its up axis (found from the markers), POINT:UNITS, point and analog rates (Hz)."""
    return {"up_axis": take.body.up_axis, "point_units": trial.units, "point_rate_hz": trial.rate,
            "analog_rate_hz": trial.analog_rate}


def analyse_lab_take(trial: C3dTrial, opts: LabOptions | None = None) -> LabAnalysis:
    """Run the pipeline over ``trial``'s marker body and, with plates, compare (see module docstring)."""
    opts = opts or LabOptions()
    first = opts.mass or trial.mass_kg or DEFAULT_MASS
    floor = plates_floor(trial, opts.markers.marker_map)
    take, times, cfg, result = run_take(trial, opts, first, floor)
    treadmill = take_treadmill(opts.treadmill, take, result.soles, result.com, trial.rate)
    if treadmill is not None:  # the contacts judged again, on the belts
        take, times, cfg, result = run_take(trial, opts, first, floor, treadmill)
    belts = None if treadmill is None else treadmill.summary(take.body.world_from_input)
    if not trial.plates:
        mass_info = _decide_mass(trial, opts, None, 0, first)
        return LabAnalysis(take, trial.rate, times, cfg, result, None, np.zeros(len(result), dtype=bool),
                           {"input": _input(trial, take), "markers": take.notes, "mass": mass_info, "plates": None,
                            "lateral_band_hz": lateral_band_hz(opts, take, cfg), "treadmill": belts}, treadmill)
    cutoff = opts.plate_cutoff_hz if opts.plate_cutoff_hz is not None else plates_band_hz(cfg.estimator)
    com_acc = com_accelerations(take, result)
    shift = opts.plate_delay_s or 0.0
    plates = plates_at(trial, take, times, cutoff, shift)
    complete, feet_on, why = _complete(trial, result, times, cfg, floor, plates, com_acc, first)
    strikes = _strikes(trial, result)
    m_plates, cycles = plate_mass(plates.force[:, 2], times, complete, gait_cycles(strikes))
    m_standing, _ = plate_mass(plates.force[:, 2], times, complete,
                               standing_span(times, complete, [t for s in strikes.values() for t in s]))
    mass_info = _decide_mass(trial, opts, m_plates, cycles, first, m_standing,
                             stance_mass(plates.force[:, 2], com_acc[:, 2], feet_on, FORCE_SEEN))
    _weighed_as_no_person(mass_info, take.notes.get("stature_m"))
    used = mass_info["used_kg"]
    if abs(used - first) > 0.005:
        take, times, cfg, result = run_take(trial, opts, used, floor, treadmill)
        com_acc = com_accelerations(take, result)
        complete, _, why = _complete(trial, result, times, cfg, floor, plates, com_acc, used)  # the same plates
    # the plates' clock against the markers': the delay that best matches (GRF - m g) / m to the CoM acceleration,
    # applied only where its halves agree: one they do not pin down is the body model's timing as much as the
    # clock's, and applying it was worse on both halves of the held-out walks (ISW's +18 ms: lag +17 ms, RMS 43
    # mm; left: -1 ms, 32 mm; docs/validation.md, "Lag and its uncertainty")
    measured, determined, halves, spread = plate_delay(com_acc, plates.force / used - [0.0, 0.0, G], complete,
                                                       1.0 / trial.rate)
    applied = (opts.plate_delay_s is None and measured is not None and determined
               and abs(measured) >= 0.5 / trial.rate)
    if applied:
        shift = measured
        plates = plates_at(trial, take, times, cutoff, shift)
    # the plates' low-pass mixes each frame with its neighbours: next to a frame with a loaded foot off the plates
    # (or too little load on them) the low-passed plates miss part of a load that the kinematics' ZMP sees, so their
    # CoP is no whole-body CoP there (docs/validation.md, "The plates' reach"). Mass and delay were fitted before.
    margin = lowpass_reach_s(cutoff, PLATE_LEAK) if cutoff else 0.0
    complete, _, why = _complete(trial, result, times, cfg, floor, plates, com_acc, used, round(margin * trial.rate))
    summary = {
        "input": _input(trial, take),
        "markers": take.notes,
        "mass": mass_info,
        "plates": {"count": len(trial.plates), "surface_z_m": round(plates.surface_z, 4),
                   "offsets_removed_n": [None if o is None else [round(float(v), 2) for v in o[0]]
                                         for o in plates.offsets],
                   "lowpass_hz": cutoff, "complete_frames": int(complete.sum()), "complete_margin_s": round(margin, 3),
                   "set_aside": plates.set_aside, **({"no_complete_frame": why} if why else {}),
                   **({"read": {k + 1: p.reading for k, p in enumerate(trial.plates) if p.reading}}
                      if any(p.reading for p in trial.plates) else {})},
        "time_alignment": {"plate_delay_measured_ms": ms(measured),
                           "plate_delay_applied_ms": round(1000 * shift, 1),
                           "plate_delay_determined": determined,
                           "plate_delay_halves_ms": [ms(h) for h in halves],
                           "plate_delay_uncertainty_ms": ms(spread),
                           "method": "CoM acceleration (kinematics) vs (GRF - m g) / m, RMS-minimising shift"},
        "cop_vs_zmp": cop_vs_zmp(result.zmp, result.has_zmp, plates.cop, complete, result.com, 1.0 / trial.rate,
                                 facing(take), (spread or 0.0) if applied else 0.0),
        "com_acc_vs_plates": com_acc_vs_plates(com_acc, plates.force, used, complete),
        "cop_vs_force_line": cop_vs_force_line(
            plates.cop, result.zmp, result.com, plates.force, used * (com_acc + [0.0, 0.0, G]), plates.surface_z,
            result.support, complete & result.has_zmp, walking_axes(result.com, facing(take)), STANCE_MIN_FRAMES),
        "cop_under_foot": _cop_under_foot(trial, result, plates, floor, used, cfg),
        "lateral_band_hz": lateral_band_hz(opts, take, cfg),
        "treadmill": belts,
    }
    return LabAnalysis(take, trial.rate, times, cfg, result, plates, complete, summary, treadmill)
