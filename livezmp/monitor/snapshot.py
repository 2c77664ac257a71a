"""What the dashboard page draws, as plain JSON-able values.

Coordinates are the internal frame (z up, metres) projected on the ground: x, y.
A frame snapshot is the top view of one frame; a plot point is one sample of the
time plots (ZMP against the support polygon's extent along x and y).
"""

from __future__ import annotations

from livezmp.balance.pipeline import FrameResult


def _xy(p) -> list[float] | None:
    return None if p is None else [round(float(p[0]), 5), round(float(p[1]), 5)]


def frame_snapshot(r: FrameResult, cop=None) -> dict:
    """Top view of one frame: soles, support polygon, ZMP (raw and clamped), CoM, state,
    and the force plates' measured centre of pressure ``cop`` (internal frame) if any."""
    return {
        "index": r.index, "t": round(r.t, 5), "support": r.support, "inside": r.inside,
        "margin": None if r.margin is None else round(float(r.margin), 5),
        "zmp": _xy(r.zmp), "clamped": _xy(r.clamped), "com": _xy(r.com),
        "polygon": [_xy(p) for p in r.polygon],
        "soles": {s: [_xy(p) for p in pts] for s, pts in r.soles.items()},
        "cop": _xy(cop),
    }


def plot_point(r: FrameResult) -> list:
    """[index, t, zmp x, zmp y, clamped x, clamped y, polygon x min, x max, y min, y max,
    inside]; None where there is no ZMP or no polygon."""
    z, c = _xy(r.zmp) or [None, None], _xy(r.clamped) or [None, None]
    if len(r.polygon):
        lo, hi = r.polygon.min(axis=0), r.polygon.max(axis=0)
        box = [round(float(lo[0]), 5), round(float(hi[0]), 5), round(float(lo[1]), 5), round(float(hi[1]), 5)]
    else:
        box = [None] * 4
    return [r.index, round(r.t, 5), *z, *c, *box, r.inside]
