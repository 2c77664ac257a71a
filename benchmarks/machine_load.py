"""The machine's load averages, printed beside every benchmark table (others may share the machine)."""

from __future__ import annotations

import os
import time
from collections.abc import Callable


def load_averages(sep: str = ", ") -> str:
    """The 1-, 5- and 15-minute load averages, 2 decimals, joined by ``sep``."""
    return sep.join(f"{v:.2f}" for v in os.getloadavg())


def cpu_times() -> tuple[int, int] | None:
    """The machine's (stolen, total) CPU time since boot, in clock ticks, from /proc/stat (None where absent).

    Steal is time the hypervisor gave this virtual machine's CPUs to others: a row run while it rises is slower
    for reasons outside the benchmark."""
    try:
        with open("/proc/stat") as f:
            fields = [int(v) for v in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    return (fields[7], sum(fields[:8])) if len(fields) >= 8 else None


def steal_percent(before: tuple[int, int] | None, after: tuple[int, int] | None) -> float:
    """Percent of all CPUs' time stolen between two ``cpu_times()`` readings (nan where unknown)."""
    if before is None or after is None or after[1] <= before[1]:
        return float("nan")
    return 100.0 * (after[0] - before[0]) / (after[1] - before[1])


def run_timed(main: Callable[[], None], end_load: bool = True) -> None:
    """Run a benchmark's ``main``, then print the load averages at its end (``end_load``) and the wall time it took."""
    t0 = time.monotonic()
    main()
    if end_load:
        print(f"\nload average at the end: {load_averages()}")
    print(f"took {time.monotonic() - t0:.0f} s")
