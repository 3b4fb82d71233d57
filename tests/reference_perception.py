"""Slow, plain references for datmo's perception kernels, written to be read, not for speed: loops over
points and segments, numpy only for small linear algebra, scipy for the circle fit. No numba.

- Features (docs/method.md §4 and §5, followed literally; datmo_cli/perception/segmentation.py, hough_lines.py,
  hough_circles.py and scan_extractor.py): segmentation,
  the Hough transform for lines and its refinement, circles; the scene helpers ray-cast walls and circles
  analytically, for synthetic scans of known geometry.
- The leg detector (datmo_cli/perception/leg_features.py and leg_forest.py): segment features one segment at a
  time, in the feature order of legs.FEATURE_NAMES, and tree-ensemble evaluation.
- Ego-motion (datmo_cli/perception/scan_odometry.py and icp.py): scan points and their thinning, line normals from
  beam neighbours, brute-force nearest map points, one Gauss-Newton linearisation of the robust
  point-to-line cost, and the whole ICP. A pose (x, y, theta) maps a sensor point p to R(theta) p + (x, y).

Sensor frame (x forward, y left) and the map frame, metres, radians.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares

from datmo_cli.perception.feature_layout import (
    CC_N,
    CC_R,
    CC_RACC,
    CC_X,
    CC_Y,
    LC_LEN,
    LC_N,
    LC_PEAK_RACC,
    LC_RACC,
    LC_RHO,
    LC_THETA,
    LC_X0,
    LC_X1,
    LC_Y0,
    LC_Y1,
)
from datmo_cli.perception.legs import (
    CANDIDATE_MAX_WIDTH,
    CANDIDATE_MIN_POINTS,
    DENSITY_CLIP,
    FEATURE_NAMES,
    JUMP_CLIP,
    NEIGHBOUR_CLIP,
    OCCLUSION_MARGIN,
    RADIUS_CLIP,
)

MIN_MATCHES = 12
CONVERGED_STEP, CONVERGED_TURN = 2e-4, 5e-5  # m, rad


# ----------------------------------------------------------------------------------------------- section 4


def is_valid(r: float, range_min: float, range_max: float) -> bool:
    """A return that counts: finite and strictly between the range limits."""
    return math.isfinite(r) and range_min < r < range_max


def c1_of(angle_increment: float) -> float:
    """C1 = sqrt(2 (1 - cos delta_alpha)): the chord of the angle step at unit range."""
    return math.sqrt(2.0 * (1.0 - math.cos(angle_increment)))


def point_distance(r_i: float, r_j: float, angle_increment: float) -> float:
    """d(P_i, P_i+1) by the law of cosines."""
    return math.sqrt(max(r_j * r_j + r_i * r_i - 2.0 * r_j * r_i * math.cos(angle_increment), 0.0))


def segment(
    ranges, angle_increment: float, c0: float, range_min: float, range_max: float, min_points: int
) -> list[tuple[int, int]]:
    """Segments [start, end) of one scan. P_i+1 joins P_i's segment when both are valid returns and
    d(P_i, P_i+1) <= C0 + C1 min(r_i, r_i+1); segments of fewer than min_points points are dropped."""
    c1 = c1_of(angle_increment)
    groups: list[list[int]] = []
    current: list[int] = []
    for i in range(len(ranges)):
        r = float(ranges[i])
        if not is_valid(r, range_min, range_max):
            if current:
                groups.append(current)
            current = []
            continue
        if current:
            prev = float(ranges[current[-1]])
            if point_distance(prev, r, angle_increment) > c0 + c1 * min(prev, r):
                groups.append(current)
                current = []
        current.append(i)
    if current:
        groups.append(current)
    return [(g[0], g[-1] + 1) for g in groups if len(g) >= min_points]


def blob(x, y) -> tuple[float, float, float]:
    """A blob's centroid and size (m): the largest distance from the point farthest from its first point
    (the first of equal ones), at least that farthest distance itself."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    d0 = (x - x[0]) ** 2 + (y - y[0]) ** 2
    far = int(np.argmax(d0))
    d1 = (x - x[far]) ** 2 + (y - y[far]) ** 2
    return float(x.mean()), float(y.mean()), math.sqrt(max(float(d0[far]), float(d1.max())))


# ----------------------------------------------------------------------------------------------- HTL


def theta_table(n_theta: int) -> list[float]:
    """The theta cells of an accumulator over [0, pi)."""
    return [t * math.pi / n_theta for t in range(n_theta)]


def box_rho_offsets(x, y, n_theta: int, rho_res: float) -> tuple[list[float], int]:
    """The accumulator adapted to the points' bounding box: for each theta cell the smallest rho a corner of
    the box gives, and how many rho cells the box's diagonal spans (plus two)."""
    xmin, xmax, ymin, ymax = min(x), max(x), min(y), max(y)
    lo = []
    for th in theta_table(n_theta):
        c, s = math.cos(th), math.sin(th)
        lo.append(min(xmin * c, xmax * c) + min(ymin * s, ymax * s))
    width = int(math.hypot(xmax - xmin, ymax - ymin) / rho_res) + 2
    return lo, width


def htl_accumulator(
    x, y, n_theta: int, rho_res: float, windows=None
) -> tuple[dict[tuple[int, int], int], tuple[int, int, int]]:
    """Full Hough accumulator for lines: every point votes in every theta cell (or, with `windows`, point i
    in the theta cells windows[i] in that order), in the rho cell of rho = x cos(theta) + y sin(theta)
    counted from the box's smallest rho. Returns the accumulator {(theta cell, rho cell): votes} and its
    peak (votes, theta cell, rho cell); of equal cells, the peak is the one that reached its count first
    (points in order, theta cells in order)."""
    lo, width = box_rho_offsets(x, y, n_theta, rho_res)
    inv = 1.0 / rho_res
    acc: dict[tuple[int, int], int] = {}
    peak = (0, 0, 0)
    thetas = theta_table(n_theta)
    for i, (px, py) in enumerate(zip(x, y, strict=True)):
        for t in range(n_theta) if windows is None else windows[i]:
            th = thetas[t]
            k = int((px * math.cos(th) + py * math.sin(th) - lo[t]) * inv)
            k = min(max(k, 0), width - 1)
            acc[(t, k)] = acc.get((t, k), 0) + 1
            if acc[(t, k)] > peak[0]:
                peak = (acc[(t, k)], t, k)
    return acc, peak


def htl_peak_line(x, y, n_theta: int, rho_res: float) -> tuple[float, float, int]:
    """The peak line of the points: (theta, rho at the centre of the peak rho cell, votes)."""
    lo, _ = box_rho_offsets(x, y, n_theta, rho_res)
    _, (votes, t, k) = htl_accumulator(x, y, n_theta, rho_res)
    return t * math.pi / n_theta, lo[t] + (k + 0.5) * rho_res, votes


def fit_line(x, y) -> tuple[float, float]:
    """Total least squares: (theta in [0, pi), rho) of x cos(theta) + y sin(theta) = rho, the normal being the
    eigenvector of the smallest eigenvalue of the scatter matrix."""
    n = len(x)
    cx = sum(x) / n
    cy = sum(y) / n
    sxx = sum((xi - cx) ** 2 for xi in x)
    syy = sum((yi - cy) ** 2 for yi in y)
    sxy = sum((xi - cx) * (yi - cy) for xi, yi in zip(x, y, strict=True))
    w, v = np.linalg.eigh(np.array([[sxx, sxy], [sxy, syy]]))
    nx, ny = v[0, 0], v[1, 0]
    theta = math.atan2(ny, nx) % math.pi
    return theta, cx * math.cos(theta) + cy * math.sin(theta)


