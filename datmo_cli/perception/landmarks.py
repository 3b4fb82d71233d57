"""Static landmarks (docs/method.md §6.2): per-scan detections and the run's landmark database.

Detections come from one scan's features in the sensor frame: corners (two perpendicular lines of a
segment meeting), convex and concave wall deflections (two lines turning by more than `deflection_min`
and less than a corner), undefined line ends (a wall line ending where its segment ends and nothing nearer
hides what lies beyond), column candidates (circles too large for legs) and benches (two support circles
with a line between them). The database accumulates them over the run in the world frame (with odometry)
or the sensor frame: a detection within `landmark_match` of a landmark of the same type is that landmark
(count, last seen, running mean position); a landmark enters the database after `landmark_min_count`
scans, and a column candidate that drifts more than `column_max_drift` (a moving circle object) never does.
The database is in landmark_database.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from datmo_cli.base import libm

from ..base.numba_runtime import key_kernel_cache_on_sources
from ..logs import cdr, types
from ..logs.vocabulary import (
    LANDMARK_BENCH,
    LANDMARK_COLUMN,
    LANDMARK_CONCAVE_DEFLECTION,
    LANDMARK_CONVEX_DEFLECTION,
    LANDMARK_CORNER,
    LANDMARK_LINE_END,
)
from .feature_layout import FP_BENCH_MAX_LENGTH, FP_BENCH_MIN_LENGTH
from .params import FeatureParams

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

LANDMARK_DTYPE = cdr.element_dtype(types.LANDMARK)
# a detection: scan index, type, x, y, orientation (rad), size (m)
DET_SCAN, DET_TYPE, DET_X, DET_Y, DET_ORIENT, DET_SIZE = range(6)


def _pairs_in_segment(lines: np.ndarray, scan: np.ndarray, max_gap: int = 3) -> np.ndarray:
    """Indices i where lines i and i + 1 are consecutive lines of one scan: in the same segment, or in
    neighbouring segments at most `max_gap` beams apart (a corner whose vertex split the segment)."""
    if len(lines) < 2:
        return np.zeros(0, np.int64)
    gap = lines["first"][1:].astype(np.int64) - lines["last"][:-1].astype(np.int64)
    same = (scan[1:] == scan[:-1]) & ((lines["segment"][1:] == lines["segment"][:-1]) | (gap <= max_gap))
    return np.flatnonzero(same)


def junction_detections(lines: np.ndarray, scan: np.ndarray, p: FeatureParams) -> np.ndarray:
    """Corners and deflections where consecutive lines of a segment meet (rows as DET_*), sensor frame."""
    i = _pairs_in_segment(lines, scan)
    if not len(i):
        return np.zeros((0, 6))
    a, b = lines[i], lines[i + 1]
    ta, tb = a["theta"].astype(np.float64), b["theta"].astype(np.float64)
    ra, rb = a["rho"].astype(np.float64), b["rho"].astype(np.float64)
    det = libm.cos(ta) * libm.sin(tb) - libm.sin(ta) * libm.cos(tb)
    with np.errstate(divide="ignore", invalid="ignore"):
        jx = (ra * libm.sin(tb) - rb * libm.sin(ta)) / det
        jy = (rb * libm.cos(ta) - ra * libm.cos(tb)) / det
    turn = np.abs(ta - tb) % np.pi
    turn = np.minimum(turn, np.pi - turn)  # angle between the lines, 0 .. pi/2
    gap = np.maximum(np.hypot(jx - a["x_end"], jy - a["y_end"]), np.hypot(jx - b["x_ini"], jy - b["y_ini"]))
    ok = np.isfinite(jx) & (gap <= p.corner_gap) & (np.minimum(a["length"], b["length"]) >= p.line_min_length)
    corner = ok & (np.abs(turn - np.pi / 2) <= np.radians(p.perpendicular_tolerance))
    walls = np.minimum(a["length"], b["length"]) >= 0.5  # a deflection is of a wall, not of a small object
    deflection = ok & ~corner & walls & (turn >= np.radians(p.deflection_min))
    # bisector of the two walls seen from the junction, and whether it bulges towards the scanner
    ux, uy = a["x_ini"] - jx, a["y_ini"] - jy
    vx, vy = b["x_end"] - jx, b["y_end"] - jy
    nu, nv = np.hypot(ux, uy), np.hypot(vx, vy)
    with np.errstate(divide="ignore", invalid="ignore"):
        orient = libm.arctan2(uy / nu + vy / nv, ux / nu + vx / nv)
    ex, ey = b["x_end"] - a["x_ini"], b["y_end"] - a["y_ini"]
    convex = (ex * (jy - a["y_ini"]) - ey * (jx - a["x_ini"])) * (ex * -a["y_ini"] - ey * -a["x_ini"]) > 0
    kind = np.where(corner, LANDMARK_CORNER, np.where(convex, LANDMARK_CONVEX_DEFLECTION, LANDMARK_CONCAVE_DEFLECTION))
    keep = corner | deflection
    out = np.zeros((int(keep.sum()), 6))
    out[:, DET_SCAN] = scan[i][keep]
    out[:, DET_TYPE] = kind[keep]
    out[:, DET_X], out[:, DET_Y], out[:, DET_ORIENT] = jx[keep], jy[keep], orient[keep]
    return out


def line_end_detections(
    lines: np.ndarray,
    scan: np.ndarray,
    seg_start: np.ndarray,
    seg_end: np.ndarray,
    seg_offsets: np.ndarray,
    ranges: np.ndarray,
    limits: tuple[float, float],
    p: FeatureParams,
) -> np.ndarray:
    """Undefined line ends, sensor frame: ends of wall lines (longer than d_max) that end their segment
    where the next return beyond (past a dropout of a few invalid beams) is absent or at least 0.5 m farther
    (so the end is seen: not hidden by something nearer, not a dropout on the wall, and not just a wall at a
    grazing angle breaking into pieces), not at the scan's own edge, and well within the range limit (a wall
    running out of range has no end there). `limits`: the scan's (range_min, range_max), metres."""
    k = np.flatnonzero(lines["length"] > p.d_max)
    if not len(k):
        return np.zeros((0, 6))
    ln, s = lines[k], scan[k]
    g = seg_offsets[s] + ln["segment"].astype(np.int64)
    out = []
    for beam, at_end, nb, ex, ey, fx, fy in (
        (ln["first"].astype(np.int64), seg_start[g], -1, ln["x_ini"], ln["y_ini"], ln["x_end"], ln["y_end"]),
        (
            ln["last"].astype(np.int64),
            seg_end[g].astype(np.int64) - 1,
            1,
            ln["x_end"],
            ln["y_end"],
            ln["x_ini"],
            ln["y_ini"],
        ),
    ):
        there, _, exists = return_beyond(ranges, s, beam, nb, limits)
        here = ranges[s, beam]
        seen = exists & (there > here + 0.5) & (here < 0.9 * limits[1])
        keep = (beam == at_end) & seen
        rows = np.zeros((int(keep.sum()), 6))
        rows[:, DET_SCAN], rows[:, DET_TYPE] = s[keep], LANDMARK_LINE_END
        rows[:, DET_X], rows[:, DET_Y] = ex[keep], ey[keep]
        rows[:, DET_ORIENT] = libm.arctan2(fy[keep] - ey[keep], fx[keep] - ex[keep])
        out.append(rows)
    return np.concatenate(out)


