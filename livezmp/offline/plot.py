"""Figures of an analysis: the ZMP along each ground axis over time, before and after the
clamp (like the seed paper's figures 5–6), with the force plates' centre of pressure when there
is one; the margin to the support polygon's edge over time (and ZMP − CoP); and a top view of
footprints, ZMP and CoM, zoomed to a stretch of the take so footprints stay readable."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from livezmp.model.body import BodyModel  # noqa: E402
from livezmp.offline.batch import BatchResult  # noqa: E402

TOP_VIEW_SPAN_M = 3.0  # the top view shows at most this much of the walk
PLOT_FRAMES = 20_000  # a figure of a longer take draws every k-th frame (k a power of 2), at most this many


class PlotSeries:
    """The frames a figure draws of a take whose results come chunk by chunk: all of them up to
    :data:`PLOT_FRAMES`, then every k-th frame, k doubling as the take goes on (bounded memory;
    a long take's figure is drawn from this decimated series)."""

    def __init__(self) -> None:
        self.start()

    def start(self) -> None:
        """(Re)start: no frame kept."""
        self.step, self.parts, self.kept = 1, [], 0

    def add(self, part: BatchResult) -> None:
        self.parts.append(part.select(part.index % self.step == 0))
        self.kept += len(self.parts[-1])
        while self.kept > PLOT_FRAMES:
            self.step *= 2
            self.parts = [p.select(p.index % self.step == 0) for p in self.parts]
            self.kept = sum(len(p) for p in self.parts)

    def result(self) -> BatchResult:
        return BatchResult.concatenate(self.parts)


def _top_view_frames(com: np.ndarray, g: list[int]) -> tuple[np.ndarray, str]:
    """Frames whose CoM lies within half ``TOP_VIEW_SPAN_M`` of the take's middle CoM (all when the
    take is short), and a note for the title."""
    mid = com[len(com) // 2, g]
    near = np.max(np.abs(com[:, g] - mid), axis=1) <= TOP_VIEW_SPAN_M / 2
    if near.all():
        return near, ""
    return near, f"\nzoomed: {TOP_VIEW_SPAN_M:g} m around the middle of the take"


def plot_analysis(body: BodyModel, result: BatchResult, path: str | Path, title: str = "",
                  cop: np.ndarray | None = None, complete: np.ndarray | None = None) -> None:
    """Write the figure to ``path`` (PNG). Axes are in the input's world frame, metres. ``cop`` (N, 3)
    internal frame (NaN where unloaded) and ``complete`` (N,) from force plates, when there are some."""
    t = result.t
    zmp = body.to_input_frame(np.where(result.has_zmp[:, None], result.zmp, np.nan))
    clamped = body.to_input_frame(np.where(result.judged[:, None], result.clamped, np.nan))
    com = body.to_input_frame(result.com)
    plates = None if cop is None else body.to_input_frame(cop)
    # a foot off the plates makes their CoP not the body's: those frames drawn apart, not as the truth
    ok = np.ones(len(t), dtype=bool) if complete is None else np.asarray(complete, dtype=bool)
    labels = result.labels
    up = "xyz".index(body.up_axis)
    g = [k for k in range(3) if k != up]
    names = ["x", "y", "z"]
    fig = plt.figure(figsize=(13, 9))
    grid = fig.add_gridspec(3, 2, width_ratios=[1.3, 1])
    for row, k in enumerate(g):
        ax = fig.add_subplot(grid[row, 0])
        ax.plot(t, zmp[:, k], lw=1, label="ZMP")
        ax.plot(t, clamped[:, k], lw=1, ls="--", label="ZMP clamped to support")
        ax.plot(t, com[:, k], lw=0.8, color="gray", label="CoM")
        if plates is not None:
            ax.plot(t, np.where(ok, plates[:, k], np.nan), lw=1, color="black", label="plate CoP (complete frames)")
            ax.plot(t, np.where(ok, np.nan, plates[:, k]), lw=0.8, ls=":", color="gray",
                    label="plate CoP, a loaded foot off the plates")
        out = result.judged & ~result.inside
        ax.scatter(t[out], zmp[out, k], s=4, color="red", label="outside support", zorder=3)
        ax.set_ylabel(f"{names[k]} (m)")
        ax.grid(alpha=0.3)
        if row == 0:
            ax.legend(loc="best", fontsize=8)
            ax.set_title(title or "ZMP over time")
    ax = fig.add_subplot(grid[2, 0])
    ax.plot(t, np.where(result.judged, 1000 * result.margin, np.nan), lw=1, label="margin to support edge (+ inside)")
    ax.axhline(0, color="black", lw=0.6)
    if plates is not None:
        err = 1000 * np.linalg.norm(zmp[:, g] - plates[:, g], axis=1)
        ax.plot(t, np.where(ok, err, np.nan), lw=1, color="black", label="|ZMP - CoP| (complete frames)")
    ax.set_ylabel("mm")
    ax.set_xlabel("time (s)")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    top = fig.add_subplot(grid[:, 1])
    shown, note = _top_view_frames(com, g)
    idx = np.flatnonzero(shown)
    for i in idx[:: max(1, len(idx) // 150)]:
        for side, soles in result.soles.items():
            if labels[i] in (side, "double"):
                s = body.to_input_frame(soles[i])[:, g]
                s = np.vstack([s, s[:1]])
                top.plot(s[:, 0], s[:, 1], lw=0.5, color="tab:green" if side == "left" else "tab:purple")
    part = np.where(shown[:, None], zmp, np.nan)
    top.plot(part[:, g[0]], part[:, g[1]], lw=0.8, label="ZMP")
    top.plot(np.where(shown, com[:, g[0]], np.nan), np.where(shown, com[:, g[1]], np.nan), lw=0.8, color="gray",
             label="CoM projection")
    if plates is not None:
        on = shown & ok
        top.plot(np.where(on, plates[:, g[0]], np.nan), np.where(on, plates[:, g[1]], np.nan), lw=0.8,
                 color="black", label="plate CoP (complete frames)")
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel(f"{names[g[0]]} (m)")
    top.set_ylabel(f"{names[g[1]]} (m)")
    top.set_title("top view: footprints in contact (left green, right purple)" + note, fontsize=9)
    top.legend(loc="best", fontsize=8)
    top.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