def line_distances(x, y) -> list[float]:
    """Each point's distance (m) from the total-least-squares line of the points."""
    theta, rho = fit_line(x, y)
    return [abs(xi * math.cos(theta) + yi * math.sin(theta) - rho) for xi, yi in zip(x, y, strict=True)]


def one_line(x, y, tol: float, tail: int) -> bool:
    """The points hold one line: their total-least-squares line lies within tol (m) of 90 % of them and of
    each of the last `tail` points."""
    d = line_distances(x, y)
    return sum(di <= tol for di in d) >= 0.9 * len(d) and all(di <= tol for di in d[len(d) - tail :])


def refine_line(x, y, theta_p: float, rho_p: float, rho_res: float) -> tuple[float, float, list[int]]:
    """The HTL peak line refined by least squares: the points within a rho cell of the peak line are fitted;
    the points within a rho cell of that fit, when more, are fitted again. Returns (theta, rho, points used)."""

    def near(theta, rho):
        c, s = math.cos(theta), math.sin(theta)
        return [i for i in range(len(x)) if abs(x[i] * c + y[i] * s - rho) <= rho_res]

    used = near(theta_p, rho_p)
    theta, rho = fit_line([x[i] for i in used], [y[i] for i in used])
    again = near(theta, rho)
    if len(again) > len(used):
        used = again
        theta, rho = fit_line([x[i] for i in used], [y[i] for i in used])
    return theta, rho, used


def angle_diff(a: float, b: float) -> float:
    """Difference of two line normal angles modulo pi, in [-pi/2, pi/2)."""
    return (a - b + math.pi / 2) % math.pi - math.pi / 2


def same_line(theta_a: float, rho_a: float, theta_b: float, rho_b: float) -> tuple[float, float]:
    """(angle difference, rho difference) of two lines in normal form, allowing (theta, rho) ~ (theta +- pi, -rho)."""
    d = angle_diff(theta_a, theta_b)
    if abs(theta_a - theta_b) > math.pi / 2:
        return abs(d), abs(rho_a + rho_b)
    return abs(d), abs(rho_a - rho_b)


def intersect(theta_a: float, rho_a: float, theta_b: float, rho_b: float) -> tuple[float, float]:
    """Where two lines in normal form cross."""
    m = np.array([[math.cos(theta_a), math.sin(theta_a)], [math.cos(theta_b), math.sin(theta_b)]])
    px, py = np.linalg.solve(m, [rho_a, rho_b])
    return float(px), float(py)


# ----------------------------------------------------------------------------------------------- HTC


def fit_circle(x, y, guess: tuple[float, float, float]) -> tuple[float, float, float]:
    """Geometric least squares circle (a, b, r): minimise sum (|p - c| - r)^2 (scipy)."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    res = least_squares(
        lambda q: np.hypot(x - q[0], y - q[1]) - q[2],
        np.asarray(guess, float),
        xtol=1e-14,
        ftol=1e-14,
        gtol=1e-14,
        method="lm",
    )
    return float(res.x[0]), float(res.x[1]), float(res.x[2])


def circle_through(p0, p1, p2) -> tuple[float, float, float]:
    """The circle through three points (e.g. P_ini, P_near, P_end)."""
    (ax, ay), (bx, by), (cx, cy) = p0, p1, p2
    d = 2.0 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    ux = ((ax * ax + ay * ay) * (by - cy) + (bx * bx + by * by) * (cy - ay) + (cx * cx + cy * cy) * (ay - by)) / d
    uy = ((ax * ax + ay * ay) * (cx - bx) + (bx * bx + by * by) * (ax - cx) + (cx * cx + cy * cy) * (bx - ax)) / d
    return ux, uy, math.hypot(ax - ux, ay - uy)


def chord_centre(x0: float, y0: float, x1: float, y1: float, radius: float) -> tuple[float, float]:
    """The centre of the circle of `radius` through P_ini and P_end that lies beyond the chord, away from the
    scanner (the side P_near bulges from)."""
    chord = math.hypot(x1 - x0, y1 - y0)
    mx, my = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    nx, ny = (y1 - y0) / chord, -(x1 - x0) / chord
    if nx * mx + ny * my < 0:
        nx, ny = -nx, -ny
    h = math.sqrt(max(radius * radius - (0.5 * chord) ** 2, 0.0))
    return mx + nx * h, my + ny * h


def htc_window(
    x, y, ca: float, cb: float, radius: float, w: int, cell: float, tol: float
) -> tuple[list[list[int]], tuple[int, int, int]]:
    """HTC with known radius in a window of (2w + 1)^2 centre cells of size `cell` around (ca, cb): a point
    votes for a centre when its distance to it is within `tol` of the radius. Returns the votes
    (votes[ia][ib], centre ca + (ia - w) cell, cb + (ib - w) cell) and the peak (votes, ia, ib); of equal
    cells the one nearest the window's centre, then the first."""
    size = 2 * w + 1
    lo2 = max(radius - tol, 0.0) ** 2
    hi2 = (radius + tol) ** 2
    votes = [[0] * size for _ in range(size)]
    for px, py in zip(x, y, strict=True):
        for ia in range(size):
            for ib in range(size):
                dx = px - (ca + (ia - w) * cell)
                dy = py - (cb + (ib - w) * cell)
                if lo2 <= dx * dx + dy * dy <= hi2:
                    votes[ia][ib] += 1
    best = (0, w, w)
    best_dc = None
    for ia in range(size):
        for ib in range(size):
            v = votes[ia][ib]
            dc = (ia - w) ** 2 + (ib - w) ** 2
            if v > best[0] or (v == best[0] and v > 0 and best_dc is not None and dc < best_dc):
                best, best_dc = (v, ia, ib), dc
    return votes, best


def htc_peak(
    x, y, r_min: float, r_max: float, r_step: float, w: int, cell: float, tol: float, min_sagitta: float
) -> int:
    """HTC over every radius the arc allows, each voted in full (htc_window): the peak's votes (0: no radius).
    The radii are r_min + k r_step within [r_lo, r_hi]: no smaller than half the chord (less tol), than the
    circle through the chord's ends and P_near (the point nearest the scanner) pushed tol further out, no larger
    than that circle with P_near pulled tol in; the nearest step to their middle when no step lies inside. Each
    radius's window is centred on the circle of that radius through the chord's ends, on the far side from the
    scanner. A later radius takes the peak only with more votes; no arc (sagitta under min_sagitta): 0."""
    n = len(x)
    if n < 3:
        return 0
    near = min(range(n), key=lambda i: (x[i] * x[i] + y[i] * y[i], i))
    chord = math.hypot(x[-1] - x[0], y[-1] - y[0])
    if chord < 1e-6:
        return 0
    mx, my = 0.5 * (x[0] + x[-1]), 0.5 * (y[0] + y[-1])
    nx, ny = (y[-1] - y[0]) / chord, -(x[-1] - x[0]) / chord
    if nx * mx + ny * my < 0:
        nx, ny = -nx, -ny
    sag = -((x[near] - mx) * nx + (y[near] - my) * ny)
    if sag < min_sagitta:
        return 0
    half = 0.5 * chord
    r_lo, r_hi = max(r_min, half - tol), r_max
    if sag > tol:
        r_hi = min(r_hi, ((sag - tol) ** 2 + half * half) / (2.0 * (sag - tol)) + tol)
    s2 = max(sag, 0.0) + tol
    r_lo = max(r_lo, (s2 * s2 + half * half) / (2.0 * s2) - tol)
    if r_lo > r_hi:
        return 0
    k0 = math.ceil((r_lo - r_min) / r_step - 1e-9)
    k1 = math.floor((r_hi - r_min) / r_step + 1e-9)
    if k1 < k0:
        k0 = k1 = round((0.5 * (r_lo + r_hi) - r_min) / r_step)
    best = 0
    for k in range(k0, k1 + 1):
        r = r_min + k * r_step
        h = math.sqrt(max(r * r - half * half, 0.0))
        _, (votes, _, _) = htc_window(x, y, mx + nx * h, my + ny * h, r, w, cell, tol)
        best = max(best, votes)
    return best


