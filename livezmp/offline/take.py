"""One take's analysis, as a plain function: what ``livezmp analyze`` does for one file and
``livezmp batch analyze`` does for each take of a library (in a Dask worker or in a loop).
A C3D gait trial goes through :mod:`livezmp.offline.gaitlab` (its markers make the body, its
force plates, when present, are compared with the ZMP); other files through :func:`load_motion`.

Outputs are written atomically (a temporary file beside the target, then :func:`os.replace`),
so a run killed at any point leaves either the old file or the complete new one.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from livezmp.balance.pipeline import Pipeline, PipelineConfig, default_config
from livezmp.correct.limits import MAX_CORRECT_FRAMES, CorrectionLimits, correction_cutoff
from livezmp.errors import InputError
from livezmp.estimate.estimator import FILE_CUTOFF_HZ
from livezmp.jsonfile import atomic_path
from livezmp.model.body import BodyModel
from livezmp.model.bvh import write_bvh
from livezmp.model.bvh_body import DEFAULT_MASS, BvhBodyOptions
from livezmp.model.loop_cycle import Loop
from livezmp.model.marker_map import load_marker_map
from livezmp.model.markers import MarkerBodyOptions
from livezmp.model.motion_file import LoadedMotion, load_motion, write_motion
from livezmp.model.segments import load_mapping
from livezmp.model.static_trial import read_walk
from livezmp.model.urdf_body import UrdfBodyOptions
from livezmp.offline.batch import DEFAULT_CHUNK, BatchResult, run_batch
from livezmp.offline.calibrate import Subject, load_subject
from livezmp.offline.gaitlab import LabAnalysis, LabOptions, analyse_lab_take
from livezmp.offline.report import TakeStats, ZmpCsvWriter, summarize, write_zmp_csv
from livezmp.offline.take_stream import (
    TakeStream,
    analyse_stream,
    check_enough_frames,
    open_bvh_take,
    open_joint_csv_take,
    within_take,
)
from livezmp.offline.validated import VALIDATED_P95_MM

ZMP_CSV = "zmp.csv"
ZMP_PNG = "zmp.png"


@dataclass(frozen=True)
class TakeOptions:
    """How a take is loaded and analysed (the body options of ``livezmp analyze``):
    ``mass`` kg (None: the file's subject mass for a C3D, else 70 kg), ``sole_width`` m, ``ground`` m in
    the input frame, ``mode`` "full" or "seed", ``tolerance_mm`` of ``inside_fraction_tol``; ``subject``
    and ``markers``: a subject file and a marker map (C3D only); ``static`` a cluster set's static trial (C3D only:
    :mod:`livezmp.model.static_trial`); ``cutoff_hz`` the estimator's
    cutoff, Hz (None: the default for the take's rate)."""

    robot: str | None = None
    robot_config: str | None = None
    mass: float | None = None
    units: str | None = None
    up: str | None = None
    mapping: str | None = None
    sole_width: float | None = None
    ground: float | None = None
    mode: str = "full"
    tolerance_mm: float = VALIDATED_P95_MM
    subject: str | None = None  # subject file (livezmp calibrate): a BVH's HAT mass fraction, a C3D's HAT
    markers: str | None = None
    static: str | None = None
    cutoff_hz: float | None = None
    bsp: str = "auto"  # a C3D body's segment table (livezmp.model.anthropometry.choose_table)
    age: float | None = None  # years: the subject's age, replacing a C3D file's
    treadmill: str | tuple[float, float] = "auto"  # a C3D walk's belts (livezmp.offline.treadmill.parse_treadmill)

    def load(self, path: str | Path) -> LoadedMotion:
        subject = load_subject(self.subject) if self.subject else None
        if Path(path).suffix.lower() != ".c3d":
            check_not_c3d_options(self, path)
        return load_motion(path, self.robot, self.bvh_options(subject, path), UrdfBodyOptions(config=self.robot_config),
                           c3d_mass=self.mass, markers=self.marker_options(), static=self.static)

    def marker_options(self) -> MarkerBodyOptions:
        """How a C3D's marker body is made: the marker map, the segment table, and the subject file's
        parameters (its table, when it names one, unless ``bsp`` asks for one)."""
        markers = MarkerBodyOptions(marker_map=load_marker_map(self.markers) if self.markers else None, bsp=self.bsp,
                                    age_years=self.age)
        return load_subject(self.subject).marker_options(markers) if self.subject else markers

    def bvh_options(self, subject: Subject | None = None, path: str | Path | None = None) -> BvhBodyOptions:
        """How a BVH's body is made (``subject``: the loaded subject file, if any; ``path``: the take, whose
        subject is a BVH's when it is one)."""
        if subject is not None and self.robot is not None:
            raise InputError(f"{self.subject}: a subject file describes a person (BVH or C3D takes), not a robot")
        bvh = subject is not None and Path(path or "").suffix.lower() == ".bvh"
        return BvhBodyOptions(total_mass=self.mass or DEFAULT_MASS, units=self.units, up_axis=self.up,
                              mapping=load_mapping(self.mapping) if self.mapping else None,
                              sole_width=self.sole_width, hat_fraction=subject.bvh_hat_fraction(self.subject)
                              if bvh else None)

    def streams(self, path: str | Path | None) -> bool:
        """Whether the take at ``path`` is analysed in bounded memory (:mod:`livezmp.offline.take_stream`):
        a BVH, or a joint CSV with its robot (a C3D is read whole)."""
        suffix = Path(path).suffix.lower() if path is not None else None
        return (suffix == ".bvh" and self.robot is None) or (suffix == ".csv" and self.robot is not None)

    def open(self, path: str | Path) -> TakeStream:
        """The take at ``path`` (see :meth:`streams`) opened for :func:`stream_take`, checked as
        :meth:`load` checks it."""
        check_not_c3d_options(self, path)
        subject = load_subject(self.subject) if self.subject else None
        bvh = self.bvh_options(subject, path)  # refuses a subject file for a robot, as load does
        if Path(path).suffix.lower() == ".csv":
            return open_joint_csv_take(path, self.robot, UrdfBodyOptions(config=self.robot_config))
        return open_bvh_take(path, bvh)


def take_config(loaded: LoadedMotion | TakeStream, mode: str, ground: float | None,
                cutoff_hz: float | None = None) -> PipelineConfig:
    """:func:`default_config` for the take (its body and fps), with ``ground`` (m, in the input frame) and
    the estimator's ``cutoff_hz`` (Hz; None: :data:`FILE_CUTOFF_HZ`, a file's default at every rate)."""
    ground_z = None
    if ground is not None:
        p = np.zeros(3)
        p["xyz".index(loaded.body.up_axis)] = ground
        ground_z = float((loaded.body.world_from_input @ p)[2])
    cutoff = FILE_CUTOFF_HZ if cutoff_hz is None else cutoff_hz
    return default_config(loaded.body, loaded.fps, mode, ground_z, cutoff)


def analyse_loaded(loaded: LoadedMotion, mode: str = "full", ground: float | None = None,
                   progress: Callable[[int], None] | None = None, cutoff_hz: float | None = None) -> BatchResult:
    """The pipeline over a loaded take: its per-frame results (a looped cycle's with its pads, as
    :mod:`livezmp.model.loop_cycle` says, their results dropped)."""
    check_enough_frames(loaded.source, len(loaded.frames))
    cfg = take_config(loaded, mode, ground, cutoff_hz)
    pipe = Pipeline(loaded.body, cfg, nominal_dt=1.0 / loaded.fps)
    if loaded.loop is None:
        return run_batch(pipe, loaded.times, loaded.frames, progress=progress)
    lead, times, padded = loaded.loop.padded(loaded.frames, loaded.times[0], loaded.fps)
    return within_take(run_batch(pipe, times, padded), lead, len(loaded.frames))


@dataclass
class TakeAnalysis:
    """A take's analysis: its ``body``, per-frame ``result``, frame rate ``fps`` (Hz), ``source``;
    ``summary`` the summary figures (see README); ``columns`` extra zmp.csv columns (the plates':
    CoP in the input frame m, plate Fz N, complete) or None; ``cop`` (F, 3) plate CoP (internal
    frame, m) and ``complete`` (F,) bool, or None without plates."""

    body: BodyModel
    result: BatchResult
    fps: float
    source: str
    summary: dict
    columns: dict[str, np.ndarray] | None = None
    cop: np.ndarray | None = None
    complete: np.ndarray | None = None


def analyse_motion(loaded: LoadedMotion, options: TakeOptions,
                   progress: Callable[[int], None] | None = None) -> TakeAnalysis:
    """The analysis of a loaded take; the summary keeps the estimator's settings, so a user sees what
    smoothed the take (README: choosing them)."""
    result = analyse_loaded(loaded, options.mode, options.ground, progress, options.cutoff_hz)
    summary = {"source": loaded.source,
               **summarize(loaded.body, result, loaded.fps, options.mode, options.tolerance_mm),
               **_rest_note(loaded.rest_frames), **_loop_note(loaded.loop, loaded.fps),
               "estimator": _estimator_settings(loaded, options)}
    return TakeAnalysis(loaded.body, result, loaded.fps, loaded.source, summary)


def _rest_note(rest: int) -> dict:
    """The summary's ``rest_pose_frames``: a BVH's leading rest-pose frames, analysed at its first moving pose."""
    return {"rest_pose_frames": rest} if rest else {}


def _loop_note(loop: Loop | None, fps: float) -> dict:
    """The summary's ``loop``: a looped cycle's period and the frames of it analysed before and after the take."""
    return {"loop": {"period_frames": loop.period, "padded_frames": loop.pad_frames(1.0 / fps)}} if loop else {}


def _estimator_settings(take: LoadedMotion | TakeStream, options: TakeOptions) -> dict:
    return asdict(replace(take_config(take, options.mode, options.ground, options.cutoff_hz).estimator,
                          rate_hz=take.fps))


def stream_take(take: str | Path | TakeStream, options: TakeOptions, csv: str | Path | None = None,
                plot: str | Path | None = None, progress: Callable[[int], None] | None = None,
                chunk: int = DEFAULT_CHUNK) -> dict:
    """The analysis of a BVH or a robot's joint CSV (a path, or a take :meth:`TakeOptions.open` opened)
    in bounded memory (:mod:`livezmp.offline.take_stream`): its zmp.csv written to ``csv`` and its
    figure (from a decimated series, :class:`livezmp.offline.plot.PlotSeries`) to ``plot`` when given,
    each atomically; returns the summary, equal to :func:`analyse_motion`'s to rounding.
    ``progress(frames_done)`` after each chunk."""
    if not isinstance(take, TakeStream):
        take = options.open(take)
    take.check_length()
    cfg = take_config(take, options.mode, options.ground, options.cutoff_hz)
    stats = TakeStats(take.total, take.fps, options.tolerance_mm)
    series = None
    if plot:
        from livezmp.offline.plot import PlotSeries, plot_analysis  # matplotlib: only when a figure is asked for

        series = PlotSeries()
    with contextlib.ExitStack() as stack:
        consumers = [stats] + ([series] if series else [])
        if csv:
            writer = ZmpCsvWriter(take.body, stack.enter_context(atomic_path(csv)))
            stack.callback(writer.close)  # before the file replaces ``csv``
            consumers.append(writer)
        analyse_stream(take, cfg, consumers, chunk, progress)
    summary = {"source": take.source, **stats.summary(take.body, options.mode), **_rest_note(take.rest_frames),
               **_loop_note(take.loop, take.fps), "estimator": _estimator_settings(take, options)}
    if series:
        with atomic_path(plot) as tmp:
            plot_analysis(take.body, series.result(), tmp, title=f"{Path(take.source).name} ({options.mode} ZMP)")
    return summary


def _lab_columns(lab: LabAnalysis) -> dict[str, np.ndarray] | None:
    """zmp.csv's plate columns: CoP (input frame, m; empty where unloaded), plate vertical force (N), complete."""
    if lab.plates is None:
        return None
    cop = lab.take.body.to_input_frame(lab.plates.cop)
    return {"cop_x": cop[:, 0], "cop_y": cop[:, 1], "cop_z": cop[:, 2], "plate_fz": lab.plates.force[:, 2],
            "complete": lab.complete.astype(float)}


def lab_options(options: TakeOptions, cutoff_hz: float | None) -> LabOptions:
    """How a C3D take is read: the marker map and the subject file's parameters, if given, and the
    estimator's ``cutoff_hz`` (Hz; None: the lab's own, :data:`livezmp.offline.gaitlab.LAB_ESTIMATOR`)."""
    return LabOptions(mass=options.mass, mode=options.mode, markers=options.marker_options(),
                      estimator=None if cutoff_hz is None else {"cutoff_hz": cutoff_hz}, treadmill=options.treadmill)


def analyse_c3d(path: str | Path, options: TakeOptions) -> TakeAnalysis:
    """The analysis of a C3D gait trial: the marker body (with the subject file's parameters when
    ``options.subject`` is set) and, with force plates, the ZMP against the plate CoP."""
    lab = analyse_lab_take(read_walk(path, options.static), lab_options(options, options.cutoff_hz))
    belt = None if lab.treadmill is None else lab.treadmill.mean_velocity
    summary = {"source": str(path), **summarize(lab.take.body, lab.result, lab.rate, options.mode,
                                                options.tolerance_mm, belt), **lab.summary,
               "estimator": asdict(lab.config.estimator)}
    plates = lab.plates is not None
    return TakeAnalysis(lab.take.body, lab.result, lab.rate, str(path), summary, _lab_columns(lab),
                        lab.plates.cop if plates else None, lab.complete if plates else None)


def analyse_path(path: str | Path, options: TakeOptions) -> TakeAnalysis:
    """The analysis of the motion file at ``path`` (C3D, BVH, or joint CSV with ``options.robot``)."""
    if Path(path).suffix.lower() == ".c3d":
        return analyse_c3d(path, options)
    check_not_c3d_options(options, path)
    return analyse_motion(options.load(path), options)


def check_not_c3d_options(options: TakeOptions, path: str | Path | None) -> None:
    """A marker map and a segment table's choice only apply to C3D trials: say so for any other input."""
    if options.markers:
        raise InputError(f"{options.markers}: --markers is for C3D trials (got {path or 'the built-in demo'})")
    if options.static:
        raise InputError(f"{options.static}: --static is for C3D trials (got {path or 'the built-in demo'})")
    if options.treadmill != "auto":
        raise InputError(f"--treadmill is for C3D walks (got {path or 'the built-in demo'})")
    if options.bsp != "auto" or options.age is not None:
        raise InputError("--bsp and --age choose a C3D marker body's segment table (got "
                         f"{path or 'the built-in demo'}; a BVH's body is de Leva's adult table)")


def analyse_take(path: str | Path, out_dir: str | Path, options: TakeOptions, plot: bool = False) -> dict:
    """Analyse the take at ``path``; write its ``zmp.csv`` and, with ``plot``, its ``zmp.png`` (each
    atomically) into the directory ``out_dir``; return the summary. A BVH or a robot's joint CSV is
    analysed in bounded memory (:func:`stream_take`), a C3D whole."""
    if options.streams(path):
        return stream_take(path, options, Path(out_dir) / ZMP_CSV, Path(out_dir) / ZMP_PNG if plot else None)
    a = analyse_path(path, options)
    with atomic_path(Path(out_dir) / ZMP_CSV) as tmp:
        write_zmp_csv(a.body, a.result, tmp, a.columns)
    if plot:
        from livezmp.offline.plot import plot_analysis  # matplotlib: only when a figure is asked for

        with atomic_path(Path(out_dir) / ZMP_PNG) as tmp:
            plot_analysis(a.body, a.result, tmp, title=f"{Path(a.source).name} ({options.mode} ZMP)", cop=a.cop,
                          complete=a.complete)
    return a.summary


def check_correctable(source: str | Path, frames: int) -> None:
    """Refuse a take too short (:func:`check_enough_frames`) or too long for the correction, which holds it
    whole (:data:`MAX_CORRECT_FRAMES`)."""
    check_enough_frames(source, frames)
    if frames > MAX_CORRECT_FRAMES:
        raise InputError(f"{source}: {frames} frames; correct solves a whole take at once and takes at most "
                         f"{MAX_CORRECT_FRAMES} (split the take)")


def correct_loaded(loaded: LoadedMotion, output: str | Path, options: TakeOptions, limits: CorrectionLimits,
                   progress: Callable[[str], None] | None = None) -> dict:
    """``livezmp correct`` of a loaded BVH or joint-CSV take, written (atomically) to ``output`` in the
    take's own format. Returns the correction report."""
    check_correctable(loaded.source, len(loaded.frames))
    from livezmp.correct.solver import correct_motion  # the correction's modules: heavy
    from livezmp.correct.unknowns import looped

    cfg = take_config(loaded, options.mode, options.ground, correction_cutoff(options.cutoff_hz))
    times, frames, unknowns = loaded.times, loaded.frames, None
    if loaded.loop is not None:  # corrected as the loop it is analysed as: one rotation per frame of its cycle
        lead, times, frames = loaded.loop.padded(loaded.frames, loaded.times[0], loaded.fps)
        unknowns = looped(lead, len(loaded.frames), loaded.loop.period)
    result = correct_motion(loaded.body, times, frames, cfg, limits, nominal_dt=1.0 / loaded.fps,
                            progress=progress, unknowns=unknowns)
    with atomic_path(output) as tmp:
        write_motion(loaded, result.frames, tmp)
    return {"source": loaded.source, "output": str(output), "mode": cfg.mode, "fps": round(loaded.fps, 6),
            "duration_s": round(float(loaded.times[-1] - loaded.times[0]), 6), **result.report(),
            **_loop_note(loaded.loop, loaded.fps)}


def correct_c3d_take(path: str | Path, output: str | Path, options: TakeOptions, limits: CorrectionLimits,
                     progress: Callable[[str], None] | None = None) -> dict:
    """``livezmp correct`` of a gait-lab C3D take: its marker body corrected as a chain and written
    (atomically) to ``output``: a C3D (the markers moved rigidly with their segments, everything else
    copied) or, for a ``.bvh`` output, a BVH of the segments. Returns the correction report."""
    from livezmp.correct.marker_take import correct_marker_take  # the correction's modules: heavy
    from livezmp.model.c3d_write import non_position_labels, write_moved_points
    from livezmp.model.marker_bvh import chain_to_bvh

    trial = read_walk(path, options.static)
    check_correctable(path, len(trial.points))
    fix = correct_marker_take(trial, lab_options(options, correction_cutoff(options.cutoff_hz)), limits,
                              non_position_labels(path), progress=progress)
    # a static trial's landmarks are not the file's: its clusters, moved, carry them again when it is read
    landmarks = trial.from_static.get("landmarks", {})
    moved = {i: xyz for i, xyz in fix.moved.items() if trial.labels[i] not in landmarks}
    with atomic_path(output) as tmp:
        if str(output).lower().endswith(".c3d"):
            write_moved_points(path, tmp, moved, fix.added, fix.first_frame)
        else:
            write_bvh(chain_to_bvh(fix.body, fix.result.frames, 1.0 / trial.rate, str(path)), tmp)
    report = fix.result.report()
    return {"source": str(path), "output": str(output), "mode": options.mode, "fps": round(trial.rate, 6),
            "duration_s": round((report["frames"] - 1) / trial.rate, 6), **report,
            "max_stance_foot_marker_move_mm": round(fix.stance_marker_mm, 4), "markers_moved": len(fix.moved),
            "hat_points_written": list(fix.added), "points_unchanged": fix.unchanged}
