"""Per-frame tables and summaries of an analysis (a :class:`~livezmp.offline.batch.BatchResult`), input world frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from livezmp.balance.support import SUPPORT_LABELS
from livezmp.checks import first_out_of_range
from livezmp.errors import InputError
from livezmp.model.body import BodyModel
from livezmp.offline.batch import BatchResult
from livezmp.offline.plausibility import PlausibilityStats
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
    (N,) values) follow, ``%.6f``, empty where not finite (see :class:`ZmpCsvWriter`)."""
    writer = ZmpCsvWriter(body, path, tuple(extra or ()))
    checked = writer.rows(result)  # before the file is opened: a refused result leaves no file
    writer.start()
    try:
        writer.write(checked, extra)
    finally:
        writer.close()


class ZmpCsvWriter:
    """zmp.csv written chunk by chunk (:func:`write_zmp_csv` for each chunk's rows in turn): memory is
    one chunk's text. Rows are formatted many at a time, each through a printf template chosen by
    which of its cells are filled (the same text as Python's ``%.6f``), CRLF line ends as ``csv``."""

    def __init__(self, body: BodyModel, path: str | Path, extra: tuple[str, ...] = ()):
        self.body, self.path, self.extra = body, path, extra
        self.file = None

    def start(self) -> None:
        """(Re)start the file: the header line, no rows."""
        self.close()
        self.file = open(self.path, "w", newline="", encoding="utf-8")  # noqa: SIM115 (closed by close)
        self.file.write(",".join((*ZMP_COLUMNS, *self.extra)) + "\r\n")

    def add(self, result: BatchResult, extra: dict[str, np.ndarray] | None = None) -> None:
        """The rows of ``result`` (consecutive frames); ``extra`` its extra columns' values."""
        self.write(self.rows(result), extra)

    def rows(self, result: BatchResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The cells of ``result``'s rows (values, which are filled, each row's template), checked:
        InputError naming the frame and column of a non-finite filled cell."""
        body = self.body
        values = np.column_stack([result.index, result.t, body.to_input_frame(result.zmp),
                                  body.to_input_frame(result.com), result.inside,
                                  body.to_input_frame(result.clamped), result.margin])
        filled = np.ones(values.shape, dtype=bool)
        filled[:, 2:5] = result.has_zmp[:, None]
        filled[:, 8:13] = result.judged[:, None]
        kind = 8 * result.has_zmp + 4 * result.judged + result.support
        bad = first_out_of_range(np.where(filled, values, 0.0), np.inf)
        if bad is not None:
            raise InputError(f"{self.path}: frame {result.index[bad[0]]} column {ZMP_COLUMNS[bad[1]]} is not finite; "
                             "the input drives the analysis out of range, not written")
        return values, filled, kind

    def write(self, checked: tuple[np.ndarray, np.ndarray, np.ndarray], extra: dict[str, np.ndarray] | None) -> None:
        """The rows :meth:`rows` checked, with their ``extra`` columns' values."""
        values, filled, kind = checked
        for lo in range(0, len(values), CSV_ROWS):
            rows = slice(lo, lo + CSV_ROWS)
            text = "".join(_TEMPLATES[kind[rows]].tolist()) % tuple(values[rows][filled[rows]].tolist())
            if extra:
                cells = [["" if not np.isfinite(v) else f"{v:.6f}" for v in col[rows]] for col in extra.values()]
                text = "".join(line + "," + ",".join(c) + "\r\n"
                               for line, c in zip(text.split("\r\n")[:-1], zip(*cells, strict=True), strict=True))
            self.file.write(text)

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None


def ground_plane(body: BodyModel) -> str:
    axes = "xyz".replace(body.up_axis, "")
    return f"{axes[0]}{axes[1]} ({body.up_axis} = ground height)"


def summarize(body: BodyModel, result: BatchResult, fps: float, mode: str,
              tolerance_mm: float = VALIDATED_P95_MM, belt: np.ndarray | None = None) -> dict:
    """The summary figures of an analysis (see README for each field). ``inside_fraction_tol``: the
    judged frames whose ZMP is inside the support polygon or less than ``tolerance_mm`` outside it. ``belt``
    (2,) m/s: a treadmill's belt velocity (internal frame), the frame the motion's plausibility is judged in."""
    stats = TakeStats(len(result), fps, tolerance_mm, belt)
    stats.add(result)
    return stats.summary(body, mode)


