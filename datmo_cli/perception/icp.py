"""numba kernels of scan-matching ego-motion's matcher: a local map in a hashed grid, and point-to-line ICP against it.

A local map is a LocalMap (new_local_map makes one): its points and their unit line normals (the fixed frame,
m), the grid's cell size (m), and the grid's bucket heads and per-point next links (EMPTY ends a list).
Frames: scan points are in the sensor frame (x forward, y left, metres); the map and poses are in the fixed
"scan_odom" frame whose origin is the first scan's sensor pose. A pose is (x, y, theta): the sensor's origin
in metres and its heading in radians, so a sensor point p maps to R(theta) p + (x, y).

The public wrapper (validation, allocation, parameters) is egomotion.py; every kernel is checked against
the plain-numpy reference in tests/reference_perception.py.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


MIN_MATCHES = 12  # correspondences below which a match is refused (the prediction is kept)


CONVERGED_STEP = 2e-4  # m: a Gauss-Newton step this small in x and y ...


CONVERGED_TURN = 5e-5  # rad: ... and in theta ends the iterations once the gate is final


EMPTY = -1


class LocalMap(NamedTuple):
    """ICP's map: up to capacity points in a hashed grid (new_local_map makes it; add_to_map fills it)."""

    mx: np.ndarray  # (capacity,) float: the points' x (fixed frame, m)
    my: np.ndarray  # (capacity,) float: the points' y (m)
    mnx: np.ndarray  # (capacity,) float: x of each point's unit line normal (0, 0: none, a corner or post)
    mny: np.ndarray  # (capacity,) float: y of each point's unit line normal
    cell: float  # m: the grid's cell size
    head: np.ndarray  # (buckets,) int64: each bucket's first point, EMPTY for none (buckets a power of two)
    nxt: np.ndarray  # (capacity,) int64: the next point in each point's bucket, EMPTY at the end


@njit(cache=True)
def new_local_map(capacity, cell) -> LocalMap:
    """An empty LocalMap for up to capacity points in cells of `cell` m: at least 2 capacity buckets (a power
    of two, 16 or more), so a bucket holds about half a point."""
    buckets = 16
    while buckets < 2 * capacity:
        buckets *= 2
    return LocalMap(
        mx=np.zeros(capacity),
        my=np.zeros(capacity),
        mnx=np.zeros(capacity),
        mny=np.zeros(capacity),
        cell=float(cell),
        head=np.full(buckets, EMPTY, np.int64),
        nxt=np.full(capacity, EMPTY, np.int64),
    )


@njit(cache=True)
def cell_of(x, cell) -> np.int64:
    """Integer grid coordinate of x (m)."""
    return np.int64(np.floor(x / cell))


@njit(cache=True)
def cell_hash(ix, iy, mask) -> np.int64:
    """Bucket of the grid cell (ix, iy): a spatial hash of the integer cell coordinates."""
    return np.int64(((ix * 73856093) ^ (iy * 19349663)) & mask)


@njit(cache=True)
def grid_insert(x, y, i, cell, head, nxt) -> None:
    """Put point i at (x, y) at the front of its bucket's list."""
    h = cell_hash(cell_of(x, cell), cell_of(y, cell), head.shape[0] - 1)
    nxt[i] = head[h]
    head[h] = i


@njit(cache=True)
def grid_nearest(qx, qy, mx, my, cell, head, nxt, max_dist) -> int:
    """Index of the map point nearest to (qx, qy) within max_dist (m), or EMPTY. Searches the cells within
    ceil(max_dist / cell) of the query's; a bucket shared by two of them (hash collision) is scanned twice,
    harmlessly."""
    mask = head.shape[0] - 1
    reach = max(np.int64(1), np.int64(np.ceil(max_dist / cell - 1e-9)))
    ix = cell_of(qx, cell)
    iy = cell_of(qy, cell)
    best = EMPTY
    best_d2 = max_dist * max_dist
    for dx in range(-reach, reach + 1):
        for dy in range(-reach, reach + 1):
            j = head[cell_hash(ix + dx, iy + dy, mask)]
            while j != EMPTY:
                d2 = (mx[j] - qx) ** 2 + (my[j] - qy) ** 2
                # ties go to the lower index so the result does not depend on bucket order
                if d2 < best_d2 or (d2 == best_d2 and best != EMPTY and j < best):
                    best_d2 = d2
                    best = j
                j = nxt[j]
    return best


