"""A circle is a well-posed arc: enough points for its size, a fit clearly better than a line's
(and than the segment's HTL lines: a corner), a radius not pinned at a bound. The kernel's test against the
plain reference, then whole scans: a 3-point arc at the radius floor and a wall corner are no circles, a
well-sampled leg and a column still are."""

from __future__ import annotations

import math

import numpy as np
import pytest
import reference_perception as ref
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.perception import hough_circles as HC
from datmo_cli.perception.features import extract_run
from datmo_cli.perception.params import FeatureParams

pytestmark = pytest.mark.unit

OFF = FeatureParams().replace(
    circle_min_coverage=0, circle_residual_ratio=0, circle_radius_margin=0, circle_lines_ratio=0
)  # the rule before the well-posedness tests


def run_of(clean: np.ndarray, inc: float, n: int = 40, sigma: float = 0.01, seed: int = 1) -> ScanRun:
    noisy = clean[None, :] + np.random.default_rng(seed).normal(0.0, sigma, (n, clean.size))
    g = ScanGeometry(-math.pi / 2, inc, clean.size, 0.0, 8.0, 0.0, 0.2, "laser")
    return ScanRun(np.arange(n, dtype=np.int64) * 200_000_000, noisy.astype(np.float32), g)


def angles(step_deg: float) -> np.ndarray:
    return -math.pi / 2 + np.arange(int(round(180 / step_deg)) + 1) * math.radians(step_deg)


def circles_near(f, x: float, y: float, within: float) -> int:
    return int((np.hypot(f.circles["x"] - x, f.circles["y"] - y) < within).sum())


# ----------------------------------------------------------------------------------------------- kernel = reference


@settings(max_examples=150, deadline=None)
@given(
    st.floats(0.03, 0.5),
    st.floats(0.5, 5.0),
    st.floats(-1.2, 1.2),
    st.floats(0.2, 3.0),
    st.integers(3, 25),
    st.floats(0.0, 0.02),
    st.integers(0, 2**31),
    st.sampled_from([0.0, 0.4, 0.6, 1.0]),
    st.sampled_from([0.0, 0.5, 0.8, 1.2]),
    st.sampled_from([0.0, 0.005, 0.01, 0.03]),
    st.sampled_from([0.0, 1.0]),
    st.sampled_from([0.25, 0.5, 1.0]),
    st.integers(0, 2),
)
def test_circle_posed_equals_the_reference(
    radius, dist, bearing, half_arc, n, sigma, seed, cover, ratio, margin, lines_ratio, step_deg, n_lines
):
    rng = np.random.default_rng(seed)
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    phi = math.atan2(-cy, -cx) + np.linspace(-half_arc / 2, half_arc / 2, n)
    x = cx + radius * np.cos(phi) + rng.normal(0, sigma, n)
    y = cy + radius * np.sin(phi) + rng.normal(0, sigma, n)
    circle = (cx + rng.normal(0, 0.01), cy + rng.normal(0, 0.01), radius * rng.uniform(0.8, 1.2))
    lines = [(float(rng.uniform(0, math.pi)), float(rng.uniform(-1, 5))) for _ in range(n_lines)]
    p = FeatureParams().replace(
        circle_min_coverage=cover,
        circle_residual_ratio=ratio,
        circle_radius_margin=margin,
        circle_lines_ratio=lines_ratio,
    )
    vec = p.kernel_vector()
    # keep away from ties at a threshold, where float rounding decides
    d = math.hypot(circle[0], circle[1])
    need = cover * (math.pi if circle[2] >= d else 2 * math.asin(circle[2] / d)) / math.radians(step_deg)
    assume(abs(n - need) > 1e-6)
    assume(min(abs(circle[2] - p.circle_radius_min - margin), abs(circle[2] - p.circle_radius_max + margin)) > 1e-9)
    rss_c = float(np.sum((np.hypot(x - circle[0], y - circle[1]) - circle[2]) ** 2))
    t, rho = ref.fit_line(list(x), list(y))
    rss_l = float(np.sum((x * math.cos(t) + y * math.sin(t) - rho) ** 2))
    assume(abs(math.sqrt(rss_c) - ratio * math.sqrt(rss_l)) > 1e-7)
    rss_h = (
        sum(
            min(abs(px * math.cos(a) + py * math.sin(a) - r) for a, r in lines) ** 2
            for px, py in zip(x, y, strict=True)
        )
        if lines
        else -1.0
    )
    if lines:
        assume(abs(math.sqrt(rss_c) - lines_ratio * math.sqrt(rss_h)) > 1e-7)
    got = HC.circle_posed(x, y, np.arange(n), n, *circle, vec, math.radians(step_deg), rss_h)
    assert got == ref.circle_well_posed(list(x), list(y), circle, p, math.radians(step_deg), lines)


