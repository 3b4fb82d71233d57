"""Slow, obvious reference versions of the simulator's kernels (plain Python and numpy).

Ray casting here solves each beam/primitive pair with a 2x2 linear system (segments) or by projecting
the centre on the beam (circles), then keeps the nearest hit: a different derivation from the kernel's.
"""

from __future__ import annotations

import math

import numpy as np


def ray_segment(o, d, p, q) -> float:
    """Distance along the unit beam (o, d) to segment pq, or inf."""
    a = np.array([[d[0], p[0] - q[0]], [d[1], p[1] - q[1]]], float)
    if abs(np.linalg.det(a)) < 1e-300:
        return math.inf
    t, s = np.linalg.solve(a, np.asarray(p, float) - np.asarray(o, float))
    return float(t) if t > 1e-9 and 0.0 <= s <= 1.0 else math.inf


def ray_circle(o, d, c, r) -> float:
    """Distance along the unit beam (o, d) to the circle (c, r) from outside, or inf."""
    oc = np.asarray(c, float) - np.asarray(o, float)
    if oc @ oc < r * r:
        return math.inf
    along = oc @ np.asarray(d, float)
    miss2 = oc @ oc - along * along
    if miss2 > r * r:
        return math.inf
    t = along - math.sqrt(max(r * r - miss2, 0.0))
    return t if t > 1e-9 else math.inf


def cast(pose, angles, segments, circles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(nearest distance, index of the nearest primitive, second-nearest distance) per beam.

    Primitive indices count segments first, then circles; -1 when nothing is hit.
    """
    n = len(angles)
    best, who, second = np.full(n, np.inf), np.full(n, -1), np.full(n, np.inf)
    for i, a in enumerate(angles):
        d = (math.cos(pose[2] + a), math.sin(pose[2] + a))
        hits = [ray_segment(pose[:2], d, s[:2], s[2:]) for s in segments]
        hits += [ray_circle(pose[:2], d, c[:2], c[2]) for c in circles]
        order = np.argsort(hits, kind="stable")
        if len(hits) and math.isfinite(hits[order[0]]):
            best[i], who[i] = hits[order[0]], order[0]
            if len(hits) > 1:
                second[i] = hits[order[1]]
    return best, who, second