@njit(cache=True)
def add_to_map(points, n, pose, min_spacing, local_map, count) -> int:
    """Add sensor-frame points (and normals) seen from pose to the map, skipping those whose normal is NaN
    (see beam_normal) and those within min_spacing (m) of a map point already there. Returns the new map
    size; stops when the map arrays are full. points = (px, py, pnx, pny), sensor frame, [0:n] used; pose =
    (x, y, theta); local_map: a LocalMap, count points used."""
    px, py, pnx, pny = points
    pose_x, pose_y, pose_t = pose
    mx = local_map.mx  # each field read once, by name (an array read in the loop would be counted each pass)
    my = local_map.my
    mnx = local_map.mnx
    mny = local_map.mny
    cell = local_map.cell
    head = local_map.head
    nxt = local_map.nxt
    c = np.cos(pose_t)
    s = np.sin(pose_t)
    for i in range(n):
        if count >= mx.shape[0]:
            break
        if np.isnan(pnx[i]):
            continue
        wx = c * px[i] - s * py[i] + pose_x
        wy = s * px[i] + c * py[i] + pose_y
        if min_spacing > 0.0 and grid_nearest(wx, wy, mx, my, cell, head, nxt, min_spacing) != EMPTY:
            continue
        mx[count] = wx
        my[count] = wy
        mnx[count] = c * pnx[i] - s * pny[i]
        mny[count] = s * pnx[i] + c * pny[i]
        grid_insert(wx, wy, count, cell, head, nxt)
        count += 1
    return count


@njit(cache=True)
def robust_weight(ares, scale, redescend) -> float:
    """Weight of a residual of size ares (m): Huber at scale, or Geman-McClure (1 / (1 + (r / scale)^2)^2,
    which all but ignores residuals a few scales out) when redescend."""
    if redescend:
        q = 1.0 + (ares / scale) ** 2
        return 1.0 / (q * q)
    return 1.0 if ares <= scale else scale / ares


@njit(cache=True)
def icp_step(source, n, pose, local_map, max_dist, scale, redescend, inlier_tol, hess, grad):
    """One Gauss-Newton linearisation of the robust point-to-line cost of source points (sx, sy)[0:n] (sensor
    frame, m) placed at pose against the map (a LocalMap).

    Each source point is matched with its nearest map point within max_dist (m). With a line normal n there,
    the residual is n . (q - m); without one (corners, posts) it is q - m, two rows. Rows get robust_weight
    (scale, m; Huber, or Geman-McClure when redescend). Fills hess (3 x 3) and grad (3,) over
    (x, y, theta) and returns (matched points, sum |residual| over them (m), points with |residual| <=
    inlier_tol). source = (sx, sy); pose = (x, y, theta).
    """
    sx, sy = source
    pose_x, pose_y, pose_t = pose
    mx = local_map.mx  # each field read once, by name
    my = local_map.my
    mnx = local_map.mnx
    mny = local_map.mny
    cell = local_map.cell
    head = local_map.head
    nxt = local_map.nxt
    for a in range(3):
        grad[a] = 0.0
        for b in range(3):
            hess[a, b] = 0.0
    c = np.cos(pose_t)
    s = np.sin(pose_t)
    matched = 0
    inliers = 0
    abs_sum = 0.0
    for i in range(n):
        # q = R p + t; dq/dtheta = (-(q_y - t_y), q_x - t_x)
        rx = c * sx[i] - s * sy[i]
        ry = s * sx[i] + c * sy[i]
        qx = rx + pose_x
        qy = ry + pose_y
        j = grid_nearest(qx, qy, mx, my, cell, head, nxt, max_dist)
        if j == EMPTY:
            continue
        matched += 1
        ex = qx - mx[j]
        ey = qy - my[j]
        nx = mnx[j]
        ny = mny[j]
        if nx != 0.0 or ny != 0.0:
            res = nx * ex + ny * ey
            ares = abs(res)
            w = robust_weight(ares, scale, redescend)
            j0 = nx
            j1 = ny
            j2 = -nx * ry + ny * rx
            hess[0, 0] += w * j0 * j0
            hess[0, 1] += w * j0 * j1
            hess[0, 2] += w * j0 * j2
            hess[1, 1] += w * j1 * j1
            hess[1, 2] += w * j1 * j2
            hess[2, 2] += w * j2 * j2
            grad[0] += w * j0 * res
            grad[1] += w * j1 * res
            grad[2] += w * j2 * res
        else:
            ares = np.sqrt(ex * ex + ey * ey)
            w = robust_weight(ares, scale, redescend)
            # rows (1, 0, -ry) . d = ex and (0, 1, rx) . d = ey
            hess[0, 0] += w
            hess[0, 2] += -w * ry
            hess[1, 1] += w
            hess[1, 2] += w * rx
            hess[2, 2] += w * (ry * ry + rx * rx)
            grad[0] += w * ex
            grad[1] += w * ey
            grad[2] += w * (-ry * ex + rx * ey)
        abs_sum += ares
        if ares <= inlier_tol:
            inliers += 1
    hess[1, 0] = hess[0, 1]
    hess[2, 0] = hess[0, 2]
    hess[2, 1] = hess[1, 2]
    return matched, abs_sum, inliers


