"""Joint-trajectory CSV files: a robot's motion as one row per frame.

Columns: ``time`` (s), one column per URDF joint name (rad), and optionally the
floating base ``base_x, base_y, base_z`` (m) and ``base_roll, base_pitch, base_yaw``
(rad; world frame z up, ground z = 0, R = Rz(yaw)·Ry(pitch)·Rx(roll), URDF's rpy).
Extra columns are ignored. Without base columns the caller places the base.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from livezmp.checks import (
    FRAME_PERIOD_RANGE,
    MAX_CHANNEL_VALUE,
    check_frame_period,
    check_input_file,
    read_input_pieces,
    read_input_text,
)
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


JOINT_CSV_BLOCK_ROWS = 4096  # rows converted to numbers at a time
JOINT_CSV_TEXT_BYTES = 1 << 20  # bytes of the file read and split into lines at a time


def read_joint_csv(path: str | Path, joint_names: list[str]) -> JointTrajectory:
    """Read a joint-trajectory CSV; every name in ``joint_names`` must be a column."""
    p = check_input_file(path, "file")
    times = TimeColumnCheck(str(p))
    parts = []
    for lines, data in _frame_blocks(p, joint_names, JOINT_CSV_BLOCK_ROWS):
        times.add(lines, data[:, 0])
        parts.append(data)
    data = np.concatenate(parts)
    times.finish(lambda: float(np.median(np.diff(data[:, 0]))))
    return _trajectory(data, joint_names, str(p))


@dataclass
class JointCsvScan:
    """A joint CSV checked from end to end (:func:`scan_joint_csv`): ``count`` frames from
    ``first_t`` to ``last_t`` s."""

    count: int
    first_t: float
    last_t: float

    @property
    def fps(self) -> float:
        """Frames per second as :attr:`livezmp.model.motion_file.LoadedMotion.fps` computes it."""
        return (self.count - 1) / (self.last_t - self.first_t) if self.count > 1 else 0.0


def scan_joint_csv(path: str | Path, joint_names: list[str]) -> JointCsvScan:
    """Check a joint CSV as :func:`read_joint_csv` does, with the same messages, in bounded memory
    (a block of rows at a time, the time column checked by :class:`TimeColumnCheck`)."""
    p = check_input_file(path, "file")
    times = TimeColumnCheck(str(p))
    count, first = 0, None
    for lines, data in _frame_blocks(p, joint_names, JOINT_CSV_BLOCK_ROWS):
        times.add(lines, data[:, 0])
        first = float(data[0, 0]) if first is None else first
        count += len(data)
    times.finish(lambda: float(np.median(np.diff(np.concatenate(
        [d[:, 0] for _, d in _frame_blocks(p, joint_names, JOINT_CSV_BLOCK_ROWS)])))))  # an error's figure only
    return JointCsvScan(count, first, float(times.last))


def joint_csv_blocks(path: str | Path, joint_names: list[str], rows: int) -> Iterator[JointTrajectory]:
    """A joint CSV ``rows`` frames at a time (the last block shorter), read lazily; the rows are
    checked as :func:`read_joint_csv` checks them but the time column is not: scan it first
    (:func:`scan_joint_csv`)."""
    p = check_input_file(path, "file")
    for _, data in _frame_blocks(p, joint_names, rows):
        yield _trajectory(data, joint_names, str(p))


def _trajectory(data: np.ndarray, joint_names: list[str], source: str) -> JointTrajectory:
    n = len(joint_names)
    base = data[:, 1 + n:] if data.shape[1] > 1 + n else None
    return JointTrajectory(data[:, 0], data[:, 1:1 + n], list(joint_names), base, source)


def _records(p: Path) -> Iterator[list[str]]:
    """The CSV records of the file, read lazily (the lines as ``io.StringIO(text, newline="")`` splits them)."""
    lines = (line for piece in read_input_pieces(p, JOINT_CSV_TEXT_BYTES) for line in io.StringIO(piece, newline=""))
    try:
        yield from csv.reader(lines)
    except csv.Error as e:
        raise InputError(f"{p}: bad CSV: {e}") from None


def _columns(p: Path, header: list[str], joint_names: list[str]) -> list[tuple[str, int]]:
    """The columns read, (name, position): ``time``, the joints, the floating base if present."""
    header = [h.strip() for h in header]
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
    names = ["time", *joint_names, *(BASE_COLUMNS if all(has_base) else ())]
    return [(n, col[n]) for n in names]


def _frame_blocks(p: Path, joint_names: list[str], rows: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """(line numbers (k,), values (k, m) in :func:`_columns` order) of the file's frames, ``rows`` at
    a time; blank rows are skipped (their lines counted); each row's fields are checked in order."""
    records = _records(p)
    header = next(records, None)
    if header is None:
        raise InputError(f"{p}:1: empty file")
    columns = _columns(p, header, joint_names)
    index = [i for _, i in columns]
    width = len(header)
    lines, data = [], []
    any_frames = False
    for line, r in enumerate(records, start=2):
        if not any(c.strip() for c in r):
            continue
        if len(r) != width:  # a missing or extra field (a decimal comma) would shift the columns
            raise InputError(f"{p}:{line}: {len(r)} fields, header has {width}")
        try:
            values = [float(r[i]) for i in index]
        except ValueError:
            values = None
        if values is None or not all(abs(v) <= MAX_CHANNEL_VALUE for v in values):
            _raise_bad_field(p, line, r, columns)
        lines.append(line)
        data.append(values)
        if len(data) == rows:
            yield np.array(lines), np.array(data)
            lines, data, any_frames = [], [], True
    if data:
        yield np.array(lines), np.array(data)
    elif not any_frames:
        raise InputError(f"{p}:2: zero frames")


