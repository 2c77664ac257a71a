"""Read a TOML input file; a missing file or bad TOML is one :class:`InputError` line naming the file."""

from __future__ import annotations

import tomllib
from pathlib import Path

from livezmp.checks import read_input_text
from livezmp.errors import InputError


def read_toml(path: str | Path, what: str) -> dict:
    """The parsed TOML of ``path``; ``what`` names the file's role in the error ("mapping", ...).
    The file passes :func:`livezmp.checks.read_input_text` (a regular UTF-8 file, BOM accepted)."""
    p = Path(path)
    text = read_input_text(p, what)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{p}: bad TOML: {e}") from None
