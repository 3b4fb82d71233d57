"""The reference constant-velocity Kalman filter (tests/reference_tracking.py, the arithmetic the compiled step's
predict and kalman_update are checked against) against filterpy's KalmanFilter (the oracle)."""

from __future__ import annotations

import numpy as np
import pytest
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis import strategies as st

from tests import reference_tracking as kalman

pytestmark = pytest.mark.unit


def _oracle(x0: np.ndarray, P0: np.ndarray) -> KalmanFilter:
    f = KalmanFilter(dim_x=4, dim_z=2)
    f.x = x0.copy()
    f.P = P0.copy()
    f.H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    return f


def test_model_is_filterpys():
    for dt, q in [(0.2, 1.0), (0.013, 7.5), (1.7, 0.01)]:
        F = kalman.transition(dt)
        assert np.allclose(F, [[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1]])
        Q = Q_discrete_white_noise(dim=2, dt=dt, var=q, block_size=2, order_by_dim=False)
        assert np.allclose(kalman.process_noise(dt, q), Q, rtol=0, atol=1e-15)


@pytest.mark.slow
@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n_tracks=st.integers(1, 6), steps=st.integers(1, 40))
def test_matches_filterpy_on_random_sequences(seed: int, n_tracks: int, steps: int):
    rng = np.random.default_rng(seed)
    x = rng.normal(0, 3, (n_tracks, 4))
    A = rng.normal(size=(n_tracks, 4, 4))
    P = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(4)
    filters = [_oracle(x[k], P[k]) for k in range(n_tracks)]
    q = float(rng.uniform(0.01, 5))
    for _ in range(steps):
        dt = float(rng.choice([0.0, rng.uniform(0.001, 2.0)]))  # repeated stamps and uneven rates
        kalman.kalman_predict(x, P, dt, q)
        for f in filters:
            f.predict(F=kalman.transition(dt), Q=Q_discrete_white_noise(2, dt, q, block_size=2, order_by_dim=False))
        measured = rng.random(n_tracks) < 0.7  # some tracks miss the scan
        if measured.any():
            z = x[measured, :2] + rng.normal(0, 0.5, (int(measured.sum()), 2))
            r = rng.uniform(0.01, 0.5, int(measured.sum()))
            xs, Ps = x[measured], P[measured]
            kalman.kalman_update(xs, Ps, z, r)
            x[measured], P[measured] = xs, Ps
            for f, zk, rk in zip([f for f, m in zip(filters, measured, strict=True) if m], z, r, strict=True):
                f.update(zk, R=np.eye(2) * rk**2)
        for k, f in enumerate(filters):
            assert np.allclose(x[k], f.x, rtol=0, atol=1e-9)
            assert np.allclose(P[k], f.P, rtol=0, atol=1e-9)


def test_distances_match_explicit_formula():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(4, 4))
    A = rng.normal(size=(4, 4, 4))
    P = A @ A.transpose(0, 2, 1) + np.eye(4)
    zx, zy, sigma = rng.normal(size=5), rng.normal(size=5), rng.uniform(0.01, 0.5, 5)
    d2, dist = kalman.mahalanobis2(x, P, zx, zy, sigma)
    for k in range(4):
        for j in range(5):
            y = np.array([zx[j], zy[j]]) - x[k, :2]
            assert np.isclose(d2[k, j], y @ np.linalg.inv(P[k, :2, :2] + sigma[j] ** 2 * np.eye(2)) @ y)
            assert np.isclose(dist[k, j], np.hypot(*y))
