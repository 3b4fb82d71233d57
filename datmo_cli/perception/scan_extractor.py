"""numba kernels that extract one scan's features, and whole blocks of scans (docs/method.md §5.2).

Sensor frame: x forward, y left, metres; angles in radians. Checked against tests/reference_perception.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..base.numba_runtime import key_kernel_cache_on_sources
from .feature_layout import (
    B_FIRST,
    B_KIND,
    B_LAST,
    B_N,
    B_SCAN,
    B_SEG,
    B_SIZE,
    B_X,
    B_Y,
    BOX_WIDTH,
    CC_N,
    CC_R,
    CC_RACC,
    CC_WIDTH,
    CC_X,
    CC_Y,
    CR_FIRST,
    CR_LAST,
    CR_N,
    CR_R,
    CR_RACC,
    CR_SCAN,
    CR_SEG,
    CR_X,
    CR_Y,
    FP_C0,
    FP_CIRCLE_CELL,
    FP_CIRCLE_MIN_POINTS,
    FP_CIRCLE_RADIUS_MAX,
    FP_CIRCLE_TOLERANCE,
    FP_CIRCLE_WINDOW,
    FP_LINE_MIN_LENGTH,
    FP_LINE_MIN_POINTS,
    FP_LINE_MIN_RACC,
    FP_MIN_POINTS,
    FP_PERPENDICULAR_TOLERANCE,
    FP_RHO_RESOLUTION,
    FP_VOTE_WINDOW,
    L_FIRST,
    L_LAST,
    L_LEN,
    L_N,
    L_RACC,
    L_RHO,
    L_SCAN,
    L_SEG,
    L_THETA,
    L_X0,
    L_X1,
    L_Y0,
    L_Y1,
    LC_FIRST,
    LC_LAST,
    LC_LEN,
    LC_N,
    LC_PEAK_RACC,
    LC_RACC,
    LC_RHO,
    LC_THETA,
    LC_WIDTH,
    LC_X0,
    LC_X1,
    LC_Y0,
    LC_Y1,
    MAX_SUB,
    PEAK_WIDTH,
    ScanWork,
)
from .hough_circles import circle_of_run, circle_posed
from .hough_lines import _bounding_box, line_of_run, line_subsegments, normal_cells
from .segmentation import segment_scan, valid_return

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True)
def _perpendicular(t1: float, t2: float, tol: float) -> bool:
    d = abs(t1 - t2) % np.pi
    return abs(d - np.pi / 2) <= tol


@njit(cache=True)
def _convex(ax, ay, jx, jy, bx, by) -> bool:
    """Junction J bulges towards the scanner (origin) from the chord A-B."""
    ex = bx - ax
    ey = by - ay
    cj = ex * (jy - ay) - ey * (jx - ax)
    co = ex * (0.0 - ay) - ey * (0.0 - ax)
    return cj * co > 0


# extract_scan's steps below are inlined into it, and it into extract_scans (inline="always"): the per-scan loop
# compiles to one function, as it was before they were cut out (calls cost 1-2 us a scan, measured)


@njit(cache=True)
def scan_work(p, nt, B, range_max) -> ScanWork:
    """ScanWork for scans of B beams, nt theta cells, returns up to range_max (m) and the parameter vector p. acc
    is not zeroed: extract_scan zeroes the part a segment needs the first time (a few % of it in practice)."""
    diag = 2.0 * min(range_max, 100.0)
    w = int(round(p[FP_CIRCLE_WINDOW] / p[FP_CIRCLE_CELL]))
    return ScanWork(
        lo=np.empty(LC_WIDTH),
        toff=np.empty(nt),
        cell=np.empty(B, np.int64),
        touched=np.zeros(nt, np.bool_),
        peaks=np.empty((MAX_SUB, PEAK_WIDTH), np.int64),
        cand=np.empty((MAX_SUB, LC_WIDTH)),
        kept=np.empty(MAX_SUB, np.int64),
        cidx=np.empty(MAX_SUB, np.int64),
        cout=np.empty(CC_WIDTH),
        hist=np.empty((B, PEAK_WIDTH), np.int64),
        box=np.empty(BOX_WIDTH),
        zeroed=np.zeros(1, np.int64),
        acc=np.empty((nt, int(diag / p[FP_RHO_RESOLUTION]) + 3), np.int32),
        cacc=np.zeros((2 * w + 1, 2 * w + 1), np.int32),
        idx=np.empty(B, np.int64),
        sub_s=np.empty(MAX_SUB, np.int64),
        sub_e=np.empty(MAX_SUB, np.int64),
    )


@njit(cache=True, inline="always")
def _merge_lines(x, y, nkept, rho_res, work) -> int:
    """Merge consecutive kept lines (work's kept, rows of cand) that are one line split by noise; returns how
    many kept lines remain."""
    lo = work.lo  # each field read once, by name (an array read in a loop would be counted each pass)
    cand = work.cand
    kept = work.kept
    idx = work.idx
    sub_s = work.sub_s
    sub_e = work.sub_e
    m = 1
    for q in range(1, nkept):
        a = cand[kept[m - 1]]
        b = cand[kept[q]]
        dt = abs(a[LC_THETA] - b[LC_THETA])
        dt = min(dt, np.pi - dt)
        same_side = (
            abs(a[LC_RHO] - b[LC_RHO]) if abs(a[LC_THETA] - b[LC_THETA]) < np.pi / 2 else abs(a[LC_RHO] + b[LC_RHO])
        )
        if dt < 3.0 * np.pi / 180 and same_side < 2 * rho_res and kept[q] == kept[m - 1] + 1:
            len_a = sub_e[kept[m - 1]] - sub_s[kept[m - 1]]
            len_b = sub_e[kept[q]] - sub_s[kept[q]]
            merged = a[LC_RACC] * len_a + b[LC_RACC] * len_b
            line_of_run(x, y, sub_s[kept[m - 1]], sub_e[kept[q]], a[LC_THETA], a[LC_RHO], merged, rho_res, idx, lo)
            sub_e[kept[m - 1]] = sub_e[kept[q]]
            cand[kept[m - 1], :] = lo
        else:
            kept[m] = kept[q]
            m += 1
    return m


@njit(cache=True, inline="always")
def _circle_case(x, y, s, e, p, ncand, cand, cidx):
    """Section 5.2: whether the segment [s, e) with ncand HTL lines (rows cidx[:ncand] of cand) is tested as a
    circle, and whether that test goes beyond the paper's rule (leg_only: if the circle fails, the lines stay).
    Only segments small enough to be a circle of the allowed radii (a long wall with a deflection stays lines)."""
    ext = np.hypot(x[e - 1] - x[s], y[e - 1] - y[s])
    try_circle = False
    leg_only = False
    if ext <= 2.0 * p[FP_CIRCLE_RADIUS_MAX] + 2.0 * p[FP_CIRCLE_TOLERANCE]:
        if ncand == 0:
            try_circle = True
        elif ncand == 1:
            # the paper tests a single line as a circle when its r_acc < 0.5; datmo tests every single
            # line of a segment small enough to be a circle, and keeps the better fit (a leg a few metres
            # away, or a column's arc, is a shallow arc that HTL can take for a line with r_acc > 0.5)
            try_circle = True
            leg_only = (
                cand[cidx[0], LC_PEAK_RACC] >= p[FP_LINE_MIN_RACC]
            )  # not the paper's case: no circle keeps the line
        elif ncand == 2:
            # two non-perpendicular lines: the paper's case; two perpendicular ones may be a box's corner
            # or an arc cut in two halves (a column seen whole): the better fit decides, lines on a tie
            try_circle = True
            leg_only = _perpendicular(cand[cidx[0], LC_THETA], cand[cidx[1], LC_THETA], p[FP_PERPENDICULAR_TOLERANCE])
        else:
            convex = 0
            for q in range(ncand - 1):
                a = cand[cidx[q]]
                b = cand[cidx[q + 1]]
                if _convex(a[LC_X0], a[LC_Y0], a[LC_X1], a[LC_Y1], b[LC_X1], b[LC_Y1]):
                    convex += 1
            try_circle = convex >= 2
    return try_circle, leg_only


@njit(cache=True)
def _lines_rss(x, y, idx, m, cand, cidx, ncand, trig) -> float:
    """Sum over the points idx[:m] of the squared distance to the nearest of the ncand lines cand[cidx[:ncand]]
    (LC_* rows: theta rad, rho m). trig: scratch of at least 2 ncand, each line's cos and sin (computed once
    a line, not once a point and line: the same values, so the same sum)."""
    for j in range(ncand):
        c = cand[cidx[j]]
        trig[2 * j] = np.cos(c[LC_THETA])
        trig[2 * j + 1] = np.sin(c[LC_THETA])
    rss = 0.0
    for q in range(m):
        i = idx[q]
        dmin = np.inf
        for j in range(ncand):
            dmin = min(dmin, abs(x[i] * trig[2 * j] + y[i] * trig[2 * j + 1] - cand[cidx[j], LC_RHO]))
        rss += dmin * dmin
    return rss


@njit(cache=True, inline="always")
def _circle_wins(x, y, s, e, p, work, ncand, htl_racc, dalpha) -> bool:
    """HTC on the segment [s, e) (its circle in work's cout, CC_*): whether the circle beats the segment's
    ncand HTL lines (r_acc htl_racc together), holds like a line must (r_acc above line_min_racc) and is a
    well-posed arc (circle_posed; dalpha: the scan's angle step, rad)."""
    cand = work.cand  # each field read once, by name
    cidx = work.cidx
    cout = work.cout
    hist = work.hist
    cacc = work.cacc
    idx = work.idx
    min_racc = p[FP_LINE_MIN_RACC]
    if e - s >= p[FP_CIRCLE_MIN_POINTS]:
        circle_of_run(x, y, s, e, p, cacc, idx, cout, max(htl_racc, min_racc))
    else:
        cout[CC_RACC] = 0.0
    lines_rss = -1.0  # the circle's points to the segment's HTL lines (two or more: a corner?)
    if ncand >= 2 and cout[CC_N] >= 3:
        # hist (HTL's scratch, free once the segment's lines are made) holds the lines' cos and sin
        lines_rss = _lines_rss(x, y, idx, int(cout[CC_N]), cand, cidx, ncand, hist.reshape(-1).view(np.float64))
    # idx[:n] still holds the points circle_of_run fitted
    return (
        cout[CC_RACC] > max(htl_racc, min_racc)
        and cout[CC_N] >= p[FP_CIRCLE_MIN_POINTS]
        and circle_posed(x, y, idx, int(cout[CC_N]), cout[CC_X], cout[CC_Y], cout[CC_R], p, dalpha, lines_rss)
    )


@njit(cache=True, inline="always")
def _circle_row(row, scan, g, s, e, cout) -> None:
    """A circle row (CR_*) of segment g ([s, e)) of scan `scan` from the circle candidate cout (CC_*)."""
    row[CR_SCAN] = scan
    row[CR_SEG] = g
    row[CR_FIRST] = s
    row[CR_LAST] = e - 1
    row[CR_N] = cout[CC_N]
    row[CR_X] = cout[CC_X]
    row[CR_Y] = cout[CC_Y]
    row[CR_R] = cout[CC_R]
    row[CR_RACC] = cout[CC_RACC]


@njit(cache=True, inline="always")
def _line_row(row, scan, g, c) -> None:
    """A line row (L_*) of segment g of scan `scan` from the line candidate c (LC_*)."""
    row[L_SCAN] = scan
    row[L_SEG] = g
    row[L_FIRST] = c[LC_FIRST]
    row[L_LAST] = c[LC_LAST]
    row[L_N] = c[LC_N]
    row[L_X0] = c[LC_X0]
    row[L_Y0] = c[LC_Y0]
    row[L_X1] = c[LC_X1]
    row[L_Y1] = c[LC_Y1]
    row[L_RHO] = c[LC_RHO]
    row[L_THETA] = c[LC_THETA]
    row[L_LEN] = c[LC_LEN]
    row[L_RACC] = c[LC_RACC]


@njit(cache=True, inline="always")
def _blob_row(row, x, y, scan, g, s, e) -> None:
    """A blob row (B_*) of segment g ([s, e)) of scan `scan`: a blob (or a point), centroid and largest extent."""
    sx = 0.0
    sy = 0.0
    far = s
    dmax = 0.0
    for i in range(s, e):  # the centroid's sums and the first sweep in one pass
        sx += x[i]
        sy += y[i]
        d = (x[i] - x[s]) ** 2 + (y[i] - y[s]) ** 2
        if d > dmax:
            dmax = d
            far = i
    for i in range(s, e):  # two sweeps: exact for convex outlines, within a few % otherwise
        d = (x[i] - x[far]) ** 2 + (y[i] - y[far]) ** 2
        if d > dmax:
            dmax = d
    row[B_SCAN] = scan
    row[B_SEG] = g
    row[B_FIRST] = s
    row[B_LAST] = e - 1
    row[B_N] = e - s
    row[B_X] = sx / (e - s)
    row[B_Y] = sy / (e - s)
    row[B_SIZE] = np.sqrt(dmax)
    row[B_KIND] = 1.0 if e - s < 3 else 0.0


@njit(cache=True, inline="always")
def extract_scan(x, y, segs, scan, p, trig, work, rows, counts, dalpha=0.0):
    """Features of one scan's segments (points x, y, m, sensor frame; segs = (starts, ends, nseg): beam
    ranges [start, end)): HTL on every segment, then the decision rule of docs/method.md §5.2, a circle kept
    only when well posed (circle_posed; `dalpha`: the scan's angle step, rad). trig = (cos_t, sin_t) of the
    theta cells; work: scan_work's ScanWork (feature_layout). Appends rows to rows = (lines, circles, blobs) from
    counts = (nl, nc, nb); returns the new counts."""
    starts, ends, nseg = segs
    lines, circles, blobs = rows
    nl, nc, nb = counts
    lo = work.lo  # each field read once, by name
    toff = work.toff
    cell = work.cell
    touched = work.touched
    peaks = work.peaks
    cand = work.cand
    kept = work.kept
    cidx = work.cidx
    cout = work.cout
    hist = work.hist
    box = work.box
    zeroed = work.zeroed
    acc = work.acc
    idx = work.idx
    sub_s = work.sub_s
    sub_e = work.sub_e
    cos_t, sin_t = trig
    rho_res = p[FP_RHO_RESOLUTION]
    min_pts = p[FP_LINE_MIN_POINTS]
    min_racc = p[FP_LINE_MIN_RACC]
    min_len = p[FP_LINE_MIN_LENGTH]
    nt = cos_t.shape[0]
    kwin = int(p[FP_VOTE_WINDOW] / (np.pi / nt))
    tstep = np.pi / nt
    for g in range(nseg):
        s = starts[g]
        e = ends[g]
        # HTL on the segment: its line candidates to cand (rows LC_*), those of more than three points to cidx,
        # those kept as lines (enough points, r_acc and length) to kept, consecutive kept lines that are one merged
        if e - s >= min_pts:
            normal_cells(x, y, s, e, nt, cell)
            # line_subsegments uses the first nt * width cells of acc (flat): zero what was never used before
            used = nt * _bounding_box(x, y, s, e, rho_res, acc.shape[1], box)
            if used > zeroed[0]:
                acc.reshape(-1)[zeroed[0] : used] = 0
                zeroed[0] = used
            runs = (sub_s, sub_e, peaks)
            nsub = line_subsegments(x, y, s, e, (acc, toff, touched), cos_t, sin_t, rho_res, kwin, cell, runs, hist)
        else:
            nsub = 0  # too few points for a line of more than three: no HTL
        nkept = 0
        ncand = 0
        votes = 0.0
        for k in range(nsub):
            t = peaks[k, 1]
            rho_p = toff[t] + (peaks[k, 2] + 0.5) * rho_res
            line_of_run(x, y, sub_s[k], sub_e[k], t * tstep, rho_p, peaks[k, 0], rho_res, idx, lo)
            cand[k, :] = lo
            if lo[LC_N] >= min_pts:  # an HTL line (more than 3 points) for the decision rule
                cidx[ncand] = k
                ncand += 1
                votes += lo[LC_RACC] * (sub_e[k] - sub_s[k])  # the refined line's r_acc, in points
            if lo[LC_N] >= min_pts and lo[LC_RACC] > min_racc and lo[LC_LEN] > min_len:
                kept[nkept] = k
                nkept += 1
        if nkept > 1:
            nkept = _merge_lines(x, y, nkept, rho_res, work)
        htl_racc = votes / (e - s)
        try_circle, leg_only = _circle_case(x, y, s, e, p, ncand, cand, cidx)
        if try_circle:
            if _circle_wins(x, y, s, e, p, work, ncand, htl_racc, dalpha):
                _circle_row(circles[nc], scan, g, s, e, cout)
                nc += 1
                continue
            if not leg_only:
                nkept = 0
        if nkept > 0:
            for q in range(nkept):
                _line_row(lines[nl], scan, g, cand[kept[q]])
                nl += 1
            continue
        _blob_row(blobs[nb], x, y, scan, g, s, e)
        nb += 1
    return nl, nc, nb


@njit(cache=True, nogil=True)
def extract_scans(ranges, k0, k1, setup, out, given):
    """Segment and extract features of scans k0 .. k1 - 1 of a block (ranges (N, B), m).

    setup: a feature_layout.ExtractSetup (the beams, range limits, parameter vector and theta cells). out =
    (seg_out, lines, circles, blobs, counts): scan k's segments (rows [start, end)), lines, circles and blobs go
    to rows [k * B, k * B + counts[k, j]) of seg_out, lines, circles and blobs (j = 0, 1, 2, 3), each (N * B,
    columns) (a scan has at most B of each). given = (rows, offsets): with offsets of
    length N + 1, the segments are not computed but taken from rows ([start, end), scan k's at
    offsets[k]:offsets[k + 1]). Scans are independent: any split of a block into calls gives the same rows, so
    extract_parallel runs disjoint ranges of scans at once."""
    cos_a = setup.cos_a  # each field read once, by name
    sin_a = setup.sin_a
    cos_inc = setup.cos_inc
    c1 = setup.c1
    range_min = setup.range_min
    range_max = setup.range_max
    p = setup.params
    cos_t = setup.cos_t
    sin_t = setup.sin_t
    seg_out, lines, circles, blobs, counts = out
    given_rows, given_offsets = given
    N, B = ranges.shape
    x = np.empty(B)
    y = np.empty(B)
    starts = np.empty(B + 1, np.int64)
    ends = np.empty(B + 1, np.int64)
    work = scan_work(p, cos_t.shape[0], B, range_max)
    min_points = int(p[FP_MIN_POINTS])
    use_given = given_offsets.shape[0] == N + 1
    dalpha = np.arccos(min(max(cos_inc, -1.0), 1.0))  # the angle step, for circle_posed
    trig = (cos_t, sin_t)
    rows = (lines, circles, blobs)
    for k in range(k0, k1):
        r = ranges[k]
        if use_given:
            nseg = 0
            for q in range(given_offsets[k], given_offsets[k + 1]):
                a = min(max(given_rows[q, 0], 0), B)
                b = min(max(given_rows[q, 1], a), B)
                if b > a and nseg < B:
                    starts[nseg] = a
                    ends[nseg] = b
                    nseg += 1
        else:
            nseg = segment_scan(r, cos_inc, p[FP_C0], c1, range_min, range_max, min_points, starts, ends)
        base = k * B
        for g in range(nseg):
            seg_out[base + g, 0] = starts[g]
            seg_out[base + g, 1] = ends[g]
        counts[k, 0] = nseg
        for i in range(B):
            ri = r[i]
            if not valid_return(ri, range_min, range_max):
                ri = 0.0  # only reachable through given segments: an invalid return is a point at the scanner
            x[i] = ri * cos_a[i]
            y[i] = ri * sin_a[i]
        nl, nc, nb = extract_scan(x, y, (starts, ends, nseg), k, p, trig, work, rows, (base, base, base), dalpha)
        counts[k, 1] = nl - base
        counts[k, 2] = nc - base
        counts[k, 3] = nb - base


@njit(cache=True, parallel=True, nogil=True)
def extract_parallel(ranges, parts, setup, out, given):
    """extract_scans over all N scans of the block (setup, out, given as there), split into `parts` ranges of
    consecutive scans run on numba's threads (numba.set_num_threads); the same rows as one
    extract_scans(ranges, 0, N, ...)."""
    N = ranges.shape[0]
    for j in prange(parts):
        extract_scans(ranges, j * N // parts, (j + 1) * N // parts, setup, out, given)


@njit(cache=True, nogil=True)
def gather_rows(rows, counts, j, B, out) -> None:
    """out (sum of counts[:, j], columns): the first counts[k, j] rows of each scan k's stretch of B rows of
    `rows` (see extract_scans), in scan order."""
    m = 0
    for k in range(counts.shape[0]):
        for q in range(counts[k, j]):
            out[m] = rows[k * B + q]
            m += 1