# ----------------------------------------------------------------------------------------------- scenes


def ray_wall(angles, rho: float, theta: float) -> np.ndarray:
    """Ranges of beams at `angles` to the line x cos(theta) + y sin(theta) = rho (rho > 0); inf where the beam
    runs parallel to it or away from it."""
    out = np.full(len(angles), np.inf)
    for i, a in enumerate(angles):
        c = math.cos(a - theta)
        if c > 1e-9:
            out[i] = rho / c
    return out


def ray_segment(angles, p0, p1) -> np.ndarray:
    """Ranges of beams to the wall segment p0-p1; inf where they miss it."""
    out = np.full(len(angles), np.inf)
    (x0, y0), (x1, y1) = p0, p1
    for i, a in enumerate(angles):
        ux, uy = math.cos(a), math.sin(a)
        ex, ey = x1 - x0, y1 - y0
        den = ux * ey - uy * ex
        if abs(den) < 1e-12:
            continue
        t = (x0 * ey - y0 * ex) / den  # distance along the beam
        s = (x0 * uy - y0 * ux) / den  # position along the wall, 0..1
        if t > 0 and 0.0 <= s <= 1.0:
            out[i] = t
    return out


def ray_circle(angles, cx: float, cy: float, radius: float) -> np.ndarray:
    """Ranges of beams to the near side of a circle; inf where they miss it."""
    out = np.full(len(angles), np.inf)
    for i, a in enumerate(angles):
        b = math.cos(a) * cx + math.sin(a) * cy
        disc = b * b - (cx * cx + cy * cy - radius * radius)
        if disc >= 0 and b - math.sqrt(disc) > 0:
            out[i] = b - math.sqrt(disc)
    return out


def points(ranges, angles) -> tuple[np.ndarray, np.ndarray]:
    """Cartesian points of ranges at angles (float64)."""
    r = np.asarray(ranges, np.float64)
    a = np.asarray(angles, np.float64)
    return r * np.cos(a), r * np.sin(a)


# ----------------------------------------------------------------------------------------------- well-posed arcs


def circle_well_posed(
    x, y, circle: tuple[float, float, float], params, angle_step: float, lines: list[tuple[float, float]] | None = None
) -> bool:
    """Whether the circle (a, b, r) fitted to the points is a well-posed arc (FeatureParams `params`; a test
    whose parameter is 0 is off): at least 3 points, and
    - a radius more than circle_radius_margin inside [circle_radius_min, circle_radius_max];
    - at least circle_min_coverage of the beams (angle step `angle_step`) that the circle's near side spans
      seen from the scanner: 2 asin(r / |c|) / angle_step (pi when the scanner is inside it);
    - a circle residual (root sum of squares) at most circle_residual_ratio times the total-least-squares
      line's, and at most circle_lines_ratio times that of the points to the segment's HTL `lines` (theta, rho),
      each point to the nearest (when there are such lines)."""
    a, b, r = circle
    m = len(x)
    if m < 3:
        return False
    margin = params.circle_radius_margin
    if margin > 0 and not (params.circle_radius_min + margin <= r <= params.circle_radius_max - margin):
        return False
    if params.circle_min_coverage > 0 and angle_step > 0:
        d = math.hypot(a, b)
        span = math.pi if r >= d else 2.0 * math.asin(r / d)
        if m < params.circle_min_coverage * span / angle_step:
            return False
    if params.circle_residual_ratio > 0:
        circle_rss = sum((math.hypot(px - a, py - b) - r) ** 2 for px, py in zip(x, y, strict=True))
        theta, rho = fit_line(x, y)
        line_rss = sum((px * math.cos(theta) + py * math.sin(theta) - rho) ** 2 for px, py in zip(x, y, strict=True))
        if math.sqrt(circle_rss) > params.circle_residual_ratio * math.sqrt(line_rss):
            return False
    if params.circle_lines_ratio > 0 and lines:
        circle_rss = sum((math.hypot(px - a, py - b) - r) ** 2 for px, py in zip(x, y, strict=True))
        lines_rss = sum(
            min(abs(px * math.cos(t) + py * math.sin(t) - rho) for t, rho in lines) ** 2
            for px, py in zip(x, y, strict=True)
        )
        if math.sqrt(circle_rss) > params.circle_lines_ratio * math.sqrt(lines_rss):
            return False
    return True


def perpendicular(t1: float, t2: float, tol: float) -> bool:
    """Two line normals (rad) at a right angle, within tol (rad), whatever their turns by pi."""
    d = math.fmod(abs(t1 - t2), math.pi)
    return abs(d - math.pi / 2) <= tol


def convex(a, j, b) -> bool:
    """Junction j bulges towards the scanner at the origin from the chord a-b: j and the origin lie on the
    same side of the line through a and b."""
    e = np.subtract(b, a)
    side_j = e[0] * (j[1] - a[1]) - e[1] * (j[0] - a[0])
    side_o = e[0] * (0.0 - a[1]) - e[1] * (0.0 - a[0])
    return bool(side_j * side_o > 0)


# ----------------------------------------------------------------------------------------------- the decision (5.2)


def line_candidates(rows, runs, n: int, params) -> tuple[list[int], list[int], float]:
    """A segment's HTL lines, one candidate per run of points (docs/method.md §5.1). rows[k]: run k's line, in
    line_of_run's columns LC_*; runs[k]: its points [start, end); n: the segment's points; params: FeatureParams.
    Returns
    - the HTL lines the decision rule counts: more than three points (line_min_points);
    - the lines kept: also r_acc > line_min_racc and length > line_min_length (the paper's 0.5 and 10 cm);
    - r_acc(HTL), the r_acc of the HTL lines together: each line's refined r_acc weighted by its run's points,
      over the segment's points (0 when there is no line), summed in run order."""
    htl = [k for k, row in enumerate(rows) if row[LC_N] >= params.line_min_points]
    kept = [k for k in htl if rows[k][LC_RACC] > params.line_min_racc and rows[k][LC_LEN] > params.line_min_length]
    votes = 0.0
    for k in htl:
        votes += rows[k][LC_RACC] * (runs[k][1] - runs[k][0])
    return htl, kept, votes / n


