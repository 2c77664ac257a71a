"""How long the live loop's link failed it, and whether that fails the run.

Two spans are timed on the loop's clock (s of loop time: cycle index x period, so deadlines the
clock skipped count as time):

- *down*: the link said its port was gone (a :class:`~livezmp.links.base.LinkError` on a read)
  until a reconnect succeeded;
- *without frames*: the watchdog had stopped commanding (no valid frame for its timeout) until a
  valid frame came again: a port gone, or a bus whose servos stopped answering (every read a
  :class:`~livezmp.links.base.LinkReadError`: servo power cut, the adapter still there).

A run fails on its link (:meth:`LinkFaults.verdict`) when either span took more than
`MAX_LOST_SHARE` of the run, was still open at its end (the link never came back), or the link
said it was unusable (:class:`~livezmp.links.base.LinkUnusable`). ``livezmp run`` then exits
with its own code (:data:`livezmp.commands.run.EXIT_LINK_FAILED`) rather than 0.
"""

from __future__ import annotations

from dataclasses import dataclass

# A run whose robot went without control for more than a tenth of it did not do what was asked of it, whatever
# its summary's averages say; a shorter outage (a cable wiggled, a reconnect) is told and counted, not failed.
MAX_LOST_SHARE = 0.1


@dataclass
class Span:
    """The periods one condition held, on the loop's clock (s): how many began, their total and longest
    closed length, and when the open one began (None: none open)."""

    events: int = 0
    seconds: float = 0.0
    longest_s: float = 0.0
    since: float | None = None

    def begin(self, t: float) -> None:
        if self.since is None:
            self.since = t
            self.events += 1

    def end(self, t: float) -> None:
        if self.since is not None:
            length = t - self.since
            self.seconds += length
            self.longest_s = max(self.longest_s, length)
            self.since = None

    def summary(self, t_end: float) -> dict:
        """JSON-ready, the open period counted up to ``t_end`` (s): ``events``, ``seconds``, ``longest_s``,
        ``share`` of the run's ``t_end`` seconds, ``at_end`` (still open when the run ended)."""
        open_s = 0.0 if self.since is None else max(t_end - self.since, 0.0)
        seconds = self.seconds + open_s
        return {"events": self.events, "seconds": round(seconds, 3), "longest_s": round(max(self.longest_s, open_s), 3),
                "share": round(seconds / t_end, 4) if t_end > 0 else 0.0, "at_end": self.since is not None}


class LinkFaults:
    """The loop's record of its link's outages (see the module docstring)."""

    def __init__(self) -> None:
        self.down = Span()
        self.without_frames = Span()
        self.unusable: str | None = None

    def summary(self, t_end: float) -> dict:
        """The summary's ``run_s``, ``link_down``, ``without_frames`` blocks and ``link_failed`` (one line, or
        None) for a run that ended at loop time ``t_end`` (s)."""
        down, without = self.down.summary(t_end), self.without_frames.summary(t_end)
        return {"run_s": round(t_end, 3), "link_down": down, "without_frames": without,
                "link_failed": self.verdict(down, without)}

    def verdict(self, down: dict, without: dict) -> str | None:
        """Why the link failed the run (one line), or None; ``down`` and ``without``: the spans' summaries."""
        if self.unusable is not None:
            return f"link unusable: {self.unusable}"
        for what, span in (("link down", down), ("without a valid frame", without)):
            if span["at_end"]:
                return f"{what} at the end of the run: it never came back ({span['seconds']:.1f} s in all)"
            if span["share"] > MAX_LOST_SHARE:
                return (f"{what} {100 * span['share']:.0f} % of the run ({span['seconds']:.1f} s in {span['events']} "
                        f"outage(s)), more than the {100 * MAX_LOST_SHARE:.0f} % allowed")
        return None
