"""A numba assignment solver for gated cost matrices: global nearest neighbour without scipy.

`lsap` solves the rectangular linear sum assignment problem by shortest augmenting paths (Crouse 2016, "On
implementing 2D rectangular assignment algorithms", the Jonker-Volgenant family), with the tie rules of
scipy.optimize.linear_sum_assignment: columns are scanned from the last, an equal shortest path that ends
in a free column wins, a tall matrix is solved transposed. So on the same matrix it returns scipy's
assignment, ties included (tests/test_tracking_assign.py checks that on random gated matrices).

`gnn` is the global nearest neighbour rule (tests/reference_tracking.reference_gnn): the pairs of `allowed`
minimising the summed cost, disallowed pairs priced INFEASIBLE (so the most allowed pairs are made first) and
dropped from the answer. Costs are unitless (squared Mahalanobis distance plus log det S, or metres); rows are
tracks, columns measurements. It solves each connected component of the allowed pairs apart (most tracks and
measurements of a scan have one candidate or none), which gives the same assignment as scipy on the whole matrix
except where two assignments' costs tie, exactly or within the resolution of sums of INFEASIBLE (about 1e-4 per pair
priced INFEASIBLE): there scipy's choice is decided by its scan order and rounding, this one by the component's and
the exact costs. On the sample logs the two never differ (tests/test_tracking_step.py compares whole runs byte for
byte).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

INFEASIBLE = 1e12


@njit(cache=True)
def lsap(cost):
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
            if min_val == np.inf:  # cannot happen with finite costs
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
def _components(allowed, rows_in, cols_in, nr, nc):
    """Connected components of the allowed pairs among rows rows_in[:nr] and columns cols_in[:nc]: a label per
    row and per column (0, 1, ...), and the number of components."""
    crow = np.full(nr, -1, np.int64)
    ccol = np.full(nc, -1, np.int64)
    stack = np.empty(nr + nc, np.int64)  # rows as a, columns as nr + b
    n_comp = 0
    for start in range(nr):
        if crow[start] >= 0:
            continue
        crow[start] = n_comp
        top = 0
        stack[top] = start
        top += 1
        while top:
            top -= 1
            v = stack[top]
            if v < nr:
                for b in range(nc):
                    if ccol[b] < 0 and allowed[rows_in[v], cols_in[b]]:
                        ccol[b] = n_comp
                        stack[top] = nr + b
                        top += 1
            else:
                for a in range(nr):
                    if crow[a] < 0 and allowed[rows_in[a], cols_in[v - nr]]:
                        crow[a] = n_comp
                        stack[top] = a
                        top += 1
        n_comp += 1
    return crow, ccol, n_comp


@njit(cache=True)
def gnn(cost, allowed):
    """The allowed pairs (rows, cols) int64 of least summed cost, each row and column at most once, rows
    ascending (see the module docstring). Solved per connected component of the allowed pairs (a pair
    outside them could only be made at INFEASIBLE): a component of one row or one column takes its cheapest
    allowed pair (the first in row-major order), a larger one is solved by lsap."""
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
    pair_col = np.full(K, -1, np.int64)  # the column each row takes
    crow, ccol, n_comp = _components(allowed, rows_in, cols_in, nr, nc)
    for comp in range(n_comp):
        rr = np.empty(nr, np.int64)
        cc = np.empty(nc, np.int64)
        a_n = 0
        for a in range(nr):
            if crow[a] == comp:
                rr[a_n] = rows_in[a]
                a_n += 1
        b_n = 0
        for b in range(nc):
            if ccol[b] == comp:
                cc[b_n] = cols_in[b]
                b_n += 1
        if a_n == 1 or b_n == 1:
            best, bk, bj = np.inf, -1, -1
            for a in range(a_n):
                for b in range(b_n):
                    k, j = rr[a], cc[b]
                    if allowed[k, j] and (bk < 0 or cost[k, j] < best):
                        best, bk, bj = cost[k, j], k, j
            pair_col[bk] = bj
            continue
        c = np.empty((a_n, b_n))
        for a in range(a_n):
            for b in range(b_n):
                k, j = rr[a], cc[b]
                c[a, b] = cost[k, j] if allowed[k, j] else INFEASIBLE
        r, q = lsap(c)
        for i in range(len(r)):
            k, j = rr[r[i]], cc[q[i]]
            if allowed[k, j]:
                pair_col[k] = j
    n = 0
    for k in range(K):
        if pair_col[k] >= 0:
            n += 1
    rows = np.empty(n, np.int64)
    cols = np.empty(n, np.int64)
    n = 0
    for k in range(K):
        if pair_col[k] >= 0:
            rows[n], cols[n] = k, pair_col[k]
            n += 1
    return rows, cols
