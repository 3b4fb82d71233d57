"""Gating and global nearest-neighbour association: invariants, and optimality against brute force."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datmo_cli.tracking._assign import gnn
from tests.reference_tracking import gate, gated_costs, mahalanobis2

pytestmark = pytest.mark.unit


def _brute_force(cost: np.ndarray, allowed: np.ndarray) -> tuple[int, float]:
    """(most pairs, least cost among those) over every one-to-one assignment of allowed pairs."""
    K, M = cost.shape
    best = (0, 0.0)
    for perm in itertools.permutations(range(M), min(K, M)) if K <= M else []:
        pairs = [(i, j) for i, j in enumerate(perm) if allowed[i, j]]
        n, c = len(pairs), sum(cost[i, j] for i, j in pairs)
        if n > best[0] or (n == best[0] and c < best[1]):
            best = (n, c)
    return best


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), K=st.integers(0, 4), M=st.integers(0, 5))
def test_gnn_is_one_to_one_within_the_gate_and_optimal(seed: int, K: int, M: int):
    rng = np.random.default_rng(seed)
    cost = rng.uniform(0, 20, (K, M))
    allowed = cost < 9.0
    rows, cols = gnn(cost, allowed)
    assert len(set(rows.tolist())) == len(rows) and len(set(cols.tolist())) == len(cols)
    assert all(allowed[i, j] for i, j in zip(rows, cols, strict=True))
    if K <= M:
        n, c = _brute_force(cost, allowed)
        assert len(rows) == n
        assert np.isclose(cost[rows, cols].sum(), c)


def test_gnn_prefers_the_global_optimum_to_greedy():
    # greedy would give track 0 its nearest measurement 0 and leave track 1 unmatched
    cost = np.array([[1.0, 2.0], [1.5, 50.0]])
    rows, cols = gnn(cost, cost < 10)
    assert dict(zip(rows.tolist(), cols.tolist(), strict=True)) == {0: 1, 1: 0}


def test_gate_needs_both_mahalanobis_and_euclidean_bounds():
    d2 = np.array([[1.0, 20.0, 1.0]])
    dist = np.array([[0.5, 0.5, 3.0]])
    assert gate(d2, dist, 13.8, 1.5).tolist() == [[True, False, False]]


def test_gnn_empty_inputs():
    for shape in [(0, 3), (3, 0), (0, 0)]:
        rows, cols = gnn(np.zeros(shape), np.zeros(shape, bool))
        assert len(rows) == len(cols) == 0
    rows, cols = gnn(np.ones((2, 2)), np.zeros((2, 2), bool))
    assert len(rows) == 0


def test_fused_gating_kernel_matches_the_reference():
    rng = np.random.default_rng(4)
    x = rng.normal(0, 2, (6, 4))
    A = rng.normal(size=(6, 4, 4))
    P = 0.1 * A @ A.transpose(0, 2, 1) + 0.01 * np.eye(4)
    zx, zy, kind = rng.normal(0, 2, 9), rng.normal(0, 2, 9), rng.integers(0, 5, 9)
    compat = rng.random((6, 5)) < 0.7
    row = rng.integers(0, 6, 6)
    cost, ok = gated_costs(x, P, zx, zy, kind, 0.05, 0.2, 13.8, 1.5, compat, row)
    sigma = np.where(kind == 1, 0.2, 0.05)
    ref_d2, dist = mahalanobis2(x, P, zx, zy, sigma)
    S = P[:, None, :2, :2] + (sigma**2)[None, :, None, None] * np.eye(2)
    assert np.allclose(cost, ref_d2 + np.log(np.linalg.det(S)))
    assert np.array_equal(ok, gate(ref_d2, dist, 13.8, 1.5) & compat[row][:, kind])
