"""One take's analysis, as a plain function: what ``livezmp analyze`` does for one file and
``livezmp batch analyze`` does for each take of a library (in a Dask worker or in a loop).

Outputs are written atomically (a temporary file beside the target, then :func:`os.replace`),
so a run killed at any point leaves either the old file or the complete new one.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from livezmp.balance.pipeline import Pipeline, PipelineConfig, default_config
from livezmp.errors import InputError
from livezmp.model.bvh_body import DEFAULT_MASS, BvhBodyOptions
from livezmp.model.motion_file import LoadedMotion, load_motion
from livezmp.model.segments import load_mapping
from livezmp.model.urdf_body import UrdfBodyOptions
from livezmp.offline.batch import BatchResult, run_batch
from livezmp.offline.report import atomic_path, summarize, write_json, write_zmp_csv
from livezmp.offline.validated import VALIDATED_P95_MM

ZMP_CSV = "zmp.csv"
SUMMARY_JSON = "summary.json"


@dataclass(frozen=True)
class TakeOptions:
    """How a take is loaded and analysed (the body options of ``livezmp analyze``):
    ``mass`` kg (None: the file's subject mass for a C3D, else 70 kg), ``sole_width`` m, ``ground`` m in
    the input frame, ``mode`` "full" or "seed", ``tolerance_mm`` of ``inside_fraction_tol``."""

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

    def load(self, path: str | Path) -> LoadedMotion:
        mapping = load_mapping(self.mapping) if self.mapping else None
        bvh = BvhBodyOptions(total_mass=self.mass or DEFAULT_MASS, units=self.units, up_axis=self.up, mapping=mapping,
                             sole_width=self.sole_width)
        return load_motion(path, self.robot, bvh, UrdfBodyOptions(config=self.robot_config),
                           c3d_mass=self.mass)

    def fingerprint(self) -> str:
        """A short hash of the options: outputs made with other options are out of date."""
        return hashlib.sha256(json.dumps(asdict(self), sort_keys=True).encode()).hexdigest()[:16]


def take_config(loaded: LoadedMotion, mode: str, ground: float | None) -> PipelineConfig:
    """:func:`default_config` for the take, with ``ground`` (m, in the input frame) if given."""
    ground_z = None
    if ground is not None:
        p = np.zeros(3)
        p["xyz".index(loaded.body.up_axis)] = ground
        ground_z = float((loaded.body.world_from_input @ p)[2])
    return default_config(loaded.body, loaded.fps, mode, ground_z)


def analyse_loaded(loaded: LoadedMotion, mode: str = "full", ground: float | None = None,
                   progress: Callable[[int], None] | None = None) -> BatchResult:
    """The pipeline over a loaded take: its per-frame results."""
    if len(loaded.frames) < 2:
        raise InputError(f"{loaded.source}: need at least 2 frames, got {len(loaded.frames)}")
    cfg = take_config(loaded, mode, ground)
    pipe = Pipeline(loaded.body, cfg, nominal_dt=1.0 / loaded.fps)
    return run_batch(pipe, loaded.times, loaded.frames, progress=progress)


def analyse_take(path: str | Path, out_dir: str | Path, options: TakeOptions) -> dict:
    """Analyse the take at ``path``; write ``zmp.csv`` then ``summary.json`` (the summary with the
    options' fingerprint) into ``out_dir``, each atomically; return the summary."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    loaded = options.load(path)
    results = analyse_loaded(loaded, options.mode, options.ground)
    summary = {"source": loaded.source,
               **summarize(loaded.body, results, loaded.fps, options.mode, options.tolerance_mm)}
    with atomic_path(out_dir / ZMP_CSV) as tmp:
        write_zmp_csv(loaded.body, results, tmp)
    summary["options"] = options.fingerprint()
    write_json(summary, out_dir / SUMMARY_JSON)
    return summary
