"""The bundles the compiled tracking step takes and returns, each field list written once: named tuples of
arrays and scalars, which numba compiles as plain tuples (no cost per call) while the kernels read them by field,
so two arrays of one dtype cannot be swapped by position (CONTRIBUTING.md, "Add or change a kernel").

Frames and units: features and measurements are in the sensor frame (x forward, y left, m) until _step moves them
to the tracking frame (_scan_measurements.moved); beam indices are inclusive int64; sizes and widths in m. Shapes:
M measurements, L leg candidates (raw: (L, RAW_COLS), columns _scan_measurements.R_*), legs (M, 4): the two legs
of a pair (x, y, x, y, m), else nan.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


# ------------------------------------------------------------------------------------- a scan's features
class Circles(NamedTuple):
    """Circles: beams first..last (int64), centre x, y and radius (float64, m)."""

    first: np.ndarray
    last: np.ndarray
    x: np.ndarray
    y: np.ndarray
    radius: np.ndarray


class Blobs(NamedTuple):
    """Blobs: beams first..last (int64), centre x, y and size (float64, m), kind (int64, vocabulary BLOB_KIND_*)."""

    first: np.ndarray
    last: np.ndarray
    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    kind: np.ndarray


class Lines(NamedTuple):
    """Lines: segment and beams first..last (int64), ends (x_ini, y_ini), (x_end, y_end) (float64, m)."""

    segment: np.ndarray
    first: np.ndarray
    last: np.ndarray
    x_ini: np.ndarray
    y_ini: np.ndarray
    x_end: np.ndarray
    y_end: np.ndarray


class Legs(NamedTuple):
    """The leg detector's candidates: beams first..last (int64), centre x, y and width (float64, m), probability."""

    first: np.ndarray
    last: np.ndarray
    x: np.ndarray
    y: np.ndarray
    width: np.ndarray
    probability: np.ndarray


class FeatureOffsets(NamedTuple):
    """A block of N scans: scan i's features of each kind are items offsets[i]:offsets[i + 1] ((N + 1,) int64)."""

    circles: np.ndarray
    blobs: np.ndarray
    lines: np.ndarray
    legs: np.ndarray


class FeatureBlock(NamedTuple):
    """The features of a block of scans, each kind flat over the scans (tracker._flat)."""

    offsets: FeatureOffsets
    circles: Circles
    blobs: Blobs
    lines: Lines
    legs: Legs


# ---------------------------------------------------------------------------------- a scan's measurements
class ScanMeasurements(NamedTuple):
    """A scan's measurements as the step takes them: centres x, y (m), size (m), kind (int64, K_*), legs (M, 4),
    raw (L, RAW_COLS) leg candidates, prob (M,) the leg detector's probability (0: none)."""

    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    kind: np.ndarray
    legs: np.ndarray
    raw: np.ndarray
    prob: np.ndarray


class PaperMeasurements(NamedTuple):
    """_kernels.measurements: the measurements by the paper's rule (x, y, size, kind, legs as ScanMeasurements')
    and the leg candidates they were made of (leg_x, leg_y, leg_size (L,), m)."""

    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    kind: np.ndarray
    legs: np.ndarray
    leg_x: np.ndarray
    leg_y: np.ndarray
    leg_size: np.ndarray


class LearnedMeasurements(NamedTuple):
    """_kernels.learned_measurements: the measurements with a leg detector (x, y, size, kind, legs, prob as
    ScanMeasurements') and cover (W,) int64: for each weaker candidate the measurement on most of its beams (-1:
    none)."""

    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    kind: np.ndarray
    legs: np.ndarray
    prob: np.ndarray
    cover: np.ndarray


class LegStage(NamedTuple):
    """_kernels.leg_stage: one measurement per track that took legs (owner (int64): the track's index; x, y, size,
    kind, legs as ScanMeasurements') and taken (L,) bool: which candidates a track took."""

    owner: np.ndarray
    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    kind: np.ndarray
    legs: np.ndarray
    taken: np.ndarray


class LegMeasurements(NamedTuple):
    """_kernels.leg_stage_measurements: the scan's measurements rebuilt after the tracks took legs (owner, x, y,
    size, kind, legs as LegStage's; other (int64): the indices of the other-kind measurements kept, in order)."""

    owner: np.ndarray
    x: np.ndarray
    y: np.ndarray
    size: np.ndarray
    kind: np.ndarray
    legs: np.ndarray
    other: np.ndarray


# ------------------------------------------------------------------------------------------------- scratch
class RtsWork(NamedTuple):
    """_rts._gain's scratch, each (4, 4) float64 (the state x, y, vx, vy): the motion model F and its transpose Ft,
    P F', F P F', the process noise Q, and two for the elimination (m, x)."""

    F: np.ndarray
    Ft: np.ndarray
    PFt: np.ndarray
    FPFt: np.ndarray
    Q: np.ndarray
    m: np.ndarray
    x: np.ndarray
