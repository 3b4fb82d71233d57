"""Slow, plain-Python references for datmo's perception kernels, following method.md sections 4 and 5 literally.

No numba: loops over points, written to be read. Sensor frame (x forward, y left), metres, radians. The
scene helpers at the end ray-cast walls and circles analytically, for synthetic scans of known geometry.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares

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


def segment(ranges, angle_increment: float, c0: float, range_min: float, range_max: float,
            min_points: int) -> list[tuple[int, int]]:
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


def htl_accumulator(x, y, n_theta: int, rho_res: float) -> tuple[dict[tuple[int, int], int], tuple[int, int, int]]:
    """Full Hough accumulator for lines: every point votes in every theta cell, in the rho cell of
    rho = x cos(theta) + y sin(theta) counted from the box's smallest rho. Returns the accumulator
    {(theta cell, rho cell): votes} and its peak (votes, theta cell, rho cell); of equal cells, the peak is
    the one that reached its count first (points in order, theta cells in order)."""
    lo, width = box_rho_offsets(x, y, n_theta, rho_res)
    inv = 1.0 / rho_res
    acc: dict[tuple[int, int], int] = {}
    peak = (0, 0, 0)
    for px, py in zip(x, y, strict=True):
        for t, th in enumerate(theta_table(n_theta)):
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
    res = least_squares(lambda q: np.hypot(x - q[0], y - q[1]) - q[2], np.asarray(guess, float),
                        xtol=1e-14, ftol=1e-14, gtol=1e-14, method="lm")
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


def htc_window(x, y, ca: float, cb: float, radius: float, w: int, cell: float,
               tol: float) -> tuple[list[list[int]], tuple[int, int, int]]:
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


def htc_peak(x, y, r_min: float, r_max: float, r_step: float, w: int, cell: float, tol: float,
             min_sagitta: float) -> int:
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
        t = (x0 * ey - y0 * ex) / den          # distance along the beam
        s = (x0 * uy - y0 * ux) / den          # position along the wall, 0..1
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


def circle_well_posed(x, y, circle: tuple[float, float, float], params, angle_step: float,
                      lines: list[tuple[float, float]] | None = None) -> bool:
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
        lines_rss = sum(min(abs(px * math.cos(t) + py * math.sin(t) - rho) for t, rho in lines) ** 2
                        for px, py in zip(x, y, strict=True))
        if math.sqrt(circle_rss) > params.circle_lines_ratio * math.sqrt(lines_rss):
            return False
    return True
