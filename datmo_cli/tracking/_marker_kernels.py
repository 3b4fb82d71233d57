"""The numba kernel of the track markers (markers.py): points, colours, velocity arrows and tails.

Positions and velocities arrive in the frame the markers are drawn in (m, m/s); tails are rings of
(T, 2) positions in that frame. Its check is tests/test_tracking_markers.py (against tail_segments).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from ..logs.vocabulary import CLASS_CIRCLE_OBJECT, CLASS_PERSON

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True)
def marker_points(px, py, vx, vy, cls, shown, alpha, color_table, tail, tail_count):
    """Points and colours of the track markers (markers.py): per shape list (people, circle objects,
    others) points (n, 3) and colours (n, 4); velocity arrows and trajectory tails of `shown` tracks as
    LINE_LIST points (2 per segment). Tentative tracks get colour alpha `alpha`."""
    K = len(px)
    T = tail.shape[1]
    counts = np.zeros(3, np.int64)
    group = np.empty(K, np.int64)
    n_shown = 0
    n_seg = 0
    for k in range(K):
        g = 0 if cls[k] == CLASS_PERSON else (1 if cls[k] == CLASS_CIRCLE_OBJECT else 2)
        group[k] = g
        counts[g] += 1
        if shown[k]:
            n_shown += 1
            n_seg += max(min(tail_count[k], T) - 1, 0)
    pts = [np.zeros((counts[g], 3)) for g in range(3)]
    cols = [np.empty((counts[g], 4), np.float32) for g in range(3)]
    arrows = np.zeros((2 * n_shown, 3))
    tails = np.zeros((2 * n_seg, 3))
    fill = np.zeros(3, np.int64)
    a = 0
    s = 0
    for k in range(K):
        g = group[k]
        i = fill[g]
        pts[g][i, 0], pts[g][i, 1] = px[k], py[k]
        c = min(cls[k], 3)
        for j in range(4):
            cols[g][i, j] = color_table[c, j]
        if not shown[k]:
            cols[g][i, 3] = alpha
        fill[g] += 1
        if shown[k]:
            arrows[a, 0], arrows[a, 1] = px[k], py[k]
            arrows[a + 1, 0], arrows[a + 1, 1] = px[k] + vx[k], py[k] + vy[k]
            a += 2
            n = min(tail_count[k], T)
            for j in range(n - 1):
                p0 = (tail_count[k] - n + j) % T
                p1 = (p0 + 1) % T
                tails[s, 0], tails[s, 1] = tail[k, p0, 0], tail[k, p0, 1]
                tails[s + 1, 0], tails[s + 1, 1] = tail[k, p1, 0], tail[k, p1, 1]
                s += 2
    return pts[0], cols[0], pts[1], cols[1], pts[2], cols[2], arrows, tails
