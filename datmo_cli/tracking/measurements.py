"""One scan's features turned into the tracker's measurements: a model centre per object (method.md §6).

Sensor frame of the scan (x forward, y left), metres. One measurement per segment: the circle's centre, the
centre of the lines' bounding box (rectangular objects) or the blob's centroid; small circles, blobs and
lines (a leg's arc can pass for a short line) may be legs, and legs are paired into people (see
people.py). Segments larger than d_max are static (walls) and are not measurements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..log import cdr, types
from . import _kernels
from .params import TrackingParams

_LEG_DTYPE = cdr.element_dtype(types.LEG)

KIND_PERSON, KIND_LEG, KIND_CIRCLE, KIND_RECT, KIND_BLOB = 0, 1, 2, 3, 4
N_KINDS = 5


@dataclass
class ScanFeatures:
    """The features of one scan (structured arrays of element_dtype(LINE/CIRCLE/BLOB/LEG)), sensor frame.
    `legs` are the segments the learned leg detector took for legs (None: no detector ran)."""

    lines: np.ndarray
    circles: np.ndarray
    blobs: np.ndarray
    legs: np.ndarray | None = None


@dataclass
class Measurements:
    """Measurements of one scan: centre (x, y) m, size m, kind KIND_*, and for people the two legs
    (left/right unknown: a and b; NaN for other kinds). Frame: as given (sensor, or world after `moved`)."""

    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    kind: np.ndarray
    legs: np.ndarray   # (M, 4): ax, ay, bx, by
    raw_legs: np.ndarray = None   # (L, 3): x, y, size of every leg candidate, paired or not (a 4th column:
    #                               the leg detector's probability, when it ran)
    prob: np.ndarray = None       # (M,) the leg detector's probability of the segment measured (0: none)

    def __post_init__(self) -> None:
        if self.raw_legs is None:
            self.raw_legs = np.zeros((0, 3))
        if self.prob is None:
            self.prob = np.zeros(len(self.x))

    def __len__(self) -> int:
        return len(self.x)

    def moved(self, pose: np.ndarray | None) -> Measurements:
        """The same measurements in the world frame of a sensor at pose (x, y, theta); self when None."""
        if pose is None:
            return self
        c, s = np.cos(pose[2]), np.sin(pose[2])
        x = c * self.x - s * self.y + pose[0]
        y = s * self.x + c * self.y + pose[1]
        legs = self.legs.copy()
        for i in (0, 2):
            legs[:, i] = c * self.legs[:, i] - s * self.legs[:, i + 1] + pose[0]
            legs[:, i + 1] = s * self.legs[:, i] + c * self.legs[:, i + 1] + pose[1]
        raw = self.raw_legs.copy()
        raw[:, 0] = c * self.raw_legs[:, 0] - s * self.raw_legs[:, 1] + pose[0]
        raw[:, 1] = s * self.raw_legs[:, 0] + c * self.raw_legs[:, 1] + pose[1]
        return Measurements(x, y, self.size, self.kind, legs, raw, self.prob)

    def take(self, keep: np.ndarray) -> Measurements:
        """The measurements selected by `keep` (mask or indices), leg candidates unchanged."""
        return Measurements(self.x[keep], self.y[keep], self.size[keep], self.kind[keep], self.legs[keep],
                            self.raw_legs, self.prob[keep])

    def extend(self, other: Measurements) -> Measurements:
        """These measurements followed by `other`'s (leg candidates: these)."""
        return Measurements(np.concatenate([self.x, other.x]), np.concatenate([self.y, other.y]),
                            np.concatenate([self.size, other.size]), np.concatenate([self.kind, other.kind]),
                            np.concatenate([self.legs, other.legs]), self.raw_legs,
                            np.concatenate([self.prob, other.prob]))


def from_legs(lx: np.ndarray, ly: np.ndarray, ls: np.ndarray, params: TrackingParams) -> Measurements:
    """Person measurements of leg candidates (x, y, size in m): pairs within the stride bound and singles."""
    x, y, size, kind, legs = _kernels.legs_to_measurements(np.ascontiguousarray(lx, np.float64),
                                                           np.ascontiguousarray(ly, np.float64),
                                                           np.ascontiguousarray(ls, np.float64), params.stride_max)
    return Measurements(x, y, size, kind, legs)


def measurements(features: ScanFeatures, params: TrackingParams, learned: bool = False) -> Measurements:
    """The measurements of one scan's features (see the module docstring). `learned`: legs are the clusters
    the leg detector gives at least params.leg_probability (features.legs), except on a circle wider than
    params.leg_radius_max, and nothing else; the other segments are circles, rectangles or blobs whatever
    their size, each with the leg probability of the cluster on its beams.
    Otherwise the paper's rule: small circles, blobs and short lines are legs."""
    c, b, li = features.circles, features.blobs, features.lines
    f8 = np.float64
    if learned:
        g = features.legs if features.legs is not None else np.zeros(0, _LEG_DTYPE)
        strong = g["probability"] >= params.leg_probability
        big = c[c["radius"] > params.leg_radius_max]   # a leg is no wider than this: that is a column's arc
        for f, e in zip(big["first"].tolist(), big["last"].tolist(), strict=True):
            strong &= (g["last"] < f) | (g["first"] > e)
        weak, g = g[~strong], g[strong]
        i8 = np.int64
        x, y, size, kind, legs, prob = _kernels.learned_measurements(
            c["first"].astype(i8), c["last"].astype(i8), c["x"].astype(f8), c["y"].astype(f8),
            c["radius"].astype(f8), b["first"].astype(i8), b["last"].astype(i8), b["x"].astype(f8),
            b["y"].astype(f8), b["size"].astype(f8), li["segment"].astype(i8), li["first"].astype(i8),
            li["last"].astype(i8), li["x_ini"].astype(f8), li["y_ini"].astype(f8), li["x_end"].astype(f8),
            li["y_end"].astype(f8), g["first"].astype(i8), g["last"].astype(i8), g["x"].astype(f8),
            g["y"].astype(f8), g["width"].astype(f8), weak["first"].astype(i8), weak["last"].astype(i8),
            weak["probability"].astype(f8), params.stride_max, params.d_max)
        raw = np.stack([g["x"].astype(f8), g["y"].astype(f8), g["width"].astype(f8), g["probability"].astype(f8)],
                       axis=1).reshape(-1, 4)
        return Measurements(x, y, size, kind, legs, raw, prob)
    x, y, size, kind, legs, lx, ly, ls = _kernels.measurements(
        c["x"].astype(f8), c["y"].astype(f8), c["radius"].astype(f8), b["x"].astype(f8), b["y"].astype(f8),
        b["size"].astype(f8), b["kind"].astype(np.int64), li["segment"].astype(np.int64), li["x_ini"].astype(f8),
        li["y_ini"].astype(f8), li["x_end"].astype(f8), li["y_end"].astype(f8), params.leg_radius_max,
        params.leg_blob_max, params.stride_max, params.d_max)
    return Measurements(x, y, size, kind, legs, np.stack([lx, ly, ls], axis=1))