def _raise_bad_field(p: Path, line: int, r: list[str], columns: list[tuple[str, int]]) -> None:
    """The first bad field of a row, in column order: not a number, or not finite / too large."""
    for n, i in columns:
        try:
            v = float(r[i])
        except ValueError:
            raise InputError(f"{p}:{line}: field {n}: not a number: {r[i]!r}") from None
        if not abs(v) <= MAX_CHANNEL_VALUE:
            raise InputError(f"{p}:{line}: field {n}: {r[i].strip()} is not finite or beyond ±{MAX_CHANNEL_VALUE:g}")


class TimeColumnCheck:
    """A time column's checks, given a block of rows at a time in bounded memory: it increases (else
    the first line where it does not), and the median frame period is one the estimator follows
    (:func:`check_frame_period`), decided exactly as ``np.median`` of all the differences would be,
    from counts and four extremes."""

    def __init__(self, source: str):
        self.source = source
        self.last: float | None = None  # the last time seen, s
        self.bad_line: int | None = None
        self.n = self.below = self.above = 0  # differences; of them below and above the period range
        self.top_below, self.least_in = -np.inf, np.inf  # the largest below lo, the smallest at or above lo
        self.least_above, self.top_in = np.inf, -np.inf  # the smallest above hi, the largest at or below hi

    def add(self, lines: np.ndarray, t: np.ndarray) -> None:
        """The next rows: their ``lines`` (k,) and times ``t`` (k,) s."""
        if self.last is None:
            d, at = np.diff(t), lines[1:]
        else:
            d, at = np.diff(t, prepend=self.last), lines
        self.last = float(t[-1])
        if self.bad_line is not None:
            return
        bad = np.nonzero(d <= 0)[0]
        if bad.size:
            self.bad_line = int(at[bad[0]])
            return
        lo, hi = FRAME_PERIOD_RANGE
        self.n += len(d)
        low, high = d < lo, d > hi
        self.below += int(low.sum())
        self.above += int(high.sum())
        self.top_below = max(self.top_below, float(d[low].max(initial=-np.inf)))
        self.least_in = min(self.least_in, float(d[~low].min(initial=np.inf)))
        self.least_above = min(self.least_above, float(d[high].min(initial=np.inf)))
        self.top_in = max(self.top_in, float(d[~high].max(initial=-np.inf)))

    def median_in_range(self) -> bool:
        """Whether ``lo <= np.median(differences) <= hi``: the median is the middle difference, or the
        mean of the two middle ones, whose side of a bound the counts tell but where the bound
        falls between the two, and then they are the extremes on either side of it."""
        lo, hi = FRAME_PERIOD_RANGE
        m = self.n // 2
        if self.n % 2:
            return self.below <= m and self.above <= m
        low = self.below > m or (self.below == m and (self.top_below + self.least_in) / 2 < lo)
        high = self.above > m or (self.above == m and (self.top_in + self.least_above) / 2 > hi)
        return not (low or high)

    def finish(self, median: Callable[[], float]) -> None:
        """Raise the time column's error, if any (``median()``: all differences' median, for the message)."""
        if self.bad_line is not None:
            raise InputError(f"{self.source}:{self.bad_line}: field time: not increasing")
        if self.n and not self.median_in_range():
            check_frame_period(median(), f"{self.source}: field time")


def write_joint_csv(traj: JointTrajectory, path: str | Path) -> None:
    """Write ``traj`` in the format :func:`read_joint_csv` reads."""
    cols = ["time", *traj.joint_names, *(BASE_COLUMNS if traj.base is not None else ())]
    parts = [traj.t[:, None], traj.q] + ([traj.base] if traj.base is not None else [])
    np.savetxt(path, np.hstack(parts), delimiter=",", header=",".join(cols), comments="", fmt="%.9g")
