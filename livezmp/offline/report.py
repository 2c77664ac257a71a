"""Per-frame tables and summaries of an analysis (a :class:`~livezmp.offline.batch.BatchResult`), input world frame."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from livezmp.balance.support import SUPPORT_LABELS
from livezmp.checks import first_out_of_range, non_finite_field
from livezmp.errors import InputError
from livezmp.model.body import BodyModel
from livezmp.offline.batch import BatchResult
from livezmp.offline.plausibility import plausibility
from livezmp.offline.validated import VALIDATED_P95_MM

ZMP_COLUMNS = ("frame", "time", "zmp_x", "zmp_y", "zmp_z", "com_x", "com_y", "com_z", "support", "inside",
               "clamped_x", "clamped_y", "clamped_z", "margin")
CSV_ROWS = 20_000  # rows formatted per write: bounds the memory of the formatting


def _row_template(has_zmp: bool, judged: bool, label: str) -> str:
    """printf template of one zmp.csv row; flight frames (and frames without support) leave the
    ZMP / clamp cells empty."""
    return ("%d,%.6f," + ("%.6f,%.6f,%.6f," if has_zmp else ",,,") + f"%.6f,%.6f,%.6f,{label},"
            + ("%d,%.6f,%.6f,%.6f,%.6f" if judged else ",,,,") + "\r\n")


# templates indexed by 8 * has_zmp + 4 * judged + support code
_TEMPLATES = np.array([_row_template(z, j, label) for z in (False, True) for j in (False, True)
                       for label in SUPPORT_LABELS])


def write_zmp_csv(body: BodyModel, result: BatchResult, path: str | Path,
                  extra: dict[str, np.ndarray] | None = None) -> None:
    """One row per frame; positions in metres in the input's world frame; flight frames
    (and frames without support) leave the ZMP/clamp cells empty. ``extra`` columns (name ->
    (N,) values) follow, ``%.6f``, empty where not finite.

    Rows are formatted many at a time, each through a printf template chosen by which of
    its cells are filled (the same text as Python's ``%.6f``), CRLF line ends as ``csv``."""
    count = len(result)
    values = np.column_stack([result.index, result.t, body.to_input_frame(result.zmp),
                              body.to_input_frame(result.com), result.inside, body.to_input_frame(result.clamped),
                              result.margin])
    filled = np.ones(values.shape, dtype=bool)
    filled[:, 2:5] = result.has_zmp[:, None]
    filled[:, 8:13] = result.judged[:, None]
    kind = 8 * result.has_zmp + 4 * result.judged + result.support
    extra = extra or {}
    bad = first_out_of_range(np.where(filled, values, 0.0), np.inf)
    if bad is not None:
        raise InputError(f"{path}: frame {bad[0]} column {ZMP_COLUMNS[bad[1]]} is not finite; "
                         "the input drives the analysis out of range, not written")
    with open(path, "w", newline="", encoding="utf-8") as f:
        f.write(",".join((*ZMP_COLUMNS, *extra)) + "\r\n")
        for lo in range(0, count, CSV_ROWS):
            rows = slice(lo, lo + CSV_ROWS)
            text = "".join(_TEMPLATES[kind[rows]].tolist()) % tuple(values[rows][filled[rows]].tolist())
            if extra:
                cells = [["" if not np.isfinite(v) else f"{v:.6f}" for v in col[rows]] for col in extra.values()]
                text = "".join(line + "," + ",".join(c) + "\r\n"
                               for line, c in zip(text.split("\r\n")[:-1], zip(*cells, strict=True), strict=True))
            f.write(text)


def ground_plane(body: BodyModel) -> str:
    axes = "xyz".replace(body.up_axis, "")
    return f"{axes[0]}{axes[1]} ({body.up_axis} = ground height)"


def summarize(body: BodyModel, result: BatchResult, fps: float, mode: str,
              tolerance_mm: float = VALIDATED_P95_MM) -> dict:
    """The summary figures of an analysis (see README for each field). ``inside_fraction_tol``: the
    judged frames whose ZMP is inside the support polygon or less than ``tolerance_mm`` outside it."""
    n = len(result)
    inside_tol = int(np.sum(result.judged & (result.margin >= -tolerance_mm / 1000)))
    none = SUPPORT_LABELS.index("none")
    judged = int(result.judged.sum())
    inside = int(result.inside[result.judged].sum())
    out = result.judged & ~result.inside
    excursion = float(np.max(-result.margin[out])) if out.any() else 0.0
    counts = np.bincount(result.support, minlength=len(SUPPORT_LABELS))
    return {
        "frames": n,
        "fps": round(fps, 6),
        "duration_s": round(float(result.t[-1] - result.t[0]), 6) if n else 0.0,
        "up_axis": body.up_axis,
        "ground_plane": ground_plane(body),
        "units": body.units,
        "output_units": "m",
        "mode": mode,
        "total_mass_kg": round(body.total_mass, 4),
        "support_frames": judged,
        "flight_frames": int(np.sum(~result.has_zmp | (result.support == none))),
        "out_of_support_frames": judged - inside,
        "inside_fraction": round(inside / judged, 6) if judged else None,
        "inside_fraction_tol": round(inside_tol / judged, 6) if judged else None,
        "tolerance_mm": tolerance_mm,
        "tolerance_source": ("ZMP error p95 against force plates, median over the shared gait trials "
                             "(docs/validation.md)" if tolerance_mm == VALIDATED_P95_MM else "--tolerance-mm"),
        "max_excursion_m": round(excursion, 6),
        "support_counts": {label: int(c) for label, c in zip(SUPPORT_LABELS, counts, strict=True)},
        "ground_height_m": round(float(result.ground_z[-1]), 6) if n else None,
        "plausibility": plausibility(result.com, result.zmp, result.has_zmp, 1.0 / fps) if n else None,
    }


@contextlib.contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside ``path``, ending in the same suffix (writers such as ezc3d add
    theirs to a name without it); on success it replaces ``path``, on error it is removed."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".part{path.suffix}", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_json(data: dict, path: str | Path) -> None:
    """Strict JSON (NaN and infinity are not JSON): a non-finite field is refused, naming it; the file
    is written atomically (:func:`atomic_path`)."""
    bad = non_finite_field(data)
    if bad:
        raise InputError(f"{path}: field {bad} is not finite; the input drives the analysis out of range, not written")
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n", encoding="utf-8")
