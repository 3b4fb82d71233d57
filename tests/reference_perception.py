"""Slow, plain references for the perception kernels (method.md sections 4 and 5), written for reading, not
speed: loops over points, numpy only for small linear algebra, scipy for the circle fit. Sensor frame,
metres, radians."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import least_squares


def valid(r: float, range_min: float, range_max: float) -> bool:
    return math.isfinite(r) and range_min < r < range_max


def segments(ranges, angle_increment: float, c0: float, range_min: float, range_max: float,
             min_points: int) -> list[tuple[int, int]]:
    """[start, end) beam ranges: P_i+1 joins P_i's segment when d(P_i, P_i+1) <= C0 + C1 min(r_i, r_i+1)."""
    c1 = math.sqrt(2.0 * (1.0 - math.cos(angle_increment)))
    out, start = [], None
    for i, r in enumerate(ranges):
        r = float(r)
        if not valid(r, range_min, range_max):
            if start is not None and i - start >= min_points:
                out.append((start, i))
            start = None
            continue
        if start is None:
            start = i
            continue
        a = float(ranges[i - 1])
        d = math.sqrt(max(a * a + r * r - 2.0 * a * r * math.cos(angle_increment), 0.0))
        if d > c0 + c1 * min(a, r):
            if i - start >= min_points:
                out.append((start, i))
            start = i
    if start is not None and len(ranges) - start >= min_points:
        out.append((start, len(ranges)))
    return out


def fit_line(x, y) -> tuple[float, float]:
    """Total least squares: (theta in [0, pi), rho) of the line x cos(theta) + y sin(theta) = rho."""
    pts = np.column_stack([x, y]).astype(float)
    c = pts.mean(axis=0)
    w, v = np.linalg.eigh(np.cov((pts - c).T))
    n = v[:, 0]                       # the normal: direction of least spread
    theta = math.atan2(n[1], n[0]) % math.pi
    return theta, c[0] * math.cos(theta) + c[1] * math.sin(theta)


def htl_peak(x, y, n_theta: int, rho_res: float) -> int:
    """Votes in the peak cell of a full accumulator adapted to the points' bounding box: theta cells of
    pi / n_theta over [0, pi); rho cells of rho_res from the smallest rho the box can give at each theta."""
    xs, ys = [min(x), max(x)], [min(y), max(y)]
    width = int(math.hypot(xs[1] - xs[0], ys[1] - ys[0]) / rho_res) + 2
    best = 0
    for t in range(n_theta):
        th = t * math.pi / n_theta
        c, s = math.cos(th), math.sin(th)
        lo = min(xs[0] * c, xs[1] * c) + min(ys[0] * s, ys[1] * s)
        cells: dict[int, int] = {}
        for px, py in zip(x, y, strict=True):
            k = min(max(int((px * c + py * s - lo) / rho_res), 0), width - 1)
            cells[k] = cells.get(k, 0) + 1
        best = max(best, max(cells.values()))
    return best


def fit_circle(x, y, guess: tuple[float, float, float]) -> tuple[float, float, float]:
    """Geometric least-squares circle (a, b, r) through the points."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    res = least_squares(lambda q: np.hypot(x - q[0], y - q[1]) - q[2], np.asarray(guess, float),
                        xtol=1e-12, ftol=1e-12, gtol=1e-12)
    return float(res.x[0]), float(res.x[1]), float(res.x[2])


def ray_wall(angles, rho: float, theta: float) -> np.ndarray:
    """Ranges of beams at `angles` to the infinite line x cos(theta) + y sin(theta) = rho (rho > 0); inf
    where the beam runs away from it."""
    cosd = np.cos(angles - theta)
    with np.errstate(divide="ignore"):
        r = np.where(cosd > 1e-9, rho / cosd, np.inf)
    return r


def ray_circle(angles, cx: float, cy: float, radius: float) -> np.ndarray:
    """Ranges of beams at `angles` to the circle's near side; inf where they miss it."""
    ux, uy = np.cos(angles), np.sin(angles)
    b = ux * cx + uy * cy
    disc = b * b - (cx * cx + cy * cy - radius * radius)
    r = b - np.sqrt(np.maximum(disc, 0.0))
    return np.where((disc >= 0) & (r > 0), r, np.inf)
