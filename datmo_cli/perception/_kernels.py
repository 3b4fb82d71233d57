"""numba kernels of segmentation and Hough feature extraction (docs/method.md §4 and §5).

Sensor frame: x forward, y left, metres; angles in radians. Every kernel is checked against the plain
Python reference in tests/reference_perception.py. Parameters arrive as one float64 vector (see
FeatureParams.kernel_vector) whose positions are the P_* constants below.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..numba_runtime import key_kernel_cache_on_sources

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

(
    P_C0,
    P_MIN_POINTS,
    P_THETA_RES,
    P_RHO_RES,
    P_WINDOW,
    P_LINE_MIN_POINTS,
    P_LINE_MIN_RACC,
    P_LINE_MIN_LENGTH,
    P_PERP_TOL,
    P_R_MIN,
    P_R_MAX,
    P_R_STEP,
    P_CELL,
    P_CWINDOW,
    P_CTOL,
    P_CIRCLE_MIN_POINTS,
    P_SMALL,
    P_MIN_SAG,
    P_LEG_R,
    P_MIN_COVER,
    P_RES_RATIO,
    P_R_MARGIN,
    P_LINES_RATIO,
) = range(23)

# columns of the line rows
L_SCAN, L_SEG, L_FIRST, L_LAST, L_N, L_X0, L_Y0, L_X1, L_Y1, L_RHO, L_THETA, L_LEN, L_RACC = range(13)
# columns of circle rows: scan, segment, first, last, n, x, y, radius, r_acc
C_SCAN, C_SEG, C_FIRST, C_LAST, C_N, C_X, C_Y, C_R, C_RACC = range(9)
# columns of blob rows: scan, segment, first, last, n, x, y, size, kind
B_SCAN, B_SEG, B_FIRST, B_LAST, B_N, B_X, B_Y, B_SIZE, B_KIND = range(9)
# a line candidate (line_of_run's `out`, the rows of extract_scan's `cand`): points, first and last point,
# end points (x0, y0, x1, y1), rho, theta, length, r_acc, and r_acc of the HTL peak cell alone
LC_N, LC_FIRST, LC_LAST, LC_X0, LC_Y0, LC_X1, LC_Y1, LC_RHO, LC_THETA, LC_LEN, LC_RACC, LC_PEAK_RACC = range(12)
# a circle candidate (circle_of_run's `out`): points, centre x, y, radius, r_acc
CC_N, CC_X, CC_Y, CC_R, CC_RACC = range(5)
MAX_SUB = 256  # line candidates per segment


@njit(cache=True)
def valid_return(r: float, range_min: float, range_max: float) -> bool:
    """A return that counts: finite and strictly between the scan's range limits."""
    return np.isfinite(r) and r > range_min and r < range_max


@njit(cache=True)
def segment_scan(r, cos_inc, c0, c1, range_min, range_max, min_points, starts, ends) -> int:
    """Segments of one scan (ranges r, m) into starts/ends ([start, end) beam indices); returns the count.

    P_i+1 joins P_i's segment when d(P_i, P_i+1) <= c0 + c1 * min(r_i, r_i+1) (law of cosines with the
    scan's angle step); invalid returns break segments; segments under min_points are dropped.
    """
    n = 0
    start = -1
    B = r.shape[0]
    for i in range(B + 1):
        ok = i < B and valid_return(r[i], range_min, range_max)
        if ok and start >= 0:
            a = np.float64(r[i - 1])  # float64 arithmetic whatever the ranges' type
            b = np.float64(r[i])
            d2 = a * a + b * b - 2.0 * a * b * cos_inc
            d = np.sqrt(max(d2, 0.0))
            if d > c0 + c1 * min(a, b):
                if i - start >= min_points:
                    starts[n] = start
                    ends[n] = i
                    n += 1
                start = i
        elif ok:
            start = i
        elif start >= 0:
            if i - start >= min_points:
                starts[n] = start
                ends[n] = i
                n += 1
            start = -1
    return n


@njit(cache=True)
def _atan2(y: float, x: float) -> float:
    """atan2 within 0.0015 rad (a polynomial): the normal only centres a voting window of many cells."""
    ax = abs(x)
    ay = abs(y)
    if ax == 0.0 and ay == 0.0:
        return 0.0
    swap = ay > ax
    t = ax / ay if swap else ay / ax
    t2 = t * t
    r = t * (0.9998660 + t2 * (-0.3302995 + t2 * (0.1801410 + t2 * (-0.0851330 + t2 * 0.0208351))))
    if swap:
        r = np.pi / 2 - r
    if x < 0:
        r = np.pi - r
    if y < 0:
        r = -r
    return r


