"""numba kernels of the leg detector's tree ensemble (random forest, extra trees or gradient boosting as flat node
arrays, see leg_model.LegModel): leaf lookup, the ensemble's probability, and features plus ensemble over a
block of scans in one compiled call.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..numba_runtime import key_kernel_cache_on_sources
from .leg_features import F_N, F_WIDTH, block_features

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


KIND_FOREST, KIND_BOOSTING = 0, 1


@njit(cache=True)
def is_candidate(row, max_width, min_points) -> bool:
    """A segment that may be a leg: at least min_points points and at most max_width (m) wide."""
    return row[F_N] >= min_points and row[F_WIDTH] <= max_width


@njit(cache=True)
def _leaf(nodes, split, row, node) -> int:
    """The leaf a row reaches from node (x goes left when float32(x[feature]) <= threshold, as in sklearn)."""
    f = nodes[node, 0]
    while f >= 0:
        # an index rather than a branch: which way a row goes is unpredictable
        node = nodes[node, 1 + np.int64(not np.float64(np.float32(row[f])) <= split[node])]
        f = nodes[node, 0]
    return node


@njit(cache=True)
def _leaves4(nodes, split, r0, r1, r2, r3, root):
    """_leaf of four rows walked together: their chains of dependent loads overlap."""
    n0 = root
    n1 = root
    n2 = root
    n3 = root
    while True:
        f0 = nodes[n0, 0]
        f1 = nodes[n1, 0]
        f2 = nodes[n2, 0]
        f3 = nodes[n3, 0]
        if f0 < 0 and f1 < 0 and f2 < 0 and f3 < 0:
            return n0, n1, n2, n3
        if f0 >= 0:
            n0 = nodes[n0, 1 + np.int64(not np.float64(np.float32(r0[f0])) <= split[n0])]
        if f1 >= 0:
            n1 = nodes[n1, 1 + np.int64(not np.float64(np.float32(r1[f1])) <= split[n1])]
        if f2 >= 0:
            n2 = nodes[n2, 1 + np.int64(not np.float64(np.float32(r2[f2])) <= split[n2])]
        if f3 >= 0:
            n3 = nodes[n3, 1 + np.int64(not np.float64(np.float32(r3[f3])) <= split[n3])]


@njit(cache=True)
def ensemble(features, max_width, min_points, nodes, split, roots, kind, base, scale, out) -> None:
    """Leg probability of each row of features (M, F) into out (M,); non-candidates get 0.

    Trees as flat node arrays: nodes[i] = (feature, left, right) with feature -1 at leaves and children as
    global indices; split[i] = the threshold of an inner node, the value of a leaf. Like scikit-learn, a node
    sends x left when float32(x[feature]) <= threshold. kind KIND_FOREST: mean over trees of the leaf values
    (positive-class fractions); KIND_BOOSTING: sigmoid(base + scale * sum of leaf values)."""
    M = features.shape[0]
    T = roots.shape[0]
    rows = np.empty(M, np.int64)
    c = 0
    for m in range(M):
        out[m] = 0.0
        if T > 0 and is_candidate(features[m], max_width, min_points):
            rows[c] = m
            c += 1
    acc = np.zeros(c, np.float64)
    for t in range(T):  # tree by tree, in sklearn's order (the same sums), four rows at a time
        root = roots[t]
        i = 0
        while i + 4 <= c:
            l0, l1, l2, l3 = _leaves4(
                nodes,
                split,
                features[rows[i]],
                features[rows[i + 1]],
                features[rows[i + 2]],
                features[rows[i + 3]],
                root,
            )
            acc[i] += split[l0]
            acc[i + 1] += split[l1]
            acc[i + 2] += split[l2]
            acc[i + 3] += split[l3]
            i += 4
        while i < c:
            acc[i] += split[_leaf(nodes, split, features[rows[i]], root)]
            i += 1
    for i in range(c):
        if kind == KIND_FOREST:
            out[rows[i]] = acc[i] / T
        else:
            out[rows[i]] = 1.0 / (1.0 + np.exp(-(base + scale * acc[i])))


@njit(cache=True, nogil=True)
def block_probabilities(ranges, beams, segs, rules, model, features, out) -> None:
    """block_features (candidates only) then ensemble, in one compiled call: the per-scan hot path. beams, segs and
    rules as block_features takes them; model = (nodes, split, roots, kind, base, scale) as ensemble takes them."""
    nodes, split, roots, kind, base, scale = model
    max_width = rules[4]
    min_points = rules[5]
    block_features(ranges, beams, segs, rules, True, features)
    ensemble(features, max_width, min_points, nodes, split, roots, kind, base, scale, out)


@njit(cache=True, parallel=True, nogil=True)
def block_probabilities_parallel(ranges, parts, beams, segs, rules, model, features, out) -> None:
    """block_probabilities on numba's threads: the block's scans split into `parts` ranges of consecutive scans,
    each range's segments (rows seg_offsets[k0]:seg_offsets[k1] of features and out) done at once. Every row's
    features and probability depend on its own scan only: the same out as block_probabilities."""
    nodes, split, roots, kind, base, scale = model
    seg_start, seg_end, seg_offsets = segs
    max_width = rules[4]
    min_points = rules[5]
    N = ranges.shape[0]
    for j in prange(parts):
        k0 = j * N // parts
        k1 = (j + 1) * N // parts
        g0 = seg_offsets[k0]
        g1 = seg_offsets[k1]
        block_features(ranges[k0:k1], beams, (seg_start, seg_end, seg_offsets[k0 : k1 + 1]), rules, True, features)
        ensemble(features[g0:g1], max_width, min_points, nodes, split, roots, kind, base, scale, out[g0:g1])
