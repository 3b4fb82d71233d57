"""numba kernels of the simulator: exact ray casting and the towed platform. Contiguous arrays only.

Ray casting works in the world frame: a beam from (ox, oy) in direction (cos a, sin a) hits a segment
(x1, y1, x2, y2) or a circle (cx, cy, r) at the smallest distance t > EPS. A beam starting inside a
circle does not see that circle, and a beam parallel to a segment misses it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

EPS = 1e-9


@njit(cache=True, inline="always")
def _ray_segment(ox, oy, dx, dy, x1, y1, x2, y2):
    ex = x2 - x1
    ey = y2 - y1
    den = dx * ey - dy * ex
    if den == 0.0:
        return np.inf
    wx = x1 - ox
    wy = y1 - oy
    t = (wx * ey - wy * ex) / den
    s = (wx * dy - wy * dx) / den
    if t > EPS and s >= 0.0 and s <= 1.0:
        return t
    return np.inf


@njit(cache=True, inline="always")
def _ray_circle(ox, oy, dx, dy, cx, cy, r):
    fx = ox - cx
    fy = oy - cy
    b = fx * dx + fy * dy
    c = fx * fx + fy * fy - r * r
    disc = b * b - c
    if disc < 0.0 or c < 0.0:
        return np.inf
    t = -b - math.sqrt(disc)
    if t > EPS:
        return t
    return np.inf


@njit(cache=True)
def cast_batch(
    poses, angles, seg_s, own_seg_s, circ_s, own_circ_s, seg_d, own_seg_d, circ_d, own_circ_d, out_t, out_owner
):
    """Cast every beam of every scan.

    poses (n, 3): sensor x, y (m), heading (rad), world frame. angles (B,): beam angles in the sensor
    frame (rad). seg_s (S, 4) / circ_s (C, 3): static primitives; seg_d (n, Sd, 4) / circ_d (n, Cd, 3):
    moving ones at each scan's instant. own_*: the object index of each primitive. Writes the distance
    to the first hit (inf when none) to out_t (n, B) and the hit object's index (-1 when none) to
    out_owner (n, B).
    """
    n = poses.shape[0]
    nb = angles.shape[0]
    for k in range(n):
        ox = poses[k, 0]
        oy = poses[k, 1]
        th = poses[k, 2]
        for i in range(nb):
            a = th + angles[i]
            dx = math.cos(a)
            dy = math.sin(a)
            best = np.inf
            who = -1
            for j in range(seg_s.shape[0]):
                t = _ray_segment(ox, oy, dx, dy, seg_s[j, 0], seg_s[j, 1], seg_s[j, 2], seg_s[j, 3])
                if t < best:
                    best = t
                    who = own_seg_s[j]
            for j in range(circ_s.shape[0]):
                t = _ray_circle(ox, oy, dx, dy, circ_s[j, 0], circ_s[j, 1], circ_s[j, 2])
                if t < best:
                    best = t
                    who = own_circ_s[j]
            for j in range(seg_d.shape[1]):
                t = _ray_segment(ox, oy, dx, dy, seg_d[k, j, 0], seg_d[k, j, 1], seg_d[k, j, 2], seg_d[k, j, 3])
                if t < best:
                    best = t
                    who = own_seg_d[j]
            for j in range(circ_d.shape[1]):
                t = _ray_circle(ox, oy, dx, dy, circ_d[k, j, 0], circ_d[k, j, 1], circ_d[k, j, 2])
                if t < best:
                    best = t
                    who = own_circ_d[j]
            out_t[k, i] = best
            out_owner[k, i] = who


@njit(cache=True)
def tow(leader, start, wire):
    """Positions (M, 2) of a load pulled on a wire of length `wire` (m) behind `leader` (M, 2).

    The wire is taut when the leader is farther than `wire`: the load then moves straight towards the
    leader until the distance is `wire` again; otherwise the load stays where it is.
    """
    m = leader.shape[0]
    out = np.empty((m, 2))
    px = start[0]
    py = start[1]
    for k in range(m):
        dx = leader[k, 0] - px
        dy = leader[k, 1] - py
        d = math.sqrt(dx * dx + dy * dy)
        if d > wire:
            px = leader[k, 0] - wire * dx / d
            py = leader[k, 1] - wire * dy / d
        out[k, 0] = px
        out[k, 1] = py
    return out
