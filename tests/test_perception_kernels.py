"""Each numba kernel of datmo_cli/perception/_kernels.py against the plain references of reference_perception.py:
segmentation, total least squares line fit, geometric circle fit, the full HTL accumulator, line splitting
and refinement, HTC voting; on hand-made inputs and on random ones (hypothesis)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import reference_perception as ref
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from datmo_cli.perception import feature_layout as FL
from datmo_cli.perception import hough_circles as HC
from datmo_cli.perception import hough_lines as HL
from datmo_cli.perception import segmentation as SEG
from datmo_cli.perception.params import FeatureParams

pytestmark = pytest.mark.unit

INC = math.radians(0.5)
N_THETA = 120  # 1.5 degree theta cells, the default
RHO_RES = 0.02


# ----------------------------------------------------------------------------------------------- helpers


def kernel_segments(r, inc=INC, c0=0.08, rmin=0.0, rmax=8.0, min_points=5) -> list[tuple[int, int]]:
    r = np.asarray(r, np.float32)
    starts = np.empty(len(r) + 1, np.int64)
    ends = np.empty(len(r) + 1, np.int64)
    n = SEG.segment_scan(r, math.cos(inc), c0, ref.c1_of(inc), rmin, rmax, min_points, starts, ends)
    return list(zip(starts[:n].tolist(), ends[:n].tolist(), strict=True))


def kernel_runs(x, y, n_theta=N_THETA, rho_res=RHO_RES, window_deg=10.0):
    """line_subsegments on all the points: (runs [(s, e)], peaks [(votes, t, k)], toff, accumulator)."""
    x = np.ascontiguousarray(x, np.float64)
    y = np.ascontiguousarray(y, np.float64)
    n = len(x)
    theta = np.arange(n_theta) * (np.pi / n_theta)
    cos_t, sin_t = np.cos(theta), np.sin(theta)
    acc = np.zeros((n_theta, 2000), np.int32)
    cell = np.empty(n, np.int64)
    HL.normal_cells(x, y, 0, n, n_theta, cell)
    toff = np.empty(n_theta)
    sub_s, sub_e = np.empty(FL.MAX_SUB, np.int64), np.empty(FL.MAX_SUB, np.int64)
    peaks = np.empty((FL.MAX_SUB, 3), np.int64)
    kwin = int(math.radians(window_deg) / (np.pi / n_theta))
    hough = (acc, toff, np.zeros(n_theta, np.bool_))
    hist = np.empty((n, 3), np.int64)
    m = HL.line_subsegments(x, y, 0, n, hough, cos_t, sin_t, rho_res, kwin, cell, (sub_s, sub_e, peaks), hist)
    runs = list(zip(sub_s[:m].tolist(), sub_e[:m].tolist(), strict=True))
    return runs, [tuple(int(v) for v in peaks[k]) for k in range(m)], toff, acc


def kernel_lines(x, y, n_theta=N_THETA, rho_res=RHO_RES, window_deg=10.0) -> list[np.ndarray]:
    """line_of_run on every run of line_subsegments: out vectors [n, first, last, x0, y0, x1, y1, rho, theta,
    length, r_acc, r_acc of the peak]."""
    x = np.ascontiguousarray(x, np.float64)
    y = np.ascontiguousarray(y, np.float64)
    runs, peaks, toff, _ = kernel_runs(x, y, n_theta, rho_res, window_deg)
    out = []
    idx = np.empty(len(x), np.int64)
    for (s, e), (votes, t, k) in zip(runs, peaks, strict=True):
        o = np.empty(12)
        HL.line_of_run(x, y, s, e, t * np.pi / n_theta, toff[t] + (k + 0.5) * rho_res, votes, rho_res, idx, o)
        out.append(o)
    return out


def line_points(theta, rho, t):
    """Points at positions t along the line x cos(theta) + y sin(theta) = rho."""
    return rho * math.cos(theta) - t * math.sin(theta), rho * math.sin(theta) + t * math.cos(theta)


def wall_scan(theta, rho, a0, a1, inc=INC, sigma=0.0, seed=0):
    """Points of a scan of the wall (theta, rho) over beam angles a0..a1."""
    angles = np.arange(a0, a1, inc)
    r = ref.ray_wall(angles, rho, theta)
    r = r + np.random.default_rng(seed).normal(0, sigma, len(r)) if sigma else r
    return ref.points(r, angles)


# ----------------------------------------------------------------------------------------------- segmentation


def test_segmentation_by_hand():
    r = np.full(30, 2.0, np.float32)
    r[5] = np.nan  # invalid returns break a segment
    r[9] = np.inf
    r[12:20] = 4.0  # a jump of 2 m breaks it too
    r[25] = 0.0  # <= range_min
    r[27] = 8.0  # >= range_max
    want = [(0, 5), (12, 20), (20, 25)]
    assert ref.segment(r, INC, 0.08, 0.0, 8.0, 5) == want
    assert kernel_segments(r) == want
    assert (
        kernel_segments(r, min_points=1)
        == ref.segment(r, INC, 0.08, 0.0, 8.0, 1)
        == [(0, 5), (6, 9), (10, 12), (12, 20), (20, 25), (26, 27), (28, 30)]
    )


def test_threshold_is_c0_plus_c1_min_range():
    # two beams at 4 m and 4 m + jump: joined exactly while the jump stays under C0 + C1 * 4 (+ the chord)
    inc = math.radians(1.0)
    c0 = 0.05
    limit = c0 + ref.c1_of(inc) * 4.0
    for d in (0.5 * limit, 0.95 * limit, 1.05 * limit, 2 * limit):
        b = np.float32(4.0 + d)
        r = np.array([4.0, b], np.float32)
        joined = ref.point_distance(4.0, float(b), inc) <= limit
        assert (kernel_segments(r, inc, c0, min_points=1) == [(0, 2)]) == joined
        assert ref.segment(r, inc, c0, 0.0, 8.0, 1) == kernel_segments(r, inc, c0, min_points=1)


SPECIAL = st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1e6, 8.0, -1.0])
RANGES = arrays(
    np.float32,
    st.integers(1, 300),
    elements=st.one_of(st.floats(0.0, 9.0, width=32), SPECIAL, st.floats(2.0, 2.25, width=32)),
)


@settings(max_examples=100, deadline=None)
@given(
    RANGES,
    st.sampled_from([0.25, 0.5, 1.0, 0.352]),
    st.floats(0.0, 0.3),
    st.integers(1, 8),
    st.sampled_from([(0.0, 8.0), (0.05, 30.0), (0.0, math.inf)]),
)
def test_segment_boundaries_equal_the_reference(r, inc_deg, c0, min_points, limits):
    inc = math.radians(inc_deg)
    lo, hi = limits
    assert kernel_segments(r, inc, c0, lo, hi, min_points) == ref.segment(r, inc, c0, lo, hi, min_points)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**31), st.integers(2, 400))
def test_segment_boundaries_equal_the_reference_on_smooth_scenes(seed, n):
    # piecewise smooth ranges with jumps, like a room: most boundaries are decided by the threshold, not NaNs
    rng = np.random.default_rng(seed)
    r = np.cumsum(rng.normal(0, 0.02, n)) + 3.0
    jumps = rng.random(n) < 0.05
    r += np.cumsum(jumps * rng.normal(0, 1.0, n))
    r = np.clip(r, 0.1, 7.5).astype(np.float32)
    assert kernel_segments(r, min_points=3) == ref.segment(r, INC, 0.08, 0.0, 8.0, 3)


# ----------------------------------------------------------------------------------------------- fits


@settings(max_examples=80, deadline=None)
@given(
    st.floats(0, math.pi, exclude_max=True),
    st.floats(-6.0, 6.0),
    st.integers(3, 80),
    st.integers(0, 2**31),
    st.sampled_from([0.0, 0.001, 0.01, 0.05]),
)
def test_fit_line_equals_total_least_squares(theta, rho, n, seed, sigma):
    rng = np.random.default_rng(seed)
    t = rng.uniform(-2, 2, n)
    x, y = line_points(theta, rho, t)
    x = x + rng.normal(0, sigma, n)
    y = y + rng.normal(0, sigma, n)
    idx = rng.permutation(n + 5)[:n]  # fit_line reads x[idx[k]]: scatter the points
    bx, by = np.zeros(n + 5), np.zeros(n + 5)
    bx[idx], by[idx] = x, y
    th, rh = HL.fit_line(bx, by, idx, n)
    th_ref, rh_ref = ref.fit_line(list(x), list(y))
    assert 0 <= th < math.pi
    dth, drho = ref.same_line(th, rh, th_ref, rh_ref)
    assert dth < 1e-9 and drho < 1e-9


def test_fit_line_of_exact_points_is_the_line():
    for theta in (0.0, 0.3, math.pi / 2, 2.0, math.pi - 1e-3):
        x, y = line_points(theta, 2.5, np.linspace(-1, 1, 11))
        th, rh = HL.fit_line(x, y, np.arange(11), 11)
        dth, drho = ref.same_line(th, rh, theta, 2.5)
        assert dth < 1e-12 and drho < 1e-12


@settings(max_examples=60, deadline=None)
@given(
    st.floats(0.05, 0.4),
    st.floats(0.7, 5.0),
    st.floats(-1.5, 1.5),
    st.floats(0.6, 1.5),
    st.integers(6, 40),
    st.integers(0, 2**31),
)
def test_fit_circle_equals_the_geometric_fit(radius, dist, bearing, half_arc, n, seed):
    # well posed only where the arc bulges well beyond the noise (3 mm) over its points: a flatter arc has
    # no distinct best circle, and the kernel (which then says not ok) and the reference stop anywhere
    assume(radius * (1 - math.cos(half_arc)) * math.sqrt(n) > 0.05)
    rng = np.random.default_rng(seed)
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    a = np.linspace(bearing + math.pi - half_arc, bearing + math.pi + half_arc, n)
    x = cx + radius * np.cos(a) + rng.normal(0, 0.003, n)
    y = cy + radius * np.sin(a) + rng.normal(0, 0.003, n)
    # a Hough-like start: within a cell (1 cm) of the truth
    guess = (cx + 0.006, cy - 0.005, radius + 0.007)
    ka, kb, kr, ok = HC.fit_circle(x, y, np.arange(n), n, *guess)
    ra, rb, rr = ref.fit_circle(x, y, guess)
    assert ok
    # the kernel stops once a Gauss-Newton step moves less than 10 µm in all; the reference iterates on
    assert abs(ka - ra) < 1e-5 and abs(kb - rb) < 1e-5 and abs(kr - rr) < 1e-5


def test_fit_circle_refuses_degenerate_input():
    x = np.array([1.0, 1.0, 1.0])
    y = np.array([0.0, 0.0, 0.0])
    *_, ok = HC.fit_circle(x, y, np.arange(3), 3, 1.0, 0.0, 0.1)  # the start at a point: no gradient
    assert not ok
    x, y = line_points(0.4, 2.0, np.linspace(-0.3, 0.3, 9))  # collinear points: no finite circle
    a, b, r, ok = HC.fit_circle(x, y, np.arange(9), 9, 2.0 * math.cos(0.4) + 0.2, 2.0 * math.sin(0.4), 0.2)
    assert not ok or r > 10


# ----------------------------------------------------------------------------------------------- HTL


def test_reference_accumulator_by_hand():
    # three points on the vertical line x = 1: at theta = 0 all fall in one rho cell
    acc, (votes, t, k) = ref.htl_accumulator([1.0, 1.0, 1.0], [0.0, 0.1, 0.2], 4, 0.05)
    assert votes == 3 and t == 0
    assert acc[(0, k)] == 3 and sum(acc.values()) == 3 * 4


@settings(max_examples=50, deadline=None)
@given(
    st.floats(0.0, math.pi, exclude_max=True),
    st.floats(0.8, 6.0),
    st.integers(6, 50),
    st.integers(0, 2**31),
    st.sampled_from([0.0, 0.003, 0.008]),
)
def test_full_window_voting_peak_equals_the_full_accumulator(theta, rho, n, seed, sigma):
    """vote_window = 90 degrees: every point votes in every theta cell, the paper's HTL."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(-1.2, 1.2, n))
    x, y = line_points(theta, rho, t)
    x = x + rng.normal(0, sigma, n)
    y = y + rng.normal(0, sigma, n)
    runs, peaks, toff, acc = kernel_runs(x, y, window_deg=90.0)
    assert not acc.any()  # the accumulator is left clean for the next segment
    assert runs == [(0, n)]
    _, peak = ref.htl_accumulator(list(x), list(y), N_THETA, RHO_RES)
    assert peaks[0] == peak
    lo, _ = ref.box_rho_offsets(list(x), list(y), N_THETA, RHO_RES)
    assert np.allclose(toff, lo, rtol=0, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(st.floats(0.0, math.pi, exclude_max=True), st.floats(0.8, 6.0), st.integers(8, 50), st.integers(0, 2**31))
def test_windowed_voting_peak_is_a_full_accumulator_cell(theta, rho, n, seed):
    """Voting only near each point's normal never invents votes: the windowed peak is at most the full one,
    and on a clean line it finds the same count."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(-1.2, 1.2, n))
    x, y = line_points(theta, rho, t)
    x = x + rng.normal(0, 0.003, n)
    y = y + rng.normal(0, 0.003, n)
    runs, peaks, _, _ = kernel_runs(x, y, window_deg=10.0)
    acc, peak = ref.htl_accumulator(list(x), list(y), N_THETA, RHO_RES)
    assert runs == [(0, n)]
    votes, tc, kc = peaks[0]
    assert votes <= acc.get((tc, kc), 0) <= peak[0]


@pytest.mark.parametrize(
    "theta_deg, rho", [(0.0, 2.0), (30.0, 3.0), (89.0, 1.5), (90.0, 2.5), (135.0, 1.0), (179.0, 4.0)]
)
def test_noise_free_straight_segment_is_one_line(theta_deg, rho):
    theta = math.radians(theta_deg)
    x, y = wall_scan(theta, rho, theta - 0.5, theta + 0.5)
    lines = kernel_lines(x, y)
    assert len(lines) == 1
    o = lines[0]
    dth, drho = ref.same_line(o[8], o[7], theta, rho)
    assert dth < 1e-9 and drho < 1e-9
    assert o[0] >= 0.95 * len(x) and o[10] > 0.95
    assert o[1] == 0 and o[2] == len(x) - 1
    assert abs(o[9] - math.hypot(x[-1] - x[0], y[-1] - y[0])) < 1e-9
    # the HTL peak line itself is within a cell of the truth
    t_peak, r_peak, _ = ref.htl_peak_line(list(x), list(y), N_THETA, RHO_RES)
    dth, drho = ref.same_line(t_peak, r_peak, theta, rho)
    assert dth <= math.pi / N_THETA and drho < 2 * RHO_RES + 0.05


def l_corner(rot: float, len_first: float, len_second: float, dist: float = 3.0):
    """Points of two perpendicular walls meeting at a corner `dist` away at bearing `rot`, facing the scanner;
    the wall of length len_first comes first in scan order. Returns (x, y, corner)."""
    corner = (dist * math.cos(rot), dist * math.sin(rot))
    ends = []
    for length, turn in ((len_first, -3 * math.pi / 4), (len_second, 3 * math.pi / 4)):
        ends.append((corner[0] + length * math.cos(rot + turn), corner[1] + length * math.sin(rot + turn)))
    angles = np.arange(rot - 1.2, rot + 1.2, INC)
    r = np.minimum(ref.ray_segment(angles, corner, ends[0]), ref.ray_segment(angles, corner, ends[1]))
    ok = np.isfinite(r)
    x, y = ref.points(r[ok], angles[ok])
    return x, y, corner


@pytest.mark.parametrize("rotation_deg", [0.0, 20.0, 45.0, 70.0, 110.0])
def test_l_shaped_corner_gives_two_lines_meeting_at_the_corner(rotation_deg):
    x, y, corner = l_corner(math.radians(rotation_deg), 1.5, 1.5)
    lines = [o for o in kernel_lines(x, y) if o[0] > 3 and o[9] > 0.1]
    assert len(lines) == 2
    a, b = lines
    px, py = ref.intersect(a[8], a[7], b[8], b[7])
    assert math.hypot(px - corner[0], py - corner[1]) < 0.01
    assert abs(abs(ref.angle_diff(a[8], b[8])) - math.pi / 2) < math.radians(0.5)
    for o in (a, b):
        assert o[10] > 0.9
    # the first line ends at the corner; the second starts within corner_gap (0.3 m) of it
    assert math.hypot(a[5] - corner[0], a[6] - corner[1]) < 0.03
    assert math.hypot(b[3] - corner[0], b[4] - corner[1]) < 0.3


def test_l_shaped_corner_second_line_starts_at_the_corner():
    x, y, corner = l_corner(0.0, 1.5, 1.5)
    a, b = [o for o in kernel_lines(x, y) if o[0] > 3 and o[9] > 0.1]
    # within two beam spacings (3.7 cm along this wall): the point next to the corner is within the first
    # line's two-cell band, so it stays with it (before the fix: 0.19 m, four corner points dropped)
    assert math.hypot(b[3] - corner[0], b[4] - corner[1]) < 0.08


@pytest.mark.parametrize("short", [0.25, 0.3])
def test_box_corner_with_a_short_second_side_gives_two_lines(short):
    x, y, corner = l_corner(0.0, 2.0, short, dist=2.5)
    lines = [o for o in kernel_lines(x, y) if o[0] > 3 and o[9] > 0.1 and o[10] > 0.5]
    assert len(lines) == 2  # got one line: the 2 m wall, whose r_acc (0.91) still passes


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, math.pi, exclude_max=True), st.floats(1.0, 5.0), st.integers(0, 2**31))
def test_noisy_wall_is_one_line_near_the_truth(theta, rho, seed):
    x, y = wall_scan(theta, rho, theta - 0.35, theta + 0.35, sigma=0.01, seed=seed)
    lines = [o for o in kernel_lines(x, y) if o[0] > 3 and o[10] > 0.5 and o[9] > 0.1]
    assert lines
    best = max(lines, key=lambda o: o[0])
    dth, drho = ref.same_line(best[8], best[7], theta, rho)
    assert math.degrees(dth) < 3.0 and drho < 0.05
    # line_of_run's fit is the reference refinement of its run's HTL peak
    runs, peaks, toff, _ = kernel_runs(x, y)
    k = max(range(len(runs)), key=lambda j: runs[j][1] - runs[j][0])
    (s, e), (_votes, t, c) = runs[k], peaks[k]
    o = kernel_lines(x, y)[k]
    th_ref, rh_ref, used = ref.refine_line(
        list(x[s:e]), list(y[s:e]), t * math.pi / N_THETA, toff[t] + (c + 0.5) * RHO_RES, RHO_RES
    )
    assert len(used) == o[0]
    dth, drho = ref.same_line(o[8], o[7], th_ref, rh_ref)
    assert dth < 1e-9 and drho < 1e-9


def test_line_end_points_are_those_of_the_fitted_points():
    theta, rho = 2.0, 2.0
    x, y = wall_scan(theta, rho, theta - 0.35, theta + 0.35, sigma=0.01, seed=4684)
    runs, peaks, toff, _ = kernel_runs(x, y)
    (s, e), (_votes, t, c) = runs[0], peaks[0]
    o = kernel_lines(x, y)[0]
    _, _, used = ref.refine_line(
        list(x[s:e]), list(y[s:e]), t * math.pi / N_THETA, toff[t] + (c + 0.5) * RHO_RES, RHO_RES
    )
    assert len(used) == o[0] == 76
    assert (s + used[0], s + used[-1]) == (o[1], o[2])  # got last = 79, a point of the unused second pass


@pytest.mark.parametrize("seed", [433, 1449])
def test_a_line_never_has_more_points_than_beams_it_spans(seed):
    rng = np.random.default_rng(seed)
    theta, rho = rng.uniform(0, math.pi), rng.uniform(1, 5)
    x, y = wall_scan(theta, rho, theta - 0.2, theta + 0.2, sigma=0.01, seed=seed)
    for o in kernel_lines(x, y):
        assert o[0] <= o[2] - o[1] + 1  # got 46 points on beams 1..45 (433), 45 on beams 2..45 (1449)


# ----------------------------------------------------------------------------------------------- HTC

PVEC = FeatureParams().kernel_vector()


def kernel_circle(x, y, p=PVEC, beat=-1.0) -> np.ndarray:
    x = np.ascontiguousarray(x, np.float64)
    y = np.ascontiguousarray(y, np.float64)
    w = int(round(p[FL.FP_CIRCLE_WINDOW] / p[FL.FP_CIRCLE_CELL]))
    out = np.zeros(5)
    HC.circle_of_run(
        x, y, 0, len(x), p, np.zeros((2 * w + 1, 2 * w + 1), np.int32), np.empty(len(x), np.int64), out, beat
    )
    return out


def arc_scan(cx, cy, radius, inc=INC, sigma=0.0, seed=0):
    bearing = math.atan2(cy, cx)
    angles = np.arange(bearing - 0.5, bearing + 0.5, inc)
    r = ref.ray_circle(angles, cx, cy, radius)
    ok = np.isfinite(r)
    r = r[ok] + (np.random.default_rng(seed).normal(0, sigma, int(ok.sum())) if sigma else 0.0)
    return ref.points(r, angles[ok])


@pytest.mark.parametrize("radius", [0.1, 0.25])
@pytest.mark.parametrize("dist, bearing", [(1.0, 0.0), (2.0, 0.5), (3.0, -1.0), (1.5, 2.0)])
def test_circle_of_run_recovers_a_noise_free_arc(radius, dist, bearing):
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    x, y = arc_scan(cx, cy, radius)
    out = kernel_circle(x, y)
    assert out[0] == len(x) and out[4] == 1.0
    assert math.hypot(out[1] - cx, out[2] - cy) < 1e-3 and abs(out[3] - radius) < 1e-3


@settings(max_examples=40, deadline=None)
@given(st.sampled_from([0.1, 0.25]), st.floats(0.8, 3.5), st.floats(-1.5, 1.5), st.integers(0, 2**31))
def test_circle_of_run_recovers_a_noisy_arc(radius, dist, bearing, seed):
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    x, y = arc_scan(cx, cy, radius, sigma=0.005, seed=seed)
    out = kernel_circle(x, y)
    assert out[0] >= 3 and out[4] > 0.5
    assert math.hypot(out[1] - cx, out[2] - cy) < 0.04 and abs(out[3] - radius) < 0.03


@settings(max_examples=40, deadline=None)
@given(st.sampled_from([0.09, 0.13, 0.25]), st.floats(0.8, 3.0), st.floats(-1.5, 1.5), st.integers(0, 2**31))
def test_circle_votes_equal_the_reference_window(radius, dist, bearing, seed):
    """With a single radius allowed, circle_of_run votes in the window around the chord's centre estimate:
    its peak votes are the reference HTC's."""
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    x, y = arc_scan(cx, cy, radius, sigma=0.004, seed=seed)
    p = PVEC.copy()
    p[FL.FP_CIRCLE_RADIUS_MIN] = radius
    p[FL.FP_CIRCLE_RADIUS_MAX] = radius + 0.001
    out = kernel_circle(x, y, p)
    if out[4] == 0.0:
        return  # the arc's chord and sagitta rule the radius out: nothing voted
    ca, cb = ref.chord_centre(x[0], y[0], x[-1], y[-1], radius)
    w = int(round(p[FL.FP_CIRCLE_WINDOW] / p[FL.FP_CIRCLE_CELL]))
    _, (votes, ia, ib) = ref.htc_window(
        list(x), list(y), ca, cb, radius, w, p[FL.FP_CIRCLE_CELL], p[FL.FP_CIRCLE_TOLERANCE]
    )
    assert round(out[4] * len(x)) == votes


def test_circle_of_run_rejects_a_flat_wall_and_too_few_points():
    x, y = wall_scan(0.3, 2.0, 0.1, 0.4)
    assert kernel_circle(x, y)[4] == 0.0  # no sagitta: not an arc
    assert kernel_circle(x[:2], y[:2])[4] == 0.0  # under three points


def test_reference_circle_through_three_points():
    a, b, r = ref.circle_through((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0))
    assert abs(a) < 1e-12 and abs(b) < 1e-12 and abs(r - 1.0) < 1e-12