def circle_detections(
    circles: np.ndarray,
    scan: np.ndarray,
    lines: np.ndarray,
    line_scan: np.ndarray,
    line_offsets: np.ndarray,
    seg_start: np.ndarray,
    seg_end: np.ndarray,
    seg_offsets: np.ndarray,
    ranges: np.ndarray,
    limits: tuple[float, float],
    p: FeatureParams,
) -> np.ndarray:
    """Column candidates (free-standing circles larger than a leg) and benches (two such supports with a
    line between them, near their axis and along it), sensor frame."""
    big = np.flatnonzero(circles["radius"] > p.column_radius_min)
    g = seg_offsets[scan[big]] + circles["segment"][big].astype(np.int64)
    big = big[
        free_standing(scan[big], seg_start[g].astype(np.int64), seg_end[g].astype(np.int64), ranges, p.c0, limits)
    ]
    c = circles[big]
    cols = np.zeros((len(big), 6))
    cols[:, DET_SCAN], cols[:, DET_TYPE] = scan[big], LANDMARK_COLUMN
    cols[:, DET_X], cols[:, DET_Y], cols[:, DET_SIZE] = c["x"], c["y"], c["radius"]
    benches = np.zeros((len(big), 6))
    nb = _benches(
        scan[big].astype(np.int64),
        c["x"].astype(np.float64),
        c["y"].astype(np.float64),
        c["radius"].astype(np.float64),
        lines["x_ini"].astype(np.float64),
        lines["y_ini"].astype(np.float64),
        lines["x_end"].astype(np.float64),
        lines["y_end"].astype(np.float64),
        np.asarray(line_offsets, np.int64),
        p.kernel_vector(),
        benches,
    )
    return np.concatenate([cols, benches[:nb]])


