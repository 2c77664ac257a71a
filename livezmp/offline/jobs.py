"""What a library run does with each take: ``livezmp batch analyze``, ``correct`` and ``gait``.

A job is a small frozen dataclass of options (sent to every Dask worker) with
:meth:`Job.run`, the per-take function (the same one ``livezmp analyze`` / ``correct`` run
for one file, or a plain loop would call), which writes the take's outputs under its own
directory and returns the take's summary; and :meth:`Job.fields`, the job's columns of the
library table from that summary. :mod:`livezmp.offline.library` runs any job over a library.
"""

from __future__ import annotations

import hashlib
import json
from abc import ABC, abstractmethod
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import ClassVar

from livezmp.correct.limits import CorrectionLimits
from livezmp.gait.features import walk_features
from livezmp.gait.take import load_take
from livezmp.jsonfile import write_json
from livezmp.offline.take import ZMP_CSV, ZMP_PNG, TakeOptions, analyse_take, correct_c3d_take, correct_loaded

# (name, Arrow type) of the columns every table starts with; "error" ends every table
COMMON_COLUMNS = (("file", "string"), ("format", "string"), ("frames", "int64"), ("fps", "float64"),
                  ("duration_s", "float64"))
ERROR_COLUMN = ("error", "string")
FEATURES_JSON = "features.json"


class Job(ABC):
    """One kind of per-take work; subclasses are frozen dataclasses of their options."""

    name: ClassVar[str]
    columns: ClassVar[tuple[tuple[str, str], ...]]  # the job's own columns, after COMMON_COLUMNS

    @abstractmethod
    def suffixes(self) -> set[str]:
        """The file suffixes (lower case, with the dot) this job takes from a library."""

    @abstractmethod
    def run(self, path: Path, out_dir: Path) -> dict:
        """Do the work for the take at ``path``, writing :meth:`outputs` atomically into ``out_dir``
        (which exists); return the summary (frames, fps, duration_s and what :meth:`fields` reads)."""

    @abstractmethod
    def outputs(self, path: Path) -> tuple[str, ...]:
        """The files a finished take at ``path`` has beside its ``summary.json``."""

    @abstractmethod
    def fields(self, summary: dict) -> dict:
        """The job's columns of a successful take's row, from its summary."""

    def fingerprint(self) -> str:
        """A short hash of the job and its options: outputs made otherwise are out of date."""
        data = json.dumps({"job": self.name, **asdict(self)}, sort_keys=True, default=str)
        return hashlib.sha256(data.encode()).hexdigest()[:16]

    def table_columns(self) -> tuple[tuple[str, str], ...]:
        return (*COMMON_COLUMNS, *self.columns, ERROR_COLUMN)


def _cop_fields(summary: dict) -> dict:
    """The ZMP against the force-plate CoP over complete frames (None without plates)."""
    cv = summary.get("cop_vs_zmp") or {}
    bias = cv.get("bias_mm") or [None, None]
    return {"cop_frames": cv.get("frames"), "cop_rms_mm": cv.get("rms_mm"), "cop_p95_mm": cv.get("p95_mm"),
            "cop_bias_fore_aft_mm": bias[0], "cop_bias_lateral_mm": bias[1], "cop_lag_ms": cv.get("lag_ms")}


@dataclass(frozen=True)
class AnalyzeJob(Job):
    """``livezmp analyze`` of each take: ``zmp.csv`` (and ``zmp.png`` with ``plot``) and the summary."""

    options: TakeOptions = field(default_factory=TakeOptions)
    plot: bool = False

    name: ClassVar[str] = "analyze"
    columns: ClassVar = (("inside_fraction", "float64"), ("inside_fraction_tol", "float64"),
                         ("tolerance_mm", "float64"), ("max_excursion_mm", "float64"), ("plausible", "bool"),
                         ("plausibility", "string"), ("cop_frames", "int64"), ("cop_rms_mm", "float64"),
                         ("cop_p95_mm", "float64"), ("cop_bias_fore_aft_mm", "float64"),
                         ("cop_bias_lateral_mm", "float64"), ("cop_lag_ms", "float64"))

    def suffixes(self) -> set[str]:
        return {".bvh", ".c3d"} | ({".csv"} if self.options.robot else set())

    def outputs(self, path: Path) -> tuple[str, ...]:
        return (ZMP_CSV, ZMP_PNG) if self.plot else (ZMP_CSV,)

    def run(self, path: Path, out_dir: Path) -> dict:
        return analyse_take(path, out_dir, self.options, self.plot)

    def fields(self, summary: dict) -> dict:
        verdict = (summary.get("plausibility") or {}).get("verdict")
        return {"inside_fraction": summary["inside_fraction"], "inside_fraction_tol": summary["inside_fraction_tol"],
                "tolerance_mm": summary["tolerance_mm"],
                "max_excursion_mm": round(1000 * summary["max_excursion_m"], 3),
                "plausible": None if verdict is None else verdict.startswith("plausible"),
                "plausibility": verdict, **_cop_fields(summary)}


