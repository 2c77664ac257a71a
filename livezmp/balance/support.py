"""Support polygons on the ground plane: the convex hull of the soles, and the clamp of a point to it.

Frame: world, z up. Everything here lives on the ground plane: points are (x, y) in metres.
A polygon is an (m, 2) array of vertices, counter-clockwise, with no repeated or collinear
vertices, as :func:`convex_hull` returns it. Degenerate polygons are valid: m = 0 (flight, no
support), m = 1 (a point) and m = 2 (a segment). Coordinates beyond 1e12 m are rejected as a units
mistake; detail finer than about 1e-100 m is below the arithmetic's resolution (products of
coordinate differences underflow).

The polygons are tiny (4 to 16 vertices) and these functions run once per frame, so the inner
loops use plain Python floats: on such sizes they beat numpy, whose per-call overhead dominates
(see benchmarks/bench_support.py).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from livezmp.errors import InputError

SUPPORT_LABELS = ("left", "right", "double", "none")

# Coordinates beyond this (metres) are a units mistake; the bound also keeps products of coordinates
# far from overflow.
_MAX_COORD = 1e12
# Hull vertices closer than this fraction of the coordinates' magnitude to the segment between their
# neighbours are dropped (collinear or coincident), so rounding noise never adds sliver vertices.
_COLLINEAR_REL_TOL = 1e-9
_TINY = float(np.finfo(float).tiny)  # smallest normal float


class SupportError(InputError):
    """Bad input to a support-polygon function: wrong shape, non-finite value, unknown support label."""


class Clamp(NamedTuple):
    """Result of :func:`clamp_to_polygon`; unpacks as ``(point, inside, margin)``."""

    point: np.ndarray
    """(2,) nearest point of the polygon to the query, in metres (the query itself if inside)."""
    inside: bool
    """True if the query lies in the polygon, its boundary included."""
    margin: float
    """Signed distance in metres: inside, the distance to the nearest edge (>= 0); outside, minus the
    distance to the polygon (< 0)."""


def _xy_rows(points, name: str) -> list[list[float]]:
    """The (x, y) columns of a (k, 2) or (k, 3) array as a list of [x, y] floats, validated."""
    try:
        a = np.asarray(points, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SupportError(f"{name}: not an array of numbers ({exc})") from None
    if a.ndim != 2 or a.shape[1] not in (2, 3):
        raise SupportError(f"{name}: expected (k, 2) or (k, 3) points in metres, got shape {a.shape}")
    rows = a[:, :2].tolist()
    # Plain floats: faster than numpy on a handful of rows. One sum bounds every coordinate (it is NaN if
    # any is); only when it does not, look row by row (the comparisons are False for NaN too).
    if not sum(abs(x) + abs(y) for x, y in rows) <= _MAX_COORD:
        for i, (x, y) in enumerate(rows):
            if not (-_MAX_COORD <= x <= _MAX_COORD and -_MAX_COORD <= y <= _MAX_COORD):
                raise SupportError(f"{name}: row {i} has a non-finite or implausible coordinate [{x}, {y}] m")
    # subnormal coordinates are taken as 0: their products with other differences underflow to 0,
    # which made a real hull vertex look collinear and dropped it
    return [[x if abs(x) >= _TINY else 0.0, y if abs(y) >= _TINY else 0.0] for x, y in rows]


def _point(p_xy, name: str = "point") -> tuple[float, float]:
    try:
        a = np.asarray(p_xy, dtype=float)
    except (TypeError, ValueError) as exc:
        raise SupportError(f"{name}: not a number pair ({exc})") from None
    if a.shape != (2,):
        raise SupportError(f"{name}: expected (x, y) in metres, got shape {a.shape}")
    x, y = a.tolist()
    if not (abs(x) <= _MAX_COORD and abs(y) <= _MAX_COORD):
        raise SupportError(f"{name}: non-finite or implausible coordinate ({x}, {y}) m")
    return x, y


def _half_hull(pts: list) -> list:
    """One chain of Andrew's monotone-chain hull over sorted points, keeping only left turns."""
    chain: list = []
    for p in pts:
        px, py = p
        while len(chain) >= 2:
            (ox, oy), (ax, ay) = chain[-2], chain[-1]
            if (ax - ox) * (py - oy) - (ay - oy) * (px - ox) > 0.0:
                break
            chain.pop()
        chain.append(p)
    return chain


