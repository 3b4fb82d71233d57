"""Layout shared by the feature kernels: positions in the parameter vector (P_*, see
FeatureParams.kernel_vector), the columns of line, circle and blob rows and of line and circle candidates, and
the bundles extract_scans takes and makes (named tuples read by field).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

(
    P_C0,
    P_MIN_POINTS,
    P_THETA_RES,
    P_RHO_RES,
    P_WINDOW,
    P_LINE_MIN_POINTS,
    P_LINE_MIN_RACC,
    P_LINE_MIN_LENGTH,
    P_PERP_TOL,
    P_R_MIN,
    P_R_MAX,
    P_R_STEP,
    P_CELL,
    P_CWINDOW,
    P_CTOL,
    P_CIRCLE_MIN_POINTS,
    P_SMALL,
    P_MIN_SAG,
    P_LEG_R,
    P_MIN_COVER,
    P_RES_RATIO,
    P_R_MARGIN,
    P_LINES_RATIO,
) = range(23)


# columns of the line rows
L_SCAN, L_SEG, L_FIRST, L_LAST, L_N, L_X0, L_Y0, L_X1, L_Y1, L_RHO, L_THETA, L_LEN, L_RACC = range(13)


# columns of circle rows: scan, segment, first, last, n, x, y, radius, r_acc
C_SCAN, C_SEG, C_FIRST, C_LAST, C_N, C_X, C_Y, C_R, C_RACC = range(9)


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
    params: np.ndarray  # the parameter vector (FeatureParams.kernel_vector, P_* slots)
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
