"""Support polygon, convex hull and clamp, against hand-computed geometry, Qhull and matplotlib."""

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from matplotlib.path import Path
from scipy.spatial import ConvexHull

from livezmp.balance.support import SupportError, clamp_to_polygon, convex_hull, support_polygon
from livezmp.errors import InputError

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
TRIANGLE = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]])  # 3-4-5 right triangle, incircle r = 1 at (1, 1)
# Two soles, the right one ahead: hull vertices worked out by hand (see test_double_support_hull).
LEFT_SOLE = np.array([[0.0, 0.1], [0.25, 0.1], [0.25, 0.2], [0.0, 0.2]])
RIGHT_SOLE = np.array([[0.3, -0.2], [0.55, -0.2], [0.55, -0.1], [0.3, -0.1]])


def shoelace_area(poly):
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def turns(poly):
    """z of the cross product at each vertex (previous edge x next edge)."""
    e_in = poly - np.roll(poly, 1, axis=0)
    e_out = np.roll(poly, -1, axis=0) - poly
    return e_in[:, 0] * e_out[:, 1] - e_in[:, 1] * e_out[:, 0]


# --- convex hull ---------------------------------------------------------------------------------


def test_hull_drops_interior_duplicate_and_collinear_points():
    pts = np.array(
        [[0.5, 0.5], [1, 1], [0, 0], [1, 0], [0, 1], [0.5, 0], [1, 0.25], [0, 0], [0.2, 0.7], [1, 1]],
        dtype=float,
    )
    np.testing.assert_array_equal(convex_hull(pts), SQUARE)


def test_hull_of_clockwise_triangle_is_counter_clockwise():
    hull = convex_hull(TRIANGLE[::-1])
    np.testing.assert_array_equal(hull, TRIANGLE)
    assert shoelace_area(hull) == pytest.approx(6.0)


def test_hull_degenerate_inputs():
    assert convex_hull(np.zeros((0, 2))).shape == (0, 2)
    np.testing.assert_array_equal(convex_hull([[0.3, -0.2]] * 5), [[0.3, -0.2]])
    # Collinear, unordered, with repeats: the two end points.
    line = [[1.0, 1.0], [3.0, 3.0], [0.0, 0.0], [2.0, 2.0], [3.0, 3.0]]
    np.testing.assert_array_equal(convex_hull(line), [[0.0, 0.0], [3.0, 3.0]])
    # Collinear up to rounding (0.1 steps are not exact in binary) is still a segment.
    steps = [[0.1 * i, 0.3 * i] for i in range(7)]
    np.testing.assert_allclose(convex_hull(steps), [[0.0, 0.0], [0.6, 1.8]])
    # A z column is ignored.
    np.testing.assert_array_equal(convex_hull(np.c_[SQUARE, [5.0, 6.0, 7.0, 8.0]]), SQUARE)


def test_hull_near_coincident_points_are_one_point():
    pts = [[2.0, 1.0], [2.0 + 1e-15, 1.0], [2.0, 1.0 - 2e-16]]
    hull = convex_hull(pts)
    assert hull.shape == (1, 2) and np.allclose(hull, [[2.0, 1.0]])


def test_hull_keeps_a_corner_beside_subnormal_coordinates():
    """Two soles, the upper one shifted by a subnormal -5e-324 m: the products in the turn test
    underflowed to 0, the lower-left corner looked collinear and was dropped (found by hypothesis)."""
    sole = np.array([[0.0, 0.0], [0.0912, 0.0], [0.0912, 0.0914], [0.0, 0.0914]])
    pts = np.vstack([sole, sole + [-5e-324, 0.175]])
    hull = convex_hull(pts)
    np.testing.assert_allclose(sorted(map(tuple, hull)), [(0, 0), (0, 0.2664), (0.0912, 0), (0.0912, 0.2664)],
                               atol=1e-15)


