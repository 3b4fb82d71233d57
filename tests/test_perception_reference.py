"""The perception kernels against the plain references in reference_perception.py: segmentation, the HTL
accumulator, the line and circle least-squares fits, on hand-made and random inputs; then whole scans of
known geometry through extract_run (walls, legs, columns, the section 5.2 decision)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import reference_perception as ref
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.logs.vocabulary import LANDMARK_COLUMN
from datmo_cli.perception import hough_circles as HC
from datmo_cli.perception import hough_lines as HL
from datmo_cli.perception import segmentation as SEG
from datmo_cli.perception.features import extract_run, segment_run
from datmo_cli.perception.params import FeatureParams

pytestmark = pytest.mark.unit

INC = math.radians(0.5)
ANGLES = -math.pi / 2 + np.arange(361) * INC


def run_of(ranges, inc: float = INC, range_max: float = 8.0) -> ScanRun:
    ranges = np.atleast_2d(np.asarray(ranges, np.float32))
    g = ScanGeometry(-math.pi / 2, inc, ranges.shape[1], 0.0, range_max, 0.0, 0.2, "laser")
    return ScanRun(np.arange(len(ranges), dtype=np.int64) * 200_000_000, ranges, g)


def kernel_segments(r, inc=INC, c0=0.08, rmin=0.0, rmax=8.0, min_points=5) -> list[tuple[int, int]]:
    r = np.asarray(r, np.float32)
    starts, ends = np.empty(len(r) + 1, np.int64), np.empty(len(r) + 1, np.int64)
    n = SEG.segment_scan(r, math.cos(inc), c0, math.sqrt(2 * (1 - math.cos(inc))), rmin, rmax, min_points, starts, ends)
    return list(zip(starts[:n].tolist(), ends[:n].tolist(), strict=True))


ranges_strategy = arrays(
    np.float32,
    st.integers(1, 400),
    elements=st.one_of(st.floats(0.0, 9.0, width=32), st.sampled_from([np.nan, np.inf, 0.0])),
)


# --------------------------------------------------------------------------------------------- segmentation


def test_segmentation_by_hand():
    r = np.full(20, 2.0, np.float32)
    r[5] = np.nan  # an invalid return breaks the segment
    r[12:] = 4.0  # a jump of 2 m breaks it too
    assert kernel_segments(r, min_points=3) == ref.segment(r, INC, 0.08, 0.0, 8.0, 3) == [(0, 5), (6, 12), (12, 20)]
    assert kernel_segments(r, min_points=7) == [(12, 20)]


@settings(max_examples=150, deadline=None)
@given(ranges_strategy, st.sampled_from([0.25, 0.5, 1.0]), st.floats(0.0, 0.3), st.integers(1, 8))
def test_segmentation_equals_the_reference(r, inc_deg, c0, min_points):
    inc = math.radians(inc_deg)
    assert kernel_segments(r, inc, c0, 0.0, 8.0, min_points) == ref.segment(r, inc, c0, 0.0, 8.0, min_points)


def test_segment_run_uses_each_scans_geometry():
    r = np.full((2, 361), 3.0, np.float32)
    start, end, offsets = segment_run(run_of(r))
    assert offsets.tolist() == [0, 1, 2] and start.tolist() == [0, 0] and end.tolist() == [361, 361]


# --------------------------------------------------------------------------------------------- fits


@settings(max_examples=60, deadline=None)
@given(st.floats(0, math.pi - 1e-6), st.floats(0.5, 6.0), st.integers(5, 80), st.integers(0, 2**31))
def test_line_fit_equals_the_reference(theta, rho, n, seed):
    rng = np.random.default_rng(seed)
    t = rng.uniform(-2, 2, n)
    x = rho * math.cos(theta) - t * math.sin(theta) + rng.normal(0, 0.01, n)
    y = rho * math.sin(theta) + t * math.cos(theta) + rng.normal(0, 0.01, n)
    th, rh = HL.fit_line(x, y, np.arange(n), n)
    th_ref, rh_ref = ref.fit_line(x, y)
    d = (th - th_ref + math.pi / 2) % math.pi - math.pi / 2
    assert abs(d) < 1e-9
    assert abs(rh - (rh_ref if abs(th - th_ref) < 1 else -rh_ref)) < 1e-9


@settings(max_examples=40, deadline=None)
@given(st.floats(0.05, 0.4), st.floats(1.0, 5.0), st.floats(-1.0, 1.0), st.integers(0, 2**31))
def test_circle_fit_equals_the_reference(radius, dist, bearing, seed):
    rng = np.random.default_rng(seed)
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    a = np.linspace(bearing + math.pi - 1.2, bearing + math.pi + 1.2, 15)
    x = cx + radius * np.cos(a) + rng.normal(0, 0.005, 15)
    y = cy + radius * np.sin(a) + rng.normal(0, 0.005, 15)
    guess = (cx + 0.02, cy - 0.02, radius * 1.1)
    ka, kb, kr, ok = HC.fit_circle(x, y, np.arange(15), 15, *guess)
    ra, rb, rr = ref.fit_circle(x, y, guess)
    assert ok
    assert abs(ka - ra) < 1e-4 and abs(kb - rb) < 1e-4 and abs(kr - rr) < 1e-4


# --------------------------------------------------------------------------------------------- HTL accumulator


def htl_kernel_peak(x, y, n_theta: int, rho_res: float, window: int) -> tuple[int, int]:
    """(runs, votes of the first run's peak) from line_subsegments with a full or windowed accumulator."""
    n = len(x)
    cos_t, sin_t = np.cos(np.arange(n_theta) * math.pi / n_theta), np.sin(np.arange(n_theta) * math.pi / n_theta)
    acc = np.zeros((n_theta, 2000), np.int32)
    cell = np.empty(n, np.int64)
    HL.normal_cells(x, y, 0, n, n_theta, cell)
    sub_s, sub_e, peaks = np.empty(256, np.int64), np.empty(256, np.int64), np.empty((256, 3), np.int64)
    hough = (acc, np.empty(n_theta), np.zeros(n_theta, np.bool_))
    hist = np.empty((n, 3), np.int64)
    runs = HL.line_subsegments(x, y, 0, n, hough, cos_t, sin_t, rho_res, window, cell, (sub_s, sub_e, peaks), hist)
    assert not acc.any()  # the accumulator is left clean for the next segment
    return runs, int(peaks[0, 0])


@settings(max_examples=40, deadline=None)
@given(st.floats(0.1, math.pi - 0.1), st.floats(1.0, 6.0), st.integers(6, 60), st.integers(0, 2**31))
def test_full_accumulator_peak_equals_the_reference(theta, rho, n, seed):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(-1.5, 1.5, n))
    x = rho * math.cos(theta) - t * math.sin(theta) + rng.normal(0, 0.005, n)
    y = rho * math.sin(theta) + t * math.cos(theta) + rng.normal(0, 0.005, n)
    runs, votes = htl_kernel_peak(x, y, 120, 0.02, 60)  # window of the whole half turn: the paper's HTL
    assert runs == 1
    assert votes == ref.htl_peak_line(x, y, 120, 0.02)[2]


