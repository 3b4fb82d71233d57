"""Layout shared by the perception kernels: the parameter vector (FEATURE_PARAMS, FP_* slots; built by
FeatureParams.kernel_vector) and the columns of line (L_*), circle (CR_*) and blob (B_*) rows and of line (LC_*)
and circle (CC_*) candidates, and the bundles extract_scans takes and makes (named tuples read by field).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# ------------------------------------------------------------------------------------- parameter vector
# The [features] keys the feature kernels read, in slot order, with the conversion each gets on its way into the
# vector ("radians": the key is in degrees). FP_<KEY> is the slot of <key>; tests/test_param_slots.py checks that
# every key has its slot, every slot is read by a kernel, and every [features] key is here or listed as read
# elsewhere (theta_resolution, say, is not here: features.py turns it into the HTL's cos/sin tables).
FEATURE_PARAMS: tuple[tuple[str, str], ...] = (
    ("c0", ""),
    ("min_points", ""),
    ("rho_resolution", ""),
    ("vote_window", "radians"),
    ("line_min_points", ""),
    ("line_min_racc", ""),
    ("line_min_length", ""),
    ("perpendicular_tolerance", "radians"),
    ("circle_radius_min", ""),
    ("circle_radius_max", ""),
    ("circle_radius_step", ""),
    ("circle_cell", ""),
    ("circle_window", ""),
    ("circle_tolerance", ""),
    ("circle_min_points", ""),
    ("circle_min_sagitta", ""),
    ("circle_min_coverage", ""),
    ("circle_residual_ratio", ""),
    ("circle_radius_margin", ""),
    ("circle_lines_ratio", ""),
    # landmarks (landmarks._benches, landmark_database.accumulate)
    ("column_radius_min", ""),
    ("bench_min_length", ""),
    ("bench_max_length", ""),
    ("landmark_match", ""),
    ("landmark_min_count", ""),
    ("column_max_drift", ""),
    ("column_min_time", ""),
)
FEATURE_PARAM_NAMES = tuple(key for key, _ in FEATURE_PARAMS)
N_FEATURE_PARAMS = len(FEATURE_PARAMS)


def _slot(key: str) -> int:
    """The slot of [features] key `key` in the vector (a key not in FEATURE_PARAMS fails the import)."""
    return FEATURE_PARAM_NAMES.index(key)


FP_C0 = _slot("c0")
FP_MIN_POINTS = _slot("min_points")
FP_RHO_RESOLUTION = _slot("rho_resolution")
FP_VOTE_WINDOW = _slot("vote_window")  # radians
FP_LINE_MIN_POINTS = _slot("line_min_points")
FP_LINE_MIN_RACC = _slot("line_min_racc")
FP_LINE_MIN_LENGTH = _slot("line_min_length")
FP_PERPENDICULAR_TOLERANCE = _slot("perpendicular_tolerance")  # radians
FP_CIRCLE_RADIUS_MIN = _slot("circle_radius_min")
FP_CIRCLE_RADIUS_MAX = _slot("circle_radius_max")
FP_CIRCLE_RADIUS_STEP = _slot("circle_radius_step")
FP_CIRCLE_CELL = _slot("circle_cell")
FP_CIRCLE_WINDOW = _slot("circle_window")
FP_CIRCLE_TOLERANCE = _slot("circle_tolerance")
FP_CIRCLE_MIN_POINTS = _slot("circle_min_points")
FP_CIRCLE_MIN_SAGITTA = _slot("circle_min_sagitta")
FP_CIRCLE_MIN_COVERAGE = _slot("circle_min_coverage")
FP_CIRCLE_RESIDUAL_RATIO = _slot("circle_residual_ratio")
FP_CIRCLE_RADIUS_MARGIN = _slot("circle_radius_margin")
FP_CIRCLE_LINES_RATIO = _slot("circle_lines_ratio")
FP_COLUMN_RADIUS_MIN = _slot("column_radius_min")
FP_BENCH_MIN_LENGTH = _slot("bench_min_length")
FP_BENCH_MAX_LENGTH = _slot("bench_max_length")
FP_LANDMARK_MATCH = _slot("landmark_match")
FP_LANDMARK_MIN_COUNT = _slot("landmark_min_count")
FP_COLUMN_MAX_DRIFT = _slot("column_max_drift")
FP_COLUMN_MIN_TIME = _slot("column_min_time")  # s


# columns of the line rows
L_SCAN, L_SEG, L_FIRST, L_LAST, L_N, L_X0, L_Y0, L_X1, L_Y1, L_RHO, L_THETA, L_LEN, L_RACC = range(13)


# columns of circle rows: scan, segment, first, last, n, x, y, radius, r_acc
CR_SCAN, CR_SEG, CR_FIRST, CR_LAST, CR_N, CR_X, CR_Y, CR_R, CR_RACC = range(9)


# columns of blob rows: scan, segment, first, last, n, x, y, size, kind
B_SCAN, B_SEG, B_FIRST, B_LAST, B_N, B_X, B_Y, B_SIZE, B_KIND = range(9)


# a line candidate (line_of_run's `out`, the rows of extract_scan's `cand`): points, first and last point,
# end points (x0, y0, x1, y1), rho, theta, length, r_acc, and r_acc of the HTL peak cell alone
LC_N, LC_FIRST, LC_LAST, LC_X0, LC_Y0, LC_X1, LC_Y1, LC_RHO, LC_THETA, LC_LEN, LC_RACC, LC_PEAK_RACC = range(12)
LC_WIDTH = LC_PEAK_RACC + 1  # columns of a line candidate


# a circle candidate (circle_of_run's `out`): points, centre x, y, radius, r_acc
CC_N, CC_X, CC_Y, CC_R, CC_RACC = range(5)
CC_WIDTH = CC_RACC + 1  # columns of a circle candidate


# an HTL peak (rows of line_subsegments' `peaks` and `hist`): votes, theta cell, rho cell; and a segment's
# bounding box (_bounding_box's `box`): xmin, xmax, ymin, ymax
PEAK_WIDTH = 3
BOX_WIDTH = 4


MAX_SUB = 256  # line candidates per segment


class ExtractSetup(NamedTuple):
    """What scan_extractor.extract_scans takes about the scanner and the parameters (features.extract_run makes
    it)."""

    cos_a: np.ndarray  # (B,) float: cos of each beam's angle (sensor frame)
    sin_a: np.ndarray  # (B,) float: sin of each beam's angle
    cos_inc: float  # cos of the angle step between beams
    c1: float  # segmentation's c1 (segmentation.segment_scan)
    range_min: float  # m: returns below are invalid
    range_max: float  # m: returns above are invalid
    params: np.ndarray  # the parameter vector (FeatureParams.kernel_vector, FP_* slots)
    cos_t: np.ndarray  # (nt,) float: cos of each HTL theta cell
    sin_t: np.ndarray  # (nt,) float: sin of each HTL theta cell


class ScanWork(NamedTuple):
    """extract_scan's scratch for scans of B beams and nt HTL theta cells (scan_extractor.scan_work makes it, once
    a call of extract_scans). Each field is written before it is read, segment by segment, but acc (see zeroed)."""

    lo: np.ndarray  # (LC_WIDTH,) float: a line candidate (LC_*), line_of_run's output
    toff: np.ndarray  # (nt,) float: each theta cell's smallest rho over the segment's bounding box (m)
    cell: np.ndarray  # (B,) int64: each point's normal theta cell (normal_cells)
    touched: np.ndarray  # (nt,) bool: theta rows of acc voted in by the segment
    peaks: np.ndarray  # (MAX_SUB, PEAK_WIDTH) int64: each HTL run's accumulator peak
    cand: np.ndarray  # (MAX_SUB, LC_WIDTH) float: the segment's line candidates (LC_*)
    kept: np.ndarray  # (MAX_SUB,) int64: rows of cand kept as lines
    cidx: np.ndarray  # (MAX_SUB,) int64: rows of cand of more than three points (the decision rule's lines)
    cout: np.ndarray  # (CC_WIDTH,) float: a circle candidate (CC_*), circle_of_run's output
    hist: np.ndarray  # (B, PEAK_WIDTH) int64: HTL's peak after each point; then the lines' cos and sin
    box: np.ndarray  # (BOX_WIDTH,) float: the segment's bounding box (m)
    zeroed: np.ndarray  # (1,) int64: how many flat cells of acc are zero (from its start)
    acc: np.ndarray  # (nt, rho cells) int32: HTL's accumulator, zeroed as segments first need it
    cacc: np.ndarray  # (2 w + 1, 2 w + 1) int32: HTC's accumulator window
    idx: np.ndarray  # (B,) int64: the points a fit takes
    sub_s: np.ndarray  # (MAX_SUB,) int64: each HTL run's first point
    sub_e: np.ndarray  # (MAX_SUB,) int64: each HTL run's end (exclusive)