def merge_lines(rows, runs, kept: list[int], rho_res: float, refit):
    """Consecutive kept lines that are one line split by noise, merged (datmo; the paper does not rejoin the
    lines HTL cut where the accumulator peak moved). In scan order, kept line b joins the line a before it when
    - their normals are within 3 degrees and their rho within two rho cells (same_line: the same side),
    - and b's run follows a's: candidate index b = a + 1 (a candidate between them, an HTL line or not, keeps
      them apart).
    a is then refitted over both runs: refit(start, end, theta, rho, votes) is the line of points [start, end)
    from a's (theta, rho) with `votes` votes (the kernel's line_of_run; votes: both lines' r_acc weighted by
    their runs' points); a's run now reaches b's end and the next kept line is compared with the merged a.
    As the kernel states it, a merged line keeps the index of its first candidate, so it takes no third line
    (candidate a + 2 is not a + 1) even when that one is collinear.
    rows (LC_* columns) and runs ([start, end)) are not changed; returns (kept lines left, rows, runs) after
    the merges, and the (a, b) pairs merged."""
    rows = [np.array(row, np.float64) for row in rows]
    runs = [list(run) for run in runs]
    left: list[int] = []
    merged: list[tuple[int, int]] = []
    for b in kept:
        if left:
            a = left[-1]
            dt, drho = same_line(rows[a][LC_THETA], rows[a][LC_RHO], rows[b][LC_THETA], rows[b][LC_RHO])
            if dt < math.radians(3.0) and drho < 2 * rho_res and b == a + 1:
                votes = rows[a][LC_RACC] * (runs[a][1] - runs[a][0]) + rows[b][LC_RACC] * (runs[b][1] - runs[b][0])
                rows[a] = np.array(refit(runs[a][0], runs[b][1], rows[a][LC_THETA], rows[a][LC_RHO], votes), np.float64)
                runs[a][1] = runs[b][1]
                merged.append((a, b))
                continue
        left.append(b)
    return left, rows, runs, merged


class Decision(NamedTuple):
    """What feature_decision makes of a segment, and why."""

    kind: str  # "circle", "lines" or "blob"
    lines: list[int]  # the candidates that are its lines (kind "lines"), in scan order
    circle: np.ndarray | None  # the circle fit's output (CC_* columns) when HTC ran on the segment
    ncand: int  # HTL lines
    tried: bool  # HTC applies (whether or not the segment has circle_min_points)
    leg_only: bool  # a case the paper does not test as a circle: a failed circle leaves the lines
    convex: int | None  # convex junctions (three HTL lines or more, small enough for a circle)


def feature_decision(
    x, y, s: int, e: int, rows, htl: list[int], kept: list[int], htl_racc: float, params, angle_step: float, circle
) -> Decision:
    """Decision rule of docs/method.md §5.2, as datmo extends it, for the segment of points [s, e) of x, y (sensor
    frame, m). rows: its line candidates (LC_* columns) after merge_lines; htl, kept, htl_racc: line_candidates'
    (htl: the HTL lines, in run order; kept: the kept lines left by merge_lines); params: FeatureParams;
    angle_step: the scan's (rad); circle(beat) -> (CC_* row, indices of the points fitted): the HTC fit of the
    segment (the kernel's circle_of_run, which stops refining a peak whose r_acc is not above `beat`: it could
    not win).

    The paper applies HTC when the segment has a single line with r_acc < 0.5, or two non-perpendicular lines,
    or more than two convex lines; the circle wins when r_acc(HTC) > r_acc(HTL), else the segment is a blob;
    in the other cases it is its lines, and a segment with no line and no circle is a blob. datmo:
    - HTC only when the segment's end points are at most 2 circle_radius_max + 2 circle_tolerance apart
      (a circle of the allowed radii fits; a long wall with a slight bend stays lines);
    - a segment with no HTL line is tested as a circle too (a far leg of a few points);
    - a single line is tested whatever its r_acc; when its peak cell's r_acc (LC_PEAK_RACC, not the refined
      r_acc) is at least line_min_racc, the paper's ELSE case, a failed circle leaves its lines (`leg_only`);
    - two perpendicular lines (perpendicular, within perpendicular_tolerance) are tested too (an arc cut in
      two halves, or a box's corner); a failed circle leaves the lines;
    - three lines or more: "convex" is at least two convex junctions (convex: the end of line q bulges towards
      the scanner from the chord between the start of line q and the end of line q + 1, for consecutive HTL
      lines);
    - the circle wins only when r_acc(HTC) > max(r_acc(HTL), line_min_racc), it has at least circle_min_points
      points, and it is a well-posed arc (circle_well_posed, against the segment's HTL lines when there are
      two or more); a segment under circle_min_points gets no fit and loses.
    Otherwise the kept lines, when there are any, else a blob.
    As the kernel has it, r_acc(HTL) and the HTL lines counted are those before the merge, while the rows the
    rule reads (perpendicular, convex, the lines of circle_well_posed) are merge_lines': a merged line's row in
    place of its first candidate's, the candidate it absorbed still counted with its own row."""
    n = e - s
    ncand = len(htl)
    extent = math.hypot(x[e - 1] - x[s], y[e - 1] - y[s])
    tried = leg_only = False
    n_convex = None
    if extent <= 2.0 * params.circle_radius_max + 2.0 * params.circle_tolerance:
        if ncand == 0:
            tried = True
        elif ncand == 1:
            tried = True
            leg_only = rows[htl[0]][LC_PEAK_RACC] >= params.line_min_racc
        elif ncand == 2:
            tried = True
            leg_only = perpendicular(
                rows[htl[0]][LC_THETA], rows[htl[1]][LC_THETA], math.radians(params.perpendicular_tolerance)
            )
        else:
            n_convex = 0
            for a, b in zip(htl[:-1], htl[1:], strict=True):
                ra, rb = rows[a], rows[b]
                n_convex += convex((ra[LC_X0], ra[LC_Y0]), (ra[LC_X1], ra[LC_Y1]), (rb[LC_X1], rb[LC_Y1]))
            tried = n_convex >= 2
    fit = None
    if tried:
        beat = max(htl_racc, params.line_min_racc)
        if n >= params.circle_min_points:
            fit, used = circle(beat)
            fit = np.array(fit, np.float64)
            lines = [(rows[k][LC_THETA], rows[k][LC_RHO]) for k in htl] if ncand >= 2 else None
            px, py = [x[i] for i in used], [y[i] for i in used]
            if (
                fit[CC_RACC] > beat
                and fit[CC_N] >= params.circle_min_points
                and circle_well_posed(px, py, (fit[CC_X], fit[CC_Y], fit[CC_R]), params, angle_step, lines)
            ):
                return Decision("circle", [], fit, ncand, tried, leg_only, n_convex)
        if not leg_only:
            kept = []
    if kept:
        return Decision("lines", list(kept), fit, ncand, tried, leg_only, n_convex)
    return Decision("blob", [], fit, ncand, tried, leg_only, n_convex)