def test_corner_gives_two_runs_that_meet_at_the_corner():
    # an L: 40 points along y = 2 from x = -1 to 1, then 40 points along x = 1 from y = 2 down to 0.4
    x = np.concatenate([np.linspace(-1, 1, 40), np.full(40, 1.0)])
    y = np.concatenate([np.full(40, 2.0), np.linspace(1.96, 0.4, 40)])
    runs, _ = htl_kernel_peak(x, y, 120, 0.02, 7)
    assert runs == 2


# --------------------------------------------------------------------------------------------- whole scans


def noisy(r: np.ndarray, sigma: float, seed: int) -> np.ndarray:
    return (r + np.random.default_rng(seed).normal(0, sigma, r.shape)).astype(np.float32)


def test_a_wall_is_one_line_within_a_degree_and_two_centimetres():
    theta, rho = math.radians(70), 3.0
    clean = ref.ray_wall(ANGLES, rho, theta)
    clean[clean > 7.9] = np.inf
    scans = np.stack([noisy(clean, 0.01, s) for s in range(30)])
    f = extract_run(run_of(scans), landmarks=False)
    assert np.all(np.diff(f.line_offsets) >= 1)
    longest = [
        f.lines[a:b][np.argmax(f.lines[a:b]["length"])]
        for a, b in zip(f.line_offsets[:-1], f.line_offsets[1:], strict=True)
    ]
    ang = [abs((ln["theta"] - theta + math.pi / 2) % math.pi - math.pi / 2) for ln in longest]
    dist = [abs(ln["rho"] - rho) for ln in longest]
    assert math.degrees(np.median(ang)) < 1.0 and np.median(dist) < 0.02
    assert len(f.circles) == 0