@njit(cache=True)
def _wrap_pi(a: float) -> float:
    """a % pi (Python's float modulo) for a in [-pi, 2 pi) without numba's call to fmod, to the same bits:
    fmod is exact, a - pi is exact for a in [pi, 2 pi) and a + pi is what the modulo adds to a negative a
    (a tiny negative a gives pi, as the modulo does; -0.0 stays -0.0 where the modulo gives 0.0)."""
    if a >= np.pi:
        return a - np.pi
    if a < 0.0:
        return a + np.pi
    return a


@njit(cache=True)
def normal_cells(x, y, s, e, nt, cell) -> None:
    """cell[i]: the theta cell (of nt over [0, pi)) of the local normal at each point i of [s, e), from the
    chord through neighbours at least 20 cm apart (at least 3 beams either side, at most 10)."""
    for i in range(s, e):
        a = max(s, i - 3)
        b = min(e - 1, i + 3)
        while (x[b] - x[a]) ** 2 + (y[b] - y[a]) ** 2 < 0.04 and (a > max(s, i - 10) or b < min(e - 1, i + 10)):
            a = max(s, a - 1)
            b = min(e - 1, b + 1)
        phi = _wrap_pi(_atan2(y[b] - y[a], x[b] - x[a]) + np.pi / 2)
        cell[i] = min(int(phi * nt / np.pi), nt - 1)


@njit(cache=True)
def _vote(x, y, i, acc, lo, cos_t, sin_t, inv_res, width, c, k, bv, bt, br, touched, box):
    """Point i votes along its sinusoid: theta cells c - k .. c + k (wrapping; all of them when 2k + 1 >= nt)
    around its local normal's cell c, and marks those theta rows in `touched`. Returns the peak (votes, theta
    cell, rho cell) updated from (bv, bt, br). acc: the accumulator as one flat array, theta row t at
    [t * width, (t + 1) * width) (rows `width` apart keep a segment's votes in a few cache lines); lo[t] is
    computed from the segment's bounding box (xmin, xmax, ymin, ymax) when row t is first voted in."""
    nt = cos_t.shape[0]
    if 2 * k + 1 >= nt:
        t_from = 0
        t_to = nt
    else:
        t_from = c - k
        t_to = c + k + 1
    xi = x[i]
    yi = y[i]
    for tt in range(t_from, t_to):
        t = tt
        if t < 0:
            t += nt
        elif t >= nt:
            t -= nt
        if not touched[t]:
            touched[t] = True
            lo[t] = _row_offset(box, cos_t[t], sin_t[t])
        ri = int((xi * cos_t[t] + yi * sin_t[t] - lo[t]) * inv_res)
        if ri < 0:
            ri = 0
        elif ri >= width:
            ri = width - 1
        j = t * width + ri
        v = acc[j] + 1
        acc[j] = v
        if v > bv:
            bv = v
            bt = t
            br = ri
    return bv, bt, br


@njit(cache=True)
def _clear(acc, touched, width) -> None:
    """Zero the rows voted in (flat rows of `width` cells, see _vote)."""
    for t in range(touched.shape[0]):
        if touched[t]:
            acc[t * width : (t + 1) * width] = 0
            touched[t] = False


@njit(cache=True)
def _row_offset(box, c, sn) -> float:
    """The smallest rho x cos + y sin (c, sn) over the bounding box (xmin, xmax, ymin, ymax)."""
    return min(box[0] * c, box[1] * c) + min(box[2] * sn, box[3] * sn)


@njit(cache=True)
def _bounding_box(x, y, s, e, rho_res, max_width, box) -> int:
    """box = (xmin, xmax, ymin, ymax) of points [s, e); returns the number of rho cells the box can produce
    (the accumulator adapted to the segment), at most max_width."""
    xmin = x[s]
    xmax = x[s]
    ymin = y[s]
    ymax = y[s]
    for i in range(s, e):
        xmin = min(xmin, x[i])
        xmax = max(xmax, x[i])
        ymin = min(ymin, y[i])
        ymax = max(ymax, y[i])
    box[0] = xmin
    box[1] = xmax
    box[2] = ymin
    box[3] = ymax
    return min(int(np.hypot(xmax - xmin, ymax - ymin) / rho_res) + 2, max_width)


@njit(cache=True)
def _one_line(x, y, a, b, tol, tail) -> bool:
    """Whether the total-least-squares line of points [a, b) lies within `tol` of 90 % of them and of each
    of the last `tail` points."""
    n = b - a
    cx = 0.0
    cy = 0.0
    for i in range(a, b):
        cx += x[i]
        cy += y[i]
    cx /= n
    cy /= n
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for i in range(a, b):
        sxx += (x[i] - cx) ** 2
        syy += (y[i] - cy) ** 2
        sxy += (x[i] - cx) * (y[i] - cy)
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy) + np.pi / 2
    c = np.cos(phi)
    s = np.sin(phi)
    on = 0
    for i in range(a, b):
        if abs((x[i] - cx) * c + (y[i] - cy) * s) <= tol:
            on += 1
        elif i >= b - tail:
            return False
    return on >= 0.9 * n