def se2(x: float, y: float, theta: float) -> np.ndarray:
    """The 3 x 3 homogeneous matrix of the pose (x, y, theta): a point p in the pose's frame is R p + (x, y)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def pose_of(m: np.ndarray) -> np.ndarray:
    """(x, y, theta in (-pi, pi]) of a homogeneous pose matrix."""
    return np.array([m[0, 2], m[1, 2], math.atan2(m[1, 0], m[0, 0])])


def cell_hash(ix: int, iy: int, mask: int) -> int:
    """The bucket of grid cell (ix, iy) in a table of mask + 1 buckets: the spatial hash of Teschner et al.
    (2003), on 64-bit integers."""
    return int((np.int64(ix) * np.int64(73856093)) ^ (np.int64(iy) * np.int64(19349663))) & mask


# ---------------------------------------------------------------------------------------------------------------- legs


def circle_fit(p: np.ndarray) -> tuple[float, np.ndarray] | None:
    """Least-squares algebraic circle (minimise sum (|p - c|^2 - r^2)^2): (radius, centre), or None when the
    points are (nearly) collinear or fewer than 3."""
    if len(p) < 3:
        return None
    q = p - p.mean(axis=0)
    scatter = q.T @ q
    if np.linalg.det(scatter) <= 1e-12 * np.trace(scatter) ** 2:
        return None
    # |q - c|^2 = r^2  <=>  2 q.c + (r^2 - |c|^2) = |q|^2
    A = np.column_stack([2 * q, np.ones(len(q))])
    sol = np.linalg.lstsq(A, (q**2).sum(axis=1), rcond=None)[0]
    c = sol[:2]
    return math.sqrt(sol[2] + c @ c), c + p.mean(axis=0)


def angle_at(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Angle a-p-b, radians in [0, pi] (0 when a or b coincides with p)."""
    u, v = a - p, b - p
    nu, nv = np.linalg.norm(u), np.linalg.norm(v)
    if nu == 0 or nv == 0:
        return 0.0
    return math.acos(max(-1.0, min(1.0, float(u @ v) / (nu * nv))))


def cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def signed_curvature(a: np.ndarray, p: np.ndarray, b: np.ndarray) -> float:
    """1 / circumradius of triangle a, p, b; positive when p lies on the sensor's side of the chord a-b."""
    la, lb, lc = np.linalg.norm(p - a), np.linalg.norm(b - p), np.linalg.norm(b - a)
    area = abs(cross(b - a, p - a)) / 2
    if la * lb * lc == 0 or area == 0:
        return 0.0
    k = 4 * area / (la * lb * lc)
    same_side = np.sign(cross(b - a, p - a)) == np.sign(cross(b - a, -a))
    return k if same_side else -k


def segment_features(
    r: np.ndarray, angles: np.ndarray, start: int, end: int, range_min: float, range_max: float
) -> np.ndarray:
    """The feature vector of beams [start, end) of one scan r (invalid returns skipped)."""
    beams = [i for i in range(start, end) if is_valid(float(r[i]), range_min, range_max)]
    f = dict.fromkeys(FEATURE_NAMES, 0.0)
    if not beams:
        return np.array([f[k] for k in FEATURE_NAMES])
    rr = np.array([float(r[i]) for i in beams])
    aa = angles[beams]
    p = np.column_stack([rr * np.cos(aa), rr * np.sin(aa)])
    n = len(p)
    centroid = p.mean(axis=0)
    f["n_points"] = n
    f["width"] = np.linalg.norm(p[-1] - p[0])
    # the best line's residuals: the smallest singular value of the centred points
    sv = np.linalg.svd(p - centroid, compute_uv=False)
    f["linearity"] = (sv[1] if len(sv) > 1 else 0.0) / math.sqrt(n)
    fit = circle_fit(p)
    if fit is None:
        f["radius"], f["circularity"] = RADIUS_CLIP, f["linearity"]
    else:
        radius, c = fit
        f["radius"] = min(radius, RADIUS_CLIP)
        f["circularity"] = math.sqrt(np.mean((np.linalg.norm(p - c, axis=1) - radius) ** 2))
    if n > 1:
        f["std"] = math.sqrt(((p - centroid) ** 2).sum() / (n - 1))
    f["median_deviation"] = np.mean(np.linalg.norm(p - np.median(p, axis=0), axis=1))
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    if n > 1:
        f["boundary_length"] = steps.sum()
        f["boundary_regularity"] = steps.std()
    if n > 2:
        f["mean_curvature"] = np.mean([signed_curvature(p[i - 1], p[i], p[i + 1]) for i in range(1, n - 1)])
        inscribed = [angle_at(p[i], p[0], p[-1]) for i in range(1, n - 1)]
        f["mean_inscribed_angle"] = np.mean(inscribed)
        f["inscribed_angle_std"] = np.std(inscribed)
    f["distance"] = np.linalg.norm(centroid)
    first, last = beams[0], beams[-1]
    f["subtended_angle"] = abs(angles[last] - angles[first])
    before, after = first - 1, last + 1
    f["occluded_start"] = float(
        before >= 0
        and is_valid(float(r[before]), range_min, range_max)
        and float(r[before]) < float(r[first]) - OCCLUSION_MARGIN
    )
    f["occluded_end"] = float(
        after < len(r)
        and is_valid(float(r[after]), range_min, range_max)
        and float(r[after]) < float(r[last]) - OCCLUSION_MARGIN
    )
    f["jump_start"] = jump(r, first, -1, range_min, range_max)
    f["jump_end"] = jump(r, last, +1, range_min, range_max)
    step = abs(float(angles[-1]) - float(angles[0])) / (len(angles) - 1) if len(angles) > 1 else 0.0
    f["density"] = min(n * step * f["distance"] / f["width"], DENSITY_CLIP) if f["width"] > 0 else DENSITY_CLIP
    f["relative_curvature"] = f["mean_curvature"] * f["width"]
    return np.array([f[k] for k in FEATURE_NAMES], np.float64)


def jump(r: np.ndarray, i: int, direction: int, range_min: float, range_max: float) -> float:
    """The nearest valid return beyond beam i (towards direction) minus r[i], clipped; +JUMP_CLIP if none."""
    j = i + direction
    while 0 <= j < len(r):
        if is_valid(float(r[j]), range_min, range_max):
            return float(np.clip(float(r[j]) - float(r[i]), -JUMP_CLIP, JUMP_CLIP))
        j += direction
    return JUMP_CLIP


def centroid(r: np.ndarray, angles: np.ndarray, start: int, end: int, range_min: float, range_max: float):
    beams = [i for i in range(start, end) if is_valid(float(r[i]), range_min, range_max)]
    rr = np.array([float(r[i]) for i in beams])
    return np.column_stack([rr * np.cos(angles[beams]), rr * np.sin(angles[beams])]).mean(axis=0)


def cluster_features(ranges, angles, seg_start, seg_end, seg_offsets, range_min, range_max) -> np.ndarray:
    rows = []
    for k in range(len(ranges)):
        scan = [
            segment_features(ranges[k], angles, int(seg_start[g]), int(seg_end[g]), range_min, range_max)
            for g in range(seg_offsets[k], seg_offsets[k + 1])
        ]
        # the neighbour distance: to the nearest other candidate (>= 3 points, <= 0.8 m wide) of the scan
        cand = [f[0] >= CANDIDATE_MIN_POINTS and f[1] <= CANDIDATE_MAX_WIDTH for f in scan]
        cents = [
            centroid(ranges[k], angles, int(seg_start[g]), int(seg_end[g]), range_min, range_max) if f[0] > 0 else None
            for g, f in zip(range(seg_offsets[k], seg_offsets[k + 1]), scan, strict=True)
        ]
        for a, f in enumerate(scan):
            if f[0] == 0:
                continue
            d = [np.linalg.norm(cents[a] - cents[b]) for b in range(len(scan)) if cand[b] and b != a]
            f[FEATURE_NAMES.index("neighbour_distance")] = min([NEIGHBOUR_CLIP, *d])
        rows.extend(scan)
    return np.array(rows).reshape(-1, len(FEATURE_NAMES))


