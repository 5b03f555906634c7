"""quadruped_control.control.strokes.base: the pieces every stroke scheme shares (cubic time profile,
recorded stroke paths, the hold template)."""
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from quadruped_control.control.strokes.base import StrokePath, arc_length_segment, cubic_time_profile
from quadruped_control.control.strokes.coordinated import CoordinatedStrokes
from quadruped_control.control.strokes.paper import StrokeCycle
from quadruped_control.model.params import load_robot_params

PARAMS = load_robot_params()


def test_cubic_time_profile():
    assert cubic_time_profile(0.0) == 0.0 and cubic_time_profile(1.0) == 1.0
    assert cubic_time_profile(-0.5) == 0.0 and cubic_time_profile(2.0) == 1.0
    assert cubic_time_profile(0.5) == 0.5
    assert cubic_time_profile(0.25) == pytest.approx(3 * 0.0625 - 2 * 0.015625)
    h = 1e-6  # zero slope at both ends, slope 1.5 in the middle
    assert cubic_time_profile(h) / h < 1e-5
    assert (1.0 - cubic_time_profile(1.0 - h)) / h < 1e-5
    assert (cubic_time_profile(0.5 + h) - cubic_time_profile(0.5 - h)) / (2 * h) == pytest.approx(1.5)


def test_stroke_path_arc_length_interpolation():
    path = StrokePath((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    path.append((0.0, 0.0, 0.0), (9.0, 9.0, 9.0))   # duplicate: ignored
    path.append((3.0, 0.0, 0.0), (2.0, 2.0, 2.0))
    path.append((3.0, 4.0, 0.0), (3.0, 3.0, 3.0))
    assert path.length == 7.0 and len(path.points) == 3
    assert path.at_arc_length(-1.0) == ((0.0, 0.0, 0.0), 0)
    assert path.at_arc_length(1.0) == ((1.0, 0.0, 0.0), 0)
    assert path.at_arc_length(3.0) == ((3.0, 0.0, 0.0), 1)
    assert path.at_arc_length(6.0) == ((3.0, 3.0, 0.0), 2)
    assert path.at_arc_length(99.0) == ((3.0, 4.0, 0.0), 2)
    single = StrokePath((1.0, 2.0, 3.0), (0.0, 0.0, 0.0))
    assert single.length == 0.0 and single.at_arc_length(0.5) == ((1.0, 2.0, 3.0), 0)


@pytest.mark.parametrize("scheme", [StrokeCycle, CoordinatedStrokes])
def test_hold_counts_its_time_and_treats_bad_steps_as_zero(scheme):
    strokes = scheme(PARAMS)
    strokes.hold(0.01)
    assert strokes.holding and strokes.hold_time == 0.0  # the first call enters the hold
    strokes.hold(0.01)
    strokes.hold(math.nan)
    strokes.hold(-1.0)
    assert strokes.hold_time == pytest.approx(0.01)
    assert strokes.pair_phase_time == (strokes.hold_time, strokes.hold_time)
    for _ in range(400):
        strokes.hold(0.01)
    assert strokes.at_rest and strokes.foot_targets() == strokes.nominal


@given(st.lists(st.floats(0.001, 1.0), min_size=1, max_size=60), st.floats(0.0, 1.0))
def test_arc_length_segment_finds_the_segment_bisect_finds(steps, fraction):
    """The compiled retrace's search and the robot's bisect pick the same segment for every arc length
    strictly inside the path (the endpoints are handled before either is called)."""
    import bisect

    cumulative = [0.0]
    for step in steps:
        cumulative.append(cumulative[-1] + step)
    a = fraction * cumulative[-1]
    if not 0.0 < a < cumulative[-1]:
        return
    assert arc_length_segment(cumulative, len(cumulative), a) == bisect.bisect_right(cumulative, a) - 1
    # and on a recorded cumulative value itself (bisect_right: that point's own segment)
    k = int(fraction * (len(cumulative) - 2)) if len(cumulative) > 2 else 0
    if 0.0 < cumulative[k] < cumulative[-1]:
        assert arc_length_segment(cumulative, len(cumulative), cumulative[k]) == k