@dataclass(frozen=True)
class CorrectJob(Job):
    """``livezmp correct`` of each take: the corrected motion, in the take's own format (BVH, C3D with
    its markers moved, or joint CSV with a robot), and the correction report as the summary."""

    options: TakeOptions = field(default_factory=TakeOptions)
    limits: CorrectionLimits = field(default_factory=CorrectionLimits)

    name: ClassVar[str] = "correct"
    columns: ClassVar = (("support_frames", "int64"), ("out_of_support_before", "int64"),
                         ("out_of_support_after", "int64"), ("inside_fraction_before", "float64"),
                         ("inside_fraction_after", "float64"), ("max_root_rotation_deg", "float64"),
                         ("rms_root_rotation_deg", "float64"), ("max_foot_displacement_mm", "float64"),
                         ("infeasible_frames", "int64"), ("output", "string"))

    def suffixes(self) -> set[str]:
        return {".bvh", ".c3d"} | ({".csv"} if self.options.robot else set())

    def outputs(self, path: Path) -> tuple[str, ...]:
        return (f"corrected{path.suffix.lower()}",)

    def run(self, path: Path, out_dir: Path) -> dict:
        if path.suffix.lower() == ".c3d":  # the markers moved with their segments, written as C3D
            return correct_c3d_take(path, out_dir / self.outputs(path)[0], self.options, self.limits)
        return correct_loaded(self.options.load(path), out_dir / self.outputs(path)[0], self.options, self.limits)

    def fields(self, summary: dict) -> dict:
        keys = [name for name, _ in self.columns]
        row = {k: summary.get(k) for k in keys}
        row["infeasible_frames"] = len(summary["infeasible_frames"])
        return row


@dataclass(frozen=True)
class GaitJob(Job):
    """The per-take half of ``livezmp gait analyze``: each walk's features (paper 003: frequency,
    stride, speed, per-channel DC and amplitude over whole cycles) in ``features.json``; the
    population statistics are computed from them once every take is done."""

    up: str | None = None  # None: detected
    units: str | None = None
    urdf: str | None = None
    markers: str | None = None  # a marker map file, for C3D walks
    static: str | None = None  # a cluster set's static trial, for C3D walks

    name: ClassVar[str] = "gait"
    columns: ClassVar = (("cycles", "int64"), ("frequency_hz", "float64"), ("stride_length_m", "float64"),
                         ("speed_mps", "float64"))

    def suffixes(self) -> set[str]:
        return {".bvh", ".c3d"} | ({".csv"} if self.urdf else set())

    def outputs(self, path: Path) -> tuple[str, ...]:
        return (FEATURES_JSON,)

    def run(self, path: Path, out_dir: Path) -> dict:
        take = load_take(path, self.up, self.units, self.urdf, self.markers, self.static)
        feats = walk_features(take)
        write_json(feats.to_json(), out_dir / FEATURES_JSON)
        t = take.t
        fps = (len(t) - 1) / float(t[-1] - t[0])
        return {"source": take.source, "frames": len(t), "fps": round(fps, 6),
                "duration_s": round(float(t[-1] - t[0]), 6), "cycles": feats.cycles.n_cycles,
                "frequency_hz": round(feats.frequency, 6), "stride_length_m": round(feats.stride_length, 6),
                "speed_mps": round(feats.speed, 6)}

    def fields(self, summary: dict) -> dict:
        return {name: summary[name] for name, _ in self.columns}
