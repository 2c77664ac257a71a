"""The machine's load averages, printed beside every benchmark table (others may share the machine)."""

from __future__ import annotations

import os


def load_averages(sep: str = ", ") -> str:
    """The 1-, 5- and 15-minute load averages, 2 decimals, joined by ``sep``."""
    return sep.join(f"{v:.2f}" for v in os.getloadavg())
