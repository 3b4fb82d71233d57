"""Slow, obvious references of the leg detector's segment features and tree-ensemble evaluation.

Plain numpy, one segment at a time, written to be read; checked against datmo_cli/perception/_leg_kernels.py.
Sensor frame (x forward, y left), metres, radians; feature order of legs.FEATURE_NAMES.
"""

from __future__ import annotations

import math

import numpy as np

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


def is_valid(r: float, range_min: float, range_max: float) -> bool:
    return math.isfinite(r) and range_min < r < range_max


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
    sol = np.linalg.lstsq(A, (q ** 2).sum(axis=1), rcond=None)[0]
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


def segment_features(r: np.ndarray, angles: np.ndarray, start: int, end: int, range_min: float,
                     range_max: float) -> np.ndarray:
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
    f["occluded_start"] = float(before >= 0 and is_valid(float(r[before]), range_min, range_max)
                                and float(r[before]) < float(r[first]) - OCCLUSION_MARGIN)
    f["occluded_end"] = float(after < len(r) and is_valid(float(r[after]), range_min, range_max)
                              and float(r[after]) < float(r[last]) - OCCLUSION_MARGIN)
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
        scan = [segment_features(ranges[k], angles, int(seg_start[g]), int(seg_end[g]), range_min, range_max)
                for g in range(seg_offsets[k], seg_offsets[k + 1])]
        # the neighbour distance: to the nearest other candidate (>= 3 points, <= 0.8 m wide) of the scan
        cand = [f[0] >= CANDIDATE_MIN_POINTS and f[1] <= CANDIDATE_MAX_WIDTH for f in scan]
        cents = [centroid(ranges[k], angles, int(seg_start[g]), int(seg_end[g]), range_min, range_max)
                 if f[0] > 0 else None for g, f in zip(range(seg_offsets[k], seg_offsets[k + 1]), scan, strict=True)]
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