@pytest.mark.parametrize("radius, dist, min_points", [(0.10, 2.0, 5), (0.10, 3.5, 5), (0.25, 3.0, 5)])
def test_circles_in_front_of_a_wall(radius, dist, min_points):
    wall = ref.ray_wall(ANGLES, 6.0, math.pi / 2 - 0.3)
    wall[wall > 7.9] = np.inf
    circ = ref.ray_circle(ANGLES, dist * math.cos(0.2), dist * math.sin(0.2), radius)
    scans = np.stack([noisy(np.minimum(wall, circ), 0.01, s) for s in range(30)])
    f = extract_run(run_of(scans), FeatureParams(min_points=min_points), landmarks=False)
    cx, cy = dist * math.cos(0.2), dist * math.sin(0.2)
    d = np.hypot(f.circles["x"] - cx, f.circles["y"] - cy)
    near = f.circles[d < 0.1]
    assert len(near) >= 25  # found in nearly every scan, as a circle
    assert np.median(d[d < 0.1]) < 0.03
    assert np.median(np.abs(near["radius"] - radius)) < 0.02


def test_the_decision_rule_keeps_flat_walls_as_lines_and_clutter_as_blobs():
    r = np.full(361, np.inf, np.float32)
    r[100:160] = ref.ray_wall(ANGLES[100:160], 2.5, math.radians(-20)).astype(np.float32)  # a wall
    r[200:206] = [3.0, 3.3, 3.0, 3.3, 3.0, 3.3]  # a saw-tooth: no line of more than 3 points, no circle
    f = extract_run(run_of(r), FeatureParams(c0=0.5), landmarks=False)
    assert len(f.lines) == 1 and f.lines[0]["first"] >= 100 and f.lines[0]["last"] < 160
    assert len(f.circles) == 0
    assert len(f.blobs) == 1 and f.blobs[0]["first"] == 200 and f.blobs[0]["last"] == 205
    assert 0.3 < f.blobs[0]["size"] < 0.4


def test_a_free_standing_column_is_one_landmark_and_a_moving_circle_none():
    wall = ref.ray_wall(ANGLES, 7.0, math.pi / 2)
    wall[wall > 7.9] = np.inf
    still = np.stack([noisy(np.minimum(wall, ref.ray_circle(ANGLES, 3.0, 1.0, 0.25)), 0.01, s) for s in range(40)])
    f = extract_run(run_of(still))
    db = f.landmarks.final()
    cols = db[db["type"] == LANDMARK_COLUMN]
    assert len(cols) == 1 and math.hypot(cols[0]["x"] - 3.0, cols[0]["y"] - 1.0) < 0.03
    moving = np.stack(
        [noisy(np.minimum(wall, ref.ray_circle(ANGLES, 3.0, -1.5 + 0.2 * k, 0.25)), 0.01, k) for k in range(40)]
    )
    f = extract_run(run_of(moving))
    assert not np.any(f.landmarks.final()["type"] == LANDMARK_COLUMN)
