"""Exact ray casting against segments and circles (rectangles are four segments), with occlusion.

World frame, metres, radians. `cast` validates and allocates; the loops are the numba kernel in
`_kernels.cast_batch`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from datmo_cli.base import libm


@dataclass
class Primitives:
    """Static geometry: segments (S, 4) as x1, y1, x2, y2 and circles (C, 3) as cx, cy, r, world frame,
    metres; each with the index of the object it belongs to."""

    segments: np.ndarray
    segment_owner: np.ndarray
    circles: np.ndarray
    circle_owner: np.ndarray

    @classmethod
    def empty(cls) -> Primitives:
        return cls(np.zeros((0, 4)), np.zeros(0, np.int32), np.zeros((0, 3)), np.zeros(0, np.int32))


def rectangle_segments(centre: np.ndarray, length: float, width: float, heading: np.ndarray | float) -> np.ndarray:
    """The four sides (..., 4, 4) of rectangles centred at `centre` (..., 2) with `length` along `heading`."""
    c, s = libm.cos(heading), libm.sin(heading)
    ax = np.stack([c, s], -1) * (length / 2)
    ay = np.stack([-s, c], -1) * (width / 2)
    corners = np.stack([centre + ax + ay, centre - ax + ay, centre - ax - ay, centre + ax - ay], -2)
    nxt = np.roll(corners, -1, axis=-2)
    return np.concatenate([corners, nxt], -1)


def _f64(a, shape_tail: tuple[int, ...], name: str) -> np.ndarray:
    a = np.ascontiguousarray(a, np.float64)
    if a.shape[a.ndim - len(shape_tail) :] != shape_tail:
        raise ValueError(f"{name} must end in shape {shape_tail}, got {a.shape}")
    return a


def cast(
    poses: np.ndarray,
    angles: np.ndarray,
    static: Primitives,
    moving_segments: np.ndarray | None = None,
    moving_segment_owner: np.ndarray | None = None,
    moving_circles: np.ndarray | None = None,
    moving_circle_owner: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Distances (n, B) float64 to the first hit of every beam (inf: no hit) and the hit object (n, B) int32
    (-1: none).

    poses (n, 3): sensor x, y, heading in the world frame. angles (B,): beam angles, sensor frame.
    moving_segments (n, Sd, 4) and moving_circles (n, Cd, 3): geometry at each pose's instant.
    """
    from ._kernels import cast_batch

    poses = _f64(np.atleast_2d(poses), (3,), "poses")
    n = len(poses)
    angles = np.ascontiguousarray(angles, np.float64).ravel()
    seg_d = np.zeros((n, 0, 4)) if moving_segments is None else _f64(moving_segments, (4,), "moving_segments")
    circ_d = np.zeros((n, 0, 3)) if moving_circles is None else _f64(moving_circles, (3,), "moving_circles")
    own_seg_d = np.ascontiguousarray(np.zeros(0) if moving_segment_owner is None else moving_segment_owner, np.int32)
    own_circ_d = np.ascontiguousarray(np.zeros(0) if moving_circle_owner is None else moving_circle_owner, np.int32)
    if seg_d.shape[:2] != (n, len(own_seg_d)) or circ_d.shape[:2] != (n, len(own_circ_d)):
        raise ValueError("moving geometry must be (n_poses, n_primitives, ...) with one owner per primitive")
    seg_s = _f64(static.segments.reshape(-1, 4), (4,), "segments")
    circ_s = _f64(static.circles.reshape(-1, 3), (3,), "circles")
    own_seg_s = np.ascontiguousarray(static.segment_owner, np.int32)
    own_circ_s = np.ascontiguousarray(static.circle_owner, np.int32)
    if len(own_seg_s) != len(seg_s) or len(own_circ_s) != len(circ_s):
        raise ValueError("one owner per static primitive")
    out_t = np.empty((n, len(angles)))
    out_owner = np.empty((n, len(angles)), np.int32)
    cast_batch(
        poses, angles, seg_s, own_seg_s, circ_s, own_circ_s, seg_d, own_seg_d, circ_d, own_circ_d, out_t, out_owner
    )
    return out_t, out_owner