@pytest.mark.parametrize(
    "bad, match",
    [
        ([[0.0, 1.0], [np.nan, 2.0]], "row 1 has a non-finite"),
        ([[0.0, 1.0], [np.inf, 2.0]], "row 1 has a non-finite"),
        ([[0.0, 1.0], [0.0, -3e12]], "row 1 has a non-finite or implausible"),
        ([0.0, 1.0], r"expected \(k, 2\) or \(k, 3\).*shape \(2,\)"),
        (np.zeros((3, 4)), r"shape \(3, 4\)"),
        ([["a", "b"]], "not an array of numbers"),
    ],
)
def test_hull_rejects_bad_input(bad, match):
    with pytest.raises(SupportError, match=match):
        convex_hull(bad)


def test_support_error_is_the_project_input_error():
    assert issubclass(SupportError, InputError)


# --- support polygon -----------------------------------------------------------------------------


def test_double_support_hull():
    # By hand: the lower chain runs from the left heel (0, 0.1) down to the right heel (0.3, -0.2)
    # and along the right sole's back edge; the upper chain from the right toe (0.55, -0.1) up to the
    # left toe (0.25, 0.2) - which lies above the line from (0.55, -0.1) to (0, 0.2) - and back.
    expected = [[0.0, 0.1], [0.3, -0.2], [0.55, -0.2], [0.55, -0.1], [0.25, 0.2], [0.0, 0.2]]
    poly = support_polygon(LEFT_SOLE[::-1], RIGHT_SOLE[[2, 0, 3, 1]], "double")
    np.testing.assert_allclose(poly, expected, atol=1e-15)
    # Shoelace by hand: (-0.03 + 0.05 + 0.055 + 0.135 + 0.05 + 0) / 2.
    assert shoelace_area(poly) == pytest.approx(0.13)


def test_single_support_is_the_stance_sole_and_flight_is_empty():
    np.testing.assert_array_equal(support_polygon(LEFT_SOLE[::-1], None, "left"), LEFT_SOLE)
    np.testing.assert_array_equal(support_polygon(None, RIGHT_SOLE, "right"), RIGHT_SOLE)
    # 3-D corners (z up) project onto the ground plane; the swing sole is ignored.
    right_3d = np.c_[RIGHT_SOLE, [0.01, 0.02, 0.0, 0.0]]
    np.testing.assert_array_equal(support_polygon(LEFT_SOLE + 9, right_3d, "right"), RIGHT_SOLE)
    assert support_polygon(LEFT_SOLE, RIGHT_SOLE, "none").shape == (0, 2)
    assert support_polygon(None, None, "none").shape == (0, 2)


def test_support_polygon_errors_name_the_problem():
    with pytest.raises(SupportError, match="unknown label 'both'"):
        support_polygon(LEFT_SOLE, RIGHT_SOLE, "both")
    with pytest.raises(SupportError, match="needs the right sole"):
        support_polygon(LEFT_SOLE, None, "double")
    with pytest.raises(SupportError, match="left sole: row 2"):
        support_polygon(np.where(np.arange(8).reshape(4, 2) == 5, np.nan, LEFT_SOLE), RIGHT_SOLE, "left")


# --- clamp ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "p, point, inside, margin",
    [
        ((0.3, 0.4), (0.3, 0.4), True, 0.3),  # nearest edge x = 0
        ((0.5, 0.5), (0.5, 0.5), True, 0.5),  # centre
        ((0.5, 0.0), (0.5, 0.0), True, 0.0),  # on an edge
        ((1.0, 1.0), (1.0, 1.0), True, 0.0),  # on a vertex
        ((0.5, -0.2), (0.5, 0.0), False, -0.2),  # edge region
        ((-0.7, 0.25), (0.0, 0.25), False, -0.7),
        ((1.3, 1.4), (1.0, 1.0), False, -0.5),  # vertex region, a 3-4-5 offset
        ((-0.6, -0.8), (0.0, 0.0), False, -1.0),
    ],
)
def test_clamp_unit_square(p, point, inside, margin):
    for poly in (SQUARE, SQUARE[::-1]):  # either orientation
        c = clamp_to_polygon(np.array(p), poly)
        np.testing.assert_allclose(c.point, point, atol=1e-15)
        assert c.inside is inside
        assert c.margin == pytest.approx(margin, abs=1e-15)


