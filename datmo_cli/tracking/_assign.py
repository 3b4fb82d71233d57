"""A numba assignment solver for gated cost matrices: global nearest neighbour without scipy.

`lsap` solves the rectangular linear sum assignment problem by shortest augmenting paths (Crouse 2016, "On
implementing 2D rectangular assignment algorithms", the Jonker-Volgenant family), with the tie rules of
scipy.optimize.linear_sum_assignment: columns are scanned from the last, an equal shortest path that ends
in a free column wins, a tall matrix is solved transposed. So on the same matrix it returns scipy's
assignment, ties included (tests/test_tracking_assign.py checks that on random gated matrices).

`gnn` is association.gnn's rule: the pairs of `allowed` minimising the summed cost, disallowed pairs priced
INFEASIBLE (so the most allowed pairs are made first) and dropped from the answer. Costs are unitless
(squared Mahalanobis distance plus log det S, or metres); rows are tracks, columns measurements. It solves
only the rows and columns that have an allowed pair (most tracks and measurements of a scan have none),
which gives the same assignment as scipy on the whole matrix except where two assignments' costs tie
within the resolution of sums of INFEASIBLE (about 1e-4 per pair priced INFEASIBLE): there scipy's choice
is decided by rounding and this one by the exact costs. On the sample logs the two never differ
(tests/test_tracking_step.py compares whole runs).
"""

from __future__ import annotations

import numpy as np
from numba import njit

INFEASIBLE = 1e12


@njit(cache=True)
def lsap(cost):  # noqa: ANN001, ANN201
    """Minimum-cost assignment of the (R, C) float64 `cost` (finite entries): (rows, cols) int64 of
    min(R, C) pairs, rows ascending, as scipy.optimize.linear_sum_assignment returns them."""
    R, C = cost.shape
    if R == 0 or C == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    transpose = C < R
    c = cost.T.copy() if transpose else cost
    nr, nc = (C, R) if transpose else (R, C)
    u = np.zeros(nr)
    v = np.zeros(nc)
    spc = np.empty(nc)
    path = np.full(nc, -1, np.int64)
    col4row = np.full(nr, -1, np.int64)
    row4col = np.full(nc, -1, np.int64)
    SR = np.zeros(nr, np.bool_)
    SC = np.zeros(nc, np.bool_)
    remaining = np.empty(nc, np.int64)
    for cur in range(nr):
        # shortest augmenting path from row `cur`
        min_val = 0.0
        n_rem = nc
        for it in range(nc):
            remaining[it] = nc - it - 1
        SR[:] = False
        SC[:] = False
        spc[:] = np.inf
        i = cur
        sink = -1
        while sink == -1:
            index = -1
            lowest = np.inf
            SR[i] = True
            for it in range(n_rem):
                j = remaining[it]
                r = min_val + c[i, j] - u[i] - v[j]
                if r < spc[j]:
                    path[j] = i
                    spc[j] = r
                if spc[j] < lowest or (spc[j] == lowest and row4col[j] == -1):
                    lowest = spc[j]
                    index = it
            min_val = lowest
            if min_val == np.inf:   # cannot happen with finite costs
                return np.zeros(0, np.int64), np.zeros(0, np.int64)
            j = remaining[index]
            if row4col[j] == -1:
                sink = j
            else:
                i = row4col[j]
            SC[j] = True
            n_rem -= 1
            remaining[index] = remaining[n_rem]
        # dual variables
        u[cur] += min_val
        for i in range(nr):
            if SR[i] and i != cur:
                u[i] += min_val - spc[col4row[i]]
        for j in range(nc):
            if SC[j]:
                v[j] -= min_val - spc[j]
        # augment
        j = sink
        while True:
            i = path[j]
            row4col[j] = i
            col4row[i], j = j, col4row[i]
            if i == cur:
                break
    rows = np.empty(nr, np.int64)
    cols = np.empty(nr, np.int64)
    if transpose:
        order = np.argsort(col4row, kind="mergesort")
        for k in range(nr):
            rows[k] = col4row[order[k]]
            cols[k] = order[k]
    else:
        for k in range(nr):
            rows[k] = k
            cols[k] = col4row[k]
    return rows, cols


@njit(cache=True)
def gnn(cost, allowed):  # noqa: ANN001, ANN201
    """The allowed pairs (rows, cols) int64 of least summed cost, each row and column at most once, rows
    ascending (see the module docstring). Rows and columns without an allowed pair are left out before
    solving (they could only be paired at INFEASIBLE); one row or column left: its cheapest allowed pair
    (the first in row-major order)."""
    K, M = cost.shape
    rows_in = np.empty(K, np.int64)
    cols_in = np.empty(M, np.int64)
    col_used = np.zeros(M, np.bool_)
    nr = 0
    for k in range(K):
        row_used = False
        for j in range(M):
            if allowed[k, j]:
                row_used = True
                col_used[j] = True
        if row_used:
            rows_in[nr] = k
            nr += 1
    nc = 0
    for j in range(M):
        if col_used[j]:
            cols_in[nc] = j
            nc += 1
    if nr == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if nr == 1 or nc == 1:
        best, bk, bj = np.inf, -1, -1
        for a in range(nr):
            for b in range(nc):
                k, j = rows_in[a], cols_in[b]
                if allowed[k, j] and (bk < 0 or cost[k, j] < best):
                    best, bk, bj = cost[k, j], k, j
        return np.array([bk], np.int64), np.array([bj], np.int64)
    c = np.empty((nr, nc))
    for a in range(nr):
        for b in range(nc):
            k, j = rows_in[a], cols_in[b]
            c[a, b] = cost[k, j] if allowed[k, j] else INFEASIBLE
    r, q = lsap(c)
    rows = np.empty(len(r), np.int64)
    cols = np.empty(len(r), np.int64)
    n = 0
    for i in range(len(r)):
        k, j = rows_in[r[i]], cols_in[q[i]]
        if allowed[k, j]:
            rows[n], cols[n] = k, j
            n += 1
    return rows[:n], cols[:n]
