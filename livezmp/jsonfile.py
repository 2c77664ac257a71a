"""Writing a result file atomically, and strict JSON: light enough (the standard library, numpy through
:mod:`livezmp.checks`) for a command to write its summary before its heavy modules are imported
(:mod:`livezmp.commands.startup`: a signal during ``run``'s start-up)."""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

from livezmp.checks import non_finite_field
from livezmp.errors import InputError


@contextlib.contextmanager
def atomic_path(path: str | Path):
    """Yield a temporary path beside ``path``, ending in the same suffix (writers such as ezc3d add
    theirs to a name without it); on success it replaces ``path``, on error it is removed. A ``path`` that
    cannot be made or replaced (an immutable or read-only file system's file, a directory that became
    read-only since the command checked it) is one line naming it, the file as it was before (a traceback
    after the whole analysis before)."""
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=f".part{path.suffix}", dir=path.parent)
    except OSError as e:
        raise InputError(f"{path}: cannot write: {e.strerror or e}") from None
    os.close(fd)
    try:
        yield Path(tmp)
        try:
            os.replace(tmp, path)
        except OSError as e:
            raise InputError(f"{path}: cannot write: {e.strerror or e}") from None
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_json(data: dict, path: str | Path) -> None:
    """Strict JSON (NaN and infinity are not JSON): a non-finite field is refused, naming it; the file
    is written atomically (:func:`atomic_path`). A file that cannot be written (a full disk, its directory
    gone since the command checked it) is one line, the file as it was before."""
    bad = non_finite_field(data)
    if bad:
        raise InputError(f"{path}: field {bad} is not finite; the input drives the analysis out of range, not written")
    write_text_atomic(json.dumps(data, indent=2, allow_nan=False) + "\n", path)


def write_text_atomic(text: str, path: str | Path) -> None:
    """``text`` written to ``path`` as UTF-8, atomically (:func:`atomic_path`); a file that cannot be written
    (a full disk, its directory gone or read-only since the command checked it) is one line (InputError), the
    file as it was before."""
    try:
        with atomic_path(path) as tmp:
            tmp.write_text(text, encoding="utf-8")
    except OSError as e:
        raise InputError(f"{path}: cannot write: {e.strerror or e}") from None
