"""numba kernels of scan-matching ego-motion: scan points, line normals, a hashed grid, point-to-line ICP.

Frames: scan points are in the sensor frame (x forward, y left, metres); the map and poses are in the fixed
"scan_odom" frame whose origin is the first scan's sensor pose. A pose is (x, y, theta): the sensor's origin
in metres and its heading in radians, so a sensor point p maps to R(theta) p + (x, y).

The public wrapper (validation, allocation, parameters) is egomotion.py; every kernel is checked against
the plain-numpy reference in tests/reference_perception.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..numba_runtime import key_kernel_cache_on_sources
from ._kernels import valid_return

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

# columns of the per-scan statistics written by odometry_run
S_RESIDUAL, S_INLIER_SHARE, S_MATCHED, S_POINTS, S_FLAGS, S_ITERATIONS = range(6)
N_STATS = 6
# flag bits in stats[:, S_FLAGS]
FLAG_KEYFRAME, FLAG_RECOVERED, FLAG_FAILED = 1, 2, 4
MIN_MATCHES = 12  # correspondences below which a match is refused (the prediction is kept)
CONVERGED_STEP = 2e-4  # m: a Gauss-Newton step this small in x and y ...
CONVERGED_TURN = 5e-5  # rad: ... and in theta ends the iterations once the gate is final
EMPTY = -1


@njit(cache=True)
def scan_points(r, cos_a, sin_a, range_min, range_max, min_spacing, max_points, x_out, y_out, beam_out) -> int:
    """Valid returns of one scan as sensor-frame points (m), thinned in beam order so that consecutive kept
    points are at least min_spacing apart, then evenly strided down to max_points. Returns the count."""
    n = 0
    lx = np.inf
    ly = np.inf
    for b in range(r.shape[0]):
        rb = r[b]
        if not valid_return(rb, range_min, range_max):
            continue
        px = rb * cos_a[b]
        py = rb * sin_a[b]
        if (px - lx) ** 2 + (py - ly) ** 2 < min_spacing * min_spacing:
            continue
        x_out[n] = px
        y_out[n] = py
        beam_out[n] = b
        lx = px
        ly = py
        n += 1
    if n > max_points:
        # keep index floor(i * n / max_points): evenly spread over the scan, first point kept
        for i in range(max_points):
            j = (i * n) // max_points
            x_out[i] = x_out[j]
            y_out[i] = y_out[j]
            beam_out[i] = beam_out[j]
        n = max_points
    return n


@njit(cache=True)
def _gather(r, cos_a, sin_a, range_min, range_max, b, direction, normal_radius, max_gap, max_window, acc) -> float:
    """Add to acc (count, sums of u, v, uu, uv, vv about beam b's point) the valid points walking from beam b
    in `direction` (+1 or -1): each within max_gap (m) of the previous one taken, until at least 2 are taken
    and one is normal_radius (m) from b's point, or max_window beams. Returns the farthest distance taken."""
    px = r[b] * cos_a[b]
    py = r[b] * sin_a[b]
    lx = px
    ly = py
    taken = 0
    far = 0.0
    for step in range(1, max_window + 1):
        j = b + direction * step
        if j < 0 or j >= r.shape[0]:
            break
        rj = r[j]
        if not valid_return(rj, range_min, range_max):
            continue
        qx = rj * cos_a[j]
        qy = rj * sin_a[j]
        if (qx - lx) ** 2 + (qy - ly) ** 2 > max_gap * max_gap:
            break
        u = qx - px
        v = qy - py
        acc[0] += 1.0
        acc[1] += u
        acc[2] += v
        acc[3] += u * u
        acc[4] += u * v
        acc[5] += v * v
        taken += 1
        lx = qx
        ly = qy
        d = np.sqrt(u * u + v * v)
        far = max(far, d)
        if taken >= 2 and d >= normal_radius:
            break
    return far


@njit(cache=True)
def beam_normal(r, cos_a, sin_a, range_min, range_max, b, normal_radius, max_gap, max_window, planarity):
    """(nx, ny) unit line normal (sensor frame) at beam b's point, by total least squares over its neighbours
    in beam order (see _gather: about normal_radius (m) each side, steps of at most max_gap (m), so sparse
    walls seen at a grazing angle still get a line).

    (0, 0) when the neighbourhood is compact (within 2 normal_radius) but not line-like (minor / major
    spread above planarity: a corner, a leg): match it point to point. (NaN, NaN) when it has under 3
    points, or is spread out and not line-like: an isolated return, or one whose beam-angle sampling would
    pin a point-to-point match to the keyframe, so it is left out of the map.
    """
    acc = np.zeros(6)
    acc[0] = 1.0  # b's own point, at the origin of the sums
    far = max(
        _gather(r, cos_a, sin_a, range_min, range_max, b, -1, normal_radius, max_gap, max_window, acc),
        _gather(r, cos_a, sin_a, range_min, range_max, b, 1, normal_radius, max_gap, max_window, acc),
    )
    m = acc[0]
    if m < 3:
        return np.nan, np.nan
    mx = acc[1] / m
    my = acc[2] / m
    a = acc[3] / m - mx * mx
    c = acc[5] / m - my * my
    h = acc[4] / m - mx * my
    mid = 0.5 * (a + c)
    dev = np.sqrt(0.25 * (a - c) ** 2 + h * h)
    lmax = mid + dev
    lmin = mid - dev
    if lmax > 0.0 and lmin <= planarity * planarity * lmax:
        phi = 0.5 * np.arctan2(2.0 * h, a - c)  # direction of the major axis
        return -np.sin(phi), np.cos(phi)
    if far <= 2.0 * normal_radius:
        return 0.0, 0.0
    return np.nan, np.nan


@njit(cache=True)
def scan_normals(
    r, cos_a, sin_a, range_min, range_max, beams, n, normal_radius, max_gap, max_window, planarity, nx_out, ny_out
) -> None:
    """beam_normal at the points of beams[0:n] into nx_out, ny_out."""
    for i in range(n):
        nx, ny = beam_normal(
            r, cos_a, sin_a, range_min, range_max, beams[i], normal_radius, max_gap, max_window, planarity
        )
        nx_out[i] = nx
        ny_out[i] = ny


@njit(cache=True)
def cell_of(x, cell) -> int:
    """Integer grid coordinate of x (m)."""
    return np.int64(np.floor(x / cell))


@njit(cache=True)
def cell_hash(ix, iy, mask) -> int:
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
    reach = max(1, np.int64(np.ceil(max_dist / cell - 1e-9)))
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
def add_to_map(
    px, py, pnx, pny, n, pose_x, pose_y, pose_t, min_spacing, cell, head, nxt, mx, my, mnx, mny, count
) -> int:
    """Add sensor-frame points (and normals) seen from pose to the map, skipping those whose normal is NaN
    (see beam_normal) and those within min_spacing (m) of a map point already there. Returns the new map
    size; stops when the map arrays are full."""
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
def icp_step(
    sx,
    sy,
    n,
    pose_x,
    pose_y,
    pose_t,
    mx,
    my,
    mnx,
    mny,
    cell,
    head,
    nxt,
    max_dist,
    scale,
    redescend,
    inlier_tol,
    hess,
    grad,
):
    """One Gauss-Newton linearisation of the robust point-to-line cost of source points (sx, sy)[0:n] (sensor
    frame, m) placed at pose against the map.

    Each source point is matched with its nearest map point within max_dist (m). With a line normal n there,
    the residual is n . (q - m); without one (corners, posts) it is q - m, two rows. Rows get robust_weight
    (scale, m; Huber, or Geman-McClure when redescend). Fills hess (3 x 3) and grad (3,) over
    (x, y, theta) and returns (matched points, sum |residual| over them (m), points with |residual| <=
    inlier_tol).
    """
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
def icp_align(
    sx,
    sy,
    n,
    init_x,
    init_y,
    init_t,
    mx,
    my,
    mnx,
    mny,
    cell,
    head,
    nxt,
    max_dist0,
    max_dist,
    scale,
    inlier_tol,
    max_iter,
    prior_weight,
    pose_out,
):
    """Pose of the source scan (sensor points (sx, sy)[0:n]) against the map by Gauss-Newton ICP from init.

    The correspondence gate halves from max_dist0 down to max_dist (m) under Huber weights, then iterations
    continue under Geman-McClure weights (moving people drop out) until the step is below CONVERGED_STEP and
    CONVERGED_TURN, or max_iter. A prior of prior_weight (per m^2, and per rad^2 at 1 m)
    pulls toward init, so directions the scene leaves free (a bare corridor) keep the prediction.
    Writes the pose into pose_out and returns (matched, mean |residual| (m), inliers, iterations); a match
    with fewer than MIN_MATCHES correspondences or a singular system leaves pose_out at init.
    """
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
            sx, sy, n, x, y, t, mx, my, mnx, mny, cell, head, nxt, gate, scale, gate <= max_dist, inlier_tol, hess, grad
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
    matched, abs_sum, inliers = icp_step(
        sx, sy, n, x, y, t, mx, my, mnx, mny, cell, head, nxt, gate, scale, True, inlier_tol, hess, grad
    )
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


@njit(cache=True)
def rebuild_map(
    kf_x, kf_y, kf_nx, kf_ny, kf_n, kf_pose, newest, n_kf, map_spacing, cell, head, nxt, mx, my, mnx, mny
) -> int:
    """The map from the n_kf keyframes ending at ring slot newest, newest first (its points win where
    keyframes overlap, so older, more drifted ones only fill in). Returns the map size."""
    head[:] = EMPTY
    count = 0
    k_slots = kf_n.shape[0]
    for a in range(n_kf):
        k = (newest - a) % k_slots
        count = add_to_map(
            kf_x[k],
            kf_y[k],
            kf_nx[k],
            kf_ny[k],
            kf_n[k],
            kf_pose[k, 0],
            kf_pose[k, 1],
            kf_pose[k, 2],
            map_spacing if a > 0 else 0.0,
            cell,
            head,
            nxt,
            mx,
            my,
            mnx,
            mny,
            count,
        )
    return count


@njit(cache=True)
def odometry_run(
    ranges,
    dt,
    cos_a,
    sin_a,
    range_min,
    range_max,
    max_points,
    source_spacing,
    map_spacing,
    normal_radius,
    max_gap,
    max_window,
    planarity,
    max_dist0,
    max_dist,
    scale,
    inlier_tol,
    max_iter,
    prior_weight,
    keyframe_dist,
    keyframe_angle,
    keyframe_share,
    n_keyframes,
    min_inlier_share,
    recovery_moves,
    poses,
    stats,
) -> None:
    """Sensor poses (N x 3, scan_odom frame) of every scan of ranges (N x B, m) by scan-to-local-map ICP.

    dt (N,): seconds since the previous scan (dt[0] unused). The prediction is the previous pose plus the
    previous motion scaled by the time ratio (constant velocity). The map holds the last n_keyframes
    keyframes; a scan becomes one when it is keyframe_dist (m) or keyframe_angle (rad) from the newest, or
    its inlier share is under keyframe_share. When the share is under min_inlier_share, or ICP did not
    converge within max_iter, it is retried from
    the previous pose moved by each row of recovery_moves (K x 3: x, y (m), theta (rad) in the previous scan's
    frame) and the best share kept. stats (N x N_STATS).
    """
    n_scans, n_beams = ranges.shape
    k_slots = max(1, n_keyframes)
    kf_x = np.zeros((k_slots, n_beams))
    kf_y = np.zeros((k_slots, n_beams))
    kf_nx = np.zeros((k_slots, n_beams))
    kf_ny = np.zeros((k_slots, n_beams))
    kf_n = np.zeros(k_slots, np.int64)
    kf_pose = np.zeros((k_slots, 3))
    beams = np.zeros(n_beams, np.int64)
    sx = np.zeros(n_beams)
    sy = np.zeros(n_beams)
    cap = k_slots * n_beams
    mx = np.zeros(cap)
    my = np.zeros(cap)
    mnx = np.zeros(cap)
    mny = np.zeros(cap)
    nxt = np.full(cap, EMPTY, np.int64)
    size = 1
    while size < 2 * cap:
        size *= 2
    head = np.full(size, EMPTY, np.int64)
    cell = max_dist
    pose = np.zeros(3)
    trial = np.zeros(3)
    newest = -1
    n_kf = 0
    for k in range(n_scans):
        r = ranges[k]
        n_src = scan_points(r, cos_a, sin_a, range_min, range_max, source_spacing, max_points, sx, sy, beams)
        flags = 0
        if k == 0 or n_kf == 0:
            pose[:] = 0.0
            matched, mean_res, inliers, iters = 0, 0.0, 0, 0
            share = 0.0
        else:
            px, py, pt = poses[k - 1, 0], poses[k - 1, 1], poses[k - 1, 2]
            if k >= 2 and dt[k - 1] > 0.0:
                vx, vy, vt = between(poses[k - 2, 0], poses[k - 2, 1], poses[k - 2, 2], px, py, pt)
                ratio = min(max(dt[k] / dt[k - 1], 0.0), 3.0)
                px, py, pt = compose(px, py, pt, ratio * vx, ratio * vy, ratio * vt)
            matched, mean_res, inliers, iters = icp_align(
                sx,
                sy,
                n_src,
                px,
                py,
                pt,
                mx,
                my,
                mnx,
                mny,
                cell,
                head,
                nxt,
                max_dist0,
                max_dist,
                scale,
                inlier_tol,
                max_iter,
                prior_weight,
                pose,
            )
            share = inliers / max(n_src, 1)
            if share < min_inlier_share or iters >= max_iter:
                for a in range(recovery_moves.shape[0]):
                    gx, gy, gt = compose(
                        poses[k - 1, 0],
                        poses[k - 1, 1],
                        poses[k - 1, 2],
                        recovery_moves[a, 0],
                        recovery_moves[a, 1],
                        recovery_moves[a, 2],
                    )
                    m2, r2, i2, i3 = icp_align(
                        sx,
                        sy,
                        n_src,
                        gx,
                        gy,
                        gt,
                        mx,
                        my,
                        mnx,
                        mny,
                        cell,
                        head,
                        nxt,
                        max_dist0,
                        max_dist,
                        scale,
                        inlier_tol,
                        max_iter,
                        prior_weight,
                        trial,
                    )
                    iters += i3
                    if m2 >= MIN_MATCHES and i2 / max(n_src, 1) > share:
                        share = i2 / max(n_src, 1)
                        matched, mean_res, inliers = m2, r2, i2
                        pose[:] = trial
                        flags |= FLAG_RECOVERED
            if matched < MIN_MATCHES:
                flags |= FLAG_FAILED
        poses[k] = pose
        new_kf = n_kf == 0
        if not new_kf and n_src >= MIN_MATCHES:  # a scan with (almost) no returns would only empty the map
            dx, dy, dth = between(kf_pose[newest, 0], kf_pose[newest, 1], kf_pose[newest, 2], pose[0], pose[1], pose[2])
            new_kf = (
                dx * dx + dy * dy > keyframe_dist * keyframe_dist or abs(dth) > keyframe_angle or share < keyframe_share
            )
        if new_kf:
            newest = (newest + 1) % k_slots
            n_kf = min(n_kf + 1, k_slots)
            m = scan_points(
                r, cos_a, sin_a, range_min, range_max, map_spacing, n_beams, kf_x[newest], kf_y[newest], beams
            )
            kf_n[newest] = m
            scan_normals(
                r,
                cos_a,
                sin_a,
                range_min,
                range_max,
                beams,
                m,
                normal_radius,
                max_gap,
                max_window,
                planarity,
                kf_nx[newest],
                kf_ny[newest],
            )
            kf_pose[newest] = pose
            rebuild_map(
                kf_x, kf_y, kf_nx, kf_ny, kf_n, kf_pose, newest, n_kf, map_spacing, cell, head, nxt, mx, my, mnx, mny
            )
            flags |= FLAG_KEYFRAME
        stats[k, S_RESIDUAL] = mean_res
        stats[k, S_INLIER_SHARE] = share
        stats[k, S_MATCHED] = matched
        stats[k, S_POINTS] = n_src
        stats[k, S_FLAGS] = flags
        stats[k, S_ITERATIONS] = iters