@njit(cache=True)
def line_subsegments(x, y, s, e, acc, lo, cos_t, sin_t, rho_res, k, cell, touched, sub_s, sub_e, peaks, hist) -> int:
    """Split points [s, e) into runs that each hold one line: the accumulator peak is followed as points are
    added in scan order, and when more than three consecutive new points lie off the peak's line (farther
    than two rho cells), a new line starts at the first of them. Returns the number of runs in sub_s/sub_e;
    peaks[k] = (votes, theta cell, rho cell) of run k's accumulator peak (lo[t]: the smallest rho the
    segment's bounding box gives at theta cell t, see _row_offset; cell: see
    normal_cells; k: theta cells voted either side of the normal; hist: scratch of at least e - s rows). Only
    the rows voted in get their lo (a peak's row always is); acc (nt, width_max) is used as one flat array of
    rows as wide as the segment needs and is left all zero, as `touched` is left all False."""
    box = np.empty(4)
    width = _bounding_box(x, y, s, e, rho_res, acc.shape[1], box)
    acc = acc.reshape(-1)
    inv = 1.0 / rho_res
    bv = 0
    bt = 0
    br = 0
    # hist[i - s]: the peak after point i, so a run's peak needs no re-voting
    n = 0
    start = s
    off = 0
    for i in range(s, e):
        bv, bt, br = _vote(x, y, i, acc, lo, cos_t, sin_t, inv, width, cell[i], k, bv, bt, br, touched, box)
        hist[i - s, 0] = bv
        hist[i - s, 1] = bt
        hist[i - s, 2] = br
        if i - start >= 4:
            t = bt
            rho_p = lo[t] + (br + 0.5) * rho_res
            # off the peak's line by more than two cells (one cell either way of the cell's quantisation)
            if abs(x[i] * cos_t[t] + y[i] * sin_t[t] - rho_p) > 2.0 * rho_res:
                off += 1
            else:
                off = 0
            if off > 3 and _one_line(x, y, start, i + 1, 2.0 * rho_res, off):
                # early in a run, clustered points leave the peak's angle loose; when one straight line
                # still holds the whole run, the off points included, it is one line
                off = 0
            if off > 3 and n < sub_s.shape[0] - 1:
                cut = i - off + 1
                sub_s[n] = start
                sub_e[n] = cut
                peaks[n, 0] = hist[cut - 1 - s, 0]
                peaks[n, 1] = hist[cut - 1 - s, 1]
                peaks[n, 2] = hist[cut - 1 - s, 2]
                n += 1
                # the peak of the points kept (cut .. i) is found by voting them again from zero
                _clear(acc, touched, width)
                bv = 0
                bt = 0
                br = 0
                for j in range(cut, i + 1):
                    bv, bt, br = _vote(x, y, j, acc, lo, cos_t, sin_t, inv, width, cell[j], k, bv, bt, br, touched, box)
                    hist[j - s, 0] = bv
                    hist[j - s, 1] = bt
                    hist[j - s, 2] = br
                start = cut
                off = 0
    sub_s[n] = start
    sub_e[n] = e
    peaks[n, 0] = bv
    peaks[n, 1] = bt
    peaks[n, 2] = br
    n += 1
    _clear(acc, touched, width)
    return n


@njit(cache=True)
def scatter(x, y, idx, m):
    """Centroid and scatter of points idx[:m]: (cx, cy, sxx, syy, sxy), sums of centred squares and product."""
    cx = 0.0
    cy = 0.0
    for k in range(m):
        cx += x[idx[k]]
        cy += y[idx[k]]
    cx /= m
    cy /= m
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for k in range(m):
        dx = x[idx[k]] - cx
        dy = y[idx[k]] - cy
        sxx += dx * dx
        syy += dy * dy
        sxy += dx * dy
    return cx, cy, sxx, syy, sxy


@njit(cache=True)
def fit_line(x, y, idx, m):
    """Total least squares line through points idx[:m]: (theta in [0, pi), rho) of x cos + y sin = rho."""
    cx, cy, sxx, syy, sxy = scatter(x, y, idx, m)
    # direction of largest spread; the normal is perpendicular to it
    phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
    theta = (phi + np.pi / 2) % np.pi
    rho = cx * np.cos(theta) + cy * np.sin(theta)
    return theta, rho


