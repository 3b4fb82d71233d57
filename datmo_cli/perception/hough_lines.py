"""numba kernels of line extraction by the Hough transform for lines, HTL (docs/method.md §5.1).

Sensor frame: x forward, y left, metres; angles in radians. Checked against tests/reference_perception.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from .feature_layout import (
    LC_FIRST,
    LC_LAST,
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

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


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
        a_min = max(s, i - 10)
        b_max = min(e - 1, i + 10)
        # unsigned indices (a, b >= s >= 0): numba drops its negative-index wrapping from the loop
        ua = np.uint64(a)
        ub = np.uint64(b)
        while (x[ub] - x[ua]) ** 2 + (y[ub] - y[ua]) ** 2 < 0.04 and (a > a_min or b < b_max):
            a = max(s, a - 1)
            b = min(e - 1, b + 1)
            ua = np.uint64(a)
            ub = np.uint64(b)
        phi = _wrap_pi(_atan2(y[ub] - y[ua], x[ub] - x[ua]) + np.pi / 2)
        cell[np.uint64(i)] = min(int(phi * nt / np.pi), nt - 1)


@njit(cache=True)
def _vote(xi, yi, acc, lo, touched, box, cos_t, sin_t, cells, peak):
    """Point (xi, yi) votes along its sinusoid: theta cells c - k .. c + k (wrapping; all of them when 2k + 1 >= nt)
    around its local normal's cell c, and marks those theta rows in `touched`; cells = (inv_res, width, c, k).
    Returns the peak (votes, theta cell, rho cell) updated from `peak`. acc: the accumulator as one flat array,
    theta row t at [t * width, (t + 1) * width) (rows `width` apart keep a segment's votes in a few cache lines);
    lo[t] is computed from the segment's bounding box (xmin, xmax, ymin, ymax) when row t is first voted in.
    Arrays are passed one by one, not in a tuple: this runs per point, and a tuple of arrays costs reference
    counting each time."""
    inv_res, width, c, k = cells
    bv, bt, br = peak
    nt = cos_t.shape[0]
    if 2 * k + 1 >= nt:
        t_from = 0
        t_to = nt
    else:
        t_from = c - k
        t_to = c + k + 1
    for tt in range(t_from, t_to):
        t = tt
        if t < 0:
            t += nt
        elif t >= nt:
            t -= nt
        u = np.uint64(t)  # an unsigned index: numba drops its negative-index wrapping (t >= 0 here)
        if not touched[u]:
            touched[u] = True
            lo[u] = _row_offset(box, cos_t[u], sin_t[u])
        ri = int((xi * cos_t[u] + yi * sin_t[u] - lo[u]) * inv_res)
        if ri < 0:
            ri = 0
        elif ri >= width:
            ri = width - 1
        j = np.uint64(t * width + ri)
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
def line_subsegments(x, y, s, e, hough, cos_t, sin_t, rho_res, k, cell, runs, hist) -> int:
    """Split points [s, e) into runs that each hold one line: the accumulator peak is followed as points are
    added in scan order, and when more than three consecutive new points lie off the peak's line (farther
    than two rho cells), a new line starts at the first of them. hough = (acc, lo, touched), runs = (sub_s,
    sub_e, peaks). Returns the number of runs in sub_s/sub_e;
    peaks[k] = (votes, theta cell, rho cell) of run k's accumulator peak (lo[t]: the smallest rho the
    segment's bounding box gives at theta cell t, see _row_offset; cell: see
    normal_cells; k: theta cells voted either side of the normal; hist: scratch of at least e - s rows). Only
    the rows voted in get their lo (a peak's row always is); acc (nt, width_max) is used as one flat array of
    rows as wide as the segment needs and is left all zero, as `touched` is left all False."""
    acc, lo, touched = hough
    sub_s, sub_e, peaks = runs
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
        ui = np.uint64(i)  # unsigned indices: no negative-index wrapping (see _vote)
        xi = x[ui]
        yi = y[ui]
        bv, bt, br = _vote(xi, yi, acc, lo, touched, box, cos_t, sin_t, (inv, width, cell[ui], k), (bv, bt, br))
        hist[i - s, 0] = bv
        hist[i - s, 1] = bt
        hist[i - s, 2] = br
        if i - start >= 4:
            t = np.uint64(bt)
            rho_p = lo[t] + (br + 0.5) * rho_res
            # off the peak's line by more than two cells (one cell either way of the cell's quantisation)
            if abs(xi * cos_t[t] + yi * sin_t[t] - rho_p) > 2.0 * rho_res:
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
                    bv, bt, br = _vote(
                        x[j], y[j], acc, lo, touched, box, cos_t, sin_t, (inv, width, cell[j], k), (bv, bt, br)
                    )
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
        i = np.uint64(idx[k])  # an unsigned index: no negative-index wrapping (see _vote)
        cx += x[i]
        cy += y[i]
    cx /= m
    cy /= m
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for k in range(m):
        i = np.uint64(idx[k])
        dx = x[i] - cx
        dy = y[i] - cy
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
        ui = np.uint64(i)  # unsigned indices here and below: no negative-index wrapping (see _vote)
        if abs(x[ui] * c + y[ui] * sn - rho_p) <= rho_res:
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
        ui = np.uint64(i)
        if abs(x[ui] * c + y[ui] * sn - rho) <= rho_res:
            m2 += 1
    if m2 > m:
        m = 0
        for i in range(s, e):
            ui = np.uint64(i)
            if abs(x[ui] * c + y[ui] * sn - rho) <= rho_res:
                idx[m] = i
                m += 1
        theta, rho = fit_line(x, y, idx, m)
        c = np.cos(theta)
        sn = np.sin(theta)
    # r_acc: the peak cell's votes, or the points in a cell-wide band centred on the fitted line if more
    on = 0
    for k in range(m):
        ui = np.uint64(idx[k])
        if abs(x[ui] * c + y[ui] * sn - rho) <= 0.5 * rho_res:
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
