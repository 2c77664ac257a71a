"""Write a C3D trial back with some of its points moved (ezc3d): everything else — analog channels,
force platforms, events, parameters, residuals of points not moved — is copied from the source file.

Points that are not positions (the POINT group's ANGLES, FORCES, MOMENTS, POWERS, SCALARS and REACTIONS
lists, which model outputs fill with angles and loads) are named by :func:`non_position_labels`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from livezmp.errors import InputError
from livezmp.model.c3d import LENGTH_UNITS, open_c3d, strip_prefix

NON_POSITION = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")


def non_position_labels(path: str | Path) -> set[str]:
    """Labels (prefix stripped) of the points of ``path`` that hold angles, loads or scalars."""
    point = open_c3d(path)["parameters"]["POINT"]
    return {strip_prefix(v) for k in NON_POSITION if k in point for v in point[k]["value"]}


def write_moved_points(source: str | Path, dest: str | Path, moved: dict[int, np.ndarray],
                       added: dict[str, np.ndarray], first_frame: int) -> None:
    """Copy ``source`` to ``dest`` with points replaced: ``moved`` point index -> (N, 3) positions (m, the
    file's world frame) for frames ``first_frame`` .. ``first_frame + N - 1`` (NaN rows: left as they were);
    ``added``: label -> (N, 3) m, new points (or replacing points of that label), unseen outside those
    frames."""
    c3d = open_c3d(source)
    point = c3d["parameters"]["POINT"]
    scale = 1.0 / LENGTH_UNITS[str(point["UNITS"]["value"][0]).strip().lower()]
    pts = np.array(c3d["data"]["points"], dtype=float)
    residuals = np.array(c3d["data"]["meta_points"]["residuals"], dtype=float)
    masks = c3d["data"]["meta_points"].get("camera_masks")
    labels = list(point["LABELS"]["value"])
    # labels beyond the points (sample01 writes 48 for 26) name none; with points added ezc3d wants one a point
    used = pts.shape[1]
    stripped = [strip_prefix(s) for s in labels[:used]]
    new = [lab for lab in added if lab not in stripped]
    if new:
        pts = np.concatenate([pts, np.zeros((4, len(new), pts.shape[2]))], axis=1)
        pts[3, -len(new):] = 1.0
        residuals = np.concatenate([residuals, -np.ones((1, len(new), pts.shape[2]))], axis=1)
        labels = labels[:used] + new
        stripped += new
        if masks is not None:
            masks = np.concatenate([np.asarray(masks), np.zeros((masks.shape[0], len(new), pts.shape[2]), bool)], 1)
    span = slice(first_frame, first_frame + len(next(iter({**moved, **added}.values()))))
    for i, xyz in [*moved.items(), *((stripped.index(k), v) for k, v in added.items())]:
        ok = np.isfinite(xyz).all(axis=1)
        block = pts[:3, i, span]
        block[:, ok] = xyz[ok].T * scale
        if stripped[i] in added:
            residuals[0, i, span] = np.where(ok, 0.0, -1.0)
    _latin1_text(c3d["parameters"])
    _trim_channels(c3d["parameters"]["ANALOG"], c3d["data"]["analogs"].shape[1])
    c3d["data"]["points"] = pts
    c3d["data"]["meta_points"]["residuals"] = residuals
    if masks is not None:
        c3d["data"]["meta_points"]["camera_masks"] = masks
    point["LABELS"]["value"] = labels
    if new and "DESCRIPTIONS" in point:
        descriptions = list(point["DESCRIPTIONS"]["value"])[:used]
        descriptions += [""] * (used - len(descriptions)) + ["livezmp HAT axis"] * len(new)
        point["DESCRIPTIONS"]["value"] = descriptions
    try:
        c3d.write(str(dest))
    except (ValueError, RuntimeError, NotImplementedError) as e:  # ezc3d's messages are one line
        raise InputError(f"{source}: its parameters cannot be written back by ezc3d ({e})") from None


def _trim_channels(analog: dict, channels: int) -> None:
    """ANALOG's per-channel parameters cut to the ``channels`` the data hold, in place: some files write more
    (sample01: 32 labels, scales and offsets for 16 channels) and ezc3d writes only as many as there are."""
    for name in ("LABELS", "DESCRIPTIONS", "UNITS", "SCALE", "OFFSET"):
        if name in analog and len(analog[name]["value"]) > channels:
            value = analog[name]["value"]
            analog[name]["value"] = list(value)[:channels] if isinstance(value, list) else np.asarray(value)[:channels]


def _latin1_text(parameters: dict) -> None:
    """ezc3d reads text bytes it cannot decode as surrogate escapes, and cannot write those back: such
    strings are read as Latin-1 instead (C3D text is ASCII; the extended bytes labs write, such as the
    ``²`` of ``mm/s²``, are Latin-1). In place."""
    for group in parameters.values():
        for p in group.values():
            if isinstance(p, dict) and p.get("type") == -1 and isinstance(p.get("value"), list):
                p["value"] = [v.encode("utf-8", "surrogateescape").decode("latin-1") if isinstance(v, str) else v
                              for v in p["value"]]