@njit(cache=True)
def line_of_run(x, y, s, e, theta_t, rho_p, votes, rho_res, idx, out) -> None:
    """The line of points [s, e) whose HTL peak is the cell (theta_t, rho_p) with `votes` votes: least squares
    over the points within a rho cell of the peak line, then again over those within a rho cell of that fit;
    r_acc from the peak cell, or from a cell-wide band on the fitted line where that holds more points.
    out = [n_points, first, last, x0, y0, x1, y1, rho, theta, length, r_acc, r_acc of the peak cell alone]."""
    c = np.cos(theta_t)
    sn = np.sin(theta_t)
    m = 0
    for i in range(s, e):
        if abs(x[i] * c + y[i] * sn - rho_p) <= rho_res:
            idx[m] = i
            m += 1
    out[LC_N] = m
    out[LC_RACC] = votes / (e - s)
    out[LC_PEAK_RACC] = votes / (e - s)
    if m < 2:
        out[LC_FIRST:LC_RACC] = 0.0
        return
    theta, rho = fit_line(x, y, idx, m)
    c = np.cos(theta)
    sn = np.sin(theta)
    # the points within a rho cell of the fitted line, fitted again: on a long line the theta cell's
    # quantisation leaves the far ends outside the peak cell, though they lie on the line
    m2 = 0
    for i in range(s, e):
        if abs(x[i] * c + y[i] * sn - rho) <= rho_res:
            m2 += 1
    if m2 > m:
        m = 0
        for i in range(s, e):
            if abs(x[i] * c + y[i] * sn - rho) <= rho_res:
                idx[m] = i
                m += 1
        theta, rho = fit_line(x, y, idx, m)
        c = np.cos(theta)
        sn = np.sin(theta)
    # r_acc: the peak cell's votes, or the points in a cell-wide band centred on the fitted line if more
    on = 0
    for k in range(m):
        if abs(x[idx[k]] * c + y[idx[k]] * sn - rho) <= 0.5 * rho_res:
            on += 1
    out[LC_N] = m
    out[LC_RACC] = max(votes, on) / (e - s)
    out[LC_PEAK_RACC] = votes / (e - s)
    i0 = idx[0]
    i1 = idx[m - 1]
    # P_ini and P_end projected on the fitted line
    d0 = x[i0] * c + y[i0] * sn - rho
    d1 = x[i1] * c + y[i1] * sn - rho
    out[LC_FIRST] = i0
    out[LC_LAST] = i1
    out[LC_X0] = x[i0] - d0 * c
    out[LC_Y0] = y[i0] - d0 * sn
    out[LC_X1] = x[i1] - d1 * c
    out[LC_Y1] = y[i1] - d1 * sn
    out[LC_RHO] = rho
    out[LC_THETA] = theta
    out[LC_LEN] = np.hypot(out[LC_X1] - out[LC_X0], out[LC_Y1] - out[LC_Y0])


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
    cell = p[P_CELL]
    w = int(round(p[P_CWINDOW] / cell))
    tol = p[P_CTOL]
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
    if sag < p[P_MIN_SAG]:
        return  # flat within the noise: a line or a blob, not an arc
    half = 0.5 * chord
    r_lo = max(p[P_R_MIN], half - tol)
    r_hi = p[P_R_MAX]
    if sag > tol:
        r_hi = min(r_hi, ((sag - tol) ** 2 + half * half) / (2.0 * (sag - tol)) + tol)
    s2 = max(sag, 0.0) + tol
    r_lo = max(r_lo, (s2 * s2 + half * half) / (2.0 * s2) - tol)
    if r_lo > r_hi:
        return
    step = p[P_R_STEP]
    k0 = int(np.ceil((r_lo - p[P_R_MIN]) / step - 1e-9))
    k1 = int(np.floor((r_hi - p[P_R_MIN]) / step + 1e-9))
    if k1 < k0:
        k0 = k1 = int(round((0.5 * (r_lo + r_hi) - p[P_R_MIN]) / step))
    size = 2 * w + 1
    best = 0
    bdc = 0
    ba = 0.0
    bb = 0.0
    br = -1.0
    reach = w * cell * np.sqrt(2.0) + 1e-9  # window centre to its farthest cell centre (and rounding)
    for k in range(k0, k1 + 1):
        r = p[P_R_MIN] + k * step
        h = np.sqrt(max(r * r - half * half, 0.0))
        ca = mx + nx * h
        cb = my + ny * h
        # at most `most` votes in any cell of this window: a point votes only within [r - tol, r + tol] of a
        # cell centre, and the cell centres lie within `reach` of (ca, cb)
        most = 0
        for i in range(s, e):
            dc = np.hypot(x[i] - ca, y[i] - cb)
            if r - tol - reach <= dc <= r + tol + reach:
                most += 1
        if most <= best or most / n <= beat:
            continue  # this radius can neither take the peak (ties go to the earlier radius) nor be kept
        for ia in range(size):
            for ib in range(size):
                cacc[ia, ib] = 0
        lo2 = max(r - tol, 0.0) ** 2
        hi2 = (r + tol) ** 2
        for i in range(s, e):
            for ia in range(size):
                dx = x[i] - (ca + (ia - w) * cell)
                dx2 = dx * dx
                if dx2 > hi2:
                    continue
                for ib in range(size):
                    dy = y[i] - (cb + (ib - w) * cell)
                    d2 = dx2 + dy * dy
                    if lo2 <= d2 <= hi2:
                        cacc[ia, ib] += 1
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
        if ok and p[P_R_MIN] * 0.8 <= fr <= p[P_R_MAX] * 1.2 and np.hypot(fa - ba, fb - bb) <= 2 * p[P_CWINDOW]:
            a, b, r = fa, fb, fr
    out[CC_N] = m
    out[CC_X] = a
    out[CC_Y] = b
    out[CC_R] = r
    out[CC_RACC] = best / n


