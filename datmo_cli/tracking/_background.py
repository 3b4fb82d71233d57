"""What is not a person's leg: the background grid (cells long occupied, tracking frame) and the beams that see
a part of the robot (carried beams), with the phases of the step that use them.

The grid: n x n cells of background_cell m, cell (0, 0) at ctx[C_BG_X0], ctx[C_BG_Y0]; per cell the time (s) it
has been occupied (score) and the last scan that occupied it (mark); the active cells and their range and beam
(cache). Its arrays travel as one tuple bg = (score, mark, active, cache); the carried beams' as carry =
(ref, seen, away), per beam (m). The sensor of a scan: sensor = (ranges (B,) float32 m, has_ranges, has_pose,
pose (x, y m, theta rad), geo: angle_min, increment, range_max, has geometry, range_min). References:
tests/reference_tracking.py (background_update, and the ReferenceTracker's _carried_update, _off_background,
_hit_background and _background).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from . import _kernels
from ._people import owns_returns, sure_person
from ._scan_measurements import CARRIED_LEG, K_BLOB, K_LEG, NOT_A_LEG, R_COVER, R_W, R_X, R_Y, RAW_COLS, to_sensor
from .bundles import ScanMeasurements
from .state import (
    C_BG_CACHED,
    C_BG_COUNT,
    C_BG_HI,
    C_BG_LO,
    C_BG_PC,
    C_BG_PS,
    C_BG_PX,
    C_BG_PY,
    C_BG_READY,
    C_BG_SCAN,
    C_BG_X0,
    C_BG_Y0,
    C_CARRY_POSED,
    C_CARRY_PX,
    C_CARRY_PY,
    ON_BG,
    P_BACKGROUND_CELL,
    P_BACKGROUND_EXTENT,
    P_BACKGROUND_TIME,
    P_CARRIED_RADIUS,
    P_CARRIED_TRAVEL,
    P_LEG_REACH,
    P_OCCLUSION_MARGIN,
    P_PERSON_RADIUS,
    X,
    Y,
)

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True)
def carried_update(carry_ref, carry_seen, carry_away, ranges, has_ranges, has_pose, pose, geo, ctx, prm):
    """Per beam, the range carry_ref it keeps returning and how far (m) the sensor has travelled while it did
    (carry_seen: the return within carried_radius of carry_ref) or did not (carry_away: nearer, farther or none).
    A beam that mostly returns the same range while the sensor moves sees something the robot carries (a part of
    the robot, carried_beams); when it has been away more than seen, its reference starts again at the return.
    Only a sensor with a pose travels (geo: angle_min, increment, range_max, has geometry, range_min)."""
    if not has_ranges or not has_pose or len(ranges) != len(carry_ref) or geo[3] == 0:
        return
    px, py = pose[0], pose[1]
    step = np.hypot(px - ctx[C_CARRY_PX], py - ctx[C_CARRY_PY]) if ctx[C_CARRY_POSED] != 0 else 0.0
    ctx[C_CARRY_POSED], ctx[C_CARRY_PX], ctx[C_CARRY_PY] = 1.0, px, py
    tol = prm[P_CARRIED_RADIUS]
    for j in range(len(ranges)):
        r = np.float64(ranges[j])
        ok = r > geo[4] and r < geo[2]
        if ok and abs(r - carry_ref[j]) <= tol:
            carry_seen[j] += step
        else:
            carry_away[j] += step
            if carry_away[j] > carry_seen[j]:
                carry_ref[j] = r if ok else np.nan
                carry_seen[j], carry_away[j] = 0.0, 0.0


@njit(cache=True)
def carried_beams(out, raw, ranges, carry_ref, carry_seen, carry_away, has_pose, pose, geo, prm):
    """Set out[i] for the leg candidates raw[i] (tracking frame: x, y, width, ...) most of whose beams are carried:
    returning their carry_ref now, after carried_travel m of travel that saw it at least three times as far as not
    (carried_update)."""
    if not has_pose or len(carry_ref) == 0 or len(ranges) != len(carry_ref) or geo[3] == 0:
        return
    B, inc, tol = len(carry_ref), abs(geo[1]), prm[P_CARRIED_RADIUS]
    for i in range(len(raw)):
        sx, sy = to_sensor(raw[i, R_X], raw[i, R_Y], has_pose, pose)
        rng = max(np.hypot(sx, sy), 0.1)
        b = int(np.rint((np.arctan2(sy, sx) - geo[0]) / geo[1]))
        h = int(np.ceil(np.arctan2(0.5 * raw[i, R_W], rng) / inc))
        total = carried = 0
        for j in range(max(b - h, 0), min(b + h + 1, B)):
            total += 1
            if (
                carry_seen[j] >= prm[P_CARRIED_TRAVEL]
                and carry_seen[j] >= 3.0 * carry_away[j]
                and abs(np.float64(ranges[j]) - carry_ref[j]) <= tol
            ):
                carried += 1
        if total > 0 and 2 * carried > total:
            out[i] = True


@njit(cache=True)
def off_background(tab, n, meas, bg_score, ctx, frame, sensor, carry, prm):
    """The leg candidates on the background or carried (carried_beams) taken out (tracker._off_background): a
    strong one becomes a blob, a weak one stays the measurement covering it, each of leg probability NOT_A_LEG
    (CARRIED_LEG when carried),
    and the other strong legs are paired again; the same arrays when none is. A candidate within leg_reach of a
    person's prediction is that person's leg, background or not (a person standing by a wall keeps their legs), but
    not when carried. meas: the scan's measurements (bundles.ScanMeasurements), tracking frame; frame: the sensor's
    pose (px, py, cos, sin of its heading). Returns the measurements (meas itself when none is taken out)."""
    mx, my, msize, mkind, mprob = meas.x, meas.y, meas.size, meas.kind, meas.prob
    mlegs, raw = meas.legs, meas.raw
    px, py = frame[0], frame[1]
    ranges, _, has_pose, pose, geo = sensor
    carry_ref, carry_seen, carry_away = carry[0], carry[1], carry[2]
    if len(raw) == 0:
        return meas
    if ctx[C_BG_READY] != 0:
        nbg = int(np.sqrt(len(bg_score)) + 0.5)
        bg = _kernels.on_background(
            bg_score,
            raw[:, R_X].copy(),
            raw[:, R_Y].copy(),
            raw[:, R_W].copy(),
            px,
            py,
            ctx[C_BG_X0],
            ctx[C_BG_Y0],
            nbg,
            prm,
        )
    else:
        bg = np.zeros(len(raw), np.bool_)
    for i in range(len(bg)):
        if bg[i]:
            for k in range(n):
                d = np.hypot(raw[i, R_X] - tab[k, X], raw[i, R_Y] - tab[k, Y])
                if sure_person(tab, k, prm) and d <= prm[P_LEG_REACH]:
                    bg[i] = False
                    break
    carried = np.zeros(len(raw), np.bool_)
    carried_beams(carried, raw, ranges, carry_ref, carry_seen, carry_away, has_pose, pose, geo, prm)
    bg |= carried
    if not bg.any():
        return meas
    strong = raw[:, R_COVER] < 0
    keep = strong & ~bg
    lx, ly, ls, kind, legs = _kernels.legs_to_measurements(
        raw[keep, R_X].copy(), raw[keep, R_Y].copy(), raw[keep, R_W].copy(), prm
    )
    n_bg = 0
    for i in range(len(bg)):
        if bg[i] and strong[i]:
            n_bg += 1
    n_other = 0
    for j in range(len(mx)):
        if mkind[j] > K_LEG:
            n_other += 1
    M = len(lx) + n_bg + n_other
    x, y, size = np.empty(M), np.empty(M), np.empty(M)
    knd = np.empty(M, np.int64)
    lg = np.full((M, 4), np.nan)
    prob = np.zeros(M)
    where = np.full(len(mx), -1, np.int64)  # an other-kind measurement's new index
    m = 0
    for i in range(len(lx)):
        x[m], y[m], size[m], knd[m] = lx[i], ly[i], ls[i], kind[i]
        lg[m] = legs[i]
        m += 1
    for i in range(len(bg)):
        if bg[i] and strong[i]:
            not_a_leg = CARRIED_LEG if carried[i] else NOT_A_LEG
            x[m], y[m], size[m], knd[m], prob[m] = raw[i, R_X], raw[i, R_Y], raw[i, R_W], K_BLOB, not_a_leg
            m += 1
    for j in range(len(mx)):
        if mkind[j] > K_LEG:
            x[m], y[m], size[m], knd[m], prob[m] = mx[j], my[j], msize[j], mkind[j], mprob[j]
            lg[m] = mlegs[j]
            where[j] = m
            m += 1
    n_keep = 0
    for i in range(len(bg)):
        if not bg[i]:
            n_keep += 1
    out = np.empty((n_keep, RAW_COLS))
    q = 0
    for i in range(len(bg)):
        c = int(raw[i, R_COVER])
        if bg[i]:
            if c >= 0 and where[c] >= 0:
                prob[where[c]] = CARRIED_LEG if carried[i] else NOT_A_LEG
            continue
        out[q] = raw[i]
        if c >= 0:
            out[q, R_COVER] = where[c]
        q += 1
    return ScanMeasurements(x, y, size, knd, lg, out, prob)


@njit(cache=True)
def hit_background(tab, n, rows, cols, meas, bg_score, ctx, frame, prm):
    """Mark (column ON_BG) the tracks that take (rows, cols) a measurement of meas (bundles.ScanMeasurements) on the
    background this scan: their motion does not count (tracker._hit_background). frame: (px, py, cos, sin) of the
    sensor."""
    px, py = frame[0], frame[1]
    for k in range(n):
        tab[k, ON_BG] = 0.0
    if ctx[C_BG_READY] == 0:
        return
    nbg = int(np.sqrt(len(bg_score)) + 0.5)
    grid = (bg_score, ctx[C_BG_X0], ctx[C_BG_Y0], nbg)
    on_bg = _kernels.tracks_on_background(grid, meas.x, meas.y, meas.size, meas.kind, rows, cols, n, px, py, prm)
    for k in range(n):
        tab[k, ON_BG] = 1.0 if on_bg[k] else 0.0


@njit(cache=True)
def background_update(bg, n_active, scan, ranges, beams, frame, dt, grid, fresh, people):
    """reference_tracking.background_update with each active cell's range and beam kept beside it (cache[a] = r, beam
    for active[a], beam -2: not yet computed), valid while the sensor pose does not change (`fresh`: it
    changed, compute them all again). The same arithmetic on the same numbers: the same grid. An inactive
    cell's mark is 0 here, not -1 (scans count from 1), so a new grid is all zeros (no 5 MB to fill). Returns
    within `radius` of a person at (qx, qy) (tracking frame) are the person's and add nothing.

    bg: (score, mark, active, cache); beams: (cos_a, sin_a, angle_min, increment, range_min, range_max) of the
    scan's beams (rad, m); frame: the sensor's pose (px, py, cos, sin of its heading); dt: s; grid: (x0, y0, cell,
    n, margin, settled), the grid's origin and cell (m), cells a side, the occlusion margin (m) and the score (s)
    of a settled cell, tested one scan in four; people: (qx, qy, radius)."""
    score, mark, active, cache = bg
    cos_a, sin_a, angle_min, increment, range_min, range_max = beams
    px, py, pc, ps = frame
    x0, y0, cell, n, margin, settled = grid
    qx, qy, radius = people
    B = len(ranges)
    keep = 0
    for a in range(n_active):
        c = active[a]
        r, jf = cache[a, 0], cache[a, 1]
        if score[c] >= settled and (c + scan) % 4 != 0:
            active[keep] = c
            cache[keep, 0], cache[keep, 1] = r, -2.0 if fresh else jf  # not tested: computed when it is
            keep += 1
            continue
        if fresh or jf == -2.0:
            wx, wy = x0 + (c // n + 0.5) * cell - px, y0 + (c % n + 0.5) * cell - py
            sx, sy = pc * wx + ps * wy, -ps * wx + pc * wy
            r = np.hypot(sx, sy)
            jf = float(int(np.rint((np.arctan2(sy, sx) - angle_min) / increment)))
        j = int(jf)
        if 0 <= j < B and r < range_max:
            rj = ranges[j]
            if (rj > r + margin and rj > range_min) or rj >= range_max:
                score[c] = 0.0
                mark[c] = 0
                continue
        active[keep] = c
        cache[keep, 0], cache[keep, 1] = r, jf
        keep += 1
    for j in range(B):
        r = ranges[j]
        if not (r > range_min and r < range_max):
            continue
        sx, sy = r * cos_a[j], r * sin_a[j]
        wx, wy = pc * sx - ps * sy + px, ps * sx + pc * sy + py
        mine = False
        for q in range(len(qx)):
            if np.hypot(wx - qx[q], wy - qy[q]) <= radius:
                mine = True
                break
        if mine:
            continue
        i = int(np.floor((wx - x0) / cell))
        k = int(np.floor((wy - y0) / cell))
        if i < 0 or k < 0 or i >= n or k >= n:
            continue
        c = i * n + k
        if mark[c] == scan:
            continue
        if mark[c] == 0:
            if keep >= len(active):
                continue
            active[keep] = c
            cache[keep, 1] = -2.0
            keep += 1
        mark[c] = scan
        score[c] += dt
    return keep


@njit(cache=True)
def background(bg, ctx, sensor, beam_dirs, frame, dt, tab, n, prm):
    """Add the scan's returns but the people's (within person_radius of a person track, or of a track of leg
    evidence at least person_evidence: owns_returns) to the background grid (tracker._background). sensor:
    (ranges, has_ranges, has_pose, pose, geo: angle_min, increment, range_max, has geometry, range_min);
    beam_dirs: (cos, sin) of each beam's angle; frame: (px, py, cos, sin) of the sensor."""
    bg_score = bg[0]
    ranges, has_ranges, _, _, geo = sensor
    cos_a, sin_a = beam_dirs
    px, py, pc, ps = frame
    if not has_ranges or geo[3] == 0 or prm[P_BACKGROUND_TIME] <= 0 or len(ranges) != len(cos_a) or len(bg_score) == 0:
        return
    if ctx[C_BG_READY] == 0:
        ctx[C_BG_READY] = 1.0
        ctx[C_BG_X0] = px - prm[P_BACKGROUND_EXTENT]
        ctx[C_BG_Y0] = py - prm[P_BACKGROUND_EXTENT]
        lo = geo[4] if np.isfinite(geo[4]) else 0.0
        ctx[C_BG_LO] = lo
        ctx[C_BG_HI] = geo[2] if np.isfinite(geo[2]) and geo[2] > lo else np.inf
    ctx[C_BG_SCAN] += 1
    fresh = not (
        ctx[C_BG_CACHED] != 0
        and ctx[C_BG_PX] == px
        and ctx[C_BG_PY] == py
        and ctx[C_BG_PC] == pc
        and ctx[C_BG_PS] == ps
    )
    ctx[C_BG_CACHED], ctx[C_BG_PX], ctx[C_BG_PY], ctx[C_BG_PC], ctx[C_BG_PS] = 1.0, px, py, pc, ps
    nbg = int(np.sqrt(len(bg_score)) + 0.5)
    n_people = 0
    for k in range(n):
        if owns_returns(tab, k, prm):
            n_people += 1
    qx, qy = np.empty(n_people), np.empty(n_people)
    q = 0
    for k in range(n):
        if owns_returns(tab, k, prm):
            qx[q], qy[q] = tab[k, X], tab[k, Y]
            q += 1
    beams = (cos_a, sin_a, geo[0], geo[1], ctx[C_BG_LO], ctx[C_BG_HI])
    grid = (
        ctx[C_BG_X0],
        ctx[C_BG_Y0],
        prm[P_BACKGROUND_CELL],
        nbg,
        prm[P_OCCLUSION_MARGIN],
        4.0 * prm[P_BACKGROUND_TIME],
    )
    people = (qx, qy, prm[P_PERSON_RADIUS])
    ctx[C_BG_COUNT] = background_update(
        bg, int(ctx[C_BG_COUNT]), int(ctx[C_BG_SCAN]), ranges, beams, frame, max(dt, 0.0), grid, fresh, people
    )