def test_clamp_triangle():
    # Incentre (1, 1) is 1 from all three edges (r = (3 + 4 - 5) / 2).
    c = clamp_to_polygon((1.0, 1.0), TRIANGLE)
    assert c.inside and c.margin == pytest.approx(1.0)
    assert clamp_to_polygon((1.0, 0.5), TRIANGLE).margin == pytest.approx(0.5)
    # Beyond the hypotenuse 3x + 4y = 12: distance (3*4 + 4*3 - 12) / 5 = 2.4, foot (4, 3) - 2.4 (3, 4) / 5.
    point, inside, margin = clamp_to_polygon((4.0, 3.0), TRIANGLE)
    np.testing.assert_allclose(point, [2.56, 1.08])
    assert not inside and margin == pytest.approx(-2.4)
    # Past the acute vertex (4, 0), outside both adjacent edges' slabs.
    point, inside, margin = clamp_to_polygon((7.0, -4.0), TRIANGLE)
    np.testing.assert_allclose(point, [4.0, 0.0])
    assert margin == pytest.approx(-5.0)


def test_clamp_segment_and_point():
    seg = np.array([[0.0, 0.0], [2.0, 0.0]])
    point, inside, margin = clamp_to_polygon((1.0, 1.0), seg)
    np.testing.assert_array_equal(point, [1.0, 0.0])
    assert (inside, margin) == (False, -1.0)
    point, inside, margin = clamp_to_polygon((5.0, 4.0), seg)
    np.testing.assert_array_equal(point, [2.0, 0.0])
    assert (inside, margin) == (False, -5.0)
    point, inside, margin = clamp_to_polygon((0.5, 0.0), seg)
    np.testing.assert_array_equal(point, [0.5, 0.0])
    assert (inside, margin) == (True, 0.0)
    dot = np.array([[1.0, 2.0]])
    point, inside, margin = clamp_to_polygon((4.0, 6.0), dot)
    np.testing.assert_array_equal(point, [1.0, 2.0])
    assert (inside, margin) == (False, -5.0)
    assert clamp_to_polygon((1.0, 2.0), dot)[1:] == (True, 0.0)


def test_clamp_collinear_vertices_act_as_their_segment():
    # Not a hull, but a caller may pass one: (0,0)-(1,0)-(2,0) is the segment from 0 to 2.
    line = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    point, inside, margin = clamp_to_polygon((3.0, 0.0), line)
    np.testing.assert_array_equal(point, [2.0, 0.0])
    assert (inside, margin) == (False, -1.0)


def test_clamp_rejects_flight_and_bad_input():
    with pytest.raises(SupportError, match="empty .*flight"):
        clamp_to_polygon((0.0, 0.0), np.zeros((0, 2)))
    with pytest.raises(SupportError, match="point: non-finite or implausible"):
        clamp_to_polygon((np.nan, 0.0), SQUARE)
    with pytest.raises(SupportError, match=r"point: expected \(x, y\)"):
        clamp_to_polygon((0.0, 0.0, 0.0), SQUARE)
    with pytest.raises(SupportError, match="polygon: row 3"):
        clamp_to_polygon((0.0, 0.0), np.vstack([SQUARE[:3], [np.inf, 0.0]]))


# --- properties ----------------------------------------------------------------------------------