@njit(cache=True)
def circle_posed(x, y, idx, m, a, b, r, p, dalpha, lines_rss=-1.0) -> bool:
    """Whether the circle (a, b, r) fitted to the points idx[:m] is a well-posed arc (each test off at 0):
    - a radius not pinned at a bound: more than P_R_MARGIN inside [circle_radius_min, circle_radius_max];
    - enough points for its size: at least P_MIN_COVER of the beams (angle step `dalpha`) that the circle's
      near side spans seen from the scanner, 2 asin(r / |c|) / dalpha;
    - a fit clearly better than a line's: the circle's residual (root sum of squares) at most P_RES_RATIO
      times that of the total-least-squares line of the same points;
    - and better than the segment's HTL lines (a corner): at most P_LINES_RATIO times sqrt(`lines_rss`), the
      sum of squared distances of the same points to those lines, each to the nearest (< 0: no lines)."""
    if m < 3:
        return False
    margin = p[P_R_MARGIN]
    if margin > 0.0 and (r < p[P_R_MIN] + margin or r > p[P_R_MAX] - margin):
        return False
    cover = p[P_MIN_COVER]
    if cover > 0.0 and dalpha > 0.0:
        d = np.hypot(a, b)
        span = np.pi if r >= d else 2.0 * np.arcsin(r / d)
        if m < cover * span / dalpha:
            return False
    ratio = p[P_RES_RATIO]
    if ratio > 0.0:
        cx, cy, sxx, syy, sxy = scatter(x, y, idx, m)
        rc = 0.0
        for k in range(m):
            rc += (np.hypot(x[idx[k]] - a, y[idx[k]] - b) - r) ** 2
        # the smallest eigenvalue of the scatter matrix: the line's sum of squared residuals
        rl = 0.5 * (sxx + syy) - np.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy)
        if np.sqrt(rc) > ratio * np.sqrt(max(rl, 0.0)):
            return False
    if p[P_LINES_RATIO] > 0.0 and lines_rss >= 0.0:
        rc = 0.0
        for k in range(m):
            rc += (np.hypot(x[idx[k]] - a, y[idx[k]] - b) - r) ** 2
        if np.sqrt(rc) > p[P_LINES_RATIO] * np.sqrt(lines_rss):
            return False
    return True


@njit(cache=True)
def _perpendicular(t1: float, t2: float, tol: float) -> bool:
    d = abs(t1 - t2) % np.pi
    return abs(d - np.pi / 2) <= tol


@njit(cache=True)
def _convex(ax, ay, jx, jy, bx, by) -> bool:
    """Junction J bulges towards the scanner (origin) from the chord A-B."""
    ex = bx - ax
    ey = by - ay
    cj = ex * (jy - ay) - ey * (jx - ax)
    co = ex * (0.0 - ay) - ey * (0.0 - ax)
    return cj * co > 0