def tree_leaf(model, root: int, x: np.ndarray) -> int:
    """The leaf x reaches in the tree at root (x goes left when float32(x[feature]) <= threshold)."""
    node = root
    while model.feature[node] >= 0:
        node = model.left[node] if np.float32(x[model.feature[node]]) <= model.threshold[node] else model.right[node]
    return node


def is_candidate(row: np.ndarray) -> bool:
    """A segment that may be a leg: at least CANDIDATE_MIN_POINTS points, at most CANDIDATE_MAX_WIDTH m wide."""
    f = dict(zip(FEATURE_NAMES, row, strict=True))
    return bool(f["n_points"] >= CANDIDATE_MIN_POINTS and f["width"] <= CANDIDATE_MAX_WIDTH)


def ensemble_probability(model, leaves: list[int]) -> float:
    """The leg probability from the leaves a row reached, one per tree: the mean of their values for a forest,
    sigmoid(base + scale * their sum) for boosting (summed tree by tree, in the model's order)."""
    total = 0.0
    for leaf in leaves:
        total += float(model.value[leaf])
    if model.kind == "forest":
        return total / len(leaves)
    return 1.0 / (1.0 + math.exp(-(model.base + model.scale * total)))


def check_segments(start, end, offsets, n_beams: int) -> int:
    """0 when offsets index the segments (non-decreasing from 0 to their number) and every segment is a beam
    range [start, end) within 0..n_beams; 1 for bad offsets, 2 for a bad segment."""
    if len(offsets) == 0 or offsets[0] != 0 or offsets[-1] != len(start) or np.any(np.diff(offsets) < 0):
        return 1
    if np.any((start < 0) | (end < start) | (end > n_beams)):
        return 2
    return 0


def gap_clusters(ranges, angles, range_min, range_max, gap, min_points):
    """leg_tracker's clustering, one beam at a time: (start, end, offsets) as legs.gap_clusters."""
    start, end, offsets = [], [], [0]
    for r in ranges:
        runs, cur = [], []
        prev = None
        for i in range(len(r)):
            if not is_valid(float(r[i]), range_min, range_max):
                runs.append(cur)
                cur, prev = [], None
                continue
            p = np.array([float(r[i]) * math.cos(angles[i]), float(r[i]) * math.sin(angles[i])])
            if prev is not None and np.linalg.norm(p - prev) > gap:
                runs.append(cur)
                cur = []
            cur.append(i)
            prev = p
        runs.append(cur)
        for c in runs:
            if len(c) >= min_points:
                start.append(c[0])
                end.append(c[-1] + 1)
        offsets.append(len(start))
    return np.array(start, np.int64), np.array(end, np.int64), np.array(offsets, np.int64)


# ---------------------------------------------------------------------------------------------------------- ego-motion