def _drop_slivers(hull: list, tol: float) -> list:
    """Remove hull vertices within ``tol`` (metres) of the segment joining their neighbours.

    Rounding can leave near-duplicate or near-collinear vertices; a tolerance inside the chain
    itself would not do, since for a near-vertical line the x order is not the order along it.
    """
    while len(hull) > 1:
        m = len(hull)
        (ax, ay), (bx, by) = hull[-1], hull[0]
        for i in range(m):
            cx, cy = hull[i + 1] if i + 1 < m else hull[0]
            ex, ey = cx - ax, cy - ay
            # Distance to the line first (cheap), to the segment only when that is small; |ex| + |ey| >= the
            # hypotenuse, so most vertices are cleared without computing it.
            cross = abs(ex * (by - ay) - ey * (bx - ax))
            if cross <= tol * (abs(ex) + abs(ey)) and cross <= tol * math.hypot(ex, ey) and (
                _nearest_on_segment(bx, by, ax, ay, cx, cy)[2] <= tol
            ):
                del hull[i]
                break  # rare: start over with the new neighbours
            ax, ay, bx, by = bx, by, cx, cy
        else:
            return hull
    return hull


def _hull_rows(rows: list[list[float]]) -> list[tuple[float, float]]:
    pts = sorted({(x, y) for x, y in rows})
    if len(pts) <= 1:
        return pts
    ys = [p[1] for p in pts]
    # Rounding in a coordinate difference scales with the coordinates' magnitude.
    scale = max(abs(pts[0][0]), abs(pts[-1][0]), abs(min(ys)), abs(max(ys)))
    hull = _half_hull(pts)[:-1] + _half_hull(pts[::-1])[:-1]
    return _drop_slivers(hull, _COLLINEAR_REL_TOL * scale)


def _quad_hull(rows: list[list[float]]) -> list[tuple[float, float]] | None:
    """:func:`_hull_rows` of four points that, in the given order, go round a strictly convex quadrilateral
    (a sole rectangle seen from above); None when they do not clearly do so (then use :func:`_hull_rows`).

    Every three of four such points are consecutive on the cycle, so when each vertex stands off the line
    through its neighbours by far more than the sliver tolerance (and rounding), the general hull keeps all
    four: it is this cycle, counter-clockwise from the lowest (x, y)."""
    (ax, ay), (bx, by), (cx, cy), (dx, dy) = rows
    tol = 4.0 * _COLLINEAR_REL_TOL * max(abs(ax), abs(ay), abs(bx), abs(by), abs(cx), abs(cy), abs(dx), abs(dy))
    # (next - previous) x (vertex - previous) at each vertex: all < 0 counter-clockwise, all > 0 clockwise;
    # |ex| + |ey| bounds the distance between the neighbours, as in _drop_slivers' test.
    sign = 0.0
    for (px, py), (vx, vy), (nx, ny) in (((dx, dy), (ax, ay), (bx, by)), ((ax, ay), (bx, by), (cx, cy)),
                                         ((bx, by), (cx, cy), (dx, dy)), ((cx, cy), (dx, dy), (ax, ay))):
        ex, ey = nx - px, ny - py
        cross = ex * (vy - py) - ey * (vx - px)
        if not abs(cross) > tol * (abs(ex) + abs(ey)) or cross * sign < 0.0:
            return None
        sign = cross
    cycle = [(ax, ay), (bx, by), (cx, cy), (dx, dy)]
    if sign > 0.0:
        cycle.reverse()
    start = cycle.index(min(cycle))
    return cycle[start:] + cycle[:start]