@njit(cache=True)
def extract_scan(
    x,
    y,
    starts,
    ends,
    nseg,
    scan,
    p,
    acc,
    cacc,
    cos_t,
    sin_t,
    idx,
    sub_s,
    sub_e,
    lines,
    nl,
    circles,
    nc,
    blobs,
    nb,
    work,
    dalpha=0.0,
):
    """Features of one scan's segments (points x, y, m, sensor frame): HTL on every segment, then the
    decision rule of docs/method.md §5.2, a circle kept only when well posed (circle_posed; `dalpha`: the
    scan's angle step, rad). Appends rows to lines/circles/blobs from nl/nc/nb; returns the new counts.
    `work`: the scratch arrays extract_scans makes; acc is zeroed as segments first need it (work[-1][0]: how
    many flat cells of acc are zero)."""
    rho_res = p[P_RHO_RES]
    window = p[P_WINDOW]
    min_pts = p[P_LINE_MIN_POINTS]
    min_racc = p[P_LINE_MIN_RACC]
    min_len = p[P_LINE_MIN_LENGTH]
    lo, toff, cell, touched, peaks, cand, kept, cidx, cout, hist, box, zeroed = work
    nt = cos_t.shape[0]
    kwin = int(window / (np.pi / nt))
    tstep = np.pi / nt
    for g in range(nseg):
        s = starts[g]
        e = ends[g]
        if e - s >= min_pts:
            normal_cells(x, y, s, e, nt, cell)
            # line_subsegments uses the first nt * width cells of acc (flat): zero what was never used before
            used = nt * _bounding_box(x, y, s, e, rho_res, acc.shape[1], box)
            if used > zeroed[0]:
                acc.reshape(-1)[zeroed[0] : used] = 0
                zeroed[0] = used
            nsub = line_subsegments(
                x, y, s, e, acc, toff, cos_t, sin_t, rho_res, kwin, cell, touched, sub_s, sub_e, peaks, hist
            )
        else:
            nsub = 0  # too few points for a line of more than three: no HTL
        nkept = 0
        ncand = 0
        votes = 0.0
        for k in range(nsub):
            t = peaks[k, 1]
            line_of_run(
                x,
                y,
                sub_s[k],
                sub_e[k],
                t * tstep,
                toff[t] + (peaks[k, 2] + 0.5) * rho_res,
                peaks[k, 0],
                rho_res,
                idx,
                lo,
            )
            cand[k, :] = lo
            if lo[LC_N] >= min_pts:  # an HTL line (more than 3 points) for the decision rule
                cidx[ncand] = k
                ncand += 1
                votes += lo[LC_RACC] * (sub_e[k] - sub_s[k])  # the refined line's r_acc, in points
            if lo[LC_N] >= min_pts and lo[LC_RACC] > min_racc and lo[LC_LEN] > min_len:
                kept[nkept] = k
                nkept += 1
        htl_racc = votes / (e - s)  # r_acc of the segment's lines together
        # merge consecutive kept lines that are one line split by noise
        if nkept > 1:
            m = 1
            for q in range(1, nkept):
                a = cand[kept[m - 1]]
                b = cand[kept[q]]
                dt = abs(a[LC_THETA] - b[LC_THETA])
                dt = min(dt, np.pi - dt)
                same_side = (
                    abs(a[LC_RHO] - b[LC_RHO])
                    if abs(a[LC_THETA] - b[LC_THETA]) < np.pi / 2
                    else abs(a[LC_RHO] + b[LC_RHO])
                )
                if dt < 3.0 * np.pi / 180 and same_side < 2 * rho_res and kept[q] == kept[m - 1] + 1:
                    len_a = sub_e[kept[m - 1]] - sub_s[kept[m - 1]]
                    len_b = sub_e[kept[q]] - sub_s[kept[q]]
                    merged = a[LC_RACC] * len_a + b[LC_RACC] * len_b
                    line_of_run(
                        x, y, sub_s[kept[m - 1]], sub_e[kept[q]], a[LC_THETA], a[LC_RHO], merged, rho_res, idx, lo
                    )
                    sub_e[kept[m - 1]] = sub_e[kept[q]]
                    cand[kept[m - 1], :] = lo
                else:
                    kept[m] = kept[q]
                    m += 1
            nkept = m
        # section 5.2: HTC for segments whose lines look like an arc; only segments small enough to be a
        # circle of the allowed radii (a long wall with a deflection stays lines)
        ext = np.hypot(x[e - 1] - x[s], y[e - 1] - y[s])
        try_circle = False
        leg_only = False  # tested as a circle beyond the paper's rule: if it fails, the lines stay
        if ext <= 2.0 * p[P_R_MAX] + 2.0 * p[P_CTOL]:
            if ncand == 0:
                try_circle = True
            elif ncand == 1:
                # the paper tests a single line as a circle when its r_acc < 0.5; datmo tests every single
                # line of a segment small enough to be a circle, and keeps the better fit (a leg a few metres
                # away, or a column's arc, is a shallow arc that HTL can take for a line with r_acc > 0.5)
                try_circle = True
                leg_only = cand[cidx[0], LC_PEAK_RACC] >= min_racc  # not the paper's case: no circle keeps the line
            elif ncand == 2:
                # two non-perpendicular lines: the paper's case; two perpendicular ones may be a box's corner
                # or an arc cut in two halves (a column seen whole): the better fit decides, lines on a tie
                try_circle = True
                leg_only = _perpendicular(cand[cidx[0], LC_THETA], cand[cidx[1], LC_THETA], p[P_PERP_TOL])
            else:
                convex = 0
                for q in range(ncand - 1):
                    a = cand[cidx[q]]
                    b = cand[cidx[q + 1]]
                    if _convex(a[LC_X0], a[LC_Y0], a[LC_X1], a[LC_Y1], b[LC_X1], b[LC_Y1]):
                        convex += 1
                try_circle = convex >= 2
        if try_circle:
            if e - s >= p[P_CIRCLE_MIN_POINTS]:
                circle_of_run(x, y, s, e, p, cacc, idx, cout, max(htl_racc, min_racc))
            else:
                cout[CC_RACC] = 0.0
            lines_rss = -1.0  # the circle's points to the segment's HTL lines (two or more: a corner?)
            if ncand >= 2 and cout[CC_N] >= 3:
                lines_rss = 0.0
                for q in range(int(cout[CC_N])):
                    i = idx[q]
                    dmin = np.inf
                    for j in range(ncand):
                        c = cand[cidx[j]]
                        dmin = min(dmin, abs(x[i] * np.cos(c[LC_THETA]) + y[i] * np.sin(c[LC_THETA]) - c[LC_RHO]))
                    lines_rss += dmin * dmin
            # a circle beats the lines, and holds like a line must (r_acc above line_min_racc)
            # and is a well-posed arc (idx[:n] still holds the points circle_of_run fitted)
            if (
                cout[CC_RACC] > max(htl_racc, min_racc)
                and cout[CC_N] >= p[P_CIRCLE_MIN_POINTS]
                and circle_posed(x, y, idx, int(cout[CC_N]), cout[CC_X], cout[CC_Y], cout[CC_R], p, dalpha, lines_rss)
            ):
                row = circles[nc]
                row[C_SCAN] = scan
                row[C_SEG] = g
                row[C_FIRST] = s
                row[C_LAST] = e - 1
                row[C_N] = cout[CC_N]
                row[C_X] = cout[CC_X]
                row[C_Y] = cout[CC_Y]
                row[C_R] = cout[CC_R]
                row[C_RACC] = cout[CC_RACC]
                nc += 1
                continue
            if not leg_only:
                nkept = 0
        if nkept > 0:
            for q in range(nkept):
                c = cand[kept[q]]
                row = lines[nl]
                row[L_SCAN] = scan
                row[L_SEG] = g
                row[L_FIRST] = c[LC_FIRST]
                row[L_LAST] = c[LC_LAST]
                row[L_N] = c[LC_N]
                row[L_X0] = c[LC_X0]
                row[L_Y0] = c[LC_Y0]
                row[L_X1] = c[LC_X1]
                row[L_Y1] = c[LC_Y1]
                row[L_RHO] = c[LC_RHO]
                row[L_THETA] = c[LC_THETA]
                row[L_LEN] = c[LC_LEN]
                row[L_RACC] = c[LC_RACC]
                nl += 1
            continue
        # a blob (or a point): centroid and largest extent
        sx = 0.0
        sy = 0.0
        for i in range(s, e):
            sx += x[i]
            sy += y[i]
        far = s
        dmax = 0.0
        for i in range(s, e):
            d = (x[i] - x[s]) ** 2 + (y[i] - y[s]) ** 2
            if d > dmax:
                dmax = d
                far = i
        for i in range(s, e):  # two sweeps: exact for convex outlines, within a few % otherwise
            d = (x[i] - x[far]) ** 2 + (y[i] - y[far]) ** 2
            if d > dmax:
                dmax = d
        row = blobs[nb]
        row[B_SCAN] = scan
        row[B_SEG] = g
        row[B_FIRST] = s
        row[B_LAST] = e - 1
        row[B_N] = e - s
        row[B_X] = sx / (e - s)
        row[B_Y] = sy / (e - s)
        row[B_SIZE] = np.sqrt(dmax)
        row[B_KIND] = 1.0 if e - s < 3 else 0.0
        nb += 1
    return nl, nc, nb


