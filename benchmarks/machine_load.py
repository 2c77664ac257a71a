"""The machine's load averages, printed beside every benchmark table (others may share the machine)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable


def load_averages(sep: str = ", ") -> str:
    """The 1-, 5- and 15-minute load averages, 2 decimals, joined by ``sep``."""
    return sep.join(f"{v:.2f}" for v in os.getloadavg())


def run_timed(main: Callable[[], None], end_load: bool = True) -> None:
    """Run a benchmark's ``main``, then print the load averages at its end (``end_load``) and the wall time it took."""
    t0 = time.monotonic()
    main()
    if end_load:
        print(f"\nload average at the end: {load_averages()}")
    print(f"took {time.monotonic() - t0:.0f} s")