def convex_hull(points_xy) -> np.ndarray:
    """Convex hull of points on the ground plane.

    points_xy: (k, 2) or (k, 3) array of points in metres (a z column is ignored), k >= 0.
    Returns an (m, 2) array of hull vertices, counter-clockwise, starting at the lowest-x (then
    lowest-y) point, without repeated or collinear vertices: a vertex within 1e-9 * L of the segment
    joining its neighbours is dropped, L being the largest absolute coordinate. Coordinates are returned
    as given, except subnormal ones (below 2.2e-308 m in magnitude), returned as 0. Degenerate inputs
    give degenerate hulls, never NaN: no points -> (0, 2); coincident points -> the single point
    (1, 2); collinear points -> the segment's two ends (2, 2).
    Raises SupportError on a wrong shape or a coordinate that is not finite or beyond 1e12 m.
    """
    return np.array(_hull_rows(_xy_rows(points_xy, "points")), dtype=float).reshape(-1, 2)


def _support_rows(left_sole_xy, right_sole_xy, support: str) -> list:
    """Vertices of the support polygon (see :func:`support_polygon`) as (x, y) float pairs."""
    if support not in SUPPORT_LABELS:
        raise SupportError(f"support: unknown label {support!r}, expected one of {', '.join(SUPPORT_LABELS)}")
    if support == "none":
        return []
    needed = ("left", "right") if support == "double" else (support,)
    soles = {"left": left_sole_xy, "right": right_sole_xy}
    rows: list[list[float]] = []
    for foot in needed:
        if soles[foot] is None:
            raise SupportError(f"support {support!r} needs the {foot} sole, got None")
        rows += _xy_rows(soles[foot], f"{foot} sole")
    hull = _quad_hull(rows) if len(rows) == 4 else None
    return _hull_rows(rows) if hull is None else hull


def support_polygon(left_sole_xy, right_sole_xy, support: str) -> np.ndarray:
    """Support polygon for one frame, on the ground plane, in metres.

    left_sole_xy, right_sole_xy: (k, 2) or (k, 3) sole corner points of each foot in world
    coordinates (z ignored), or None when that foot is not needed (a swing foot, or flight).
    support: "left" or "right" (single support on that foot), "double", or "none" (flight).
    Returns the convex hull (see :func:`convex_hull`) of the stance sole, of both soles in double
    support, or an empty (0, 2) array in flight.
    Raises SupportError on an unknown label or when a needed sole is None or malformed.
    """
    return np.array(_support_rows(left_sole_xy, right_sole_xy, support), dtype=float).reshape(-1, 2)


def support_vertices(left_sole_xy, right_sole_xy, support: str) -> list[tuple[float, float]]:
    """:func:`support_polygon`'s vertices as plain (x, y) float pairs (m, ground plane, world frame), for a caller
    that keeps a polygon and clamps to it many times (:func:`clamp_to_vertices`): checked here, once."""
    return _support_rows(left_sole_xy, right_sole_xy, support)


def clamp_to_vertices(p_xy, vertices: list[tuple[float, float]]) -> Clamp:
    """:func:`clamp_to_polygon` of ``p_xy`` (2,) m to a polygon given as :func:`support_vertices` made it (not
    checked again: the simulator clamps its true ZMP every step to a polygon it rebuilds only when the feet move).
    Raises SupportError for an empty polygon or a bad point, as clamp_to_polygon does."""
    px, py = _point(p_xy)
    if not vertices:
        raise SupportError("polygon: empty (flight phase, no support), nothing to clamp to")
    qx, qy, inside, margin = _clamp_rows(px, py, vertices)
    return Clamp(np.array((qx, qy)), inside, margin)


def support_and_clamp(left_sole_xy, right_sole_xy, support: str, p_xy) -> tuple[np.ndarray, Clamp | None]:
    """:func:`support_polygon` and :func:`clamp_to_polygon` of ``p_xy`` (2,) m to it, in one call (the polygon is
    not checked again): the polygon (k, 2) m on the ground plane, world frame, and the Clamp, None in flight or
    when ``p_xy`` is None (no ZMP)."""
    rows = _support_rows(left_sole_xy, right_sole_xy, support)
    poly = np.array(rows, dtype=float).reshape(-1, 2)
    if p_xy is None or not rows:
        return poly, None
    px, py = _point(p_xy)
    qx, qy, inside, margin = _clamp_rows(px, py, rows)
    return poly, Clamp(np.array((qx, qy)), inside, margin)


