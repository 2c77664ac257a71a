"""The plain-float paths of contact detection equal what numpy gives: the warm-up percentile of the
ground height, the lowest sole corner, and the checks on sole input."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from livezmp.balance.contacts import ContactDetector, ContactError, GroundConfig, GroundEstimator, percentile_of_sorted

heights = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(st.lists(heights, min_size=1, max_size=80), st.floats(min_value=0.0, max_value=100.0))
def test_percentile_of_sorted_equals_numpy_percentile(values, percentile):
    assert percentile_of_sorted(sorted(values), percentile) == np.percentile(values, percentile)


@settings(max_examples=50, deadline=None)
@given(st.lists(heights, min_size=1, max_size=70), st.sampled_from([0.0, 5.0, 37.5, 50.0, 100.0]))
def test_ground_warm_up_is_numpys_percentile_at_every_frame(values, percentile):
    est = GroundEstimator(GroundConfig(warmup_frames=60, percentile=percentile, track_step=0.001))
    previous = None
    for k, z in enumerate(values):
        got = est.update(z)
        if k < 60:
            assert got == np.percentile(values[: k + 1], percentile)
        else:  # after the warm-up: one tracking step from the previous estimate
            assert abs(got - previous) == pytest.approx(0.001 * (percentile / 100 if z >= previous else
                                                                 1 - percentile / 100), abs=1e-12)
        previous = got


def test_lowest_corner_is_the_first_of_equal_heights_and_its_speed_is_used():
    det = ContactDetector(ground=GroundConfig(override=0.0))
    sole = np.array([[0.0, 0.0, 0.02], [0.2, 0.0, 0.0], [0.2, 0.1, 0.0], [0.0, 0.1, 0.02]])
    vel = np.array([[9.0, 0.0, 0.0], [0.3, 0.4, 7.0], [5.0, 5.0, 0.0], [9.0, 0.0, 0.0]])
    # corners 1 and 2 are the lowest; corner 1 counts: 0.5 m/s, under speed_off (1 m/s), not corner 2's 7 m/s
    assert det.update(sole, vel, sole, vel) == "double"
    det2 = ContactDetector(ground=GroundConfig(override=0.0))
    assert det2.update(sole, vel[[1, 0, 2, 3]], sole, vel) == "right"  # the left foot's corner 1 now: 9 m/s


def test_huge_but_finite_sole_is_not_called_non_finite():
    # The sum of these coordinates overflows; they are still finite numbers.
    det = ContactDetector(ground=GroundConfig(override=0.0))
    sole = np.array([[1e308, 1e308, 0.0], [1e308, -1e307, 0.0]])
    assert det.update(sole, np.zeros(3), sole, np.zeros(3)) == "double"


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_sole_coordinate_names_its_row(bad):
    det = ContactDetector(ground=GroundConfig(override=0.0))
    sole = np.zeros((4, 3))
    sole[2, 0] = bad
    with pytest.raises(ContactError, match="frame 0: right sole: row 2 has a non-finite coordinate"):
        det.update(np.zeros((4, 3)), np.zeros(3), sole, np.zeros(3))


def test_update_lowest_equals_update_on_a_noisy_two_foot_sequence():
    rng = np.random.default_rng(4)
    a, b = ContactDetector(), ContactDetector()  # warm-up ground estimate, debouncing, hysteresis
    for k in range(400):
        phase = (k % 60) / 60
        feet = []
        for side in (0, 1):
            lift = max(0.0, math.sin(2 * math.pi * (phase + 0.5 * side))) * 0.08
            sole = np.array([[0.0, 0.1 * side, 0.0], [0.25, 0.1 * side, 0.0], [0.25, 0.1 * side + 0.1, 0.01],
                             [0.0, 0.1 * side + 0.1, 0.01]]) + [0.0, 0.0, lift]
            sole += rng.normal(scale=0.003, size=sole.shape)
            feet += [sole, rng.normal(scale=0.3 + 5 * lift, size=(4, 3))]
        lowest = []
        for sole, vel in zip(feet[::2], feet[1::2], strict=True):
            i = int(np.argmin(sole[:, 2]))
            lowest += [sole[i, 2], math.hypot(vel[i, 0], vel[i, 1])]
        outside = (True, False) if k % 97 == 5 else None
        assert a.update(*feet, contacts=outside) == b.update_lowest(*lowest, contacts=outside)
        assert a.ground_height == b.ground_height and (a.left, a.right) == (b.left, b.right)


@pytest.mark.parametrize("values", [(math.nan, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0, math.inf), (0.0, "fast", 0.0, 0.0)])
def test_update_lowest_rejects_non_finite_values(values):
    det = ContactDetector()
    with pytest.raises(ContactError, match="frame 0: lowest sole point heights and speeds must be finite"):
        det.update_lowest(*values)
    assert det.frame == 0
