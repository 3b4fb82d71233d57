"""Data association: gating on Mahalanobis distance and global nearest neighbour (method.md §6.2, datmo's
addition to the paper). Pure functions on cost matrices; tracks are rows, measurements columns.
The solver is the numba kernel of _assign.py (checked against scipy in tests)."""

from __future__ import annotations

import numpy as np

from ._assign import INFEASIBLE  # noqa: F401 - the price of a disallowed pair, here as before


def gate(d2: np.ndarray, dist: np.ndarray, gate: float, max_distance: float) -> np.ndarray:
    """Boolean (K, M): pairs whose squared Mahalanobis distance is within `gate` and whose Euclidean
    distance (m) is within `max_distance`."""
    return (d2 <= gate) & (dist <= max_distance)


def gnn(cost: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global nearest neighbour: the assignment of rows to columns that minimises the summed cost over the
    `allowed` pairs (each row and column used at most once; disallowed pairs never returned), by the numba
    solver of _assign (scipy's linear_sum_assignment's answer, ties included). Returns (rows, cols) int64."""
    from . import _assign

    return _assign.gnn(np.ascontiguousarray(cost, np.float64), np.ascontiguousarray(allowed, np.bool_))
