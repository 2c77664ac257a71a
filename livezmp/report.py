"""Per-frame tables and summaries of analysed frames, in the input's world frame."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from livezmp.body import BodyModel
from livezmp.pipeline import FrameResult

ZMP_COLUMNS = ("frame", "time", "zmp_x", "zmp_y", "zmp_z", "com_x", "com_y", "com_z", "support", "inside",
               "clamped_x", "clamped_y", "clamped_z", "margin")


def _xyz(body: BodyModel, p: np.ndarray | None) -> list[str]:
    return ["", "", ""] if p is None else [f"{v:.6f}" for v in body.to_input_frame(p)]


def write_zmp_csv(body: BodyModel, results: list[FrameResult], path: str | Path) -> None:
    """One row per frame; positions in metres in the input's world frame; flight frames
    (and frames without support) leave the ZMP/clamp cells empty."""
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(ZMP_COLUMNS)
        for r in results:
            inside = "" if r.inside is None else int(r.inside)
            margin = "" if r.margin is None else f"{r.margin:.6f}"
            w.writerow([r.index, f"{r.t:.6f}", *_xyz(body, r.zmp), *_xyz(body, r.com), r.support, inside,
                        *_xyz(body, r.clamped), margin])


def ground_plane(body: BodyModel) -> str:
    axes = "xyz".replace(body.up_axis, "")
    return f"{axes[0]}{axes[1]} ({body.up_axis} = ground height)"


def summarize(body: BodyModel, results: list[FrameResult], fps: float, mode: str) -> dict:
    """The summary figures of an analysis (see README for each field)."""
    n = len(results)
    flight = sum(1 for r in results if r.zmp is None or r.support == "none")
    judged = [r for r in results if r.inside is not None]
    inside = sum(1 for r in judged if r.inside)
    excursion = max((-r.margin for r in judged if not r.inside), default=0.0)
    counts = {k: sum(1 for r in results if r.support == k) for k in ("left", "right", "double", "none")}
    return {
        "frames": n,
        "fps": round(fps, 6),
        "duration_s": round(results[-1].t - results[0].t, 6) if n else 0.0,
        "up_axis": body.up_axis,
        "ground_plane": ground_plane(body),
        "units": body.units,
        "output_units": "m",
        "mode": mode,
        "total_mass_kg": round(body.total_mass, 4),
        "support_frames": len(judged),
        "flight_frames": flight,
        "out_of_support_frames": len(judged) - inside,
        "inside_fraction": round(inside / len(judged), 6) if judged else None,
        "max_excursion_m": round(float(excursion), 6),
        "support_counts": counts,
        "ground_height_m": round(float(results[-1].ground_z), 6) if n else None,
    }


def write_json(data: dict, path: str | Path) -> None:
    Path(path).write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