DROPOUT_BEAMS = 3  # invalid beams a surface may drop out for and still continue beyond them


def return_beyond(
    ranges: np.ndarray, scan: np.ndarray, beam: np.ndarray, step: int, limits: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The range (metres) of the first valid return beyond `beam` in direction `step` (+1 or -1), looking
    past up to DROPOUT_BEAMS invalid beams (a dropout on a surface); inf where there is none that near (open
    space). Also its beam (-1 where none), and whether the next beam exists at all (False at the scan's own
    edge)."""
    beam = np.asarray(beam, np.int64)
    out = np.full(len(beam), np.inf)
    where = np.full(len(beam), -1, np.int64)
    _beyond(
        ranges, np.asarray(scan, np.int64), beam, step, float(limits[0]), float(limits[1]), DROPOUT_BEAMS, out, where
    )
    B = ranges.shape[1]
    return out, where, (beam + step >= 0) & (beam + step < B)


@njit(cache=True)
def _beyond(ranges, scan, beam, step, lo, hi, dropout, out, where) -> None:
    B = ranges.shape[1]
    for i in range(len(beam)):
        for j in range(1, dropout + 2):
            nb = beam[i] + step * j
            if nb < 0 or nb >= B:
                break
            r = np.float64(ranges[scan[i], nb])
            if np.isfinite(r) and r > lo and r < hi:
                out[i] = r
                where[i] = nb
                break


def free_standing(
    scan: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    ranges: np.ndarray,
    c0: float,
    limits: tuple[float, float],
    line: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    behind: float = 0.3,
) -> np.ndarray:
    """Whether segments [a, b) of scans `scan` stand free: beyond each end the next return (past a dropout of
    a few invalid beams) is absent or at least 0.5 m farther (open space behind), or nearer (an occluder), and
    at least one end is open; no return beyond is open space only well within the range limit. The scan's
    own edges are neither. A wall seen at a grazing angle breaks into pieces whose neighbours are only a
    little farther, a structure attached to a wall continues at its range, and a wall with a dropout
    continues beyond it. With `line` = (theta, rho, beam angles) of each segment's line (sensor frame,
    radians and metres), an open end's return must also lie `behind` metres or more off that line: the back
    of a shallow recess in a wall seen at a grazing angle is far in range but close to the wall's line."""
    n_open = np.zeros(len(scan), np.int64)
    closed = np.zeros(len(scan), bool)
    for inside, step in ((a, -1), (b - 1, 1)):
        there, beam, exists = return_beyond(ranges, scan, inside, step, limits)
        here = ranges[scan, np.clip(inside, 0, ranges.shape[1] - 1)]
        # no return beyond is open space unless the end is within 25 cm of the range limit, where it may be
        # the same surface running out of range (a wall seen at a grazing angle)
        is_open = exists & np.where(np.isfinite(there), there > here + 0.5, here < limits[1] - 0.25)
        if line is not None:
            theta, rho, angles = line
            t = angles[np.maximum(beam, 0)]
            off = np.abs(there * libm.cos(t - theta) - rho)
            is_open &= ~np.isfinite(there) | (off >= behind)
        occluded = exists & (there < here - c0)
        n_open += is_open
        closed |= exists & ~is_open & ~occluded
    return (n_open >= 1) & ~closed


