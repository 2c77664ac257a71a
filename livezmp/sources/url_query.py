"""The query of a source URL, checked against the parameters the source knows."""

from __future__ import annotations

import math
from urllib.parse import parse_qs, urlsplit

from livezmp.errors import InputError

MAX_WAIT_S = 3600.0  # s: the longest wait a URL may ask for (beyond it, select() and liblsl overflow or hang)


def query_params(url: str, allowed: set[str]) -> dict[str, str]:
    """``?a=1&b=2`` → {"a": "1", "b": "2"} (the last value of a repeated key); InputError
    naming the first parameter not in ``allowed``."""
    query = {k: v[-1] for k, v in parse_qs(urlsplit(url).query, keep_blank_values=True).items()}
    unknown = sorted(set(query) - allowed)
    if unknown:
        raise InputError(f"{url}: unknown parameter {unknown[0]!r} (one of {', '.join(sorted(allowed)) or 'none'})")
    return query


def query_seconds(query: dict[str, str], key: str, default: float, url: str) -> float:
    """``?key=`` a wait in seconds, in (0, :data:`MAX_WAIT_S`] (``default`` when absent); InputError naming the
    parameter otherwise (a NaN or negative wait was taken as given: liblsl waited for ever on -1)."""
    if key not in query:
        return default
    try:
        v = float(query[key])
    except ValueError:
        v = math.nan
    if not 0 < v <= MAX_WAIT_S:
        raise InputError(f"{url}: {key}: need seconds in (0, {MAX_WAIT_S:g}], got {query[key]!r}")
    return v
