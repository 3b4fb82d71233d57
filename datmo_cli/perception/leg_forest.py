"""numba kernels of the leg detector's tree ensemble (random forest, extra trees or gradient boosting as flat node
arrays, see leg_model.LegModel): leaf lookup, the ensemble's probability, and features plus ensemble over a
block of scans in one compiled call.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..base.numba_runtime import key_kernel_cache_on_sources
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
def perfect_sum(row, feature, threshold, value, depth) -> float:
    """Sum over the perfect trees (leg_model.perfect_trees: flat arrays, 2**depth - 1 inner nodes and 2**depth
    leaves a tree) of the leaf value the float32 row (F,) reaches, tree by tree in the model's order (the sum
    ensemble makes): each walk is depth steps without a branch. Unsigned indices: no negative-index checks."""
    inner = (1 << depth) - 1
    one = np.uint64(1)
    acc = 0.0
    for t in range(value.shape[0] // (inner + 1)):
        b = np.uint64(t * inner)
        i = np.uint64(0)
        for _ in range(depth):
            # the same way as _leaf: right unless x <= threshold (NaN goes right)
            i = i + i + one + np.uint64(not row[np.uint64(feature[b + i])] <= threshold[b + i])
        acc += value[np.uint64(t * (inner + 1)) - np.uint64(inner) + i]
    return acc


@njit(cache=True)
def perfect_sums8(rows, feature, threshold, value, depth, acc) -> None:
    """perfect_sum of the float32 rows (R, F), R a multiple of 8, into acc (R,): eight rows walk each tree
    together (eight independent chains of loads), and each row's sum is still taken tree by tree."""
    inner = (1 << depth) - 1
    one = np.uint64(1)
    for q in range(0, rows.shape[0], 8):
        r0, r1, r2, r3 = rows[q], rows[q + 1], rows[q + 2], rows[q + 3]
        r4, r5, r6, r7 = rows[q + 4], rows[q + 5], rows[q + 6], rows[q + 7]
        a0 = a1 = a2 = a3 = a4 = a5 = a6 = a7 = 0.0
        for t in range(value.shape[0] // (inner + 1)):
            b = np.uint64(t * inner)
            i0 = i1 = i2 = i3 = i4 = i5 = i6 = i7 = np.uint64(0)
            for _ in range(depth):
                i0 = i0 + i0 + one + np.uint64(not r0[np.uint64(feature[b + i0])] <= threshold[b + i0])
                i1 = i1 + i1 + one + np.uint64(not r1[np.uint64(feature[b + i1])] <= threshold[b + i1])
                i2 = i2 + i2 + one + np.uint64(not r2[np.uint64(feature[b + i2])] <= threshold[b + i2])
                i3 = i3 + i3 + one + np.uint64(not r3[np.uint64(feature[b + i3])] <= threshold[b + i3])
                i4 = i4 + i4 + one + np.uint64(not r4[np.uint64(feature[b + i4])] <= threshold[b + i4])
                i5 = i5 + i5 + one + np.uint64(not r5[np.uint64(feature[b + i5])] <= threshold[b + i5])
                i6 = i6 + i6 + one + np.uint64(not r6[np.uint64(feature[b + i6])] <= threshold[b + i6])
                i7 = i7 + i7 + one + np.uint64(not r7[np.uint64(feature[b + i7])] <= threshold[b + i7])
            v = np.uint64(t * (inner + 1)) - np.uint64(inner)  # leaf node k of tree t is value[v + k]
            a0 += value[v + i0]
            a1 += value[v + i1]
            a2 += value[v + i2]
            a3 += value[v + i3]
            a4 += value[v + i4]
            a5 += value[v + i5]
            a6 += value[v + i6]
            a7 += value[v + i7]
        acc[q], acc[q + 1], acc[q + 2], acc[q + 3] = a0, a1, a2, a3
        acc[q + 4], acc[q + 5], acc[q + 6], acc[q + 7] = a4, a5, a6, a7


@njit(cache=True)
def ensemble(features, max_width, min_points, nodes, split, roots, kind, base, scale, pf, pt, pv, depth, out) -> None:
    """Leg probability of each row of features (M, F) into out (M,); non-candidates get 0. Walks the perfect
    trees (pf, pt, pv: leg_model.perfect_trees) when depth >= 0, else the node arrays (ensemble_nodes): the
    same leaves, the same sums."""
    if depth < 0 or roots.shape[0] == 0:
        ensemble_nodes(features, max_width, min_points, nodes, split, roots, kind, base, scale, out)
        return
    M, F = features.shape
    T = roots.shape[0]
    take = np.empty(M, np.int64)
    c = 0
    for m in range(M):
        out[m] = 0.0
        if is_candidate(features[m], max_width, min_points):
            take[c] = m
            c += 1
    if c == 0:
        return
    R = (c + 7) // 8 * 8
    rows = np.empty((R, F), np.float32)  # the candidates as float32 (sklearn's comparisons), padded by repeats
    for j in range(R):
        m = take[min(j, c - 1)]
        for f in range(F):
            rows[j, f] = np.float32(features[m, f])
    acc = np.empty(R, np.float64)
    perfect_sums8(rows, pf, pt, pv, depth, acc)
    for j in range(c):
        if kind == KIND_FOREST:
            out[take[j]] = acc[j] / T
        else:
            out[take[j]] = 1.0 / (1.0 + np.exp(-(base + scale * acc[j])))


@njit(cache=True)
def ensemble_nodes(features, max_width, min_points, nodes, split, roots, kind, base, scale, out) -> None:
    """Leg probability of each row of features (M, F) into out (M,) by walking the node arrays (any depth);
    non-candidates get 0.

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
    rules as block_features takes them; model: the leg_model.EnsembleArrays that ensemble takes
    (LegModel._kernel_args)."""
    nodes = model.nodes  # each field read once, by name
    split = model.split
    roots = model.roots
    kind = model.kind
    base = model.base
    scale = model.scale
    pf = model.perfect_feature
    pt = model.perfect_threshold
    pv = model.perfect_value
    depth = model.depth
    max_width = rules[4]
    min_points = rules[5]
    block_features(ranges, beams, segs, rules, True, features)
    ensemble(features, max_width, min_points, nodes, split, roots, kind, base, scale, pf, pt, pv, depth, out)


@njit(cache=True, parallel=True, nogil=True)
def block_probabilities_parallel(ranges, parts, beams, segs, rules, model, features, out) -> None:
    """block_probabilities on numba's threads: the block's scans split into `parts` ranges of consecutive scans,
    each range's segments (rows seg_offsets[k0]:seg_offsets[k1] of features and out) done at once. Every row's
    features and probability depend on its own scan only: the same out as block_probabilities."""
    nodes = model.nodes  # each field read once, by name
    split = model.split
    roots = model.roots
    kind = model.kind
    base = model.base
    scale = model.scale
    pf = model.perfect_feature
    pt = model.perfect_threshold
    pv = model.perfect_value
    depth = model.depth
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
        ensemble(
            features[g0:g1],
            max_width,
            min_points,
            nodes,
            split,
            roots,
            kind,
            base,
            scale,
            pf,
            pt,
            pv,
            depth,
            out[g0:g1],
        )