def _nearest_on_segment(px: float, py: float, ax: float, ay: float, bx: float, by: float):
    """Nearest point (qx, qy) of segment ab to p, and its distance to p."""
    ex, ey = bx - ax, by - ay
    length = math.hypot(ex, ey)  # not ex*ex + ey*ey, which underflows for tiny segments
    if length == 0.0:
        return ax, ay, math.hypot(px - ax, py - ay)
    ux, uy = ex / length, ey / length
    s = min(length, max(0.0, (px - ax) * ux + (py - ay) * uy))
    qx, qy = ax + s * ux, ay + s * uy
    return qx, qy, math.hypot(px - qx, py - qy)


def _clamp_rows(px: float, py: float, verts: list[list[float]]) -> tuple[float, float, bool, float]:
    m = len(verts)
    if m == 1:
        qx, qy = verts[0]
        d = math.hypot(px - qx, py - qy)
        return qx, qy, d == 0.0, -d
    if m == 2:
        (ax, ay), (bx, by) = verts
        qx, qy, d = _nearest_on_segment(px, py, ax, ay, bx, by)
        return qx, qy, d == 0.0, -d
    # Accept either orientation: the sign of the doubled area says which side of an edge is inside.
    area2 = 0.0
    ax, ay = verts[-1]
    for bx, by in verts:
        area2 += ax * by - bx * ay
        ax, ay = bx, by
    if area2 == 0.0:
        # Three or more vertices on one line (not a hull): clamp to the segment they span.
        return _clamp_rows(px, py, _hull_rows(verts))
    sign = -1.0 if area2 < 0.0 else 1.0
    inner = math.inf  # smallest distance to an edge line, meaningful when inside
    best = (px, py, math.inf)  # nearest boundary point over the edges that see p from outside
    ax, ay = verts[-1]
    for bx, by in verts:
        ex, ey = bx - ax, by - ay
        length = math.hypot(ex, ey)
        if length > 0.0:
            cross = sign * (ex * (py - ay) - ey * (px - ax))
            if cross < 0.0:
                # For a convex polygon the nearest boundary point lies on an edge that has p on
                # its outer side, so only those edges need a projection.
                q = _nearest_on_segment(px, py, ax, ay, bx, by)
                if q[2] < best[2]:
                    best = q
            else:
                inner = min(inner, cross / length)
        ax, ay = bx, by
    if best[2] == math.inf:
        return px, py, True, inner
    return best[0], best[1], False, -best[2]


def clamp_to_polygon(p_xy, poly) -> Clamp:
    """Clamp a ground-plane point (e.g. the ZMP) to a convex support polygon.

    p_xy: (2,) point (x, y) in metres, world frame.
    poly: (m, 2) convex polygon in metres, as from :func:`convex_hull` or :func:`support_polygon`
    (either orientation is accepted); m = 1 (point) and m = 2 (segment) are handled. A non-convex
    polygon gives meaningless results.
    Returns Clamp(point, inside, margin): the nearest point of the polygon (p itself if inside),
    whether p is inside (boundary included), and the signed distance to the polygon's edge:
    positive inside (distance to the nearest edge), negative outside (minus the distance to the
    polygon), 0 on the boundary. For a point or a segment, inside means on it, and margin <= 0.
    Raises SupportError for an empty polygon (flight: there is nothing to clamp to), a wrong shape
    or a coordinate that is not finite or beyond 1e12 m.
    """
    px, py = _point(p_xy)
    verts = _xy_rows(poly, "polygon")
    if not verts:
        raise SupportError("polygon: empty (flight phase, no support), nothing to clamp to")
    qx, qy, inside, margin = _clamp_rows(px, py, verts)
    return Clamp(np.array((qx, qy)), inside, margin)
