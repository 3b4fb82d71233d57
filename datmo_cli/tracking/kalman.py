"""A constant-velocity Kalman filter with white-noise acceleration, batched over all tracks (method.md §6.2).

State [x, y, vx, vy] (m, m/s) in the tracking frame (the sensor frame, or the world frame with odometry);
covariance 4x4. The model is filterpy's: F = [[I, dt I], [0, I]] and Q = Q_discrete_white_noise(dim=2, dt,
var=q, block_size=2, order_by_dim=False); measurement z = [x, y] with R = sigma^2 I. The update uses the
Joseph form, as filterpy's KalmanFilter.update does, so the two agree to rounding (tests check 1e-9).
Separate x and y filters of the paper equal this one with a block-diagonal covariance.
"""

from __future__ import annotations

import numpy as np

from . import _kernels


def transition(dt: float) -> np.ndarray:
    """F for a step of dt seconds (4x4)."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    return F


def process_noise(dt: float, q: float) -> np.ndarray:
    """Q for a step of dt seconds and white-noise acceleration of variance q (4x4, filterpy's values)."""
    a, b, c = 0.25 * dt**4 * q, 0.5 * dt**3 * q, dt**2 * q
    return np.array([[a, 0, b, 0], [0, a, 0, b], [b, 0, c, 0], [0, b, 0, c]])


def predict(x: np.ndarray, P: np.ndarray, dt: float, q: float | np.ndarray) -> None:
    """Predict every track dt seconds ahead, in place: x (K, 4), P (K, 4, 4) float64 C-contiguous;
    q the white-noise acceleration variance, one for all tracks or one per track."""
    if len(x) and dt != 0:
        _kernels.predict(x, P, float(dt), np.ascontiguousarray(np.broadcast_to(q, (len(x),)), np.float64))


def distances(x: np.ndarray, P: np.ndarray, zx: np.ndarray, zy: np.ndarray,
              sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, M) squared Mahalanobis distances, with S = H P H^T + sigma^2 I per measurement, and (K, M)
    Euclidean distances (m) of measurements (zx, zy) from the K predicted positions."""
    return _kernels.mahalanobis2(x, P, np.ascontiguousarray(zx, np.float64), np.ascontiguousarray(zy, np.float64),
                                 np.ascontiguousarray(sigma, np.float64))


def update_rows(x: np.ndarray, P: np.ndarray, rows: np.ndarray, zx: np.ndarray, zy: np.ndarray,
                sigma: np.ndarray) -> None:
    """Update tracks `rows` with position measurements (zx, zy), sigmas in m, in place (Joseph form)."""
    if len(rows):
        _kernels.update(x, P, np.ascontiguousarray(rows, np.int64), np.ascontiguousarray(zx, np.float64),
                        np.ascontiguousarray(zy, np.float64), np.ascontiguousarray(sigma, np.float64))


def update(x: np.ndarray, P: np.ndarray, z: np.ndarray, r: np.ndarray) -> None:
    """Update every track with position measurements z (K, 2), sigmas r (K,) in m, in place."""
    z = np.asarray(z, np.float64)
    update_rows(x, P, np.arange(len(x)), z[:, 0], z[:, 1], np.broadcast_to(np.asarray(r, np.float64), (len(x),)))
