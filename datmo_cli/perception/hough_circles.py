"""numba kernels of circle extraction by the Hough transform for circles, HTC, and the circle's checks
(docs/method.md §5.2).

Sensor frame: x forward, y left, metres; angles in radians. Checked against tests/reference_perception.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from .feature_layout import (
    CC_N,
    CC_R,
    CC_RACC,
    CC_X,
    CC_Y,
    FP_CIRCLE_CELL,
    FP_CIRCLE_LINES_RATIO,
    FP_CIRCLE_MIN_COVERAGE,
    FP_CIRCLE_MIN_SAGITTA,
    FP_CIRCLE_RADIUS_MARGIN,
    FP_CIRCLE_RADIUS_MAX,
    FP_CIRCLE_RADIUS_MIN,
    FP_CIRCLE_RADIUS_STEP,
    FP_CIRCLE_RESIDUAL_RATIO,
    FP_CIRCLE_TOLERANCE,
    FP_CIRCLE_WINDOW,
)
from .hough_lines import scatter

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True)
def fit_circle(x, y, idx, m, a, b, r):
    """Geometric least-squares circle through points idx[:m] (Gauss-Newton from (a, b, r)); returns
    (a, b, r, ok)."""
    for _ in range(8):
        # normal equations of residuals d_k - r, d_k = |p_k - c|
        j00 = j01 = j02 = j11 = j12 = j22 = 0.0
        g0 = g1 = g2 = 0.0
        for k in range(m):
            dx = x[idx[k]] - a
            dy = y[idx[k]] - b
            d = np.hypot(dx, dy)
            if d < 1e-12:
                return a, b, r, False
            u = -dx / d
            v = -dy / d
            res = d - r
            j00 += u * u
            j01 += u * v
            j02 += -u
            j11 += v * v
            j12 += -v
            j22 += 1.0
            g0 += u * res
            g1 += v * res
            g2 += -res
        # solve the symmetric 3x3 system by Cramer's rule (no allocation in the loop)
        det = j00 * (j11 * j22 - j12 * j12) - j01 * (j01 * j22 - j12 * j02) + j02 * (j01 * j12 - j11 * j02)
        if abs(det) < 1e-18:
            return a, b, r, False
        s0 = (g0 * (j11 * j22 - j12 * j12) - j01 * (g1 * j22 - j12 * g2) + j02 * (g1 * j12 - j11 * g2)) / det
        s1 = (j00 * (g1 * j22 - j12 * g2) - g0 * (j01 * j22 - j12 * j02) + j02 * (j01 * g2 - g1 * j02)) / det
        s2 = (j00 * (j11 * g2 - g1 * j12) - j01 * (j01 * g2 - g1 * j02) + g0 * (j01 * j12 - j11 * j02)) / det
        a -= s0
        b -= s1
        r -= s2
        if abs(s0) + abs(s1) + abs(s2) < 1e-5:
            break
    return a, b, r, np.isfinite(a) and np.isfinite(b) and np.isfinite(r) and r > 0


@njit(cache=True)
def ring_count(x, y, s, e, ca, cb, d_lo, d_hi) -> int:
    """How many points of [s, e) lie at a distance d (np.hypot) from (ca, cb) with d_lo <= d <= d_hi (m).

    The same count as testing np.hypot on every point, most points decided on the squared distance alone: the
    squared bounds are narrowed (and widened) by a relative 1e-9, far beyond the few ulps by which hypot and
    the square root of the sum of squares can differ, and hypot decides the points between them."""
    in_lo = (d_lo * (1.0 + 1e-9)) ** 2 if d_lo > 0.0 else -1.0
    out_lo = (d_lo * (1.0 - 1e-9)) ** 2 if d_lo > 0.0 else -1.0
    in_hi = (d_hi * (1.0 - 1e-9)) ** 2 if d_hi > 0.0 else -1.0
    out_hi = (d_hi * (1.0 + 1e-9)) ** 2 if d_hi > 0.0 else 0.0
    n = 0
    for i in range(s, e):
        u = np.uint64(i)  # an unsigned index: numba drops its negative-index wrapping
        dx = x[u] - ca
        dy = y[u] - cb
        d2 = dx * dx + dy * dy
        if in_lo < d2 < in_hi:
            n += 1
        elif out_lo <= d2 <= out_hi:
            d = np.hypot(dx, dy)
            if d_lo <= d <= d_hi:
                n += 1
    return n


@njit(cache=True)
def circle_of_run(x, y, s, e, p, cacc, idx, out, beat=-1.0) -> None:
    """HTC on points [s, e): centre estimated from P_ini, P_near (nearest the scanner) and P_end, votes over
    (a, b) in a window around it for each radius the arc allows, peak, then a least-squares fit over the
    points within the tolerance. out = [n_points, x, y, radius, r_acc]; r_acc 0 when no circle fits. A
    peak whose r_acc is not above `beat` is not refined (out[0] = 0: it would not be kept anyway); nor is a
    radius voted for that cannot give more votes than the peak so far, or than `beat` allows (the points
    near enough to the ring of some cell of its window, counted first): its peak could not be the circle."""
    out[CC_N] = 0.0
    out[CC_RACC] = 0.0
    n = e - s
    if n < 3 or beat >= 1.0:  # r_acc is at most 1: nothing can beat `beat`
        return
    cell = p[FP_CIRCLE_CELL]
    w = int(round(p[FP_CIRCLE_WINDOW] / cell))
    tol = p[FP_CIRCLE_TOLERANCE]
    near = s
    for i in range(s, e):
        if x[i] * x[i] + y[i] * y[i] < x[near] * x[near] + y[near] * y[near]:
            near = i
    x0 = x[s]
    y0 = y[s]
    x1 = x[e - 1]
    y1 = y[e - 1]
    chord = np.hypot(x1 - x0, y1 - y0)
    if chord < 1e-6:
        return
    mx = 0.5 * (x0 + x1)
    my = 0.5 * (y0 + y1)
    nx = (y1 - y0) / chord
    ny = -(x1 - x0) / chord
    if nx * mx + ny * my < 0:  # the normal of the chord pointing away from the scanner
        nx = -nx
        ny = -ny
    sag = -((x[near] - mx) * nx + (y[near] - my) * ny)  # P_near's bulge towards the scanner
    if sag < p[FP_CIRCLE_MIN_SAGITTA]:
        return  # flat within the noise: a line or a blob, not an arc
    half = 0.5 * chord
    r_lo = max(p[FP_CIRCLE_RADIUS_MIN], half - tol)
    r_hi = p[FP_CIRCLE_RADIUS_MAX]
    if sag > tol:
        r_hi = min(r_hi, ((sag - tol) ** 2 + half * half) / (2.0 * (sag - tol)) + tol)
    s2 = max(sag, 0.0) + tol
    r_lo = max(r_lo, (s2 * s2 + half * half) / (2.0 * s2) - tol)
    if r_lo > r_hi:
        return
    step = p[FP_CIRCLE_RADIUS_STEP]
    k0 = int(np.ceil((r_lo - p[FP_CIRCLE_RADIUS_MIN]) / step - 1e-9))
    k1 = int(np.floor((r_hi - p[FP_CIRCLE_RADIUS_MIN]) / step + 1e-9))
    if k1 < k0:
        k0 = k1 = int(round((0.5 * (r_lo + r_hi) - p[FP_CIRCLE_RADIUS_MIN]) / step))
    size = 2 * w + 1
    best = 0
    bdc = 0
    ba = 0.0
    bb = 0.0
    br = -1.0
    reach = w * cell * np.sqrt(2.0) + 1e-9  # window centre to its farthest cell centre (and rounding)
    for k in range(k0, k1 + 1):
        r = p[FP_CIRCLE_RADIUS_MIN] + k * step
        h = np.sqrt(max(r * r - half * half, 0.0))
        ca = mx + nx * h
        cb = my + ny * h
        # at most `most` votes in any cell of this window: a point votes only within [r - tol, r + tol] of a
        # cell centre, and the cell centres lie within `reach` of (ca, cb)
        most = ring_count(x, y, s, e, ca, cb, r - tol - reach, r + tol + reach)
        if most <= best or most / n <= beat:
            continue  # this radius can neither take the peak (ties go to the earlier radius) nor be kept
        for ia in range(size):
            for ib in range(size):
                cacc[ia, ib] = 0
        lo2 = max(r - tol, 0.0) ** 2
        hi2 = (r + tol) ** 2
        for i in range(s, e):
            xi = x[np.uint64(i)]  # unsigned indices: numba drops its negative-index wrapping
            yi = y[np.uint64(i)]
            for ia in range(size):
                dx = xi - (ca + (ia - w) * cell)
                dx2 = dx * dx
                if dx2 > hi2:
                    continue
                row = cacc[np.uint64(ia)]
                for ib in range(size):
                    dy = yi - (cb + (ib - w) * cell)
                    d2 = dx2 + dy * dy
                    row[np.uint64(ib)] += np.int32((lo2 <= d2) & (d2 <= hi2))  # no branch: a vote is 0 or 1
        for ia in range(size):
            for ib in range(size):
                v = cacc[ia, ib]
                # ties go to the cell nearest the estimate, then to the smaller radius
                dc = (ia - w) ** 2 + (ib - w) ** 2
                if v > best or (v == best and v > 0 and br == r and dc < bdc):
                    best = v
                    bdc = dc
                    ba = ca + (ia - w) * cell
                    bb = cb + (ib - w) * cell
                    br = r
    if best == 0:
        return
    if best / n <= beat:
        out[CC_RACC] = best / n
        return
    m = 0
    for i in range(s, e):
        if abs(np.hypot(x[i] - ba, y[i] - bb) - br) <= tol:
            idx[m] = i
            m += 1
    a, b, r = ba, bb, br
    if m >= 3:
        fa, fb, fr, ok = fit_circle(x, y, idx, m, ba, bb, br)
        # keep the fit when it stays a circle of the allowed size near the Hough estimate
        if (
            ok
            and p[FP_CIRCLE_RADIUS_MIN] * 0.8 <= fr <= p[FP_CIRCLE_RADIUS_MAX] * 1.2
            and np.hypot(fa - ba, fb - bb) <= 2 * p[FP_CIRCLE_WINDOW]
        ):
            a, b, r = fa, fb, fr
    out[CC_N] = m
    out[CC_X] = a
    out[CC_Y] = b
    out[CC_R] = r
    out[CC_RACC] = best / n


@njit(cache=True)
def circle_posed(x, y, idx, m, a, b, r, p, dalpha, lines_rss=-1.0) -> bool:
    """Whether the circle (a, b, r) fitted to the points idx[:m] is a well-posed arc (each test off at 0):
    - a radius not pinned at a bound: more than FP_CIRCLE_RADIUS_MARGIN inside [circle_radius_min, circle_radius_max];
    - enough points for its size: at least FP_CIRCLE_MIN_COVERAGE of the beams (angle step `dalpha`) that the circle's
      near side spans seen from the scanner, 2 asin(r / |c|) / dalpha;
    - a fit clearly better than a line's: the circle's residual (root sum of squares) at most FP_CIRCLE_RESIDUAL_RATIO
      times that of the total-least-squares line of the same points;
    - and better than the segment's HTL lines (a corner): at most FP_CIRCLE_LINES_RATIO times sqrt(`lines_rss`), the
      sum of squared distances of the same points to those lines, each to the nearest (< 0: no lines)."""
    if m < 3:
        return False
    margin = p[FP_CIRCLE_RADIUS_MARGIN]
    if margin > 0.0 and (r < p[FP_CIRCLE_RADIUS_MIN] + margin or r > p[FP_CIRCLE_RADIUS_MAX] - margin):
        return False
    cover = p[FP_CIRCLE_MIN_COVERAGE]
    if cover > 0.0 and dalpha > 0.0:
        d = np.hypot(a, b)
        span = np.pi if r >= d else 2.0 * np.arcsin(r / d)
        if m < cover * span / dalpha:
            return False
    ratio = p[FP_CIRCLE_RESIDUAL_RATIO]
    by_lines = p[FP_CIRCLE_LINES_RATIO] > 0.0 and lines_rss >= 0.0
    rc = 0.0  # the circle's sum of squared residuals, computed once for both tests
    if ratio > 0.0 or by_lines:
        for k in range(m):
            rc += (np.hypot(x[idx[k]] - a, y[idx[k]] - b) - r) ** 2
    if ratio > 0.0:
        cx, cy, sxx, syy, sxy = scatter(x, y, idx, m)
        # the smallest eigenvalue of the scatter matrix: the line's sum of squared residuals
        rl = 0.5 * (sxx + syy) - np.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy)
        if np.sqrt(rc) > ratio * np.sqrt(max(rl, 0.0)):
            return False
    if by_lines:
        if np.sqrt(rc) > p[FP_CIRCLE_LINES_RATIO] * np.sqrt(lines_rss):
            return False
    return True
