"""numba kernels of the leg detector's features: per-segment geometric features, and leg_tracker's gap clusters.

Sensor frame: x forward, y left, metres; angles in radians. The public wrappers (validation, allocation) are in
legs.py; every feature is checked against the plain-numpy reference in tests/reference_perception.py. Feature
columns are the F_* constants below, in the order of legs.FEATURE_NAMES.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from .segmentation import valid_return

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


(
    F_N,
    F_WIDTH,
    F_LINEARITY,
    F_CIRCULARITY,
    F_RADIUS,
    F_STD,
    F_MEDIAN_DEV,
    F_BOUNDARY_LENGTH,
    F_BOUNDARY_REGULARITY,
    F_MEAN_CURVATURE,
    F_INSCRIBED_ANGLE,
    F_INSCRIBED_ANGLE_STD,
    F_DISTANCE,
    F_SUBTENDED_ANGLE,
    F_OCCLUDED_START,
    F_OCCLUDED_END,
    F_JUMP_START,
    F_JUMP_END,
    F_NEIGHBOUR,
    F_DENSITY,
    F_RELATIVE_CURVATURE,
) = range(21)


N_FEATURES = 21


JUMP_CLIP = 3.0  # m: bound of the range jumps; the jump when no valid return lies beyond an end


NEIGHBOUR_CLIP = 2.0  # m: bound of the distance to the nearest other candidate (also when there is none)


DENSITY_CLIP = 10.0  # bound of the angle-step-free point density (also for a segment of zero width)


DEGENERATE = 1e-12  # circle fit refused when det(scatter) <= DEGENERATE * trace(scatter)**2 (collinear points)


@njit(cache=True)
def _median(v, n, work) -> float:
    """Median of v[0:n], sorting a copy in work."""
    w = work[:n]
    if n <= 64:
        # insertion sort: numba's general sort costs more than the whole of a leg's other features
        for i in range(n):
            t = v[i]
            j = i
            while j > 0 and w[j - 1] > t:
                w[j] = w[j - 1]
                j -= 1
            w[j] = t
    else:
        for i in range(n):
            w[i] = v[i]
        w.sort()
    h = n // 2
    return w[h] if n % 2 else 0.5 * (w[h - 1] + w[h])


@njit(cache=True)
def segment_features(x, y, n, radius_clip, work, step, out) -> None:
    """The shape features of points (x, y)[0:n] (scan order, sensor frame, m) into out; the scan-context
    columns (subtended angle, occlusion) are left to the caller. n == 0 gives zeros. work and step are
    scratch arrays of at least n elements."""
    for f in range(out.shape[0]):
        out[f] = 0.0
    if n == 0:
        return
    out[F_N] = n
    mx = 0.0
    my = 0.0
    for i in range(n):
        mx += x[i]
        my += y[i]
    mx /= n
    my /= n
    out[F_DISTANCE] = np.sqrt(mx * mx + my * my)
    out[F_WIDTH] = np.sqrt((x[n - 1] - x[0]) ** 2 + (y[n - 1] - y[0]) ** 2)

    # centred second and third moments: the best line and the algebraic (Kasa) circle
    suu = 0.0
    suv = 0.0
    svv = 0.0
    bu = 0.0
    bv = 0.0
    for i in range(n):
        u = x[i] - mx
        v = y[i] - my
        q = u * u + v * v
        suu += u * u
        suv += u * v
        svv += v * v
        bu += u * q
        bv += v * q
    # smallest eigenvalue of the scatter matrix = sum of squared orthogonal residuals of the best line
    h = 0.5 * (suu - svv)
    tr = suu + svv
    lam = 0.5 * tr - np.sqrt(h * h + suv * suv)
    linearity = np.sqrt(max(lam, 0.0) / n)
    out[F_LINEARITY] = linearity
    det = suu * svv - suv * suv
    if n < 3 or det <= DEGENERATE * tr * tr:
        out[F_RADIUS] = radius_clip
        out[F_CIRCULARITY] = linearity
    else:
        a = 0.5 * (svv * bu - suv * bv) / det
        b = 0.5 * (suu * bv - suv * bu) / det
        r = np.sqrt(a * a + b * b + tr / n)
        cx = mx + a
        cy = my + b
        s = 0.0
        for i in range(n):
            d = np.sqrt((x[i] - cx) ** 2 + (y[i] - cy) ** 2) - r
            s += d * d
        out[F_RADIUS] = min(r, radius_clip)
        out[F_CIRCULARITY] = np.sqrt(s / n)
    if n > 1:
        out[F_STD] = np.sqrt(tr / (n - 1))

    xm = _median(x, n, work)
    ym = _median(y, n, work)
    s = 0.0
    for i in range(n):
        s += np.sqrt((x[i] - xm) ** 2 + (y[i] - ym) ** 2)
    out[F_MEDIAN_DEV] = s / n

    if n > 1:
        length = 0.0
        for i in range(n - 1):
            step[i] = np.sqrt((x[i + 1] - x[i]) ** 2 + (y[i + 1] - y[i]) ** 2)
            length += step[i]
        mean = length / (n - 1)
        s = 0.0
        for i in range(n - 1):
            s += (step[i] - mean) ** 2
        out[F_BOUNDARY_LENGTH] = length
        out[F_BOUNDARY_REGULARITY] = np.sqrt(s / (n - 1))

    if n > 2:
        curv = 0.0
        ang = 0.0
        ex = x[n - 1]
        ey = y[n - 1]
        for i in range(1, n - 1):
            ax = x[i] - x[i - 1]
            ay = y[i] - y[i - 1]
            cx = x[i + 1] - x[i - 1]
            cy = y[i + 1] - y[i - 1]
            cross = cx * ay - cy * ax  # side of p_i relative to the chord p_i-1 -> p_i+1
            abc = step[i - 1] * step[i] * np.sqrt(cx * cx + cy * cy)
            if abc > 0.0 and cross != 0.0:
                k = 2.0 * abs(cross) / abc  # 1 / circumradius
                origin = cy * x[i - 1] - cx * y[i - 1]
                curv += k if cross * origin > 0.0 else -k
            # inscribed angle at p_i between the first and the last point, in [0, pi]
            ux = x[0] - x[i]
            uy = y[0] - y[i]
            vx = ex - x[i]
            vy = ey - y[i]
            work[i] = np.arctan2(abs(ux * vy - uy * vx), ux * vx + uy * vy)
            ang += work[i]
        m = n - 2
        out[F_MEAN_CURVATURE] = curv / m
        mean = ang / m
        s = 0.0
        for i in range(1, n - 1):
            s += (work[i] - mean) ** 2
        out[F_INSCRIBED_ANGLE] = mean
        out[F_INSCRIBED_ANGLE_STD] = np.sqrt(s / m)


@njit(cache=True)
def _jump(r, i, d, B, range_min, range_max) -> float:
    """Range of the nearest valid return beyond beam i in direction d (+1 / -1) minus r[i], clipped to
    +-JUMP_CLIP; +JUMP_CLIP when there is none."""
    j = i + d
    while 0 <= j < B:
        if valid_return(r[j], range_min, range_max):
            return min(max(np.float64(r[j]) - np.float64(r[i]), -JUMP_CLIP), JUMP_CLIP)
        j += d
    return JUMP_CLIP


@njit(cache=True)
def block_features(ranges, beams, segs, rules, skip, out) -> None:
    """Features of every segment of a block of scans into out (M, N_FEATURES).

    Scan k's segments are seg_start/seg_end[seg_offsets[k]:seg_offsets[k + 1]], beam ranges [start, end)
    within the scan; invalid returns inside a segment are skipped. A side is occluded when the beam next to
    the segment's first (last) point is a valid return nearer than that point by more than `margin` (m); the
    jump of a side is the range of the nearest valid return beyond it minus the end point's range. Candidates
    (is_candidate with max_width, min_points) give the neighbour distance: from a segment's centroid to the
    nearest other candidate's centroid in the same scan. angle_step (rad) is the scan's beam spacing, for the
    density n_points * angle_step * distance / width. With skip, segments that are not candidates get only
    n_points and width, the rest zero: the hot path skips what the ensemble will not look at.

    beams = (cos_a, sin_a, angles, angle_step) of the beams; segs = (seg_start, seg_end, seg_offsets); rules =
    (range_min, range_max, radius_clip, margin, max_width, min_points).
    """
    cos_a, sin_a, angles, angle_step = beams
    seg_start, seg_end, seg_offsets = segs
    range_min, range_max, radius_clip, margin, max_width, min_points = rules
    N, B = ranges.shape
    x = np.empty(B, np.float64)
    y = np.empty(B, np.float64)
    work = np.empty(B, np.float64)
    step = np.empty(B, np.float64)
    most = 0
    for k in range(N):
        most = max(most, seg_offsets[k + 1] - seg_offsets[k])
    cx = np.empty(most, np.float64)
    cy = np.empty(most, np.float64)
    cand = np.zeros(most, np.bool_)
    for k in range(N):
        r = ranges[k]
        g0 = seg_offsets[k]
        for g in range(g0, seg_offsets[k + 1]):
            o = out[g]
            n = 0
            first = -1
            last = -1
            sx = 0.0
            sy = 0.0
            for i in range(seg_start[g], seg_end[g]):
                if valid_return(r[i], range_min, range_max):
                    ri = np.float64(r[i])
                    x[n] = ri * cos_a[i]
                    y[n] = ri * sin_a[i]
                    sx += x[n]
                    sy += y[n]
                    n += 1
                    if first < 0:
                        first = i
                    last = i
            cand[g - g0] = False
            if n > 0:
                width = np.sqrt((x[n - 1] - x[0]) ** 2 + (y[n - 1] - y[0]) ** 2)
                cand[g - g0] = n >= min_points and width <= max_width
                cx[g - g0] = sx / n
                cy[g - g0] = sy / n
                if skip and not cand[g - g0]:
                    for f in range(o.shape[0]):
                        o[f] = 0.0
                    o[F_N] = n
                    o[F_WIDTH] = width
                    continue
            segment_features(x, y, n, radius_clip, work, step, o)
            if n == 0:
                continue
            o[F_SUBTENDED_ANGLE] = abs(angles[last] - angles[first])
            j = first - 1
            if j >= 0 and valid_return(r[j], range_min, range_max) and r[j] < np.float64(r[first]) - margin:
                o[F_OCCLUDED_START] = 1.0
            j = last + 1
            if j < B and valid_return(r[j], range_min, range_max) and r[j] < np.float64(r[last]) - margin:
                o[F_OCCLUDED_END] = 1.0
            o[F_JUMP_START] = _jump(r, first, -1, B, range_min, range_max)
            o[F_JUMP_END] = _jump(r, last, 1, B, range_min, range_max)
            w = o[F_WIDTH]
            dens = DENSITY_CLIP
            if w > 0.0:
                dens = min(n * angle_step * o[F_DISTANCE] / w, DENSITY_CLIP)
            o[F_DENSITY] = dens
            o[F_RELATIVE_CURVATURE] = o[F_MEAN_CURVATURE] * w
        # the nearest other candidate of each segment with features
        for g in range(g0, seg_offsets[k + 1]):
            o = out[g]
            if o[F_N] == 0 or (skip and not cand[g - g0]):
                continue
            best = NEIGHBOUR_CLIP * NEIGHBOUR_CLIP
            ax = cx[g - g0]
            ay = cy[g - g0]
            for h in range(seg_offsets[k + 1] - g0):
                if cand[h] and h != g - g0:
                    d2 = (cx[h] - ax) ** 2 + (cy[h] - ay) ** 2
                    if d2 < best:
                        best = d2
            o[F_NEIGHBOUR] = np.sqrt(best)


@njit(cache=True)
def check_segments(seg_start, seg_end, seg_offsets, B) -> int:
    """0 when the offsets index the segments (non-decreasing, 0 to M) and every segment is a beam range
    [start, end) within 0..B; 1 for bad offsets, 2 for a bad segment."""
    M = seg_start.shape[0]
    N = seg_offsets.shape[0] - 1
    if N < 0 or seg_offsets[0] != 0 or seg_offsets[N] != M:
        return 1
    for k in range(N):
        if seg_offsets[k + 1] < seg_offsets[k]:
            return 1
    for g in range(M):
        if seg_start[g] < 0 or seg_end[g] < seg_start[g] or seg_end[g] > B:
            return 2
    return 0


@njit(cache=True)
def _gap_pass(ranges, cos_a, sin_a, range_min, range_max, gap, min_points, start, end, counts) -> None:
    """Gap clusters of every scan: counts[k] clusters of scan k; written to start/end (from the running
    total) when those are not empty."""
    N, B = ranges.shape
    fill = start.shape[0] > 0
    g2 = gap * gap
    m = 0
    for k in range(N):
        r = ranges[k]
        c = 0
        first = -1  # first beam of the open cluster (-1: none)
        last = -1
        n = 0
        px = 0.0
        py = 0.0
        qx = 0.0
        qy = 0.0
        for i in range(B + 1):
            ok = i < B and valid_return(r[i], range_min, range_max)
            close = not ok
            if ok:
                ri = np.float64(r[i])
                qx = ri * cos_a[i]
                qy = ri * sin_a[i]
                if first >= 0 and (qx - px) ** 2 + (qy - py) ** 2 > g2:
                    close = True
            if close and first >= 0:
                if n >= min_points:
                    if fill:
                        start[m] = first
                        end[m] = last + 1
                    m += 1
                    c += 1
                first = -1
                n = 0
            if ok:
                if first < 0:
                    first = i
                last = i
                n += 1
                px = qx
                py = qy
        counts[k] = c
