"""Figures of an analysis: the ZMP along each ground axis over time, before and after the
clamp (like the seed paper's figures 5–6), and a top view of footprints, ZMP and CoM."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from livezmp.model.body import BodyModel  # noqa: E402
from livezmp.offline.batch import BatchResult  # noqa: E402


def plot_analysis(body: BodyModel, result: BatchResult, path: str | Path, title: str = "") -> None:
    """Write the figure to ``path`` (PNG). Axes are in the input's world frame, metres."""
    t = result.t
    zmp = body.to_input_frame(np.where(result.has_zmp[:, None], result.zmp, np.nan))
    clamped = body.to_input_frame(np.where(result.judged[:, None], result.clamped, np.nan))
    com = body.to_input_frame(result.com)
    labels = result.labels
    up = "xyz".index(body.up_axis)
    g = [k for k in range(3) if k != up]
    names = ["x", "y", "z"]
    fig = plt.figure(figsize=(13, 7))
    grid = fig.add_gridspec(2, 2, width_ratios=[1.3, 1])
    for row, k in enumerate(g):
        ax = fig.add_subplot(grid[row, 0])
        ax.plot(t, zmp[:, k], lw=1, label="ZMP")
        ax.plot(t, clamped[:, k], lw=1, ls="--", label="ZMP clamped to support")
        ax.plot(t, com[:, k], lw=0.8, color="gray", label="CoM")
        out = result.judged & ~result.inside
        ax.scatter(t[out], zmp[out, k], s=4, color="red", label="outside support", zorder=3)
        ax.set_ylabel(f"{names[k]} (m)")
        ax.grid(alpha=0.3)
        if row == 0:
            ax.legend(loc="best", fontsize=8)
            ax.set_title(title or "ZMP over time")
        else:
            ax.set_xlabel("time (s)")
    top = fig.add_subplot(grid[:, 1])
    step = max(1, len(result) // 150)
    for i in range(0, len(result), step):
        for side, soles in result.soles.items():
            if labels[i] in (side, "double"):
                s = body.to_input_frame(soles[i])[:, g]
                s = np.vstack([s, s[:1]])
                top.plot(s[:, 0], s[:, 1], lw=0.5, color="tab:green" if side == "left" else "tab:purple")
    top.plot(zmp[:, g[0]], zmp[:, g[1]], lw=0.8, label="ZMP")
    top.plot(com[:, g[0]], com[:, g[1]], lw=0.8, color="gray", label="CoM projection")
    top.set_aspect("equal", adjustable="datalim")
    top.set_xlabel(f"{names[g[0]]} (m)")
    top.set_ylabel(f"{names[g[1]]} (m)")
    top.set_title("top view: footprints in contact (left green, right purple)")
    top.legend(loc="best", fontsize=8)
    top.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