# Detail below 1e-100 m is out of scope (documented: products of differences underflow).
coord = st.floats(-1.0, 1.0, allow_nan=False).map(lambda x: 0.0 if abs(x) < 1e-100 else x)
point_sets = st.lists(st.tuples(coord, coord), min_size=1, max_size=14)
# Far from the origin (a long walk), and on a small grid, which makes many exact collinear and
# repeated points.
far = st.floats(-1e4, 1e4, allow_nan=False).map(lambda x: 0.0 if abs(x) < 1e-100 else x)
grid = st.sampled_from([0.0, 0.5, 1.0, 2.0, 1e-9])
any_point_sets = st.one_of(
    point_sets,
    st.lists(st.tuples(far, far), min_size=1, max_size=10),
    st.lists(st.tuples(grid, grid), min_size=1, max_size=10),
)


def convex_polygons():
    # Hulls of random points, with at least a little area so "inside" is not measure-zero.
    return point_sets.map(convex_hull).filter(lambda h: len(h) >= 3 and abs(shoelace_area(h)) > 1e-4)


@settings(max_examples=400, deadline=None)
@given(any_point_sets)
def test_hull_properties(pts):
    pts = np.array(pts)
    hull = convex_hull(pts)
    # The documented collinearity tolerance, twice over for rounding.
    tol = 2e-9 * np.abs(pts).max()
    assert np.isfinite(hull).all()
    # Vertices are input points, without repeats.
    assert all(np.any(np.all(pts == v, axis=1)) for v in hull)
    assert len({tuple(v) for v in hull}) == len(hull)
    # Every input point is in the hull (to the collinearity tolerance).
    for p in pts:
        assert clamp_to_polygon(p, hull).margin >= -tol
    if len(hull) >= 3:
        # Strictly convex and counter-clockwise: every turn is a strict left turn.
        assert (turns(hull) > 0).all()
        # Same area as Qhull's, up to the slivers dropped within tol of an edge.
        perimeter = np.linalg.norm(np.roll(hull, -1, axis=0) - hull, axis=1).sum()
        assert shoelace_area(hull) == pytest.approx(ConvexHull(pts).volume, rel=1e-12, abs=tol * perimeter)


def boundary_samples(poly, per_edge=400):
    t = np.linspace(0.0, 1.0, per_edge, endpoint=False)[:, None]
    return np.concatenate([a + t * (b - a) for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True)])


@settings(max_examples=200, deadline=None)
@given(
    convex_polygons(),
    st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0)),
    st.sampled_from([0.0, 1234.5]),  # near the origin, or far along a long walk
)
def test_clamp_properties(poly, p, offset):
    poly, p = poly + offset, np.array(p) + offset
    eps = 1e-12 * (1.0 + offset)  # rounding of coordinates of this size
    point, inside, margin = clamp_to_polygon(p, poly)
    assume(abs(margin) > 1e3 * eps)  # on the boundary, rounding decides either way
    # The margin's sign agrees with matplotlib's crossing-number point-in-polygon test.
    assert inside == (margin > 0) == Path(poly).contains_point(p)
    # The clamped point is in the polygon.
    assert clamp_to_polygon(point, poly).margin >= -eps
    d = math.dist(p, point)
    boundary = boundary_samples(poly)
    to_boundary = np.linalg.norm(boundary - p, axis=1)
    if inside:
        assert d == 0.0
        # The margin is the distance to the boundary: no boundary point is closer, and the dense
        # samples come within a sample spacing of it.
        spacing = max(np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1)) / 400
        assert to_boundary.min() >= margin - eps
        assert to_boundary.min() <= margin + spacing
    else:
        assert margin == pytest.approx(-d, rel=1e-12, abs=eps)
        # No point of the polygon - boundary samples, vertices, interior mixes - is closer.
        rng = np.random.default_rng(0)
        mixes = rng.dirichlet(np.ones(len(poly)), size=200) @ poly
        candidates = np.vstack([boundary, poly, mixes])
        assert np.linalg.norm(candidates - p, axis=1).min() >= d - eps
