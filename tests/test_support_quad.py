"""The closed-form hull of a single sole (four corners round a convex quadrilateral) equals the general
hull, vertex for vertex, on rotated rectangles, arbitrary four-point sets and degenerate ones; the
combined support_and_clamp, and clamp_to_vertices on support_vertices (the simulator's kept polygon), equal
support_polygon then clamp_to_polygon."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from livezmp.balance.support import (
    SupportError,
    _quad_hull,
    clamp_to_polygon,
    clamp_to_vertices,
    convex_hull,
    support_and_clamp,
    support_polygon,
    support_vertices,
)

angle = st.floats(-math.pi, math.pi, allow_nan=False)
size = st.floats(1e-3, 0.4, allow_nan=False)
offset = st.sampled_from([0.0, 0.3, -1234.5, 1e4])


def rotation(yaw: float, pitch: float, roll: float) -> np.ndarray:
    cy, sy, cp, sp, cr, sr = math.cos(yaw), math.sin(yaw), math.cos(pitch), math.sin(pitch), math.cos(roll), \
        math.sin(roll)
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


@st.composite
def soles(draw):
    """The four corners (heel, toe, toe, heel order) of a tilted foot rectangle, in world coordinates."""
    length, width = draw(size), draw(size)
    local = np.array([[0, -width / 2, 0], [length, -width / 2, 0], [length, width / 2, 0], [0, width / 2, 0]])
    if draw(st.booleans()):
        local = local[::-1]  # the other way round
    r = rotation(draw(angle), draw(angle), draw(angle))
    return local @ r.T + np.array([draw(offset), draw(offset), 0.05])


coord = st.floats(-1.0, 1.0, allow_nan=False).map(lambda x: 0.0 if abs(x) < 1e-100 else x)
grid = st.sampled_from([0.0, 0.5, 1.0, 2.0, 1e-9])
four_points = st.one_of(
    st.lists(st.tuples(coord, coord), min_size=4, max_size=4),
    st.lists(st.tuples(grid, grid), min_size=4, max_size=4),  # repeats and exact collinearity
).map(np.array)


@settings(max_examples=500, deadline=None)
@given(st.one_of(soles(), four_points))
def test_single_sole_hull_equals_the_general_hull(sole):
    np.testing.assert_array_equal(support_polygon(sole, None, "left"), convex_hull(sole))


@settings(max_examples=300, deadline=None)
@given(soles())
def test_clear_quadrilaterals_take_the_closed_form(sole):
    # Each corner's distance to the line through its neighbours, against the largest coordinate.
    xy = sole[:, :2]
    prev, nxt = np.roll(xy, 1, axis=0), np.roll(xy, -1, axis=0)
    e, r = nxt - prev, xy - prev
    distance = np.abs(e[:, 0] * r[:, 1] - e[:, 1] * r[:, 0]) / np.hypot(e[:, 0], e[:, 1])
    if distance.min() > 1e-8 * np.abs(xy).max():
        assert _quad_hull(xy.tolist()) is not None
        assert len(support_polygon(sole, None, "left")) == 4


def test_sliver_and_collinear_quadrilaterals_fall_back():
    square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
    assert _quad_hull(square) == [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    assert _quad_hull(square[::-1]) == [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
    assert _quad_hull([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [1.0, 1.0]]) is None  # collinear
    assert _quad_hull([[0.0, 0.0], [1.0, 1e-12], [2.0, 0.0], [1.0, 1.0]]) is None  # a sliver vertex
    assert _quad_hull([[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]) is None  # a bow tie
    assert _quad_hull([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]) is None  # a repeated corner


@settings(max_examples=300, deadline=None)
@given(soles(), soles(), st.sampled_from(["left", "right", "double", "none"]),
       st.one_of(st.none(), st.tuples(st.floats(-2e4, 2e4), st.floats(-2e4, 2e4))))
def test_support_and_clamp_equals_polygon_then_clamp(left, right, support, p):
    poly, clamp = support_and_clamp(left, right, support, p)
    expected = support_polygon(left, right, support)
    np.testing.assert_array_equal(poly, expected)
    if p is None or support == "none":
        assert clamp is None
    else:
        point, inside, margin = clamp_to_polygon(p, expected)
        np.testing.assert_array_equal(clamp.point, point)
        assert (clamp.inside, clamp.margin) == (inside, margin)


@settings(max_examples=300, deadline=None)
@given(soles(), soles(), st.sampled_from(["left", "right", "double"]),
       st.tuples(st.floats(-2e4, 2e4), st.floats(-2e4, 2e4)))
def test_clamp_to_kept_vertices_equals_polygon_then_clamp(left, right, support, p):
    vertices = support_vertices(left, right, support)
    expected = support_polygon(left, right, support)
    np.testing.assert_array_equal(np.array(vertices, dtype=float).reshape(-1, 2), expected)
    point, inside, margin = clamp_to_polygon(p, expected)
    clamp = clamp_to_vertices(p, vertices)
    assert clamp.point.tobytes() == point.tobytes()
    assert (clamp.inside, clamp.margin) == (inside, margin)


def test_clamp_to_no_vertices_is_refused_as_an_empty_polygon():
    with pytest.raises(SupportError, match="empty"):
        clamp_to_vertices((0.0, 0.0), support_vertices(None, None, "none"))
