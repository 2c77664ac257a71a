"""Labelled sets of takes: each walk file with its subject (if known) and condition.

Either a manifest CSV with the header ``path,subject,condition`` (paths relative to the
manifest; ``subject`` may be empty when unknown), or file names matched by a regular
expression with a named group ``condition`` and optionally ``subject``. The default
pattern reads ``walk_normal_001.bvh`` as condition "normal", subject unknown.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from livezmp.errors import InputError
from livezmp.model.trajectory_csv import read_csv_rows

DEFAULT_PATTERN = r"(?:^|[_-])(?P<condition>[A-Za-z]+)[_-](?P<take>\d+)\.(?:bvh|c3d|csv)$"
WALK_SUFFIXES = (".bvh", ".c3d", ".csv")


@dataclass(frozen=True)
class TakeSpec:
    """One walk file: ``subject`` None when not known."""

    path: Path
    subject: str | None
    condition: str


def read_manifest(path: str | Path) -> list[TakeSpec]:
    """Read a manifest CSV (see module doc)."""
    p = Path(path)
    rows = read_csv_rows(p, "manifest")
    header = [h.strip().lower() for h in rows[0]]
    missing = [c for c in ("path", "subject", "condition") if c not in header]
    if missing:
        raise InputError(f"{p}:1: manifest needs columns path,subject,condition; missing {', '.join(missing)}")
    col = {h: i for i, h in enumerate(header)}
    out = []
    for line, row in enumerate(rows[1:], start=2):
        if not any(c.strip() for c in row):
            continue
        if len(row) < len(header):
            raise InputError(f"{p}:{line}: {len(row)} fields, header has {len(header)}")
        take, subject, cond = (row[col[c]].strip() for c in ("path", "subject", "condition"))
        if not take or not cond:
            raise InputError(f"{p}:{line}: empty {'path' if not take else 'condition'}")
        out.append(TakeSpec(p.parent / take, subject or None, cond))
    if not out:
        raise InputError(f"{p}:2: manifest lists no takes")
    return out


def takes_from_paths(paths: list[str | Path], pattern: str = DEFAULT_PATTERN) -> list[TakeSpec]:
    """Label files (directories: their .bvh, .c3d and .csv files) by ``pattern`` on the file name."""
    try:
        rx = re.compile(pattern)
    except re.error as e:
        raise InputError(f"--pattern: bad regular expression: {e}") from None
    if "condition" not in rx.groupindex:
        raise InputError("--pattern: needs a named group (?P<condition>...)")
    files: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            files += sorted(f for f in p.iterdir() if f.suffix.lower() in WALK_SUFFIXES)
        elif p.exists():
            files.append(p)
        else:
            raise InputError(f"{p}: no such file or directory")
    out = []
    for f in files:
        m = rx.search(f.name)
        if m is None:
            raise InputError(f"{f}: file name does not match the pattern {pattern!r} (give --pattern or --manifest)")
        subject = m.groupdict().get("subject")
        out.append(TakeSpec(f, subject or None, m.group("condition")))
    if not out:
        raise InputError(f"{', '.join(map(str, paths))}: no .bvh, .c3d or .csv walks found")
    return out
