"""numba kernels of the tracker's per-scan arithmetic, called by the phases of the compiled step
(_scan_measurements.py, _people.py, _background.py, _life_cycle.py).

Kernels take contiguous arrays, scalars and tuples of those that travel together (a scan's circles, its lines,
the background grid); frames and units are their callers'. Tracking parameters arrive as one float64 vector
`prm` (state.param_vector, indexed by the state.P_* constants). Their references are in
tests/reference_tracking.py.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from ..logs.vocabulary import BLOB_KIND_BLOB
from .bundles import LearnedMeasurements, LegMeasurements, LegStage, PaperMeasurements
from .state import (
    P_BACKGROUND_CELL,
    P_BACKGROUND_TIME,
    P_D_MAX,
    P_LEG_BLOB_MAX,
    P_LEG_RADIUS_MAX,
    P_LEG_REACH,
    P_MERGE_DISTANCE,
    P_MERGE_SPEED,
    P_OCCLUSION_MARGIN,
    P_STRIDE_MAX,
)

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

HIDDEN, OUT_OF_VIEW = 1, 2  # how a missed track is unseen (occlusion; the track table's OCCLUDED column)


@njit(cache=True)
def pair_legs(x, y, prm):
    """Greedy nearest-first pairing of leg candidates at most prm[P_STRIDE_MAX] m apart; returns (a, b, single):
    the pairs' two legs and the unpaired legs (indices)."""
    stride_max = prm[P_STRIDE_MAX]
    n = len(x)
    a = np.empty(n // 2 + 1, np.int64)
    b = np.empty(n // 2 + 1, np.int64)
    used = np.zeros(n, np.bool_)
    m = 0
    while True:
        best, bi, bj = stride_max, -1, -1
        for i in range(n):
            if used[i]:
                continue
            for j in range(i + 1, n):
                if used[j]:
                    continue
                d = np.hypot(x[i] - x[j], y[i] - y[j])
                if d <= best and (bi < 0 or d < best):
                    best, bi, bj = d, i, j
        if bi < 0:
            break
        used[bi] = used[bj] = True
        a[m], b[m] = bi, bj
        m += 1
    single = np.empty(n, np.int64)
    s = 0
    for i in range(n):
        if not used[i]:
            single[s] = i
            s += 1
    return a[:m], b[:m], single[:s]


@njit(cache=True)
def legs_to_measurements(lx, ly, ls, prm):
    """Person measurements (kind 0) at the centre of paired legs and single legs (kind 1): x, y, size,
    kind, legs (M, 4)."""
    a, b, single = pair_legs(lx, ly, prm)
    n = len(a) + len(single)
    x = np.empty(n)
    y = np.empty(n)
    size = np.empty(n)
    kind = np.empty(n, np.int64)
    legs = np.full((n, 4), np.nan)
    m = 0
    for k in range(len(a)):
        i, j = a[k], b[k]
        x[m], y[m] = 0.5 * (lx[i] + lx[j]), 0.5 * (ly[i] + ly[j])
        size[m] = np.hypot(lx[i] - lx[j], ly[i] - ly[j]) + 0.5 * (ls[i] + ls[j])
        kind[m] = 0
        legs[m, 0], legs[m, 1], legs[m, 2], legs[m, 3] = lx[i], ly[i], lx[j], ly[j]
        m += 1
    for i in single:
        x[m], y[m], size[m], kind[m] = lx[i], ly[i], ls[i], 1
        m += 1
    return x, y, size, kind, legs


@njit(cache=True)
def _people_first(lx, ly, ls, prm, n_more):
    """Measurement buffers (x, y, size, kind, legs) with room for n_more after the people and single legs
    made of leg candidates lx, ly, ls (legs_to_measurements), which fill them first; and how many those are."""
    px, py, psize, pkind, plegs = legs_to_measurements(lx, ly, ls, prm)
    n = len(px)
    cap = n + n_more
    x = np.empty(cap)
    y = np.empty(cap)
    size = np.empty(cap)
    kind = np.empty(cap, np.int64)
    legs = np.full((cap, 4), np.nan)
    x[:n], y[:n], size[:n], kind[:n], legs[:n] = px, py, psize, pkind, plegs
    return x, y, size, kind, legs, n


@njit(cache=True)
def measurements(circles, blobs, lines, prm):
    """Measurements of one scan (see measurements.py) from its circles (x, y, radius), blobs (x, y, size, kind)
    and lines (segment, x_ini, y_ini, x_end, y_end): a bundles.PaperMeasurements (x, y, size, kind, legs (M, 4),
    and the leg candidates made of, leg_x, leg_y, leg_size (L,))."""
    cx, cy, cr = circles
    bx, by, bsize, bkind = blobs
    lseg, lx0, ly0, lx1, ly1 = lines
    leg_radius_max, leg_blob_max, d_max = prm[P_LEG_RADIUS_MAX], prm[P_LEG_BLOB_MAX], prm[P_D_MAX]
    nc, nb, nl = len(cx), len(bx), len(lseg)
    # rectangular objects: the bounding box of each segment's lines
    ox = np.empty(nl)
    oy = np.empty(nl)
    osize = np.empty(nl)
    no = 0
    if nl:
        order = np.argsort(lseg, kind="mergesort")
        k = 0
        while k < nl:
            seg = lseg[order[k]]
            x0 = y0 = np.inf
            x1 = y1 = -np.inf
            while k < nl and lseg[order[k]] == seg:
                i = order[k]
                x0 = min(x0, lx0[i], lx1[i])
                x1 = max(x1, lx0[i], lx1[i])
                y0 = min(y0, ly0[i], ly1[i])
                y1 = max(y1, ly0[i], ly1[i])
                k += 1
            ox[no], oy[no], osize[no] = 0.5 * (x0 + x1), 0.5 * (y0 + y1), np.hypot(x1 - x0, y1 - y0)
            no += 1
    # leg candidates: small circles, small blobs, and lines as short as a leg is wide
    lx = np.empty(nc + nb + no)
    ly = np.empty(nc + nb + no)
    ls = np.empty(nc + nb + no)
    nleg = 0
    for i in range(nc):
        if cr[i] <= leg_radius_max:
            lx[nleg], ly[nleg], ls[nleg] = cx[i], cy[i], 2.0 * cr[i]
            nleg += 1
    for i in range(nb):
        if bsize[i] <= leg_blob_max and bkind[i] == BLOB_KIND_BLOB:
            lx[nleg], ly[nleg], ls[nleg] = bx[i], by[i], bsize[i]
            nleg += 1
    for i in range(no):
        if osize[i] <= leg_blob_max:
            lx[nleg], ly[nleg], ls[nleg] = ox[i], oy[i], osize[i]
            nleg += 1
    lx, ly, ls = lx[:nleg], ly[:nleg], ls[:nleg]
    x, y, size, kind, legs, m = _people_first(lx, ly, ls, prm, nc + nb + no)
    for i in range(nc):
        if cr[i] > leg_radius_max:
            x[m], y[m], size[m], kind[m] = cx[i], cy[i], 2.0 * cr[i], 2
            m += 1
    for i in range(nb):
        if not (bsize[i] <= leg_blob_max and bkind[i] == BLOB_KIND_BLOB):
            x[m], y[m], size[m], kind[m] = bx[i], by[i], bsize[i], 4
            m += 1
    for i in range(no):
        if osize[i] > leg_blob_max:
            x[m], y[m], size[m], kind[m] = ox[i], oy[i], osize[i], 3
            m += 1
    keep = 0
    for i in range(m):
        if size[i] <= d_max:
            x[keep], y[keep], size[keep], kind[keep] = x[i], y[i], size[i], kind[i]
            legs[keep] = legs[i]
            keep += 1
    return PaperMeasurements(x[:keep], y[:keep], size[:keep], kind[:keep], legs[:keep], lx, ly, ls)


@njit(cache=True)
def _beam_marks(first, last, value, top):
    """Per beam 0..top-1, the largest `value` of the intervals [first, last] (beam indices) covering it."""
    out = np.zeros(top)
    for i in range(len(first)):
        for j in range(first[i], last[i] + 1):
            out[j] = max(out[j], value[i])
    return out


@njit(cache=True)
def _span_max(marks, a, b):
    v = 0.0
    for j in range(a, b + 1):
        v = max(v, marks[j])
    return v


@njit(cache=True)
def learned_measurements(circles, blobs, lines, legs, weak, prm):
    """Measurements of one scan when a leg detector ran (see measurements.py): its legs (beams gfirst..glast
    at gx, gy, width gw) paired into people or single, then everything else as what it is: a circle
    (kind 2), the bounding box of a segment's lines (kind 3) or a blob (kind 4), whatever its size up to
    d_max; circles, blobs and lines on a leg's beams are that leg. Beams wfirst..wlast are clusters the
    detector gave a lower leg probability wp: a measurement on them takes it (the largest it covers).
    Beam ranges are inclusive. The groups: circles, blobs, lines, legs: bundles.Circles, Blobs (its kind unread),
    Lines, Legs (its probability unread); weak (wfirst, wlast, wp). Returns a bundles.LearnedMeasurements: x, y,
    size, kind, legs (M, 4), prob (M,: 0 for the legs, whose probabilities the caller has, and for what the
    detector gave none) and cover (W,): for each of those weaker clusters the measurement on most of its beams
    (-1: none), which is that cluster if a track takes it as a leg."""
    cfirst, clast, cx, cy, cr = circles.first, circles.last, circles.x, circles.y, circles.radius
    bfirst, blast, bx, by, bsize = blobs.first, blobs.last, blobs.x, blobs.y, blobs.size
    lseg, lfirst, llast = lines.segment, lines.first, lines.last
    lx0, ly0, lx1, ly1 = lines.x_ini, lines.y_ini, lines.x_end, lines.y_end
    gfirst, glast, gx, gy, gw = legs.first, legs.last, legs.x, legs.y, legs.width
    wfirst, wlast, wp = weak
    nc, nb, nl, ng = len(cx), len(bx), len(lseg), len(gx)
    d_max = prm[P_D_MAX]
    top = 1
    for arr in (clast, blast, llast, glast, wlast):
        for v in arr:
            top = max(top, v + 1)
    is_leg = _beam_marks(gfirst, glast, np.ones(ng), top)
    weak = _beam_marks(wfirst, wlast, wp, top)
    x, y, size, kind, mlegs, m = _people_first(gx, gy, gw, prm, nc + nb + nl)
    prob = np.zeros(len(x))
    nw = len(wfirst)
    cover = np.full(nw, -1, np.int64)
    best = np.zeros(nw, np.int64)
    for i in range(nc):
        if _span_max(is_leg, cfirst[i], clast[i]) == 0.0:
            x[m], y[m], size[m], kind[m] = cx[i], cy[i], 2.0 * cr[i], 2
            prob[m] = _span_max(weak, cfirst[i], clast[i])
            _cover(cover, best, wfirst, wlast, cfirst[i], clast[i], m)
            m += 1
    for i in range(nb):
        if _span_max(is_leg, bfirst[i], blast[i]) == 0.0:
            x[m], y[m], size[m], kind[m] = bx[i], by[i], bsize[i], 4
            prob[m] = _span_max(weak, bfirst[i], blast[i])
            _cover(cover, best, wfirst, wlast, bfirst[i], blast[i], m)
            m += 1
    if nl:
        order = np.argsort(lseg, kind="mergesort")
        k = 0
        while k < nl:
            seg = lseg[order[k]]
            x0 = y0 = np.inf
            x1 = y1 = -np.inf
            f, e = top, 0
            while k < nl and lseg[order[k]] == seg:
                i = order[k]
                x0 = min(x0, lx0[i], lx1[i])
                x1 = max(x1, lx0[i], lx1[i])
                y0 = min(y0, ly0[i], ly1[i])
                y1 = max(y1, ly0[i], ly1[i])
                f, e = min(f, lfirst[i]), max(e, llast[i])
                k += 1
            if _span_max(is_leg, f, e) == 0.0:
                x[m], y[m], size[m], kind[m] = 0.5 * (x0 + x1), 0.5 * (y0 + y1), np.hypot(x1 - x0, y1 - y0), 3
                prob[m] = _span_max(weak, f, e)
                _cover(cover, best, wfirst, wlast, f, e, m)
                m += 1
    keep = 0
    where = np.full(m, -1, np.int64)
    for i in range(m):
        if size[i] <= d_max:
            x[keep], y[keep], size[keep], kind[keep], prob[keep] = x[i], y[i], size[i], kind[i], prob[i]
            mlegs[keep] = mlegs[i]
            where[i] = keep
            keep += 1
    for i in range(nw):
        if cover[i] >= 0:
            cover[i] = where[cover[i]]
    return LearnedMeasurements(x[:keep], y[:keep], size[:keep], kind[:keep], mlegs[:keep], prob[:keep], cover)


@njit(cache=True)
def _cover(cover, best, wfirst, wlast, f, e, m):
    """Measurement m (beams f..e) covers each weaker cluster (wfirst..wlast) it overlaps more than any before."""
    for i in range(len(wfirst)):
        overlap = min(e, wlast[i]) - max(f, wfirst[i]) + 1
        if overlap > best[i]:
            best[i], cover[i] = overlap, m


@njit(cache=True)
def leg_stage(tx, ty, lx, ly, ls, prm):
    """Leg candidates (lx, ly, ls) to tracks predicted at (tx, ty), nearest pairs first: each leg to at
    most one track, each track at most two legs: the first within leg_reach, the second within stride_max
    of the track and of the first leg (a lagging prediction sits by one leg, a stride from the other).
    Returns a bundles.LegStage (owner, x, y, size, kind, legs, taken): one measurement per track that took legs
    (the centre of two legs, kind 0, or one leg, kind 1) with the owner's index, and which legs were taken."""
    reach, stride_max = prm[P_LEG_REACH], prm[P_STRIDE_MAX]
    T, L = len(tx), len(lx)
    d = np.empty((T, L))
    for k in range(T):
        for j in range(L):
            d[k, j] = np.hypot(lx[j] - tx[k], ly[j] - ty[k])
    first = np.full(T, -1, np.int64)
    second = np.full(T, -1, np.int64)
    taken = np.zeros(L, np.bool_)
    while True:
        best, bk, bj = np.inf, -1, -1
        for k in range(T):
            if second[k] >= 0:
                continue
            f = first[k]
            limit = reach if f < 0 else stride_max  # a second leg: anywhere within a stride of the first
            for j in range(L):
                if taken[j] or d[k, j] > limit or d[k, j] >= best:
                    continue
                if f >= 0 and np.hypot(lx[j] - lx[f], ly[j] - ly[f]) > stride_max:
                    continue
                best, bk, bj = d[k, j], k, j
        if bk < 0:
            break
        taken[bj] = True
        if first[bk] < 0:
            first[bk] = bj
        else:
            second[bk] = bj
    n = 0
    for k in range(T):
        if first[k] >= 0:
            n += 1
    owner = np.empty(n, np.int64)
    x = np.empty(n)
    y = np.empty(n)
    size = np.empty(n)
    kind = np.empty(n, np.int64)
    legs = np.full((n, 4), np.nan)
    m = 0
    for k in range(T):
        i, j = first[k], second[k]
        if i < 0:
            continue
        owner[m] = k
        if j >= 0:
            x[m], y[m] = 0.5 * (lx[i] + lx[j]), 0.5 * (ly[i] + ly[j])
            size[m] = np.hypot(lx[i] - lx[j], ly[i] - ly[j]) + 0.5 * (ls[i] + ls[j])
            kind[m] = 0
            legs[m, 0], legs[m, 1], legs[m, 2], legs[m, 3] = lx[i], ly[i], lx[j], ly[j]
        else:
            x[m], y[m], size[m], kind[m] = lx[i], ly[i], ls[i], 1
        m += 1
    return LegStage(owner, x, y, size, kind, legs, taken)


@njit(cache=True)
def duplicates(x, y, vx, vy, vvar, victim, candidate, confirmed, rank, prm):
    """Which `victim` tracks lie within merge_distance of a `candidate` track of higher rank (ties: lower index),
    unless both are confirmed and their velocities differ by at least merge_speed plus the standard deviation of
    that difference (vvar: each track's velocity variance, m²/s², the trace of its velocity covariance): two
    confirmed people passing each other close are not one, but a track whose velocity is not known yet (just
    restarted) moves like anything."""
    merge_distance, merge_speed = prm[P_MERGE_DISTANCE], prm[P_MERGE_SPEED]
    K = len(x)
    dup = np.zeros(K, np.bool_)
    for i in range(K):
        if not victim[i]:
            continue
        for j in range(K):
            if j == i or not candidate[j]:
                continue
            if rank[j] > rank[i] or (rank[j] == rank[i] and j < i):
                if np.hypot(x[i] - x[j], y[i] - y[j]) < merge_distance and (
                    not (confirmed[i] and confirmed[j])
                    or np.hypot(vx[i] - vx[j], vy[i] - vy[j]) < merge_speed + np.sqrt(vvar[i] + vvar[j])
                ):
                    dup[i] = True
                    break
    return dup


@njit(cache=True)
def leg_stage_measurements(tx, ty, cand, meas, prm):
    """leg_stage on every leg candidate (cand: lx, ly, ls, strong, cover), then the scan's measurements rebuilt:
    first one per track that took legs (owner gives the track), then the free strong candidates paired
    (legs_to_measurements), then the measurements of other kinds (mkind not 0 or 1) but those a taken weaker
    candidate was measured as
    (cover[i] >= 0: the measurement on its beams, which is that candidate). Returns a bundles.LegMeasurements
    (owner, x, y, size, kind, legs, other): `other` the indices (into mx) of the other-kind measurements kept, in
    their order. meas: the scan's measurements (mx, my, msize, mkind, mlegs)."""
    lx, ly, ls, strong, cover = cand
    mx, my, msize, mkind, mlegs = meas
    took = leg_stage(tx, ty, lx, ly, ls, prm)
    free = ~took.taken & strong
    rx, ry, rsize, rkind, rlegs = legs_to_measurements(lx[free], ly[free], ls[free], prm)
    dropped = np.zeros(len(mx), np.bool_)
    for i in range(len(lx)):
        if took.taken[i] and cover[i] >= 0:
            dropped[cover[i]] = True
    n_other = 0
    for i in range(len(mx)):
        if mkind[i] > 1 and not dropped[i]:
            n_other += 1
    n = len(took.x) + len(rx) + n_other
    x = np.empty(n)
    y = np.empty(n)
    size = np.empty(n)
    kind = np.empty(n, np.int64)
    legs = np.full((n, 4), np.nan)
    other = np.empty(n_other, np.int64)
    a, b = len(took.x), len(took.x) + len(rx)
    x[:a], y[:a], size[:a], kind[:a], legs[:a] = took.x, took.y, took.size, took.kind, took.legs
    x[a:b], y[a:b], size[a:b], kind[a:b], legs[a:b] = rx, ry, rsize, rkind, rlegs
    m = b
    for i in range(len(mx)):
        if mkind[i] > 1 and not dropped[i]:
            x[m], y[m], size[m], kind[m] = mx[i], my[i], msize[i], mkind[i]
            other[m - b] = i
            m += 1
    return LegMeasurements(took.owner, x, y, size, kind, legs, other)


@njit(cache=True)
def occlusion(sx, sy, size, missed, ranges, angle_min, increment, range_max, prm):
    """How each missed track (sensor-frame centres sx, sy and extents, m) is unseen (int64): OUT_OF_VIEW (2)
    outside the field of view or at least range_max away, HIDDEN (1) behind a return more than occlusion_margin
    m nearer within its angular extent, else 0 (it should have been seen; a track seen is 0 too)."""
    margin = prm[P_OCCLUSION_MARGIN]
    K, B = len(sx), len(ranges)
    occ = np.zeros(K, np.int64)
    for k in range(K):
        if not missed[k]:
            continue
        rng = np.hypot(sx[k], sy[k])
        beam = int(np.rint((np.arctan2(sy[k], sx[k]) - angle_min) / increment))
        if beam < 0 or beam >= B or rng >= range_max:
            occ[k] = OUT_OF_VIEW
            continue
        half = int(np.ceil(np.arctan2(max(size[k], 0.2) / 2, max(rng, 0.1)) / abs(increment)))
        for j in range(max(beam - half, 0), min(beam + half + 1, B)):
            if ranges[j] < rng - margin:
                occ[k] = HIDDEN
                break
    return occ


@njit(cache=True)
def on_background(score, lx, ly, ls, px, py, x0, y0, n, prm):
    """Which leg candidates (lx, ly, extent ls; tracking frame) lie on the background: a cell (of the n x n
    grid of background_cell m cells, cell (0, 0) at (x0, y0)) around the candidate's side facing the sensor at
    (px, py) has been occupied for at least background_time s."""
    cell, threshold = prm[P_BACKGROUND_CELL], prm[P_BACKGROUND_TIME]
    out = np.zeros(len(lx), np.bool_)
    for m in range(len(lx)):
        dx, dy = lx[m] - px, ly[m] - py
        d = max(np.hypot(dx, dy), 1e-6)
        fx, fy = lx[m] - 0.5 * ls[m] * dx / d, ly[m] - 0.5 * ls[m] * dy / d
        ci = int(np.floor((fx - x0) / cell))
        ck = int(np.floor((fy - y0) / cell))
        for i in range(max(ci - 1, 0), min(ci + 2, n)):
            for k in range(max(ck - 1, 0), min(ck + 2, n)):
                if score[i * n + k] >= threshold:
                    out[m] = True
    return out


@njit(cache=True)
def tracks_on_background(grid, mx, my, msize, mkind, rows, cols, n_tracks, px, py, prm):
    """Which of n_tracks tracks took (rows, cols) a measurement on the background (see on_background; legs and
    circles are tested on their side facing the sensor, other kinds at their centre). grid: (score, x0, y0, n)."""
    score, x0, y0, n = grid
    out = np.zeros(n_tracks, np.bool_)
    if not len(rows):
        return out
    x = np.empty(len(cols))
    y = np.empty(len(cols))
    front = np.zeros(len(cols))
    for q in range(len(cols)):
        j = cols[q]
        x[q], y[q] = mx[j], my[j]
        if mkind[j] == 1 or mkind[j] == 2:
            front[q] = msize[j]
    bg = on_background(score, x, y, front, px, py, x0, y0, n, prm)
    for q in range(len(rows)):
        out[rows[q]] = bg[q]
    return out
