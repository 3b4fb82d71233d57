"""Layout shared by the feature kernels: positions in the parameter vector (P_*, see
FeatureParams.kernel_vector) and the columns of line, circle and blob rows and of line and circle candidates.
"""

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