class TakeStats:
    """:func:`summarize` of a take of ``total`` frames at ``fps`` Hz, its results added chunk by chunk
    (consecutive frames, in order) in bounded memory: counts, a maximum, the last ground height, and
    :class:`PlausibilityStats` (exact percentiles). With a treadmill's ``belt`` velocity (2,) m/s (internal frame)
    the plausibility is judged in the belt's frame, where the walk travels: the CoM and the ZMP each moved by
    -belt * t (a belt at constant speed: the same accelerations and ZMP-CoM distances, the walk's own heading)."""

    def __init__(self, total: int, fps: float, tolerance_mm: float = VALIDATED_P95_MM,
                 belt: np.ndarray | None = None):
        self.total, self.fps, self.tolerance_mm = total, fps, tolerance_mm
        self.belt = None if belt is None else np.array([belt[0], belt[1], 0.0])
        self.plausibility: PlausibilityStats | None = None
        self.start()

    def start(self) -> None:
        """(Re)start: no frame added (the plausibility's spill file of a start before is closed)."""
        if self.plausibility is not None:
            self.plausibility.close()
        self.count = self.judged = self.inside = self.inside_tol = self.flight = 0
        self.excursion: float | None = None
        self.support = np.zeros(len(SUPPORT_LABELS), dtype=np.int64)
        self.first_t = self.last_t = self.ground = None
        self.plausibility = PlausibilityStats(self.total, 1.0 / self.fps) if self.total else None

    def add(self, result: BatchResult) -> None:
        if not len(result):
            return
        self.count += len(result)
        self.inside_tol += int(np.sum(result.judged & (result.margin >= -self.tolerance_mm / 1000)))
        self.judged += int(result.judged.sum())
        self.inside += int(result.inside[result.judged].sum())
        flight = ~result.has_zmp | (result.support == SUPPORT_LABELS.index("none"))
        self.flight += int(np.sum(flight))
        out = result.judged & ~result.inside
        if out.any():
            worst = float(np.max(-result.margin[out]))
            self.excursion = worst if self.excursion is None else max(self.excursion, worst)
        self.support += np.bincount(result.support, minlength=len(SUPPORT_LABELS))
        self.first_t = float(result.t[0]) if self.first_t is None else self.first_t
        self.last_t, self.ground = float(result.t[-1]), float(result.ground_z[-1])
        com, zmp = result.com, result.zmp
        if self.belt is not None:
            moved = result.t[:, None] * self.belt
            com, zmp = com - moved, zmp - moved
        self.plausibility.add(com, zmp, result.has_zmp, flight)

    def summary(self, body: BodyModel, mode: str) -> dict:
        n, judged, inside, tolerance_mm = self.count, self.judged, self.inside, self.tolerance_mm
        return {
            "frames": n,
            "fps": round(self.fps, 6),
            "duration_s": round(self.last_t - self.first_t, 6) if n else 0.0,
            "up_axis": body.up_axis,
            "ground_plane": ground_plane(body),
            "units": body.units,
            "output_units": "m",
            "mode": mode,
            "total_mass_kg": round(body.total_mass, 4),
            "placeholder_inertias": list(body.placeholder_inertias),  # links whose file's inertia is a placeholder
            "support_frames": judged,
            "flight_frames": self.flight,
            "out_of_support_frames": judged - inside,
            "inside_fraction": round(inside / judged, 6) if judged else None,
            "inside_fraction_tol": round(self.inside_tol / judged, 6) if judged else None,
            "tolerance_mm": tolerance_mm,
            "tolerance_source": ("ZMP error p95 against force plates, median over the shared gait trials "
                                 "(docs/validation.md)" if tolerance_mm == VALIDATED_P95_MM else "--tolerance-mm"),
            "max_excursion_m": round(self.excursion or 0.0, 6),
            "support_counts": {label: int(c) for label, c in zip(SUPPORT_LABELS, self.support, strict=True)},
            "ground_height_m": round(self.ground, 6) if n else None,
            "plausibility": self._plausibility(),
        }

    def _plausibility(self) -> dict | None:
        """The plausibility verdict of the frames added (None for none); its spill file closed either way."""
        if not self.count:
            if self.plausibility is not None:
                self.plausibility.close()
            return None
        return self.plausibility.result()