def seat_detections(
    lines: np.ndarray,
    scan: np.ndarray,
    seg_start: np.ndarray,
    seg_end: np.ndarray,
    seg_offsets: np.ndarray,
    ranges: np.ndarray,
    limits: tuple[float, float],
    angles: np.ndarray,
    p: FeatureParams,
) -> np.ndarray:
    """Benches whose supports the scan cannot resolve as circles: a free-standing line of a bench's length,
    sensor frame. It spans its segment but for a support's arc at either end (8 beams), and beyond each end
    of the segment the next beam returns nothing, or returns 0.5 m farther and 0.3 m or more behind the line
    (open space behind the bench), or nearer (an occluder); at least one end must be open (`angles`: the
    beams' angles, radians). A wall seen at a grazing angle breaks into pieces
    whose neighbours are only a little farther, so it is not taken for a bench. A static one accumulates
    into a bench landmark; a moving one never does."""
    ln = lines
    ok = (ln["length"] >= p.bench_min_length) & (ln["length"] <= p.bench_max_length)
    k = np.flatnonzero(ok)
    if not len(k):
        return np.zeros((0, 6))
    ln, s = lines[k], scan[k]
    g = seg_offsets[s] + ln["segment"].astype(np.int64)
    a, b = seg_start[g].astype(np.int64), seg_end[g].astype(np.int64)
    spans = (ln["first"].astype(np.int64) - a <= 8) & (b - 1 - ln["last"].astype(np.int64) <= 8)
    line = (ln["theta"].astype(np.float64), ln["rho"].astype(np.float64), angles)
    free = spans & free_standing(s, a, b, ranges, p.c0, limits, line)
    ln, s = ln[free], s[free]
    out = np.zeros((len(ln), 6))
    out[:, DET_SCAN], out[:, DET_TYPE] = s, LANDMARK_BENCH
    out[:, DET_X] = 0.5 * (ln["x_ini"] + ln["x_end"])
    out[:, DET_Y] = 0.5 * (ln["y_ini"] + ln["y_end"])
    out[:, DET_ORIENT] = libm.arctan2(ln["y_end"] - ln["y_ini"], ln["x_end"] - ln["x_ini"])
    out[:, DET_SIZE] = ln["length"]
    return out


@njit(cache=True)
def _benches(cs, cx, cy, cr, x0, y0, x1, y1, line_offsets, p, out) -> int:
    """Bench detections (rows DET_*) from support circles sorted by scan cs: pairs of one scan bench_min_length
    to bench_max_length apart (p: FeatureParams.kernel_vector) with a line whose middle lies between them within
    0.4 m of their axis and that runs along it."""
    dmin = p[FP_BENCH_MIN_LENGTH]
    dmax = p[FP_BENCH_MAX_LENGTH]
    n = 0
    m = cs.shape[0]
    for u in range(m):
        for v in range(u + 1, m):
            if cs[v] != cs[u]:
                break
            d = np.hypot(cx[v] - cx[u], cy[v] - cy[u])
            if d < dmin or d > dmax or n >= out.shape[0]:
                continue
            ux = (cx[v] - cx[u]) / d
            uy = (cy[v] - cy[u]) / d
            k = cs[u]
            for q in range(line_offsets[k], line_offsets[k + 1]):
                mx = 0.5 * (x0[q] + x1[q]) - cx[u]
                my = 0.5 * (y0[q] + y1[q]) - cy[u]
                along = mx * ux + my * uy
                across = abs(-mx * uy + my * ux)
                dx = x1[q] - x0[q]
                dy = y1[q] - y0[q]
                if 0 < along < d and across < 0.4 and abs(dx * ux + dy * uy) >= 0.9 * np.hypot(dx, dy):
                    out[n, 0] = k
                    out[n, 1] = LANDMARK_BENCH
                    out[n, 2] = 0.5 * (cx[u] + cx[v])
                    out[n, 3] = 0.5 * (cy[u] + cy[v])
                    out[n, 4] = np.arctan2(uy, ux)
                    out[n, 5] = d + cr[u] + cr[v]
                    n += 1
                    break
    return n


def to_world(det: np.ndarray, poses: np.ndarray | None) -> np.ndarray:
    """Detections moved to the world frame by the sensor pose (x, y, theta) of each one's scan."""
    if poses is None or not len(det):
        return det
    out = det.copy()
    pose = poses[det[:, DET_SCAN].astype(np.int64)]
    c, s = libm.cos(pose[:, 2]), libm.sin(pose[:, 2])
    out[:, DET_X] = c * det[:, DET_X] - s * det[:, DET_Y] + pose[:, 0]
    out[:, DET_Y] = s * det[:, DET_X] + c * det[:, DET_Y] + pose[:, 1]
    out[:, DET_ORIENT] = libm.arctan2(
        libm.sin(det[:, DET_ORIENT] + pose[:, 2]), libm.cos(det[:, DET_ORIENT] + pose[:, 2])
    )
    return out
