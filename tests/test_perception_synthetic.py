"""extract_run on synthetic scans of known geometry (walls, a box corner, legs of radius 0.1 m and columns of
radius 0.25 m in front of a wall), ray-cast analytically by reference_perception and given Gaussian range noise of
1 cm from fixed seeds; the section 5.2 decision rule; the landmark database on a static and a moving column.
Bounds are looser than the paper's: medians over many scans."""

from __future__ import annotations

import math

import numpy as np
import pytest
import reference_perception as ref

from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.logs.vocabulary import LANDMARK_BENCH, LANDMARK_COLUMN, LANDMARK_LINE_END
from datmo_cli.perception.features import extract_run

pytestmark = pytest.mark.unit

INC = math.radians(0.5)
ANGLE_MIN = -math.pi / 2
ANGLES = ANGLE_MIN + np.arange(361) * INC
RANGE_MAX = 8.0
N_SCANS = 30


def run_of(ranges: np.ndarray, inc: float = INC, angle_min: float = ANGLE_MIN, dt_ns: int = 200_000_000) -> ScanRun:
    ranges = np.atleast_2d(np.asarray(ranges, np.float32))
    g = ScanGeometry(
        angle_min=angle_min,
        angle_increment=inc,
        n_beams=ranges.shape[1],
        range_min=0.0,
        range_max=RANGE_MAX,
        scan_time=0.2,
        frame_id="laser",
    )
    return ScanRun(
        stamps=np.arange(len(ranges), dtype=np.int64) * dt_ns,
        ranges=ranges,
        geometry=g,
        intensities=np.zeros((len(ranges), 0), np.float32),
    )


def noisy_scans(clean: np.ndarray, n: int = N_SCANS, sigma: float = 0.01, seed: int = 1234) -> np.ndarray:
    """n scans of the clean ranges with Gaussian noise; beams out of range stay invalid (inf)."""
    rng = np.random.default_rng(seed)
    out = np.repeat(clean[None, :], n, axis=0) + rng.normal(0, sigma, (n, len(clean)))
    out[:, ~(clean < RANGE_MAX - 0.05)] = np.inf
    return out.astype(np.float32)


def scan_lines(f, k: int) -> np.ndarray:
    return f.lines[f.line_offsets[k] : f.line_offsets[k + 1]]


def scan_circles(f, k: int) -> np.ndarray:
    return f.circles[f.circle_offsets[k] : f.circle_offsets[k + 1]]


def scan_blobs(f, k: int) -> np.ndarray:
    return f.blobs[f.blob_offsets[k] : f.blob_offsets[k + 1]]


# ----------------------------------------------------------------------------------------------- walls


@pytest.mark.parametrize("theta_deg, rho", [(0.0, 3.0), (70.0, 2.5), (-40.0 % 180.0, 4.0), (100.0, 1.5), (35.0, 6.0)])
def test_a_wall_is_found_within_1_5_degrees_and_3_cm(theta_deg, rho):
    theta = math.radians(theta_deg)
    f = extract_run(run_of(noisy_scans(ref.ray_wall(ANGLES, rho, theta))), landmarks=False)
    ang, dist = [], []
    for k in range(N_SCANS):
        lines = scan_lines(f, k)
        assert len(lines) >= 1
        best = lines[np.argmax(lines["length"])]
        dth, drho = ref.same_line(float(best["theta"]), float(best["rho"]), theta, rho)
        ang.append(dth)
        dist.append(drho)
    assert math.degrees(np.median(ang)) < 1.5 and np.median(dist) < 0.03
    assert len(f.circles) == 0


