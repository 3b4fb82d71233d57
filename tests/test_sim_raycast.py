"""Ray casting: analytic answers (wall, circle, rectangle corner), occlusion, and the kernel vs reference_sim."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from reference_sim import cast as naive_cast

from datmo_cli.sim.raycast import Primitives, cast, rectangle_segments

pytestmark = pytest.mark.unit

ANGLES = np.radians(-90 + 0.5 * np.arange(361))


def prims(segments=(), circles=()) -> Primitives:
    segs = np.array(segments, float).reshape(-1, 4)
    circ = np.array(circles, float).reshape(-1, 3)
    return Primitives(
        segs, np.arange(len(segs), dtype=np.int32), circ, np.arange(len(segs), len(segs) + len(circ), dtype=np.int32)
    )


def test_wall_at_known_distance_and_angle():
    # The line x cos(a) + y sin(a) = d, drawn as a long segment; a beam at angle phi meets it at d / cos(phi - a).
    a, d = math.radians(20.0), 3.0
    n, u = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    p, q = d * n - 50 * u, d * n + 50 * u
    t, owner = cast(np.zeros(3), ANGLES, prims([[*p, *q]]))
    expect = d / np.cos(ANGLES - a)
    hit = np.cos(ANGLES - a) > 0.1  # the segment is 100 m long: these beams all meet it
    np.testing.assert_allclose(t[0, hit], expect[hit], rtol=1e-12)
    assert np.all(owner[0, hit] == 0)
    assert t[0, np.argmin(t[0])] == pytest.approx(d, abs=d * (1 - math.cos(math.radians(0.25))))


def test_wall_seen_from_a_turned_and_moved_sensor():
    t, _ = cast(np.array([[1.0, 2.0, math.pi / 2]]), np.array([0.0, math.radians(45)]), prims([[-10, 5.0, 10, 5.0]]))
    np.testing.assert_allclose(t[0], [3.0, 3.0 * math.sqrt(2)], rtol=1e-12)


def test_circle_visible_arc_and_nearest_point():
    D, R = 4.0, 0.5
    t, owner = cast(np.zeros(3), ANGLES, prims(circles=[[D, 0.0, R]]))
    half = math.asin(R / D)
    inside = np.abs(ANGLES) < half - 1e-9
    outside = np.abs(ANGLES) > half + 1e-9
    assert np.all(owner[0, inside] == 0) and np.all(owner[0, outside] == -1)
    assert np.isinf(t[0, outside]).all()
    assert t[0, 180] == pytest.approx(D - R, abs=1e-12)  # the beam at 0° meets the nearest point
    # every hit lies on the circle
    x, y = t[0, inside] * np.cos(ANGLES[inside]), t[0, inside] * np.sin(ANGLES[inside])
    np.testing.assert_allclose(np.hypot(x - D, y), R, atol=1e-12)


def test_rectangle_corner_towards_the_sensor():
    # A 1 m square turned 45° so one corner points at the sensor from 3 m.
    c = np.array([3.0 + math.sqrt(0.5), 0.0])
    segs = rectangle_segments(c, 1.0, 1.0, np.float64(math.pi / 4))
    t, owner = cast(np.zeros(3), ANGLES, prims(segs))
    assert t[0, 180] == pytest.approx(3.0, abs=1e-12)
    # beam at angle phi > 0 meets the face through (3, 0) at 45°: range = 3 sin(45°) / sin(45° + ... )
    phi = ANGLES[181:185]
    expect = 3.0 * math.sin(math.radians(135)) / np.sin(math.radians(45) - phi)
    np.testing.assert_allclose(t[0, 181:185], expect, rtol=1e-12)
    assert set(owner[0, 181:185]) | set(owner[0, 176:180]) <= set(range(4))
    assert owner[0, 181] != owner[0, 179]  # the two sides of the corner


def test_nearer_object_occludes_farther_one():
    # a small circle at 2 m in front of a big one at 5 m: the big one's middle beams see the small one
    t, owner = cast(np.zeros(3), ANGLES, prims(circles=[[2.0, 0.0, 0.2], [5.0, 0.0, 1.0]]))
    small = np.abs(ANGLES) < math.asin(0.2 / 2.0) - 1e-9
    big = (np.abs(ANGLES) < math.asin(1.0 / 5.0) - 1e-9) & ~small
    assert np.all(owner[0, small] == 0) and np.all(owner[0, big] == 1)
    assert np.all(t[0, small] < 2.0) and np.all(t[0, big] > 4.0)


def test_moving_primitives_per_pose():
    poses = np.zeros((2, 3))
    circles = np.array([[[3.0, 0.0, 0.5]], [[6.0, 0.0, 0.5]]])
    t, owner = cast(
        poses, np.array([0.0]), Primitives.empty(), moving_circles=circles, moving_circle_owner=np.array([7])
    )
    np.testing.assert_allclose(t[:, 0], [2.5, 5.5])
    assert list(owner[:, 0]) == [7, 7]


def test_moving_rectangles_per_pose_match_naive():
    poses = np.array([[0.0, 0.0, 0.0], [0.5, -0.2, 0.3]])
    boxes = rectangle_segments(np.array([[3.0, 0.5], [2.5, -0.5]]), 0.8, 0.5, np.array([0.2, 1.0]))
    angles = ANGLES[::4]
    t, owner = cast(poses, angles, Primitives.empty(), moving_segments=boxes, moving_segment_owner=np.full(4, 9))
    for k in range(2):
        best, _, _ = naive_cast(poses[k], angles, boxes[k], np.zeros((0, 3)))
        np.testing.assert_allclose(t[k], best, rtol=1e-9)
        assert np.all(owner[k][np.isfinite(best)] == 9) and np.all(owner[k][~np.isfinite(best)] == -1)


def test_sensor_inside_a_circle_does_not_see_it():
    t, owner = cast(np.zeros(3), np.array([0.0, 1.0]), prims(circles=[[0.1, 0.0, 0.5]]))
    assert np.isinf(t).all() and (owner == -1).all()


def compare_with_naive(pose, segments, circles, angles):
    """Kernel == reference on every beam that is not a tangent or grazes a segment's end (where a turn of
    the beam by 1e-7 rad changes what it hits, and either answer is right)."""
    p = prims(segments, circles)
    t, owner = cast(np.asarray(pose, float), angles, p)
    best, who, second = naive_cast(np.asarray(pose, float), angles, p.segments, p.circles)
    lo, who_lo, _ = naive_cast(np.asarray(pose, float), angles - 1e-7, p.segments, p.circles)
    hi, who_hi, _ = naive_cast(np.asarray(pose, float), angles + 1e-7, p.segments, p.circles)
    with np.errstate(invalid="ignore"):
        steady = (who_lo == who) & (who_hi == who) & (np.isinf(lo) == np.isinf(best)) & (np.isinf(hi) == np.isinf(best))
        clear = steady & ~(second - best <= 1e-7)  # where two primitives tie, either owner is right
    np.testing.assert_allclose(t[0][steady], best[steady], rtol=1e-9, atol=1e-6)
    assert np.array_equal(owner[0][clear], who[clear])


def test_kernel_matches_naive_on_a_hand_made_scene():
    segs = [[1, -3, 1, -1], [2, -1, 4, 1], [6, -5, 6, 5], [0.5, 2, 3, 2]]
    circles = [[3, 0, 0.3], [2, 1.2, 0.2], [4.5, -2, 0.6]]
    compare_with_naive([0.1, -0.2, 0.3], segs, circles, ANGLES)


coord = st.floats(-6, 6, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(
    pose=st.tuples(coord, coord, st.floats(-math.pi, math.pi)),
    segments=st.lists(st.tuples(coord, coord, coord, coord), max_size=6),
    circles=st.lists(st.tuples(coord, coord, st.floats(0.05, 2.0)), max_size=6),
)
def test_kernel_matches_naive_on_random_scenes(pose, segments, circles):
    compare_with_naive(pose, segments, circles, ANGLES[::8])
