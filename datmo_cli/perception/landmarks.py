"""Static landmarks (docs/method.md §6.2): per-scan detections and the run's landmark database.

Detections come from one scan's features in the sensor frame: corners (two perpendicular lines of a
segment meeting), convex and concave wall deflections (two lines turning by more than `deflection_min`
and less than a corner), undefined line ends (a wall line ending where its segment ends and nothing nearer
hides what lies beyond), column candidates (circles too large for legs) and benches (two support circles
with a line between them). The database accumulates them over the run in the world frame (with odometry)
or the sensor frame: a detection within `landmark_match` of a landmark of the same type is that landmark
(count, last seen, running mean position); a landmark enters the database after `landmark_min_count`
scans, and a column candidate that drifts more than `column_max_drift` (a moving circle object) never does.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..log import cdr, types
from ..log.vocabulary import (
    LANDMARK_BENCH,
    LANDMARK_COLUMN,
    LANDMARK_CONCAVE_DEFLECTION,
    LANDMARK_CONVEX_DEFLECTION,
    LANDMARK_CORNER,
    LANDMARK_LINE_END,
)
from ..numba_runtime import key_kernel_cache_on_sources
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
    det = np.cos(ta) * np.sin(tb) - np.sin(ta) * np.cos(tb)
    with np.errstate(divide="ignore", invalid="ignore"):
        jx = (ra * np.sin(tb) - rb * np.sin(ta)) / det
        jy = (rb * np.cos(ta) - ra * np.cos(tb)) / det
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
        orient = np.arctan2(uy / nu + vy / nv, ux / nu + vx / nv)
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
        rows[:, DET_ORIENT] = np.arctan2(fy[keep] - ey[keep], fx[keep] - ex[keep])
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
        p.bench_min_length,
        p.bench_max_length,
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
            off = np.abs(there * np.cos(t - theta) - rho)
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
    out[:, DET_ORIENT] = np.arctan2(ln["y_end"] - ln["y_ini"], ln["x_end"] - ln["x_ini"])
    out[:, DET_SIZE] = ln["length"]
    return out


@njit(cache=True)
def _benches(cs, cx, cy, cr, x0, y0, x1, y1, line_offsets, dmin, dmax, out) -> int:
    """Bench detections (rows DET_*) from support circles sorted by scan cs: pairs of one scan dmin..dmax
    apart with a line whose middle lies between them within 0.4 m of their axis and that runs along it."""
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
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    out[:, DET_X] = c * det[:, DET_X] - s * det[:, DET_Y] + pose[:, 0]
    out[:, DET_Y] = s * det[:, DET_X] + c * det[:, DET_Y] + pose[:, 1]
    out[:, DET_ORIENT] = np.arctan2(np.sin(det[:, DET_ORIENT] + pose[:, 2]), np.cos(det[:, DET_ORIENT] + pose[:, 2]))
    return out


# columns of the database rows: type, x, y, orientation, size, count, first scan, last scan, x0, y0, moved,
# confirmed, hidden (a column candidate at a bench's support: part of the bench, never listed)
DB_COLUMNS = 13
DB_MOVED, DB_CONFIRMED, DB_HIDDEN = 10, 11, 12
# counters of a database carried from block to block: rows used, live rows, confirmed rows
C_ROWS, C_LIVE, C_CONFIRMED = 0, 1, 2


@njit(cache=True)
def accumulate(
    det,
    stamps,
    k0,
    match,
    min_count,
    max_drift,
    column_time,
    forget,
    column_radius_min,
    db,
    first_ns,
    last_ns,
    live,
    confirmed,
    counters,
    snap_idx,
    snap_vals,
    snap_last,
    snap_count,
):
    """Fold one block of scans' detections (rows DET_*, sorted by scan; scans k0 .. k0 + len(stamps) - 1,
    stamped `stamps` ns) into the database `db` (rows as DB_COLUMNS; first_ns/last_ns: the stamps its row was
    first and last seen), carrying `live`, `confirmed` and `counters` (C_*) from the blocks before. After
    each scan k, the landmarks in the database (confirmed, not moved, not hidden) are appended to snap_idx
    (row index), snap_vals (x, y, orientation, size, count, last scan: their state then) and snap_last (last
    seen, ns), and their number stored in snap_count[k - k0]. A candidate seen fewer than min_count times and
    not for `forget` scans is forgotten; a column enters the database only once seen over `column_time` ns (a
    circle object that stops for a moment is not a column); a column candidate by a confirmed bench's support
    (its end, column_radius_min in) is hidden. Capacities: db rows >= counters[C_ROWS] + len(det), snapshot
    entries >= len(stamps) * (counters[C_CONFIRMED] + len(det)). Returns the snapshot entries written."""
    n_scans = stamps.shape[0]
    nd = det.shape[0]
    n = counters[C_ROWS]
    nlive = counters[C_LIVE]
    nconf = counters[C_CONFIRMED]
    ns = 0
    j = 0
    for kk in range(n_scans):
        k = k0 + kk
        stamp = stamps[kk]
        while j < nd and det[j, 0] == k:
            t = det[j, 1]
            x = det[j, 2]
            y = det[j, 3]
            best = -1
            bd = 2 * match
            # a column does not move: a tight gate; a bench's visible middle moves with what hides its ends
            gate = max_drift if t == 4.0 else (2 * match if t == 5.0 else match)
            for u in range(nlive):
                q = live[u]
                if db[q, 0] == t:
                    d = np.hypot(db[q, 1] - x, db[q, 2] - y)
                    if t == 5.0:
                        # a bench is seen whole or in parts (people and columns hide its ends): a detection
                        # belongs to it when it lies on the bench's axis within its length
                        ux = np.cos(db[q, 3])
                        uy = np.sin(db[q, 3])
                        along = abs((x - db[q, 1]) * ux + (y - db[q, 2]) * uy)
                        across = abs(-(x - db[q, 1]) * uy + (y - db[q, 2]) * ux)
                        d = across + max(0.0, along - 0.5 * db[q, 4])
                    if d <= min(bd, gate) and db[q, 7] != k:
                        bd = d
                        best = q
            if best < 0 and n < db.shape[0]:
                best = n
                for c in range(DB_COLUMNS):
                    db[n, c] = 0.0
                db[n, 0] = t
                db[n, 1] = x
                db[n, 2] = y
                db[n, 3] = det[j, 4]
                db[n, 4] = det[j, 5]
                db[n, 5] = 1.0
                db[n, 6] = k
                db[n, 7] = k
                db[n, 8] = x
                db[n, 9] = y
                first_ns[n] = stamp
                last_ns[n] = stamp
                live[nlive] = n
                nlive += 1
                n += 1
                if min_count <= 1 and (t != 4.0 or column_time <= 0):
                    db[n - 1, DB_CONFIRMED] = 1.0
                    confirmed[nconf] = best
                    nconf += 1
            elif best >= 0:
                c = db[best, 5] + 1.0
                if t == 5.0:
                    if det[j, 5] > db[best, 4]:  # the most complete view of a bench stands for it
                        db[best, 1] = x
                        db[best, 2] = y
                        db[best, 3] = det[j, 4]
                        db[best, 4] = det[j, 5]
                else:
                    db[best, 1] += (x - db[best, 1]) / c
                    db[best, 2] += (y - db[best, 2]) / c
                    db[best, 3] = det[j, 4]
                    db[best, 4] += (det[j, 5] - db[best, 4]) / c
                db[best, 5] = c
                db[best, 7] = k
                last_ns[best] = stamp
                # a column that drifts from where it was first seen is a mover, not a landmark
                if t == 4.0 and np.hypot(x - db[best, 8], y - db[best, 9]) > max_drift:
                    db[best, DB_MOVED] = 1.0
                if (
                    db[best, DB_CONFIRMED] == 0.0
                    and c >= min_count
                    and (t != 4.0 or stamp - first_ns[best] >= column_time)
                ):
                    db[best, DB_CONFIRMED] = 1.0
                    confirmed[nconf] = best
                    nconf += 1
            j += 1
        u = 0
        while u < nlive:  # forget stale candidates and moved columns
            q = live[u]
            if (db[q, DB_CONFIRMED] == 0.0 and k - db[q, 7] > forget) or db[q, DB_MOVED] != 0.0:
                nlive -= 1
                live[u] = live[nlive]
            else:
                u += 1
        _hide_bench_supports(db, confirmed, nconf, min_count, column_radius_min)
        count = 0
        for u in range(nconf):
            q = confirmed[u]
            if db[q, DB_MOVED] == 0.0 and db[q, DB_HIDDEN] == 0.0:
                if ns < snap_idx.shape[0]:
                    snap_idx[ns] = q
                    for c in range(6):
                        snap_vals[ns, c] = db[q, 1 + c] if c < 5 else db[q, 7]
                    snap_last[ns] = last_ns[q]
                ns += 1
                count += 1
        snap_count[kk] = count
    counters[C_ROWS] = n
    counters[C_LIVE] = nlive
    counters[C_CONFIRMED] = nconf
    return ns


@njit(cache=True)
def _hide_bench_supports(db, confirmed, nconf, min_count, column_radius_min):
    """Hide each confirmed column within 0.5 m of a support of a confirmed bench (its ends, column_radius_min
    in): it is part of the bench, not a column."""
    for u in range(nconf):
        q = confirmed[u]
        if db[q, 0] != 4.0 or db[q, DB_HIDDEN] != 0.0:
            continue
        for v in range(nconf):
            b = confirmed[v]
            if db[b, 0] != 5.0 or db[b, 5] < min_count:
                continue
            half = 0.5 * (db[b, 4] - 2 * column_radius_min)
            for sgn in (-1.0, 1.0):
                sx = db[b, 1] + sgn * half * np.cos(db[b, 3])
                sy = db[b, 2] + sgn * half * np.sin(db[b, 3])
                if np.hypot(db[q, 1] - sx, db[q, 2] - sy) < 0.5:
                    db[q, DB_HIDDEN] = 1.0


def landmark_elements(
    db: np.ndarray, first_ns: np.ndarray, snap_idx: np.ndarray, snap_vals: np.ndarray, snap_last: np.ndarray
) -> np.ndarray:
    """Landmark message elements of snapshot entries (see accumulate)."""
    out = np.zeros(len(snap_vals), LANDMARK_DTYPE)
    out["id"] = snap_idx + 1
    out["count"] = snap_vals[:, 4]
    for key, ns in (("first_seen", first_ns[snap_idx]), ("last_seen", snap_last)):
        out[key]["sec"] = ns // 1_000_000_000
        out[key]["nanosec"] = ns % 1_000_000_000
    out["x"], out["y"], out["orientation"], out["size"] = (
        snap_vals[:, 0],
        snap_vals[:, 1],
        snap_vals[:, 2],
        snap_vals[:, 3],
    )
    out["type"] = db[snap_idx, 0]
    return out


SNAPSHOT_SCANS = 32  # scans per kernel call of LandmarkStream.add


class LandmarkStream:
    """The landmark database built block by block: `add` folds one block of scans' detections in and returns
    the database after each of its scans. Memory: one row per landmark candidate ever seen (13 floats and two
    stamps), nothing per scan."""

    def __init__(self, p: FeatureParams) -> None:
        self.p = p
        self.db = np.zeros((64, DB_COLUMNS))
        self.first_ns = np.zeros(64, np.int64)
        self.last_ns = np.zeros(64, np.int64)
        self.live = np.zeros(64, np.int64)
        self.confirmed = np.zeros(64, np.int64)
        self.counters = np.zeros(3, np.int64)
        self.scans = 0
        self._last = np.zeros(0, LANDMARK_DTYPE)

    def _reserve(self, rows: int) -> None:
        cap = len(self.db)
        if rows <= cap:
            return
        new = max(rows, 2 * cap)
        for name in ("db", "first_ns", "last_ns", "live", "confirmed"):
            old = getattr(self, name)
            grown = np.zeros((new, *old.shape[1:]), old.dtype)
            grown[:cap] = old
            setattr(self, name, grown)

    @property
    def rows(self) -> np.ndarray:
        """The database rows used so far (DB_COLUMNS)."""
        return self.db[: self.counters[C_ROWS]]

    def add(self, detections: np.ndarray, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fold in the detections (rows DET_*, DET_SCAN counted from this block's first scan, world or sensor
        frame as the database's) of the next len(stamps) scans, stamped `stamps` (ns). Returns (elements,
        offsets (len(stamps) + 1,)): the Landmark elements in the database after each of these scans."""
        stamps = np.ascontiguousarray(stamps, np.int64)
        nb = len(stamps)
        det = np.ascontiguousarray(detections[np.argsort(detections[:, DET_SCAN], kind="stable")])
        # a few scans a kernel call: the snapshot buffer is sized for the worst case of each scan
        cuts = np.searchsorted(det[:, DET_SCAN], np.arange(0, nb + SNAPSHOT_SCANS, SNAPSHOT_SCANS))
        parts, counts = [], []
        for a, lo, hi in zip(range(0, nb, SNAPSHOT_SCANS), cuts[:-1].tolist(), cuts[1:].tolist(), strict=False):
            chunk = det[lo:hi].copy()
            chunk[:, DET_SCAN] -= a
            elems, count = self._add(chunk, stamps[a : a + SNAPSHOT_SCANS])
            parts.append(elems)
            counts.append(count)
        elems = np.concatenate(parts) if parts else np.zeros(0, LANDMARK_DTYPE)
        offsets = np.concatenate([[0], np.cumsum(np.concatenate(counts) if counts else [])]).astype(np.int64)
        if nb:
            self._last = elems[offsets[-2] : offsets[-1]]
        return elems, offsets

    def _add(self, det: np.ndarray, stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One kernel call: detections `det` (sorted, DET_SCAN counted from the call's first scan) of the next
        len(stamps) scans; (elements, count per scan)."""
        p = self.p
        nb = len(stamps)
        det[:, DET_SCAN] += self.scans
        self._reserve(int(self.counters[C_ROWS]) + len(det) + 1)
        cap = nb * (int(self.counters[C_CONFIRMED]) + len(det)) + 1
        snap_idx, snap_vals = np.zeros(cap, np.int64), np.zeros((cap, 6))
        snap_last, snap_count = np.zeros(cap, np.int64), np.zeros(nb, np.int64)
        ns = accumulate(
            det,
            stamps,
            self.scans,
            p.landmark_match,
            p.landmark_min_count,
            p.column_max_drift,
            p.column_min_time * 1e9,
            10,
            p.column_radius_min,
            self.db,
            self.first_ns,
            self.last_ns,
            self.live,
            self.confirmed,
            self.counters,
            snap_idx,
            snap_vals,
            snap_last,
            snap_count,
        )
        self.scans += nb
        return landmark_elements(self.db, self.first_ns, snap_idx[:ns], snap_vals[:ns], snap_last[:ns]), snap_count

    def final(self) -> np.ndarray:
        """Landmark elements of the database after the last scan added."""
        return self._last


class LandmarkDatabase:
    """The landmark database after each scan of a run or of a block of one: `rows` (DB_COLUMNS, the whole
    database) and, per scan, the Landmark elements in it after that scan (`all_snapshots`, sliced by
    snap_offsets). Built at once from a whole run's detections, or by `LandmarkStream.add` for a block."""

    def __init__(
        self, detections: np.ndarray, stamps: np.ndarray, p: FeatureParams, stream: LandmarkStream | None = None
    ) -> None:
        stream = stream if stream is not None else LandmarkStream(p)
        self._elems, self.snap_offsets = stream.add(detections, stamps)
        self.rows = stream.rows
        self.snap_idx = self._elems["id"].astype(np.int64) - 1
        self._final = stream.final()

    def final(self) -> np.ndarray:
        """Landmark elements of the database after the last scan."""
        return self._final

    def all_snapshots(self, stamps: np.ndarray | None = None) -> np.ndarray:
        """Landmark message elements of every snapshot entry (slice with snap_offsets)."""
        return self._elems

    def snapshot(self, k: int, stamps: np.ndarray | None = None) -> np.ndarray:
        """Landmark elements of the database after scan k."""
        return self._elems[self.snap_offsets[k] : self.snap_offsets[k + 1]]
