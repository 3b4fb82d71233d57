"""People (method.md §6.1): pairing leg circles into a person, and the walking pattern.

A person is two leg circles no farther apart than a stride bound, tracked at the centre between the legs.
Walking shows as the legs alternating: along the direction of travel first one leg leads, then the other,
by up to a step of 2 l sin(theta). Positions in metres, any one frame.
These are the plain numpy statements of the rules; the tracker runs them fused in _kernels (leg_stage,
legs_to_measurements, apply_updates), and tests check the kernels against these.
"""

from __future__ import annotations

import numpy as np


def pair_legs(x: np.ndarray, y: np.ndarray, stride_max: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pair leg candidates greedily, nearest pairs first, each leg at most once, pairs at most
    `stride_max` m apart. Returns (a, b, single): index arrays of the pairs' legs and of unpaired legs."""
    n = len(x)
    if n < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.arange(n)
    d = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
    i, j = np.nonzero(np.triu(d <= stride_max, 1))
    if not len(i):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.arange(n)
    order = np.argsort(d[i, j], kind="stable")
    used = np.zeros(n, bool)
    a, b = [], []
    for k in order.tolist():
        p, q = i[k], j[k]
        if not used[p] and not used[q]:
            used[p] = used[q] = True
            a.append(p)
            b.append(q)
    return np.array(a, np.int64), np.array(b, np.int64), np.flatnonzero(~used)


def leg_lead(legs: np.ndarray, vx: np.ndarray, vy: np.ndarray) -> np.ndarray:
    """How far the left leg leads the right one along the direction of travel (m), for rows of
    legs (ax, ay, bx, by) and velocities (vx, vy); NaN where the speed is zero. Left is the leg on the
    left of the direction of travel, so the sign alternates from step to step while walking."""
    speed = np.hypot(vx, vy)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux, uy = vx / speed, vy / speed
    dx, dy = legs[:, 0] - legs[:, 2], legs[:, 1] - legs[:, 3]  # a minus b
    along = dx * ux + dy * uy
    left_is_a = (ux * dy - uy * dx) > 0                          # a lies left of b
    return np.where(left_is_a, along, -along)
