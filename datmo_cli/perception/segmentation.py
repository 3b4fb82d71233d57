"""numba kernels of scan segmentation (docs/method.md §4).

Sensor frame: x forward, y left, metres. Checked against tests/reference_perception.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True)
def valid_return(r: float, range_min: float, range_max: float) -> bool:
    """A return that counts: finite and strictly between the scan's range limits."""
    return np.isfinite(r) and r > range_min and r < range_max


@njit(cache=True)
def segment_scan(r, cos_inc, c0, c1, range_min, range_max, min_points, starts, ends) -> int:
    """Segments of one scan (ranges r, m) into starts/ends ([start, end) beam indices); returns the count.

    P_i+1 joins P_i's segment when d(P_i, P_i+1) <= c0 + c1 * min(r_i, r_i+1) (law of cosines with the
    scan's angle step); invalid returns break segments; segments under min_points are dropped.
    """
    n = 0
    start = -1
    B = r.shape[0]
    for i in range(B + 1):
        ok = i < B and valid_return(r[i], range_min, range_max)
        if ok and start >= 0:
            a = np.float64(r[i - 1])  # float64 arithmetic whatever the ranges' type
            b = np.float64(r[i])
            d2 = a * a + b * b - 2.0 * a * b * cos_inc
            d = np.sqrt(max(d2, 0.0))
            if d > c0 + c1 * min(a, b):
                if i - start >= min_points:
                    starts[n] = start
                    ends[n] = i
                    n += 1
                start = i
        elif ok:
            start = i
        elif start >= 0:
            if i - start >= min_points:
                starts[n] = start
                ends[n] = i
                n += 1
            start = -1
    return n


@njit(cache=True)
def segment_block(ranges, cos_inc, c0, c1, range_min, range_max, min_points, seg_out, seg_count) -> int:
    """Segments of every scan of a block: seg_out rows [start, end), seg_count per scan; returns the total."""
    N, B = ranges.shape
    starts = np.empty(B, np.int64)
    ends = np.empty(B, np.int64)
    ns = 0
    for k in range(N):
        nseg = segment_scan(ranges[k], cos_inc, c0, c1, range_min, range_max, min_points, starts, ends)
        for g in range(nseg):
            seg_out[ns + g, 0] = starts[g]
            seg_out[ns + g, 1] = ends[g]
        ns += nseg
        seg_count[k] = nseg
    return ns