def test_two_perpendicular_walls_give_two_lines_meeting_at_the_corner():
    corner = (3.0, 0.5)
    a = ref.ray_segment(ANGLES, corner, (1.5, 2.0))  # 2.1 m of wall to the left
    b = ref.ray_segment(ANGLES, corner, (1.8, -0.7))  # 1.7 m of wall to the right, perpendicular
    f = extract_run(run_of(noisy_scans(np.minimum(a, b))), landmarks=False)
    hits = 0
    for k in range(N_SCANS):
        lines = scan_lines(f, k)
        big = lines[lines["length"] > 0.5]
        if len(big) != 2:
            continue
        hits += 1
        assert big[0]["segment"] == big[1]["segment"]  # one segment, two lines
        t0, t1 = float(big[0]["theta"]), float(big[1]["theta"])
        assert abs(abs(ref.angle_diff(t0, t1)) - math.pi / 2) < math.radians(3)
        px, py = ref.intersect(t0, float(big[0]["rho"]), t1, float(big[1]["rho"]))
        assert math.hypot(px - corner[0], py - corner[1]) < 0.05
    assert hits >= 0.9 * N_SCANS


def test_a_box_with_a_short_side_gives_two_lines():
    corner = (2.5, 0.0)
    long_side = ref.ray_segment(ANGLES, corner, (2.5 - 2.0 * math.cos(math.pi / 4), -2.0 * math.sin(math.pi / 4)))
    short_side = ref.ray_segment(ANGLES, corner, (2.5 - 0.3 * math.cos(math.pi / 4), 0.3 * math.sin(math.pi / 4)))
    f = extract_run(run_of(noisy_scans(np.minimum(long_side, short_side), sigma=0.003)), landmarks=False)
    two = sum(len(scan_lines(f, k)) == 2 for k in range(N_SCANS))
    assert two >= 0.8 * N_SCANS  # got 0 of 30: one line per scan


# ----------------------------------------------------------------------------------------------- circles


def circles_near(f, cx: float, cy: float, within: float = 0.15) -> tuple[np.ndarray, int]:
    """The circle nearest (cx, cy) of each scan, where one lies within `within`; and in how many scans."""
    found = []
    for k in range(len(f)):
        c = scan_circles(f, k)
        if len(c):
            d = np.hypot(c["x"] - cx, c["y"] - cy)
            if d.min() < within:
                found.append(c[np.argmin(d)])
    return np.array(found, dtype=f.circles.dtype), len(found)


@pytest.mark.parametrize("dist, bearing", [(1.0, 0.0), (1.5, 0.3), (2.5, -0.5), (3.5, 0.2), (4.0, -0.1)])
def test_legs_within_4_m_are_circles_within_4_cm(dist, bearing):
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    clean = np.minimum(ref.ray_wall(ANGLES, 7.0, math.pi / 2 - 0.2), ref.ray_circle(ANGLES, cx, cy, 0.1))
    f = extract_run(run_of(noisy_scans(clean)), landmarks=False)
    legs, n = circles_near(f, cx, cy)
    assert n >= 0.6 * N_SCANS
    assert np.median(np.hypot(legs["x"] - cx, legs["y"] - cy)) < 0.04
    assert np.median(np.abs(legs["radius"] - 0.1)) < 0.03


@pytest.mark.parametrize("dist, bearing", [(1.5, 0.0), (2.5, 0.6), (4.0, -0.4), (5.5, 0.1)])
def test_columns_are_circles_within_4_cm(dist, bearing):
    cx, cy = dist * math.cos(bearing), dist * math.sin(bearing)
    clean = np.minimum(ref.ray_wall(ANGLES, 7.5, math.pi / 2 + 0.1), ref.ray_circle(ANGLES, cx, cy, 0.25))
    f = extract_run(run_of(noisy_scans(clean)), landmarks=False)
    cols, n = circles_near(f, cx, cy)
    assert n >= 0.8 * N_SCANS
    assert np.median(np.hypot(cols["x"] - cx, cols["y"] - cy)) < 0.04
    assert np.median(np.abs(cols["radius"] - 0.25)) < 0.03


