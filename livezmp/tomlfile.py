"""Read a TOML input file; a missing file or bad TOML is one :class:`InputError` line naming the file."""

from __future__ import annotations

import tomllib
from pathlib import Path

from livezmp.errors import InputError


def read_toml(path: str | Path, what: str) -> dict:
    """The parsed TOML of ``path``; ``what`` names the file's role in the error ("mapping", ...)."""
    p = Path(path)
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as e:
        raise InputError(f"{p}: cannot read {what}: {e.strerror}") from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"{p}: bad TOML: {e}") from None
