"""The numba assignment solver (datmo_cli/tracking/_assign.py) against scipy.optimize.linear_sum_assignment,
its reference (the same assignment, ties included), and the numba GNN against the reference GNN on random
gated matrices."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import linear_sum_assignment

from datmo_cli.tracking import _assign
from tests.reference_tracking import reference_gnn

pytestmark = pytest.mark.unit


@settings(max_examples=200, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), R=st.integers(1, 9), C=st.integers(1, 9), integer=st.booleans())
def test_lsap_is_scipys_assignment(seed: int, R: int, C: int, integer: bool):
    rng = np.random.default_rng(seed)
    # integer costs from a few values make many exact ties: the tie rules must be scipy's too
    cost = rng.integers(0, 4, (R, C)).astype(np.float64) if integer else rng.uniform(-5, 20, (R, C))
    rows, cols = _assign.lsap(cost)
    want_r, want_c = linear_sum_assignment(cost)
    np.testing.assert_array_equal(rows, want_r)
    np.testing.assert_array_equal(cols, want_c)


@settings(max_examples=200, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    K=st.integers(0, 10),
    M=st.integers(0, 10),
    share=st.floats(0.0, 1.0),
    integer=st.booleans(),
)
def test_gnn_is_the_reference_gnn_on_gated_matrices(seed: int, K: int, M: int, share: float, integer: bool):
    """The reference's pairs; with exact ties (integer costs) an assignment as good: as many pairs, the same
    summed cost (which of the tied ones is taken may differ: gnn solves the rows and columns that have an
    allowed pair, scipy the whole matrix)."""
    rng = np.random.default_rng(seed)
    # gated costs as the tracker makes them: d2 + ln det S, some of them negative; pairs outside the gate
    cost = rng.integers(-2, 3, (K, M)).astype(np.float64) if integer else rng.uniform(-8, 14, (K, M))
    allowed = rng.uniform(0, 1, (K, M)) < share
    rows, cols = _assign.gnn(cost, allowed)
    want_r, want_c = reference_gnn(cost, allowed)
    assert all(allowed[i, j] for i, j in zip(rows, cols, strict=True))
    assert len(set(rows.tolist())) == len(rows) and len(set(cols.tolist())) == len(cols)
    assert (np.diff(rows) > 0).all()
    if integer:
        assert len(rows) == len(want_r)
        assert cost[rows, cols].sum() == cost[want_r, want_c].sum()
    else:
        np.testing.assert_array_equal(rows, want_r)
        np.testing.assert_array_equal(cols, want_c)


def test_gnn_takes_the_global_optimum_and_the_most_pairs():
    # greedy would give row 0 column 0 (cost 1) and leave row 1 without: the optimum pairs both
    cost = np.array([[1.0, 2.0], [1.5, 50.0]])
    allowed = np.array([[True, True], [True, False]])
    rows, cols = _assign.gnn(cost, allowed)
    assert rows.tolist() == [0, 1] and cols.tolist() == [1, 0]


def test_gnn_of_nothing_allowed_is_empty():
    for shape in ((0, 0), (0, 3), (3, 0), (2, 2)):
        rows, cols = _assign.gnn(np.zeros(shape), np.zeros(shape, np.bool_))
        assert len(rows) == len(cols) == 0