@njit(cache=True)
def solve3(a, b, out) -> bool:
    """out = a^-1 b for a symmetric 3 x 3 a (Cramer's rule); False when a is singular."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    scale = abs(a[0, 0] * a[1, 1] * a[2, 2]) + 1e-300
    if not np.isfinite(det) or abs(det) <= 1e-12 * scale:
        return False
    c10 = a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]
    c11 = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    c12 = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    c20 = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    c21 = a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]
    c22 = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    out[0] = (c00 * b[0] + c10 * b[1] + c20 * b[2]) / det
    out[1] = (c01 * b[0] + c11 * b[1] + c21 * b[2]) / det
    out[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) / det
    return True


@njit(cache=True)
def icp_align(source, n, init, local_map, settings, pose_out):
    """Pose of the source scan (sensor points (sx, sy)[0:n]) against the map by Gauss-Newton ICP from init.

    The correspondence gate halves from max_dist0 down to max_dist (m) under Huber weights, then iterations
    continue under Geman-McClure weights (moving people drop out) until the step is below CONVERGED_STEP and
    CONVERGED_TURN, or max_iter. A prior of prior_weight (per m^2, and per rad^2 at 1 m)
    pulls toward init, so directions the scene leaves free (a bare corridor) keep the prediction.
    Writes the pose into pose_out and returns (matched, mean |residual| (m), inliers, iterations); a match
    with fewer than MIN_MATCHES correspondences or a singular system leaves pose_out at init. source = (sx, sy);
    init = (x, y, theta); settings = (max_dist0, max_dist, scale, inlier_tol, max_iter, prior_weight).
    """
    init_x, init_y, init_t = init
    max_dist0, max_dist, scale, inlier_tol, max_iter, prior_weight = settings
    hess = np.empty((3, 3))
    grad = np.empty(3)
    step = np.empty(3)
    x = init_x
    y = init_y
    t = init_t
    gate = max_dist0
    matched = 0
    abs_sum = 0.0
    inliers = 0
    it = 0
    while it < max_iter:
        it += 1
        matched, abs_sum, inliers = icp_step(
            source, n, (x, y, t), local_map, gate, scale, gate <= max_dist, inlier_tol, hess, grad
        )
        if matched < MIN_MATCHES:
            break
        hess[0, 0] += prior_weight
        hess[1, 1] += prior_weight
        hess[2, 2] += prior_weight
        grad[0] += prior_weight * (x - init_x)
        grad[1] += prior_weight * (y - init_y)
        grad[2] += prior_weight * (t - init_t)
        if not solve3(hess, grad, step):
            matched = 0
            break
        x -= step[0]
        y -= step[1]
        t -= step[2]
        small = abs(step[0]) < CONVERGED_STEP and abs(step[1]) < CONVERGED_STEP and abs(step[2]) < CONVERGED_TURN
        if gate > max_dist:
            gate = max(max_dist, 0.5 * gate)
        elif small:
            break
    if matched < MIN_MATCHES:
        pose_out[0] = init_x
        pose_out[1] = init_y
        pose_out[2] = init_t
        return matched, 0.0, 0, it
    # the figures of the final pose, at the final gate
    matched, abs_sum, inliers = icp_step(source, n, (x, y, t), local_map, gate, scale, True, inlier_tol, hess, grad)
    pose_out[0] = x
    pose_out[1] = y
    pose_out[2] = np.arctan2(np.sin(t), np.cos(t))
    return matched, abs_sum / max(matched, 1), inliers, it


@njit(cache=True)
def compose(ax, ay, at, bx, by, bt):
    """a (+) b: pose b, given in a's frame, expressed in a's parent frame."""
    c = np.cos(at)
    s = np.sin(at)
    return ax + c * bx - s * by, ay + s * bx + c * by, at + bt


@njit(cache=True)
def between(ax, ay, at, bx, by, bt):
    """a^-1 (+) b: pose b expressed in a's frame."""
    c = np.cos(at)
    s = np.sin(at)
    dx = bx - ax
    dy = by - ay
    dt = bt - at
    return c * dx + s * dy, -s * dx + c * dy, np.arctan2(np.sin(dt), np.cos(dt))
