"""Support polygons and the clamp of the ZMP to them over many frames at once:
:func:`livezmp.balance.support.support_polygon` then :func:`livezmp.balance.support.clamp_to_polygon`,
frame by frame, with the same results.

Each frame's polygon is the convex hull of a few sole corners (4 in single support,
8 in double). The hull's edges are the ordered corner pairs with every other corner
strictly on their left, found for all frames at once. Where that test is not clear-cut
(a corner within 1e-7 of the largest coordinate from the line through two others:
coincident or collinear corners, degenerate soles), the per-frame functions decide:
they drop such vertices, so both must agree on the vertex set.

Frame: world, z up; points are (x, y) on the ground plane in metres.
"""

from __future__ import annotations

import itertools

import numpy as np

from livezmp.balance.support import clamp_to_polygon, support_polygon

NEAR_LINE = 1e-7  # relative to the largest coordinate: closer to a line leaves the frame to the per-frame code
MAX_COORD = 1e12  # m: larger coordinates are the per-frame code's to reject


def _edges(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Counter-clockwise hull edges of (F, k, 2) point sets, as candidate pairs.

    Returns (start, end) (F, p, 2) for the p = k (k - 1) / 2 point pairs, oriented so that
    the hull is on their left, a mask (F, p) of the pairs that are hull edges, and a mask
    (F,) of the frames whose hull is not clear-cut."""
    k = points.shape[1]
    pairs = list(itertools.combinations(range(k), 2))
    i = np.array([p[0] for p in pairs])
    j = np.array([p[1] for p in pairs])
    a, b = points[:, i], points[:, j]  # (F, p, 2)
    e = b - a
    rel = points[:, None, :, :] - a[:, :, None, :]  # (F, p, k, 2)
    cross = e[:, :, None, 0] * rel[..., 1] - e[:, :, None, 1] * rel[..., 0]  # (F, p, k)
    others = np.ones((len(pairs), k), dtype=bool)
    others[np.arange(len(pairs)), i] = False
    others[np.arange(len(pairs)), j] = False
    cross = cross[:, others].reshape(len(points), len(pairs), k - 2)
    length = np.hypot(e[..., 0], e[..., 1])
    scale = np.max(np.abs(points), axis=(1, 2))
    # distance of every other corner to the pair's line, against the tolerance
    unclear = np.any(np.abs(cross) <= (NEAR_LINE * scale)[:, None, None] * length[:, :, None], axis=(1, 2))
    unclear |= ~(scale <= MAX_COORD)
    left = np.all(cross > 0.0, axis=2)
    right = np.all(cross < 0.0, axis=2)
    start = np.where(right[..., None], b, a)
    end = np.where(right[..., None], a, b)
    return start, end, left | right, unclear


def clamp_batch(zmp_xy: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Clamp F points (F, 2) to the convex hulls of F point sets (F, k, 2), k >= 3.

    Returns (clamped (F, 2), inside (F,), margin (F,), unclear (F,)) as
    :func:`livezmp.balance.support.clamp_to_polygon` defines them; rows where ``unclear`` is True
    are not computed (the caller runs the per-frame code there)."""
    start, end, is_edge, unclear = _edges(points)
    p = zmp_xy[:, None, :]
    e = end - start
    # the per-frame code's arithmetic: cross of the edge with (p - start), its length, the nearest point
    cross = e[..., 0] * (p[..., 1] - start[..., 1]) - e[..., 1] * (p[..., 0] - start[..., 0])
    length = np.hypot(e[..., 0], e[..., 1])
    u = e / np.where(length > 0.0, length, 1.0)[..., None]
    s = np.clip(np.sum((p - start) * u, axis=2), 0.0, length)
    near = start + s[..., None] * u
    dist = np.hypot(p[..., 0] - near[..., 0], p[..., 1] - near[..., 1])
    outside_edge = is_edge & (cross < 0.0)
    inside = ~outside_edge.any(axis=1)
    inner = np.min(np.where(is_edge, cross / np.where(length > 0.0, length, 1.0), np.inf), axis=1)
    dist = np.where(outside_edge, dist, np.inf)
    best = np.argmin(dist, axis=1)
    rows = np.arange(len(p))
    clamped = np.where(inside[:, None], zmp_xy, near[rows, best])
    margin = np.where(inside, inner, -dist[rows, best])
    return clamped, inside, margin, unclear


def support_clamp(zmp_xy: np.ndarray, codes: np.ndarray, soles: dict[str, np.ndarray],
                  judged: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Clamp, inside flag and margin of the ZMP (F, 2) against each frame's support polygon.

    ``codes`` (F,) index ``SUPPORT_LABELS`` ("left", "right", "double", "none"); ``soles``
    {"left", "right"} (F, k, 3) sole corners; only the rows where ``judged`` is True
    (a ZMP and some support) are computed, the others are left at zero / False."""
    count = len(zmp_xy)
    clamped = np.zeros((count, 2))
    inside = np.zeros(count, dtype=bool)
    margin = np.zeros(count)
    groups = {0: soles["left"][..., :2], 1: soles["right"][..., :2],
              2: np.concatenate([soles["left"][..., :2], soles["right"][..., :2]], axis=1)}
    for code, pts in groups.items():
        rows = np.flatnonzero(judged & (codes == code))
        if not len(rows):
            continue
        c, ins, mar, unclear = clamp_batch(zmp_xy[rows], pts[rows])
        clamped[rows], inside[rows], margin[rows] = c, ins, mar
        for r in rows[unclear]:
            label = ("left", "right", "double")[code]
            poly = support_polygon(soles["left"][r, :, :2], soles["right"][r, :, :2], label)
            got = clamp_to_polygon(zmp_xy[r], poly)
            clamped[r], inside[r], margin[r] = got.point, got.inside, got.margin
    return clamped, inside, margin