def test_every_test_is_off_at_zero():
    x = np.array([2.0, 1.97, 2.0])
    y = np.array([-0.05, 0.0, 0.05])
    vec = OFF.kernel_vector()
    # pinned at the floor, three points for a wide circle, worse than a line: all allowed when off
    assert HC.circle_posed(x, y, np.arange(3), 3, 2.05, 0.0, 0.05, vec, math.radians(0.1), 0.0)
    assert not HC.circle_posed(
        x, y, np.arange(3), 3, 2.05, 0.0, 0.05, FeatureParams().kernel_vector(), math.radians(0.1), 0.0
    )


# ----------------------------------------------------------------------------------------------- whole scans


def test_a_3_point_arc_at_the_radius_floor_is_no_circle():
    """A thin post (3 cm radius) 1.5 m away: 3-4 beams of a 0.5° scan, a fit pinned at circle_radius_min.
    The old rule made circles of it; the well-posed rule does not."""
    a = angles(0.5)
    clean = np.minimum(ref.ray_wall(a, 6.0, math.pi / 2 + 0.1), ref.ray_circle(a, 1.5, 0.3, 0.03))
    run = run_of(clean, math.radians(0.5))
    before = extract_run(run, OFF, landmarks=False)
    after = extract_run(run, landmarks=False)
    assert circles_near(before, 1.5, 0.3, 0.1) >= 5  # 10 of 40 scans with the old rule
    assert circles_near(after, 1.5, 0.3, 0.1) == 0


@pytest.mark.parametrize(
    "arm, dist, rot", [(0.25, 1.0, 0.0), (0.25, 1.0, 0.3), (0.25, 2.0, 0.0), (0.25, 2.0, 0.3), (0.3, 1.5, 0.0)]
)
def test_a_wall_corner_is_no_circle(arm, dist, rot):
    """A convex corner (two 25-30 cm walls at 90°, its vertex towards the scanner) in a 0.5° scan: two HTL
    lines fit it better than a circle."""
    a = angles(0.5)
    v = np.array([dist, 0.3])
    d1 = np.array([math.cos(math.pi / 4 + rot), math.sin(math.pi / 4 + rot)])
    d2 = np.array([math.cos(-math.pi / 4 + rot), math.sin(-math.pi / 4 + rot)])
    corner = np.minimum(ref.ray_segment(a, v, v + arm * d1), ref.ray_segment(a, v, v + arm * d2))
    run = run_of(np.minimum(ref.ray_wall(a, 6.0, math.pi / 2 + 0.1), corner), math.radians(0.5))
    mx, my = v + 0.25 * arm * (d1 + d2)
    assert circles_near(extract_run(run, landmarks=False), mx, my, 0.3) == 0


@pytest.mark.parametrize("step_deg", [0.5, 1.0])
@pytest.mark.parametrize("radius, dist", [(0.1, 1.0), (0.1, 2.5), (0.25, 2.0), (0.25, 4.0), (0.2, 3.0)])
def test_a_well_sampled_leg_or_column_is_still_a_circle(step_deg, radius, dist):
    a = angles(step_deg)
    clean = np.minimum(ref.ray_wall(a, 6.0, math.pi / 2 + 0.1), ref.ray_circle(a, dist, 0.3, radius))
    run = run_of(clean, math.radians(step_deg))
    f = extract_run(run, landmarks=False)
    assert circles_near(f, dist, 0.3, 0.1) == len(run)  # in every scan, as with the old rule
    near = np.hypot(f.circles["x"] - dist, f.circles["y"] - 0.3) < 0.1
    assert abs(float(np.median(f.circles["radius"][near])) - radius) < 0.02
