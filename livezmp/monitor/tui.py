"""The terminal view (``--tui``): a live status table, alarms printed above it.

Built on ``rich``'s Live display, refreshed at most ``refresh_hz`` times per second
from the monitor loop, so it costs the loop almost nothing per frame.
"""

from __future__ import annotations

import time

from rich.console import Console
from rich.live import Live
from rich.table import Table

from livezmp.monitor.alarms import AlarmEvent


def _fmt(v, unit: str = "", scale: float = 1.0, digits: int = 1) -> str:
    return "–" if v is None else f"{v * scale:.{digits}f}{unit}"


def status_table(s: dict) -> Table:
    """The status as a two-column table (see :meth:`Monitor.status` for the fields)."""
    t = Table(title=f"livezmp monitor — {s['source']}", show_header=False, expand=False)
    t.add_column(style="bold")
    t.add_column()
    alarm = s["alarm_active"]
    rows = [
        ("frames", f"{s['inputs']} in, {s['results']} analysed, {_fmt(s['input_fps'], ' Hz')}"),
        ("support", s["support"] or "–"),
        ("margin", _fmt(s["margin"], " mm", 1000.0)),
        ("out of support", f"{s['out_of_support']} frames ({_fmt(s['out_fraction'], ' %', 100.0)})"),
        ("alarms", f"{s['alarms']}" + (" — [bold red]ACTIVE[/]" if alarm else "")),
        ("cadence", _fmt(s["cadence"], " steps/min")),
        ("dropped input", f"{s['dropped']} (lost {s['lost']})"),
        ("recording", s["recording"] or "off"),
    ]
    for k, v in rows:
        t.add_row(k, v)
    return t


class TerminalView:
    """Live status on ``console`` (default: the terminal's stderr)."""

    def __init__(self, console: Console | None = None, refresh_hz: float = 8.0):
        self.console = console or Console(stderr=True)
        self.interval = 1.0 / refresh_hz
        self._live: Live | None = None
        self._last = 0.0

    def update(self, status: dict, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last < self.interval:
            return
        self._last = now
        if self._live is None:
            self._live = Live(status_table(status), console=self.console, auto_refresh=False, transient=False)
            self._live.start()
        else:
            self._live.update(status_table(status))
        self._live.refresh()

    def alarm(self, ev: AlarmEvent) -> None:
        style = "bold red" if ev.event == "raised" else "green"
        self.console.print(f"[{style}]{ev.message}[/]")

    def close(self, status: dict) -> None:
        self.update(status, force=True)
        if self._live is not None:
            self._live.stop()