def scan_points(r, angles, range_min, range_max, min_spacing, max_points):
    """(x, y, beams) of valid returns, each kept when at least min_spacing from the last kept one, then
    indices floor(i * n / max_points) when over max_points."""
    xs, ys, beams = [], [], []
    for b, rb in enumerate(r):
        if not is_valid(float(rb), range_min, range_max):
            continue
        x, y = float(rb) * math.cos(angles[b]), float(rb) * math.sin(angles[b])
        if xs and math.hypot(x - xs[-1], y - ys[-1]) < min_spacing:
            continue
        xs.append(x)
        ys.append(y)
        beams.append(b)
    n = len(xs)
    if n > max_points:
        keep = [(i * n) // max_points for i in range(max_points)]
        xs, ys, beams = [xs[j] for j in keep], [ys[j] for j in keep], [beams[j] for j in keep]
    return np.array(xs), np.array(ys), np.array(beams, np.int64)


def beam_normal(r, angles, range_min, range_max, b, normal_radius, max_gap, max_window, planarity):
    """Line normal at beam b: walk each way over valid beams, each step within max_gap of the last point taken,
    stopping once two are taken and one is normal_radius away (or after max_window beams); eigenvector of the
    smallest eigenvalue of the points' covariance when line-like, (0, 0) when compact but not line-like,
    (NaN, NaN) otherwise or under 3 points."""
    p = np.array([float(r[b]) * math.cos(angles[b]), float(r[b]) * math.sin(angles[b])])
    pts = [p]
    far = 0.0
    for direction in (-1, 1):
        last, taken = p, 0
        for step in range(1, max_window + 1):
            j = b + direction * step
            if not 0 <= j < len(r):
                break
            if not is_valid(float(r[j]), range_min, range_max):
                continue
            q = np.array([float(r[j]) * math.cos(angles[j]), float(r[j]) * math.sin(angles[j])])
            if np.linalg.norm(q - last) > max_gap:
                break
            pts.append(q)
            taken += 1
            last = q
            d = float(np.linalg.norm(q - p))
            far = max(far, d)
            if taken >= 2 and d >= normal_radius:
                break
    if len(pts) < 3:
        return math.nan, math.nan
    cov = np.cov(np.array(pts).T, bias=True)
    w, v = np.linalg.eigh(cov)
    if w[1] > 0 and w[0] <= planarity**2 * w[1]:
        return float(v[0, 0]), float(v[1, 0])
    if far <= 2 * normal_radius:
        return 0.0, 0.0
    return math.nan, math.nan


def gather(r, angles, range_min, range_max, b, direction, normal_radius, max_gap, max_window):
    """One side of beam_normal's walk from beam b in `direction` (+1 or -1): the points taken, relative to
    b's point (m, sensor frame), and the farthest distance among them."""
    p = np.array([float(r[b]) * math.cos(angles[b]), float(r[b]) * math.sin(angles[b])])
    last, taken, far = p, [], 0.0
    for step in range(1, max_window + 1):
        j = b + direction * step
        if not 0 <= j < len(r):
            break
        if not is_valid(float(r[j]), range_min, range_max):
            continue
        q = np.array([float(r[j]) * math.cos(angles[j]), float(r[j]) * math.sin(angles[j])])
        if np.linalg.norm(q - last) > max_gap:
            break
        taken.append(q - p)
        last = q
        d = float(np.linalg.norm(q - p))
        far = max(far, d)
        if len(taken) >= 2 and d >= normal_radius:
            break
    return np.array(taken).reshape(-1, 2), far


def rebuild_map(keyframes, newest, n_kf, map_spacing, capacity):
    """The local map (points, normals; world frame) of the n_kf keyframes of the ring `keyframes` (a list of
    (points, normals, pose)) ending at slot newest, newest first: its points all, each older one's only where
    no map point is within map_spacing (m)."""
    xy, nn = np.zeros((0, 2)), np.zeros((0, 2))
    for a in range(n_kf):
        pts, nrm, pose = keyframes[(newest - a) % len(keyframes)]
        xy, nn = add_to_map(pts, nrm, pose, map_spacing if a > 0 else 0.0, xy, nn, capacity)
    return xy, nn


def nearest(q, map_xy, max_dist):
    """Index of the nearest map point within max_dist (lowest index on ties), or -1."""
    d2 = ((map_xy - q) ** 2).sum(axis=1)
    j = int(np.argmin(d2))
    return j if d2[j] <= max_dist**2 else -1


def add_to_map(points, normals, pose, min_spacing, map_xy, map_n, capacity):
    """The map (points, normals; world frame) after adding sensor-frame points with their normals seen from
    pose (x, y, theta), in order: a point whose normal is NaN is skipped, and so is one within min_spacing
    (m) of a map point already there (added earlier in the same call included); at most `capacity` points."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    rot = np.array([[c, -s], [s, c]])
    xy, nn = [tuple(p) for p in map_xy], [tuple(v) for v in map_n]
    for p, v in zip(points, normals, strict=True):
        if len(xy) >= capacity:
            break
        if math.isnan(v[0]):
            continue
        w = rot @ p + pose[:2]
        if min_spacing > 0 and xy and nearest(w, np.array(xy), min_spacing) >= 0:
            continue
        xy.append(tuple(w))
        nn.append(tuple(rot @ v))
    return np.array(xy).reshape(-1, 2), np.array(nn).reshape(-1, 2)


def weight(ares, scale, redescend):
    if redescend:
        return 1.0 / (1.0 + (ares / scale) ** 2) ** 2
    return 1.0 if ares <= scale else scale / ares


def icp_step(src, pose, map_xy, map_n, max_dist, scale, redescend, inlier_tol):
    """(H, g, matched, sum |r|, inliers) of the robust point-to-line cost at pose; rows stacked as a matrix."""
    x, y, t = pose
    R = np.array([[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]])
    rows, res, ws = [], [], []
    matched = inliers = 0
    abs_sum = 0.0
    for p in src:
        rp = R @ p
        q = rp + (x, y)
        j = nearest(q, map_xy, max_dist)
        if j < 0:
            continue
        matched += 1
        e = q - map_xy[j]
        n = map_n[j]
        dq_dt = np.array([-rp[1], rp[0]])
        if n[0] != 0 or n[1] != 0:
            r = float(n @ e)
            a = abs(r)
            rows.append([n[0], n[1], n @ dq_dt])
            res.append(r)
            ws.append(weight(a, scale, redescend))
        else:
            a = float(np.linalg.norm(e))
            w = weight(a, scale, redescend)
            rows += [[1.0, 0.0, dq_dt[0]], [0.0, 1.0, dq_dt[1]]]
            res += [e[0], e[1]]
            ws += [w, w]
        abs_sum += a
        inliers += a <= inlier_tol
    J = np.array(rows).reshape(-1, 3)
    W = np.diag(ws)
    return J.T @ W @ J, J.T @ W @ np.array(res), matched, abs_sum, inliers


def icp_align(src, init, map_xy, map_n, max_dist0, max_dist, scale, inlier_tol, max_iter, prior_weight):
    """Pose and (matched, mean |r|, inliers, iterations) by the kernel's schedule: Huber while the gate halves
    from max_dist0 to max_dist, then Geman-McClure until the step is tiny; a prior pulls toward init."""
    pose = np.array(init, float)
    gate = max_dist0
    it = matched = 0
    while it < max_iter:
        it += 1
        H, g, matched, _, _ = icp_step(src, pose, map_xy, map_n, gate, scale, gate <= max_dist, inlier_tol)
        if matched < MIN_MATCHES:
            break
        H = H + prior_weight * np.eye(3)
        g = g + prior_weight * (pose - init)
        step = np.linalg.solve(H, g)
        pose = pose - step
        small = max(abs(step[0]), abs(step[1])) < CONVERGED_STEP and abs(step[2]) < CONVERGED_TURN
        if gate > max_dist:
            gate = max(max_dist, 0.5 * gate)
        elif small:
            break
    if matched < MIN_MATCHES:
        return np.array(init, float), (matched, 0.0, 0, it)
    _, _, matched, abs_sum, inliers = icp_step(src, pose, map_xy, map_n, gate, scale, True, inlier_tol)
    pose[2] = math.atan2(math.sin(pose[2]), math.cos(pose[2]))
    return pose, (matched, abs_sum / max(matched, 1), inliers, it)


# ----------------------------------------------------------------------------------------------------------- landmarks


def beyond(ranges, scan, beam, step, lo, hi, dropout):
    """For each (scan, beam): the first return in (lo, hi) (m) among the dropout + 1 beams beyond it in
    direction `step` (inside the scan), and its beam; (inf, -1) where there is none."""
    out, where = [], []
    for k, b in zip(scan, beam, strict=True):
        found = (math.inf, -1)
        for j in range(1, dropout + 2):
            nb = b + step * j
            if not 0 <= nb < ranges.shape[1]:
                break
            r = float(ranges[k, nb])
            if math.isfinite(r) and lo < r < hi:
                found = (r, nb)
                break
        out.append(found[0])
        where.append(found[1])
    return np.array(out), np.array(where, np.int64)


def benches(circles, lines, dmin, dmax, bench_type):
    """Bench detections (scan, type, x, y, orientation, size) from support circles (scan, x, y, radius) and
    lines (scan, x0, y0, x1, y1): two circles of one scan dmin..dmax (m) apart, the first line of the scan
    whose middle lies between them (along their axis, within 0.4 m of it) and that runs along the axis
    (at least 0.9 of its length)."""
    out = []
    for u, (su, xu, yu, ru) in enumerate(circles):
        for sv, xv, yv, rv in circles[u + 1 :]:
            if sv != su:
                continue
            d = math.hypot(xv - xu, yv - yu)
            if not dmin <= d <= dmax:
                continue
            axis = np.array([xv - xu, yv - yu]) / d
            for sl, x0, y0, x1, y1 in lines:
                if sl != su:
                    continue
                mid = np.array([0.5 * (x0 + x1) - xu, 0.5 * (y0 + y1) - yu])
                along, across = mid @ axis, abs(axis[0] * mid[1] - axis[1] * mid[0])
                run = np.array([x1 - x0, y1 - y0])
                if 0 < along < d and across < 0.4 and abs(run @ axis) >= 0.9 * np.linalg.norm(run):
                    out.append(
                        (su, bench_type, 0.5 * (xu + xv), 0.5 * (yu + yv), math.atan2(axis[1], axis[0]), d + ru + rv)
                    )
                    break
    return np.array(out).reshape(-1, 6)


COLUMN, BENCH = 4, 5  # landmark types (Landmark.msg)


def bench_support_hides(column, bench, support_radius) -> bool:
    """Whether a column (x, y) is within 0.5 m of a support of a bench (x, y, orientation, length): the
    supports stand support_radius (m) in from its ends."""
    half = 0.5 * (bench[3] - 2 * support_radius)
    for sgn in (-1.0, 1.0):
        sx, sy = bench[0] + sgn * half * math.cos(bench[2]), bench[1] + sgn * half * math.sin(bench[2])
        if math.hypot(column[0] - sx, column[1] - sy) < 0.5:
            return True
    return False


def landmark_database(det, stamps, match, min_count, max_drift, column_time, forget, support_radius):
    """The landmark database rules, scan by scan: detections det (scan, type, x, y, orientation, size), scan k
    stamped stamps[k] (ns). A detection is the nearest landmark of its type not yet seen in this scan within
    its gate (match; a column max_drift, at most 2 match; a bench 2 match, its distance measured across its
    axis and beyond its half-length), else a new one. A match counts one more sighting: running mean
    position and size, the latest orientation (a bench takes the whole detection when it is longer). A
    column that drifts over max_drift from where it was first seen has moved. A landmark is confirmed at
    min_count sightings (a column once seen over column_time ns). After each scan, unconfirmed landmarks
    not seen for `forget` scans and moved ones are no longer matched, and confirmed columns by a confirmed
    bench's supports are hidden. Returns (rows (type, x, y, orientation, size, count, first scan, last
    scan, first x, first y, moved, confirmed, hidden), first_ns, and per scan the snapshot: (row, x, y,
    orientation, size, count, last scan, last seen ns) of the confirmed landmarks neither moved nor hidden,
    in the order confirmed)."""
    rows, first_ns, last_ns, live, confirmed, snapshots = [], [], [], [], [], []
    for k, stamp in enumerate(stamps):
        for _, t, x, y, orient, size in det[det[:, 0] == k]:
            gate = min(max_drift, 2 * match) if t == COLUMN else (2 * match if t == BENCH else match)
            best, bd = -1, math.inf
            for q in live:
                row = rows[q]
                if row[0] != t or row[7] == k:
                    continue
                d = math.hypot(row[1] - x, row[2] - y)
                if t == BENCH:
                    ux, uy, rx, ry = math.cos(row[3]), math.sin(row[3]), x - row[1], y - row[2]
                    d = abs(ux * ry - uy * rx) + max(0.0, abs(rx * ux + ry * uy) - 0.5 * row[4])
                if d <= gate and d < bd:
                    best, bd = q, d
            if best < 0:
                rows.append([t, x, y, orient, size, 1.0, k, k, x, y, 0.0, 0.0, 0.0])
                first_ns.append(stamp)
                last_ns.append(stamp)
                live.append(len(rows) - 1)
                if min_count <= 1 and (t != COLUMN or column_time <= 0):
                    rows[-1][11] = 1.0
                    confirmed.append(len(rows) - 1)
                continue
            row = rows[best]
            c = row[5] + 1
            if t == BENCH:
                if size > row[4]:
                    row[1:5] = [x, y, orient, size]
            else:
                row[1] += (x - row[1]) / c
                row[2] += (y - row[2]) / c
                row[3] = orient
                row[4] += (size - row[4]) / c
            row[5], row[7] = c, k
            last_ns[best] = stamp
            if t == COLUMN and math.hypot(x - row[8], y - row[9]) > max_drift:
                row[10] = 1.0
            if row[11] == 0 and c >= min_count and (t != COLUMN or stamp - first_ns[best] >= column_time):
                row[11] = 1.0
                confirmed.append(best)
        live = [q for q in live if not ((rows[q][11] == 0 and k - rows[q][7] > forget) or rows[q][10] != 0)]
        for q in confirmed:
            if rows[q][0] != COLUMN:
                continue
            for b in confirmed:
                bench = rows[b]
                if (
                    bench[0] == BENCH
                    and bench[5] >= min_count
                    and bench_support_hides(rows[q][1:3], bench[1:5], support_radius)
                ):
                    rows[q][12] = 1.0
        snapshots.append(
            [(q, *rows[q][1:6], rows[q][7], last_ns[q]) for q in confirmed if rows[q][10] == 0 and rows[q][12] == 0]
        )
    return np.array(rows).reshape(-1, 13), np.array(first_ns, np.int64), snapshots


FLAG_KEYFRAME, FLAG_RECOVERED, FLAG_FAILED = 1, 2, 4


def compose(a, b) -> np.ndarray:
    """a (+) b: pose b (x, y, theta), given in a's frame, in a's parent frame (theta not wrapped)."""
    x, y, _ = se2(*a) @ [b[0], b[1], 1.0]
    return np.array([x, y, a[2] + b[2]])


def odometry(ranges, dt, angles, range_min, range_max, p, max_window):
    """Poses (N, 3) and stats (N, 6: mean |residual|, inlier share, matched, points, flags, iterations) of
    scan-to-local-map ICP over scans `ranges` (m), dt (s) since the previous scan, parameters p (IcpParams).
    Each scan is aligned (icp_align) to the map of the last p.n_keyframes keyframes (rebuild_map) from the
    previous pose moved on by the previous motion times the ratio of the time steps (at most 3); when its
    inlier share is under p.min_inlier_share or ICP used all p.max_iter iterations, also from the previous
    pose moved by each recovery move, the best share kept. A scan is a keyframe when it is the first, or
    (with MIN_MATCHES points) p.keyframe_dist or p.keyframe_angle from the newest, or its share is under
    p.keyframe_share; its points are scan_points at p.map_spacing with their beam normals."""
    slots = max(1, p.n_keyframes)
    ring: list = [None] * slots
    newest, n_kf = -1, 0
    map_xy, map_n = np.zeros((0, 2)), np.zeros((0, 2))
    moves = np.asarray(p.recovery_moves, float).reshape(-1, 3)
    poses, stats = np.zeros((len(ranges), 3)), np.zeros((len(ranges), 6))
    align = (p.max_dist0, p.max_dist, p.robust_scale, p.inlier_tol, p.max_iter, p.prior_weight)
    for k, r in enumerate(ranges):
        sx, sy, _ = scan_points(r, angles, range_min, range_max, p.source_spacing, p.max_points)
        src, n_src = np.column_stack([sx, sy]).reshape(-1, 2), len(sx)
        flags = 0
        if k == 0 or n_kf == 0:
            pose, (matched, mean_res, inliers, iters), share = np.zeros(3), (0, 0.0, 0, 0), 0.0
        else:
            prev = poses[k - 1]
            guess = prev
            if k >= 2 and dt[k - 1] > 0:
                motion = pose_of(np.linalg.inv(se2(*poses[k - 2])) @ se2(*prev))
                guess = compose(prev, min(max(dt[k] / dt[k - 1], 0.0), 3.0) * motion)
            pose, (matched, mean_res, inliers, iters) = icp_align(src, guess, map_xy, map_n, *align)
            share = inliers / max(n_src, 1)
            if share < p.min_inlier_share or iters >= p.max_iter:
                for move in moves:
                    trial, (m2, r2, i2, it2) = icp_align(src, compose(prev, move), map_xy, map_n, *align)
                    iters += it2
                    if m2 >= MIN_MATCHES and i2 / max(n_src, 1) > share:
                        share, matched, mean_res, inliers, pose = i2 / max(n_src, 1), m2, r2, i2, trial
                        flags |= FLAG_RECOVERED
            if matched < MIN_MATCHES:
                flags |= FLAG_FAILED
        poses[k] = pose
        new_kf = n_kf == 0
        if not new_kf and n_src >= MIN_MATCHES:
            dx, dy, dth = pose_of(np.linalg.inv(se2(*ring[newest][2])) @ se2(*pose))
            new_kf = math.hypot(dx, dy) > p.keyframe_dist or abs(dth) > p.keyframe_angle or share < p.keyframe_share
        if new_kf:
            newest, n_kf = (newest + 1) % slots, min(n_kf + 1, slots)
            kx, ky, beams = scan_points(r, angles, range_min, range_max, p.map_spacing, len(r))
            normals = np.array(
                [
                    beam_normal(r, angles, range_min, range_max, b, p.normal_radius, p.max_gap, max_window, p.planarity)
                    for b in beams
                ]
            ).reshape(-1, 2)
            ring[newest] = (np.column_stack([kx, ky]).reshape(-1, 2), normals, poses[k].copy())
            map_xy, map_n = rebuild_map(ring, newest, n_kf, p.map_spacing, slots * len(r))
            flags |= FLAG_KEYFRAME
        stats[k] = mean_res, share, matched, n_src, flags, iters
    return poses, stats
