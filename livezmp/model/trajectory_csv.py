"""Joint-trajectory CSV files: a robot's motion as one row per frame.

Columns: ``time`` (s), one column per URDF joint name (rad), and optionally the
floating base ``base_x, base_y, base_z`` (m) and ``base_roll, base_pitch, base_yaw``
(rad; world frame z up, ground z = 0, R = Rz(yaw)·Ry(pitch)·Rx(roll), URDF's rpy).
Extra columns are ignored. Without base columns the caller places the base.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from livezmp.checks import MAX_CHANNEL_VALUE, check_frame_period, read_input_text
from livezmp.errors import InputError

BASE_COLUMNS = ("base_x", "base_y", "base_z", "base_roll", "base_pitch", "base_yaw")


@dataclass
class JointTrajectory:
    """``t`` (F,) s; ``q`` (F, n) rad in ``joint_names`` order; ``base`` (F, 6) or None."""

    t: np.ndarray
    q: np.ndarray
    joint_names: list[str]
    base: np.ndarray | None = None
    source: str = "<memory>"


def read_csv_rows(path: Path, what: str = "file") -> list[list[str]]:
    """All rows of a CSV file; a one-line InputError if it cannot be read or is empty."""
    text = read_input_text(path, what)
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as e:
        raise InputError(f"{path}: bad CSV: {e}") from None
    if not rows:
        raise InputError(f"{path}:1: empty {what}")
    return rows


def read_joint_csv(path: str | Path, joint_names: list[str]) -> JointTrajectory:
    """Read a joint-trajectory CSV; every name in ``joint_names`` must be a column."""
    p = Path(path)
    rows = read_csv_rows(p)
    header = [h.strip() for h in rows[0]]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise InputError(f"{p}:1: column {dup[0]!r} appears more than once")
    col = {h: i for i, h in enumerate(header)}
    if "time" not in col:
        raise InputError(f"{p}:1: no 'time' column")
    missing = [n for n in joint_names if n not in col]
    if missing:
        raise InputError(f"{p}:1: missing joint column(s): {', '.join(missing)}")
    has_base = [b in col for b in BASE_COLUMNS]
    if any(has_base) and not all(has_base):
        absent = [b for b, h in zip(BASE_COLUMNS, has_base, strict=True) if not h]
        raise InputError(f"{p}:1: incomplete floating base, missing {', '.join(absent)}")
    body = [(k + 2, r) for k, r in enumerate(rows[1:]) if any(c.strip() for c in r)]
    if not body:
        raise InputError(f"{p}:2: zero frames")
    names = ["time", *joint_names, *(BASE_COLUMNS if all(has_base) else ())]
    idx = [col[n] for n in names]
    data = np.empty((len(body), len(idx)))
    for k, (line, r) in enumerate(body):
        if len(r) != len(header):  # a missing or extra field (a decimal comma) would shift the columns
            raise InputError(f"{p}:{line}: {len(r)} fields, header has {len(header)}")
        for c, (n, i) in enumerate(zip(names, idx, strict=True)):
            try:
                data[k, c] = float(r[i])
            except ValueError:
                raise InputError(f"{p}:{line}: field {n}: not a number: {r[i]!r}") from None
            if not abs(data[k, c]) <= MAX_CHANNEL_VALUE:
                raise InputError(f"{p}:{line}: field {n}: {r[i].strip()} is not finite or "
                                 f"beyond ±{MAX_CHANNEL_VALUE:g}")
    t = data[:, 0]
    bad = np.nonzero(np.diff(t) <= 0)[0]
    if bad.size:
        raise InputError(f"{p}:{body[bad[0] + 1][0]}: field time: not increasing")
    if len(t) > 1:
        check_frame_period(float(np.median(np.diff(t))), f"{p}: field time")
    n = len(joint_names)
    base = data[:, 1 + n :] if all(has_base) else None
    return JointTrajectory(t, data[:, 1 : 1 + n], list(joint_names), base, str(p))


def write_joint_csv(traj: JointTrajectory, path: str | Path) -> None:
    """Write ``traj`` in the format :func:`read_joint_csv` reads."""
    cols = ["time", *traj.joint_names, *(BASE_COLUMNS if traj.base is not None else ())]
    parts = [traj.t[:, None], traj.q] + ([traj.base] if traj.base is not None else [])
    np.savetxt(path, np.hstack(parts), delimiter=",", header=",".join(cols), comments="", fmt="%.9g")
