"""Data association: gating on Mahalanobis distance and global nearest neighbour (method.md §6.2, datmo's
addition to the paper). Pure functions on cost matrices; tracks are rows, measurements columns."""

from __future__ import annotations

import numpy as np

INFEASIBLE = 1e12


def gate(d2: np.ndarray, dist: np.ndarray, gate: float, max_distance: float) -> np.ndarray:
    """Boolean (K, M): pairs whose squared Mahalanobis distance is within `gate` and whose Euclidean
    distance (m) is within `max_distance`."""
    return (d2 <= gate) & (dist <= max_distance)


def gnn(cost: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global nearest neighbour: the assignment of rows to columns that minimises the summed cost over the
    `allowed` pairs (each row and column used at most once; disallowed pairs never returned).
    Returns (rows, cols) as int64 arrays."""
    K, M = cost.shape
    if K == 0 or M == 0 or not allowed.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if K == 1 or M == 1:  # one row or column: the cheapest allowed pair is the optimum
        c = np.where(allowed, cost, np.inf)
        i, j = np.unravel_index(int(np.argmin(c)), c.shape)
        return np.array([i], np.int64), np.array([j], np.int64)
    from scipy.optimize import linear_sum_assignment

    c = np.where(allowed, cost, INFEASIBLE)
    rows, cols = linear_sum_assignment(c)
    ok = allowed[rows, cols]
    return rows[ok].astype(np.int64), cols[ok].astype(np.int64)
