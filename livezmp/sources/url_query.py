"""The query of a source URL, checked against the parameters the source knows."""

from __future__ import annotations

from urllib.parse import parse_qs, urlsplit

from livezmp.errors import InputError


def query_params(url: str, allowed: set[str]) -> dict[str, str]:
    """``?a=1&b=2`` → {"a": "1", "b": "2"} (the last value of a repeated key); InputError
    naming the first parameter not in ``allowed``."""
    query = {k: v[-1] for k, v in parse_qs(urlsplit(url).query, keep_blank_values=True).items()}
    unknown = sorted(set(query) - allowed)
    if unknown:
        raise InputError(f"{url}: unknown parameter {unknown[0]!r} (one of {', '.join(sorted(allowed)) or 'none'})")
    return query
