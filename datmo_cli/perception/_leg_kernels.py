"""numba kernels of the learned leg detector: per-segment geometric features and a tree-ensemble evaluator.

Sensor frame: x forward, y left, metres; angles in radians. The public wrappers (validation, allocation,
model loading) are in legs.py; every feature is checked against the plain-numpy reference in
tests/naive_legs.py. Feature columns are the F_* constants below, in the order of legs.FEATURE_NAMES.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import valid_return

(F_N, F_WIDTH, F_LINEARITY, F_CIRCULARITY, F_RADIUS, F_STD, F_MEDIAN_DEV, F_BOUNDARY_LENGTH,
 F_BOUNDARY_REGULARITY, F_MEAN_CURVATURE, F_INSCRIBED_ANGLE, F_INSCRIBED_ANGLE_STD, F_DISTANCE,
 F_SUBTENDED_ANGLE, F_OCCLUDED_START, F_OCCLUDED_END) = range(16)
N_FEATURES = 16
DEGENERATE = 1e-12   # circle fit refused when det(scatter) <= DEGENERATE * trace(scatter)**2 (collinear points)
KIND_FOREST, KIND_BOOSTING = 0, 1


@njit(cache=True)
def _circle(x, y, n, mx, my, radius_clip, linearity):
    """Algebraic (Kasa) least-squares circle of points 0..n-1: (radius, RMS radial residual), metres.

    Solved in centred coordinates; collinear or fewer than 3 points: (radius_clip, linearity)."""
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
    det = suu * svv - suv * suv
    tr = suu + svv
    if n < 3 or det <= DEGENERATE * tr * tr:
        return radius_clip, linearity
    bu *= 0.5
    bv *= 0.5
    a = (svv * bu - suv * bv) / det
    b = (suu * bv - suv * bu) / det
    r = np.sqrt(a * a + b * b + tr / n)
    cx = mx + a
    cy = my + b
    s = 0.0
    for i in range(n):
        d = np.sqrt((x[i] - cx) ** 2 + (y[i] - cy) ** 2) - r
        s += d * d
    return min(r, radius_clip), np.sqrt(s / n)


@njit(cache=True)
def _median(v, n, work) -> float:
    for i in range(n):
        work[i] = v[i]
    w = work[:n]
    w.sort()
    h = n // 2
    return w[h] if n % 2 else 0.5 * (w[h - 1] + w[h])


@njit(cache=True)
def segment_features(x, y, n, radius_clip, work, out) -> None:
    """The shape features of points (x, y)[0:n] (scan order, sensor frame, m) into out; the scan-context
    columns (subtended angle, occlusion) are left to the caller. n == 0 gives zeros."""
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

    suu = 0.0
    suv = 0.0
    svv = 0.0
    for i in range(n):
        u = x[i] - mx
        v = y[i] - my
        suu += u * u
        suv += u * v
        svv += v * v
    # smallest eigenvalue of the scatter matrix = sum of squared orthogonal residuals of the best line
    h = 0.5 * (suu - svv)
    lam = 0.5 * (suu + svv) - np.sqrt(h * h + suv * suv)
    out[F_LINEARITY] = np.sqrt(max(lam, 0.0) / n)
    out[F_RADIUS], out[F_CIRCULARITY] = _circle(x, y, n, mx, my, radius_clip, out[F_LINEARITY])
    if n > 1:
        out[F_STD] = np.sqrt((suu + svv) / (n - 1))

    xm = _median(x, n, work)
    ym = _median(y, n, work)
    s = 0.0
    for i in range(n):
        s += np.sqrt((x[i] - xm) ** 2 + (y[i] - ym) ** 2)
    out[F_MEDIAN_DEV] = s / n

    if n > 1:
        length = 0.0
        for i in range(n - 1):
            length += np.sqrt((x[i + 1] - x[i]) ** 2 + (y[i + 1] - y[i]) ** 2)
        mean = length / (n - 1)
        s = 0.0
        for i in range(n - 1):
            d = np.sqrt((x[i + 1] - x[i]) ** 2 + (y[i + 1] - y[i]) ** 2) - mean
            s += d * d
        out[F_BOUNDARY_LENGTH] = length
        out[F_BOUNDARY_REGULARITY] = np.sqrt(s / (n - 1))

    if n > 2:
        curv = 0.0
        ang = 0.0
        for i in range(1, n - 1):
            ax = x[i] - x[i - 1]
            ay = y[i] - y[i - 1]
            cx = x[i + 1] - x[i - 1]
            cy = y[i + 1] - y[i - 1]
            cross = cx * ay - cy * ax             # side of p_i relative to the chord p_i-1 -> p_i+1
            abc = np.sqrt(ax * ax + ay * ay) * np.sqrt((x[i + 1] - x[i]) ** 2 + (y[i + 1] - y[i]) ** 2) \
                * np.sqrt(cx * cx + cy * cy)
            if abc > 0.0 and cross != 0.0:
                k = 2.0 * abs(cross) / abc          # 1 / circumradius
                origin = cx * (-y[i - 1]) - cy * (-x[i - 1])
                curv += k if cross * origin > 0.0 else -k
            ang += _inscribed(x, y, n, i)
        m = n - 2
        out[F_MEAN_CURVATURE] = curv / m
        mean = ang / m
        s = 0.0
        for i in range(1, n - 1):
            d = _inscribed(x, y, n, i) - mean
            s += d * d
        out[F_INSCRIBED_ANGLE] = mean
        out[F_INSCRIBED_ANGLE_STD] = np.sqrt(s / m)


@njit(cache=True)
def _inscribed(x, y, n, i) -> float:
    """Angle at p_i between p_0 and p_n-1, radians in [0, pi]."""
    ux = x[0] - x[i]
    uy = y[0] - y[i]
    vx = x[n - 1] - x[i]
    vy = y[n - 1] - y[i]
    return np.arctan2(abs(ux * vy - uy * vx), ux * vx + uy * vy)


@njit(cache=True)
def block_features(ranges, angles, cos_a, sin_a, seg_start, seg_end, seg_offsets, range_min, range_max,
                   radius_clip, margin, out) -> None:
    """Features of every segment of a block of scans into out (M, N_FEATURES).

    Scan k's segments are seg_start/seg_end[seg_offsets[k]:seg_offsets[k + 1]], beam ranges [start, end)
    within the scan; invalid returns inside a segment are skipped. A side is occluded when the beam next to
    the segment's first (last) point is a valid return nearer than that point by more than `margin` (m).
    """
    N, B = ranges.shape
    x = np.empty(B, np.float64)
    y = np.empty(B, np.float64)
    work = np.empty(B, np.float64)
    for k in range(N):
        r = ranges[k]
        for g in range(seg_offsets[k], seg_offsets[k + 1]):
            n = 0
            first = -1
            last = -1
            for i in range(seg_start[g], seg_end[g]):
                if valid_return(r[i], range_min, range_max):
                    ri = np.float64(r[i])
                    x[n] = ri * cos_a[i]
                    y[n] = ri * sin_a[i]
                    n += 1
                    if first < 0:
                        first = i
                    last = i
            o = out[g]
            segment_features(x, y, n, radius_clip, work, o)
            if n == 0:
                continue
            o[F_SUBTENDED_ANGLE] = abs(angles[last] - angles[first])
            j = first - 1
            if j >= 0 and valid_return(r[j], range_min, range_max) and r[j] < np.float64(r[first]) - margin:
                o[F_OCCLUDED_START] = 1.0
            j = last + 1
            if j < B and valid_return(r[j], range_min, range_max) and r[j] < np.float64(r[last]) - margin:
                o[F_OCCLUDED_END] = 1.0


@njit(cache=True)
def is_candidate(row, max_width, min_points) -> bool:
    """A segment that may be a leg: at least min_points points and at most max_width (m) wide."""
    return row[F_N] >= min_points and row[F_WIDTH] <= max_width


@njit(cache=True)
def ensemble(features, max_width, min_points, feature, threshold, left, right, value, roots, kind, base, scale,
             out) -> None:
    """Leg probability of each row of features (M, F) into out (M,); non-candidates get 0.

    Trees as flat node arrays (feature -1 at leaves; children global indices). Like scikit-learn, a node
    sends x left when float32(x[feature]) <= threshold. kind KIND_FOREST: mean over trees of the leaf values
    (positive-class fractions); KIND_BOOSTING: sigmoid(base + scale * sum of leaf values)."""
    T = roots.shape[0]
    for m in range(features.shape[0]):
        row = features[m]
        if T == 0 or not is_candidate(row, max_width, min_points):
            out[m] = 0.0
            continue
        acc = 0.0
        for t in range(T):
            node = roots[t]
            while feature[node] >= 0:
                if np.float64(np.float32(row[feature[node]])) <= threshold[node]:
                    node = left[node]
                else:
                    node = right[node]
            acc += value[node]
        if kind == KIND_FOREST:
            out[m] = acc / T
        else:
            out[m] = 1.0 / (1.0 + np.exp(-(base + scale * acc)))


@njit(cache=True)
def block_probabilities(ranges, angles, cos_a, sin_a, seg_start, seg_end, seg_offsets, range_min, range_max,
                        radius_clip, margin, max_width, min_points, feature, threshold, left, right, value, roots,
                        kind, base, scale, features, out) -> None:
    """block_features then ensemble in one compiled call (the per-scan hot path)."""
    block_features(ranges, angles, cos_a, sin_a, seg_start, seg_end, seg_offsets, range_min, range_max,
                   radius_clip, margin, features)
    ensemble(features, max_width, min_points, feature, threshold, left, right, value, roots, kind, base, scale,
             out)
