"""Odometry poses checked where they are read: a pose whose x, y or yaw is not finite, or whose x or y is
beyond MAX_POSE_M, is dropped (never passed on to empty the world columns or every track's position), and the
reader says how many it dropped, naming the file (`note`)."""

from __future__ import annotations

import numpy as np

from .scan import Odometry

MAX_POSE_M = 1e6  # |x|, |y| of an odometry pose, metres: 1,000 km from the odometry origin; a robot's dead
# reckoning never gets there, and float64 positions there still resolve nanometres


class BadPoseWarning(UserWarning):
    """Odometry poses were dropped: not finite, or beyond MAX_POSE_M."""


def sane(x: np.ndarray, y: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """True where a pose (x, y in metres, theta in radians) is finite and within MAX_POSE_M."""
    x, y, theta = (np.asarray(a, np.float64) for a in (x, y, theta))
    with np.errstate(invalid="ignore"):
        return np.isfinite(theta) & (np.abs(x) <= MAX_POSE_M) & (np.abs(y) <= MAX_POSE_M)


def keep_sane(odo: Odometry) -> tuple[Odometry | None, int, int]:
    """(`odo` without its bad poses, None when none is left; how many were dropped; the index of the first
    dropped, -1 when none was)."""
    ok = sane(odo.x, odo.y, odo.theta)
    if ok.all():
        return odo, 0, -1
    first = int(np.argmin(ok))
    if not ok.any():
        return None, len(ok), first
    kept = Odometry(odo.stamps[ok], odo.x[ok], odo.y[ok], odo.theta[ok], odo.frame_id, odo.child_frame_id)
    return kept, int((~ok).sum()), first


def note(where: object, dropped: int, total: int, first: int) -> str:
    """The warning for `dropped` bad poses of `total` read from `where` (the first: pose `first`, from 0)."""
    return (
        f"{where}: dropped {dropped:,} of {total:,} odometry poses that are not finite or lie beyond "
        f"{MAX_POSE_M:,.0f} m (the first: pose {first})"
    )