def test_two_legs_side_by_side_are_two_circles():
    legs = [(2.0, 0.15), (2.0, -0.15)]
    clean = ref.ray_wall(ANGLES, 6.0, 0.0)
    for cx, cy in legs:
        clean = np.minimum(clean, ref.ray_circle(ANGLES, cx, cy, 0.1))
    f = extract_run(run_of(noisy_scans(clean)), landmarks=False)
    for cx, cy in legs:
        found, n = circles_near(f, cx, cy, 0.08)
        assert n >= 0.8 * N_SCANS


# ----------------------------------------------------------------------------------------------- section 5.2


def segment_of(f, k: int, beam: int) -> int:
    """Index (within scan k) of the segment holding `beam`, -1 if none."""
    a, b = f.seg_offsets[k], f.seg_offsets[k + 1]
    for g in range(b - a):
        if f.seg_start[a + g] <= beam < f.seg_end[a + g]:
            return g
    return -1


def test_the_decision_rule_arc_circle_wall_lines_clutter_blob():
    r = np.full(361, np.inf)
    # a flat wall on beams 20..110
    r[20:110] = ref.ray_wall(ANGLES[20:110], 3.0, math.radians(-55))
    # an arc: a column of radius 0.25 at 2 m, bearing 0.2 rad
    col = ref.ray_circle(ANGLES, 2.0 * math.cos(0.2), 2.0 * math.sin(0.2), 0.25)
    # a small irregular cluster (clutter, 18 cm wide, 8 cm deep) around 2.5 m on beams 280..288: no four
    # points on a line, no arc
    clutter = [2.5, 2.57, 2.52, 2.58, 2.5, 2.56, 2.51, 2.58, 2.5]
    r = np.minimum(r, col)
    r[280:289] = clutter
    scans = np.stack([r, r]).astype(np.float32)
    f = extract_run(run_of(scans), landmarks=False)
    arc_beam = int(np.flatnonzero(np.isfinite(col))[len(np.flatnonzero(np.isfinite(col))) // 2])
    for k in range(2):
        lines, circles, blobs = scan_lines(f, k), scan_circles(f, k), scan_blobs(f, k)
        g_wall, g_arc, g_clutter = segment_of(f, k, 60), segment_of(f, k, arc_beam), segment_of(f, k, 284)
        assert len({g_wall, g_arc, g_clutter}) == 3 and min(g_wall, g_arc, g_clutter) >= 0
        # the arc is a circle and nothing else
        assert np.sum(circles["segment"] == g_arc) == 1
        assert not np.any(lines["segment"] == g_arc) and not np.any(blobs["segment"] == g_arc)
        c = circles[circles["segment"] == g_arc][0]
        assert math.hypot(c["x"] - 2.0 * math.cos(0.2), c["y"] - 2.0 * math.sin(0.2)) < 0.03
        # the wall is line(s) and nothing else
        assert np.sum(lines["segment"] == g_wall) >= 1
        assert not np.any(circles["segment"] == g_wall) and not np.any(blobs["segment"] == g_wall)
        # the clutter is a blob
        assert np.sum(blobs["segment"] == g_clutter) == 1
        assert not np.any(circles["segment"] == g_clutter) and not np.any(lines["segment"] == g_clutter)
        b = blobs[blobs["segment"] == g_clutter][0]
        assert b["kind"] == 0 and b["n_points"] == 9 and b["first"] == 280 and b["last"] == 288
        xs, ys = ref.points(r[280:289], ANGLES[280:289])
        assert abs(b["x"] - xs.mean()) < 1e-4 and abs(b["y"] - ys.mean()) < 1e-4


def test_every_segment_is_exactly_one_kind_of_feature():
    """Lines (one or more), or one circle, or one blob: never two kinds for one segment."""
    clean = ref.ray_wall(ANGLES, 6.0, math.pi / 2 - 0.3)
    for cx, cy, rad in ((2.0, 0.5, 0.1), (3.0, -1.0, 0.25), (1.5, 1.5, 0.1)):
        clean = np.minimum(clean, ref.ray_circle(ANGLES, cx, cy, rad))
    f = extract_run(run_of(noisy_scans(clean)), landmarks=False)
    for k in range(N_SCANS):
        nseg = f.seg_offsets[k + 1] - f.seg_offsets[k]
        kinds = np.zeros((nseg, 3), int)
        for j, items in enumerate((scan_lines(f, k), scan_circles(f, k), scan_blobs(f, k))):
            for g in items["segment"]:
                kinds[g, j] += 1
        assert np.all((kinds > 0).sum(axis=1) == 1)
        assert np.all(kinds[:, 1] <= 1) and np.all(kinds[:, 2] <= 1)


# ----------------------------------------------------------------------------------------------- landmarks


def test_a_free_standing_column_is_one_landmark_at_its_place():
    cx, cy = 3.0, 0.8
    clean = ref.ray_circle(ANGLES, cx, cy, 0.25)  # open space behind it: nothing else in range
    f = extract_run(run_of(noisy_scans(clean, n=20)))
    db = f.landmarks.final()
    cols = db[db["type"] == LANDMARK_COLUMN]
    assert len(cols) == 1
    assert math.hypot(cols[0]["x"] - cx, cols[0]["y"] - cy) < 0.04
    assert abs(cols[0]["size"] - 0.25) < 0.03
    assert cols[0]["count"] >= 15


def test_a_column_in_front_of_a_far_wall_is_one_landmark():
    cx, cy = 2.5, -0.6
    clean = np.minimum(ref.ray_wall(ANGLES, 7.0, 0.0), ref.ray_circle(ANGLES, cx, cy, 0.25))
    f = extract_run(run_of(noisy_scans(clean, n=20)))
    cols = f.landmarks.final()
    cols = cols[cols["type"] == LANDMARK_COLUMN]
    assert len(cols) == 1 and math.hypot(cols[0]["x"] - cx, cols[0]["y"] - cy) < 0.04


def test_a_circle_moving_20_cm_per_scan_is_no_landmark():
    scans = []
    for k in range(20):
        clean = ref.ray_circle(ANGLES, 3.0, -2.0 + 0.2 * k, 0.25)
        scans.append(noisy_scans(clean, n=1, seed=k)[0])
    f = extract_run(run_of(np.stack(scans)))
    assert len(f.circles) >= 15  # it is seen, as a circle, in most scans
    assert not np.any(f.landmarks.final()["type"] == LANDMARK_COLUMN)
    assert not np.any(f.landmarks.rows[:, 0] == LANDMARK_COLUMN) or np.all(
        (f.landmarks.rows[f.landmarks.rows[:, 0] == LANDMARK_COLUMN, 5] < 3)
        | (f.landmarks.rows[f.landmarks.rows[:, 0] == LANDMARK_COLUMN, 10] != 0)
    )


@pytest.mark.parametrize("dropouts", [[150], [140, 141], [175, 176, 177, 210]])
def test_dropouts_on_a_wall_make_no_line_ends_benches_or_columns(dropouts):
    """Beams that return nothing in the middle of a wall (a dark patch, a glass pane) break it into pieces of
    a bench's length, but the wall continues beyond them at its range: no piece stands free, no end is seen."""
    clean = ref.ray_wall(ANGLES, 3.0, 0.0)
    scans = noisy_scans(clean, n=20)
    scans[:, dropouts] = np.nan
    scans[:, 195] = 0.0  # an invalid return of another kind (below range_min)
    f = extract_run(run_of(scans))
    assert len(f.lines) >= 3 * 20  # the pieces are seen as lines
    types = f.landmarks.final()["type"]
    assert not np.isin(types, [LANDMARK_LINE_END, LANDMARK_BENCH, LANDMARK_COLUMN]).any(), types
