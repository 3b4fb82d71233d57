"""Slow, obvious references of the ego-motion kernels (datmo_cli/perception/_egomotion_kernels.py).

Plain numpy, written to be read: scan points and their thinning, line normals from beam neighbours, brute-force
nearest map points, one Gauss-Newton linearisation of the robust point-to-line cost, and the whole ICP.
Sensor frame (x forward, y left) and the map frame, metres and radians; a pose (x, y, theta) maps a sensor
point p to R(theta) p + (x, y).
"""

from __future__ import annotations

import math

import numpy as np

MIN_MATCHES = 12
CONVERGED_STEP, CONVERGED_TURN = 2e-4, 5e-5   # m, rad


def is_valid(r: float, range_min: float, range_max: float) -> bool:
    return math.isfinite(r) and range_min < r < range_max


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
    p = np.array([r[b] * math.cos(angles[b]), r[b] * math.sin(angles[b])])
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
            q = np.array([r[j] * math.cos(angles[j]), r[j] * math.sin(angles[j])])
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
    if w[1] > 0 and w[0] <= planarity ** 2 * w[1]:
        return float(v[0, 0]), float(v[1, 0])
    if far <= 2 * normal_radius:
        return 0.0, 0.0
    return math.nan, math.nan


def nearest(q, map_xy, max_dist):
    """Index of the nearest map point within max_dist (lowest index on ties), or -1."""
    d2 = ((map_xy - q) ** 2).sum(axis=1)
    j = int(np.argmin(d2))
    return j if d2[j] <= max_dist ** 2 else -1


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