@njit(cache=True)
def extract_scans(
    ranges,
    k0,
    k1,
    cos_a,
    sin_a,
    cos_inc,
    c1,
    range_min,
    range_max,
    p,
    cos_t,
    sin_t,
    seg_out,
    lines,
    circles,
    blobs,
    counts,
    given,
    given_offsets,
):
    """Segment and extract features of scans k0 .. k1 - 1 of a block (ranges (N, B), m): scan k's segments
    (rows [start, end)), lines, circles and blobs go to rows [k * B, k * B + counts[k, j]) of seg_out, lines,
    circles and blobs (j = 0, 1, 2, 3), each (N * B, columns) (a scan has at most B of each). With
    given_offsets of length N + 1, the segments are not computed but taken from `given` (rows [start, end),
    scan k's at given_offsets[k]:given_offsets[k + 1]). Scans are independent: any split of a block into
    calls gives the same rows, so extract_parallel runs disjoint ranges of scans at once."""
    N, B = ranges.shape
    x = np.empty(B)
    y = np.empty(B)
    starts = np.empty(B + 1, np.int64)
    ends = np.empty(B + 1, np.int64)
    idx = np.empty(B, np.int64)
    sub_s = np.empty(MAX_SUB, np.int64)
    sub_e = np.empty(MAX_SUB, np.int64)
    diag = 2.0 * min(range_max, 100.0)
    # not zeroed here: extract_scan zeroes the part a segment needs the first time (a few % of it in practice)
    acc = np.empty((cos_t.shape[0], int(diag / p[P_RHO_RES]) + 3), np.int32)
    w = int(round(p[P_CWINDOW] / p[P_CELL]))
    cacc = np.zeros((2 * w + 1, 2 * w + 1), np.int32)
    min_points = int(p[P_MIN_POINTS])
    use_given = given_offsets.shape[0] == N + 1
    dalpha = np.arccos(min(max(cos_inc, -1.0), 1.0))  # the angle step, for circle_posed
    nt = cos_t.shape[0]
    work = (
        np.empty(12),
        np.empty(nt),
        np.empty(B, np.int64),
        np.zeros(nt, np.bool_),
        np.empty((MAX_SUB, 3), np.int64),
        np.empty((MAX_SUB, 12)),
        np.empty(MAX_SUB, np.int64),
        np.empty(MAX_SUB, np.int64),
        np.empty(5),
        np.empty((B, 3), np.int64),
        np.empty(4),
        np.zeros(1, np.int64),
    )
    for k in range(k0, k1):
        r = ranges[k]
        if use_given:
            nseg = 0
            for q in range(given_offsets[k], given_offsets[k + 1]):
                a = min(max(given[q, 0], 0), B)
                b = min(max(given[q, 1], a), B)
                if b > a and nseg < B:
                    starts[nseg] = a
                    ends[nseg] = b
                    nseg += 1
        else:
            nseg = segment_scan(r, cos_inc, p[P_C0], c1, range_min, range_max, min_points, starts, ends)
        base = k * B
        for g in range(nseg):
            seg_out[base + g, 0] = starts[g]
            seg_out[base + g, 1] = ends[g]
        counts[k, 0] = nseg
        for i in range(B):
            ri = r[i]
            if not valid_return(ri, range_min, range_max):
                ri = 0.0  # only reachable through given segments: an invalid return is a point at the scanner
            x[i] = ri * cos_a[i]
            y[i] = ri * sin_a[i]
        nl, nc, nb = extract_scan(
            x,
            y,
            starts,
            ends,
            nseg,
            k,
            p,
            acc,
            cacc,
            cos_t,
            sin_t,
            idx,
            sub_s,
            sub_e,
            lines,
            base,
            circles,
            base,
            blobs,
            base,
            work,
            dalpha,
        )
        counts[k, 1] = nl - base
        counts[k, 2] = nc - base
        counts[k, 3] = nb - base


