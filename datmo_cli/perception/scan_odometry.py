"""numba kernels of scan-matching ego-motion over a run: scan points, line normals, keyframes, odometry_run.

Frames: scan points are in the sensor frame (x forward, y left, metres); the map and poses are in the fixed
"scan_odom" frame whose origin is the first scan's sensor pose. A pose is (x, y, theta): the sensor's origin
in metres and its heading in radians, so a sensor point p maps to R(theta) p + (x, y).

The public wrapper (validation, allocation, parameters) is egomotion.py; every kernel is checked against
the plain-numpy reference in tests/reference_perception.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from .icp import EMPTY, MIN_MATCHES, add_to_map, between, compose, icp_align, new_local_map
from .segmentation import valid_return

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


# columns of the per-scan statistics written by odometry_run
S_RESIDUAL, S_INLIER_SHARE, S_MATCHED, S_POINTS, S_FLAGS, S_ITERATIONS = range(6)


N_STATS = 6


# flag bits in stats[:, S_FLAGS]
FLAG_KEYFRAME, FLAG_RECOVERED, FLAG_FAILED = 1, 2, 4


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
def scan_normals(r, scan, beams, n, normal, nx_out, ny_out) -> None:
    """beam_normal at the points of beams[0:n] into nx_out, ny_out. scan = (cos_a, sin_a, range_min, range_max);
    normal = (normal_radius, max_gap, max_window, planarity)."""
    cos_a, sin_a, range_min, range_max = scan
    normal_radius, max_gap, max_window, planarity = normal
    for i in range(n):
        nx, ny = beam_normal(
            r, cos_a, sin_a, range_min, range_max, beams[i], normal_radius, max_gap, max_window, planarity
        )
        nx_out[i] = nx
        ny_out[i] = ny


@njit(cache=True)
def rebuild_map(keyframes, newest, n_kf, map_spacing, local_map) -> int:
    """The map (local_map, an icp.LocalMap) from the n_kf keyframes ending at ring slot newest, newest first (its
    points win where keyframes overlap, so older, more drifted ones only fill in). keyframes = (kf_x, kf_y,
    kf_nx, kf_ny, kf_n, kf_pose): per ring slot, its points, normals, count and pose. Returns the map size."""
    kf_x, kf_y, kf_nx, kf_ny, kf_n, kf_pose = keyframes
    local_map.head[:] = EMPTY
    count = 0
    k_slots = kf_n.shape[0]
    for a in range(n_kf):
        k = (newest - a) % k_slots
        pose = (kf_pose[k, 0], kf_pose[k, 1], kf_pose[k, 2])
        points = (kf_x[k], kf_y[k], kf_nx[k], kf_ny[k])
        count = add_to_map(points, kf_n[k], pose, map_spacing if a > 0 else 0.0, local_map, count)
    return count


@njit(cache=True)
def _predict(poses, dt, k):
    """Scan k's pose predicted from the two before it (constant velocity, scaled by the ratio of the scan
    intervals dt, s): the previous pose alone for k = 1 or a zero interval."""
    px, py, pt = poses[k - 1, 0], poses[k - 1, 1], poses[k - 1, 2]
    if k >= 2 and dt[k - 1] > 0.0:
        vx, vy, vt = between(poses[k - 2, 0], poses[k - 2, 1], poses[k - 2, 2], px, py, pt)
        ratio = min(max(dt[k] / dt[k - 1], 0.0), 3.0)
        px, py, pt = compose(px, py, pt, ratio * vx, ratio * vy, ratio * vt)
    return px, py, pt


@njit(cache=True)
def _match(source, n_src, poses, dt, k, local_map, icp, recovery, pose, trial):
    """Scan k's pose (into pose) by ICP of its points source = (sx, sy)[0:n_src] from the prediction; when the
    inlier share is under recovery's min_inlier_share, or ICP did not converge, retried from the previous pose
    moved by each row of recovery's moves and the best share kept (trial: scratch pose). icp: icp_align's
    settings. Returns (matched, mean residual (m), inliers, iterations, inlier share, flags)."""
    min_inlier_share, recovery_moves = recovery
    max_iter = icp[4]
    matched, mean_res, inliers, iters = icp_align(source, n_src, _predict(poses, dt, k), local_map, icp, pose)
    share = inliers / max(n_src, 1)
    flags = 0
    if share < min_inlier_share or iters >= max_iter:
        for a in range(recovery_moves.shape[0]):
            start = compose(
                poses[k - 1, 0],
                poses[k - 1, 1],
                poses[k - 1, 2],
                recovery_moves[a, 0],
                recovery_moves[a, 1],
                recovery_moves[a, 2],
            )
            m2, r2, i2, i3 = icp_align(source, n_src, start, local_map, icp, trial)
            iters += i3
            if m2 >= MIN_MATCHES and i2 / max(n_src, 1) > share:
                share = i2 / max(n_src, 1)
                matched, mean_res, inliers = m2, r2, i2
                pose[:] = trial
                flags |= FLAG_RECOVERED
    if matched < MIN_MATCHES:
        flags |= FLAG_FAILED
    return matched, mean_res, inliers, iters, share, flags


@njit(cache=True)
def odometry_run(ranges, dt, scan, thinning, normal, icp, keyframing, recovery, poses, stats) -> None:
    """Sensor poses (N x 3, scan_odom frame) of every scan of ranges (N x B, m) by scan-to-local-map ICP.

    dt (N,): seconds since the previous scan (dt[0] unused). The prediction is the previous pose plus the
    previous motion scaled by the time ratio (constant velocity). The map holds the last n_keyframes
    keyframes; a scan becomes one when it is keyframe_dist (m) or keyframe_angle (rad) from the newest, or
    its inlier share is under keyframe_share. When the share is under min_inlier_share, or ICP did not
    converge within max_iter, it is retried from
    the previous pose moved by each row of recovery_moves (K x 3: x, y (m), theta (rad) in the previous scan's
    frame) and the best share kept. stats (N x N_STATS).

    The settings, grouped: scan = (cos_a, sin_a, range_min, range_max) of the beams; thinning = (max_points,
    source_spacing, map_spacing); normal = (normal_radius, max_gap, max_window, planarity) as scan_normals takes
    them; icp = (max_dist0, max_dist, scale, inlier_tol, max_iter, prior_weight) as icp_align takes them;
    keyframing = (keyframe_dist, keyframe_angle, keyframe_share, n_keyframes); recovery = (min_inlier_share,
    recovery_moves).
    """
    cos_a, sin_a, range_min, range_max = scan
    max_points, source_spacing, map_spacing = thinning
    keyframe_dist, keyframe_angle, keyframe_share, n_keyframes = keyframing
    n_scans, n_beams = ranges.shape
    k_slots = max(1, n_keyframes)
    kf_x = np.zeros((k_slots, n_beams))
    kf_y = np.zeros((k_slots, n_beams))
    kf_nx = np.zeros((k_slots, n_beams))
    kf_ny = np.zeros((k_slots, n_beams))
    kf_n = np.zeros(k_slots, np.int64)
    kf_pose = np.zeros((k_slots, 3))
    keyframes = (kf_x, kf_y, kf_nx, kf_ny, kf_n, kf_pose)
    beams = np.zeros(n_beams, np.int64)
    sx = np.zeros(n_beams)
    sy = np.zeros(n_beams)
    local_map = new_local_map(k_slots * n_beams, icp[1])  # the map's cell is the final correspondence gate
    pose = np.zeros(3)
    trial = np.zeros(3)
    newest = -1
    n_kf = 0
    for k in range(n_scans):
        r = ranges[k]
        n_src = scan_points(r, cos_a, sin_a, range_min, range_max, source_spacing, max_points, sx, sy, beams)
        if k == 0 or n_kf == 0:
            pose[:] = 0.0
            matched, mean_res, inliers, iters, share, flags = 0, 0.0, 0, 0, 0.0, 0
        else:
            matched, mean_res, inliers, iters, share, flags = _match(
                (sx, sy), n_src, poses, dt, k, local_map, icp, recovery, pose, trial
            )
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
            scan_normals(r, scan, beams, m, normal, kf_nx[newest], kf_ny[newest])
            kf_pose[newest] = pose
            rebuild_map(keyframes, newest, n_kf, map_spacing, local_map)
            flags |= FLAG_KEYFRAME
        stats[k, S_RESIDUAL] = mean_res
        stats[k, S_INLIER_SHARE] = share
        stats[k, S_MATCHED] = matched
        stats[k, S_POINTS] = n_src
        stats[k, S_FLAGS] = flags
        stats[k, S_ITERATIONS] = iters
