"""One scan's features turned into the tracker's measurements: a model centre per object (docs/method.md §6).

Sensor frame of the scan (x forward, y left), metres. One measurement per segment: the circle's centre, the
centre of the lines' bounding box (rectangular objects) or the blob's centroid; small circles, blobs and
lines (a leg's arc can pass for a short line) may be legs, and legs are paired into people. Segments larger
than d_max are static (walls) and are not measurements. The rule runs compiled (_kernels.measurements and
learned_measurements, called by _scan_measurements); this module holds the kinds and the containers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
    (left/right unknown: a and b; NaN for other kinds). Frame: as given (the compiled step moves them to
    the tracking frame)."""

    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    kind: np.ndarray
    legs: np.ndarray  # (M, 4): ax, ay, bx, by
    # (L, 3): x, y, size of every leg candidate, paired or not (a 4th column: the leg detector's probability, when
    # it ran; a 5th: -1 for a strong candidate, a leg, else the index of the measurement of its beams); None: none
    raw_legs: np.ndarray = None  # type: ignore[assignment]  # __post_init__ makes None an array
    # (M,) the leg detector's probability of the segment measured (0: none)
    prob: np.ndarray = None  # type: ignore[assignment]  # __post_init__ makes None an array

    def __post_init__(self) -> None:
        if self.raw_legs is None:
            self.raw_legs = np.zeros((0, 3))
        if self.prob is None:
            self.prob = np.zeros(len(self.x))

    def __len__(self) -> int:
        return len(self.x)