@njit(cache=True, parallel=True)
def extract_parallel(
    ranges,
    parts,
    cos_a,
    sin_a,
    cos_inc,
    c1,
    range_min,
    range_max,
    p,
    cos_t,
    sin_t,
    seg_out,
    lines,
    circles,
    blobs,
    counts,
    given,
    given_offsets,
):
    """extract_scans over all N scans of the block, split into `parts` ranges of consecutive scans run on
    numba's threads (numba.set_num_threads); the same rows as one extract_scans(ranges, 0, N, ...)."""
    N = ranges.shape[0]
    for j in prange(parts):
        extract_scans(
            ranges,
            j * N // parts,
            (j + 1) * N // parts,
            cos_a,
            sin_a,
            cos_inc,
            c1,
            range_min,
            range_max,
            p,
            cos_t,
            sin_t,
            seg_out,
            lines,
            circles,
            blobs,
            counts,
            given,
            given_offsets,
        )


@njit(cache=True)
def gather_rows(rows, counts, j, B, out) -> None:
    """out (sum of counts[:, j], columns): the first counts[k, j] rows of each scan k's stretch of B rows of
    `rows` (see extract_scans), in scan order."""
    m = 0
    for k in range(counts.shape[0]):
        for q in range(counts[k, j]):
            out[m] = rows[k * B + q]
            m += 1


@njit(cache=True)
def segment_block(ranges, cos_inc, c0, c1, range_min, range_max, min_points, seg_out, seg_count) -> int:
    """Segments of every scan of a block: seg_out rows [start, end), seg_count per scan; returns the total."""
    N, B = ranges.shape
    starts = np.empty(B, np.int64)
    ends = np.empty(B, np.int64)
    ns = 0
    for k in range(N):
        nseg = segment_scan(ranges[k], cos_inc, c0, c1, range_min, range_max, min_points, starts, ends)
        for g in range(nseg):
            seg_out[ns + g, 0] = starts[g]
            seg_out[ns + g, 1] = ends[g]
        ns += nseg
        seg_count[k] = nseg
    return ns
