"""The compiled tracking step: one numba call tracks a scan, or a block of scans, on the track table.

Every phase of Tracker.step (tracker.py's docstring has the rules) runs here on the table of state.py:
features to measurements, moved to the tracking frame, leg candidates on the background taken out, legs
given to the tracks of people, prediction, gating and global nearest neighbour (_assign), Kalman update,
reacquisition of tracks lost while occluded, leg evidence, occlusion, life cycle and duplicates, new tracks,
classification, tails, the background grid, and the Track elements out. tests/reference_tracking.py holds
the same rules as numpy statements; tests/test_tracking_step.py checks the two agree, phase by phase and
over whole logs.

Frames: measurements arrive in the sensor frame (x forward, y left, m); tracks live in the tracking frame
(the world frame when a pose (x, y, theta) is given, else the sensor frame); the Track elements out carry
sensor-frame positions and velocities and, with a pose, world ones. Times: ns since the tracker's first
scan (int64), seconds for durations. Kinds: measurements.KIND_*; classes and mobility: datmo_msgs/Track's.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..log.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    MOBILITY_DYNAMIC,
)
from . import _assign, _kernels
from .state import (
    AGE,
    BORN,
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
    C_HAS_STAMP,
    C_N_TRACKS,
    C_NEXT_ID,
    C_STAMP,
    CLS,
    CONFIRMED,
    FIRST_X,
    FIRST_Y,
    HISTORY,
    HIT,
    HITS,
    ID,
    LAST_HIT,
    LAST_X,
    LAST_Y,
    LEAD_LEFT,
    LEAD_RIGHT,
    LEG_SCORE,
    MISSES,
    MOBILITY,
    MOVING_TIME,
    OCCLUDED,
    ON_BG,
    P0,
    P_BACKGROUND_CELL,
    P_BACKGROUND_EXTENT,
    P_BACKGROUND_TIME,
    P_CARRIED_RADIUS,
    P_CARRIED_TRAVEL,
    P_CONFIRM_HITS,
    P_CONFIRM_WINDOW,
    P_D_MAX,
    P_DELETE_AFTER,
    P_DELETE_AFTER_OCCLUDED,
    P_GATE,
    P_INITIAL_SPEED_SIGMA,
    P_LEG_BESIDE,
    P_LEG_EVIDENCE_RATE,
    P_LEG_MEASUREMENT_NOISE,
    P_LEG_PROBABILITY,
    P_LEG_RADIUS_MAX,
    P_MAX_GATE_DISTANCE,
    P_MEASUREMENT_NOISE,
    P_MOVING_DISTANCE,
    P_MOVING_PERSON_EVIDENCE,
    P_MOVING_PERSON_PAIRS,
    P_MOVING_SPEED,
    P_MOVING_TIME,
    P_OCCLUSION_MARGIN,
    P_PERSON_EVIDENCE,
    P_PERSON_PAIRS,
    P_PERSON_PROCESS_NOISE,
    P_PERSON_VOTES,
    P_PROCESS_NOISE,
    P_REACQUIRE_DISTANCE,
    P_REACQUIRE_SPEED,
    P_SPAWN_CLEARANCE,
    P_STEP_MAX,
    P_STEP_MIN,
    P_TAIL_LENGTH,
    P_TENTATIVE_DELETE_AFTER,
    P_UNDEFINED_WINDOW,
    P_WALKING_AFTER,
    POSE_FIRST_X,
    POSE_FIRST_Y,
    SENSOR_DEV,
    SENSOR_REF_X,
    SENSOR_REF_Y,
    SIZE,
    TAIL,
    TAIL_COUNT,
    VOTES,
    VX,
    VY,
    X,
    Y,
)

K_PERSON, K_LEG, K_CIRCLE, K_RECT, K_BLOB = 0, 1, 2, 3, 4
ANY_ROW = 4   # the compatibility row of tentative tracks (tracker._COMPAT)


# ------------------------------------------------------------------------------------- measurements
@njit(cache=True)
def paper_measurements(cx, cy, cr, bx, by, bsize, bkind, lseg, lx0, ly0, lx1, ly1, prm):
    """One scan's measurements by the paper's rule (reference: tests/reference_tracking.reference_measurements,
    learned=False), sensor frame: x, y, size, kind, legs (M, 4), raw leg candidates (L, 4: x, y, size, 0),
    prob (M,: zeros)."""
    x, y, size, kind, legs, lx, ly, ls = _kernels.measurements(
        cx, cy, cr, bx, by, bsize, bkind, lseg, lx0, ly0, lx1, ly1, prm)
    raw = np.zeros((len(lx), 4))
    for i in range(len(lx)):
        raw[i, 0], raw[i, 1], raw[i, 2] = lx[i], ly[i], ls[i]
    return x, y, size, kind, legs, raw, np.zeros(len(x))


@njit(cache=True)
def learned_measurements(cfirst, clast, cx, cy, cr, bfirst, blast, bx, by, bsize, lseg, lfirst, llast, lx0, ly0,
                         lx1, ly1, gfirst, glast, gx, gy, gw, gp, prm):
    """One scan's measurements with a leg detector's legs (reference_measurements, learned=True): the legs
    of probability >= leg_probability not on the beams of a circle wider than leg_radius_max are legs, the
    others lend their probability to what covers their beams. Returns x, y, size, kind, legs, raw (L, 4: x, y,
    width, probability of the legs), prob. The thresholds compare in float32, as numpy compares the
    features' float32 fields with a Python float."""
    thr = np.float32(prm[P_LEG_PROBABILITY])
    rmax = np.float32(prm[P_LEG_RADIUS_MAX])
    strong = np.empty(len(gx), np.bool_)
    for i in range(len(gx)):
        s = np.float32(gp[i]) >= thr
        for q in range(len(cx)):
            if np.float32(cr[q]) > rmax and not (glast[i] < cfirst[q] or gfirst[i] > clast[q]):
                s = False
        strong[i] = s
    weak = ~strong
    x, y, size, kind, legs, prob = _kernels.learned_measurements(
        cfirst, clast, cx, cy, cr, bfirst, blast, bx, by, bsize, lseg, lfirst, llast, lx0, ly0, lx1, ly1,
        gfirst[strong], glast[strong], gx[strong], gy[strong], gw[strong], gfirst[weak], glast[weak], gp[weak],
        prm)
    ns = 0
    for i in range(len(gx)):
        if strong[i]:
            ns += 1
    raw = np.empty((ns, 4))
    q = 0
    for i in range(len(gx)):
        if strong[i]:
            raw[q, 0], raw[q, 1], raw[q, 2], raw[q, 3] = gx[i], gy[i], gw[i], gp[i]
            q += 1
    return x, y, size, kind, legs, raw, prob


@njit(cache=True)
def moved(mx, my, mlegs, raw, px, py, pc, ps):
    """Measurements (mx, my), their legs and the raw leg candidates in the tracking frame of a sensor at
    (px, py) with heading cos/sin (pc, ps): new arrays (reference: tests/reference_tracking.moved)."""
    x = pc * mx - ps * my + px
    y = ps * mx + pc * my + py
    legs = mlegs.copy()
    for i in range(len(mlegs)):
        for c in (0, 2):
            legs[i, c] = pc * mlegs[i, c] - ps * mlegs[i, c + 1] + px
            legs[i, c + 1] = ps * mlegs[i, c] + pc * mlegs[i, c + 1] + py
    r = raw.copy()
    for i in range(len(raw)):
        r[i, 0] = pc * raw[i, 0] - ps * raw[i, 1] + px
        r[i, 1] = ps * raw[i, 0] + pc * raw[i, 1] + py
    return x, y, legs, r


# ------------------------------------------------------------------------------------------- helpers
@njit(cache=True)
def kind_group(tab, k):
    """The kind group that fed track k most (reference_tracking.kind_groups): 0 legs, 1 circles, 2 lines, 3 blobs,
    5 a lone leg never paired that is not dynamic."""
    legs = tab[k, VOTES + K_PERSON] + tab[k, VOTES + K_LEG]
    best, arg = legs, 0
    for j in range(1, 4):
        v = tab[k, VOTES + 1 + j]
        if v > best:
            best, arg = v, j
    if arg == 0 and tab[k, VOTES + K_PERSON] == 0 and tab[k, MOBILITY] != MOBILITY_DYNAMIC:
        arg = 5
    return arg


@njit(cache=True)
def to_sensor(x, y, has_pose, pose):
    """A tracking-frame point in the sensor frame of `pose` (itself without a pose)."""
    if not has_pose:
        return x, y
    c, s = np.cos(pose[2]), np.sin(pose[2])
    dx, dy = x - pose[0], y - pose[1]
    return c * dx + s * dy, -s * dx + c * dy


@njit(cache=True)
def leg_probability(mx, my, mkind, mlegs, mprob, raw, has_prob, j):
    """The leg detector's probability of measurement j (tracker._leg_probability): a leg's own, the mean of
    a pair's two (the nearest raw candidates to its legs), the segment's for the rest; 1 for legs when the
    candidates carry no probability."""
    if mkind[j] > K_LEG:
        return mprob[j]
    if not has_prob or len(raw) == 0:
        return 1.0
    pair = mkind[j] == K_PERSON
    ax, ay = (mlegs[j, 0], mlegs[j, 1]) if pair else (mx[j], my[j])
    bx, by = (mlegs[j, 2], mlegs[j, 3]) if pair else (mx[j], my[j])
    ia = ib = 0
    da = db = np.inf
    for i in range(len(raw)):
        d = np.hypot(ax - raw[i, 0], ay - raw[i, 1])
        if d < da:
            da, ia = d, i
        d = np.hypot(bx - raw[i, 0], by - raw[i, 1])
        if d < db:
            db, ib = d, i
    return 0.5 * (raw[ia, 3] + raw[ib, 3])


@njit(cache=True)
def predict(tab, n, dt, prm):
    """Constant-velocity prediction of tracks 0..n-1 dt s ahead, in place (q by kind
    group; reference: tests/reference_tracking.cv_predict)."""
    if dt == 0:
        return
    for k in range(n):
        g = kind_group(tab, k)
        q = prm[P_PERSON_PROCESS_NOISE] if g == 0 or g == 5 else prm[P_PROCESS_NOISE]
        P = tab[k, P0:P0 + 16].reshape((4, 4))
        qa, qb, qc = 0.25 * dt**4 * q, 0.5 * dt**3 * q, dt**2 * q
        tab[k, X] += dt * tab[k, VX]
        tab[k, Y] += dt * tab[k, VY]
        for s in range(4):
            P[0, s] += dt * P[2, s]
            P[1, s] += dt * P[3, s]
        for r in range(4):
            P[r, 0] += dt * P[r, 2]
            P[r, 1] += dt * P[r, 3]
        P[0, 0] += qa
        P[1, 1] += qa
        P[0, 2] += qb
        P[2, 0] += qb
        P[1, 3] += qb
        P[3, 1] += qb
        P[2, 2] += qc
        P[3, 3] += qc


@njit(cache=True)
def kalman_update(tab, k, zx, zy, sigma, scratch):
    """Kalman update of track k with a position measurement (zx, zy) of sigma m, Joseph form
    (reference: tests/reference_tracking.joseph_update); scratch: (3, 4, 4) work space."""
    P = tab[k, P0:P0 + 16].reshape((4, 4))
    I_KH = scratch[0]
    G = scratch[1]
    T = scratch[2]
    v = sigma * sigma
    a, b, c = P[0, 0] + v, P[0, 1], P[1, 1] + v
    det = a * c - b * b
    i00, i01, i11 = c / det, -b / det, a / det
    for r in range(4):
        G[r, 0] = P[r, 0] * i00 + P[r, 1] * i01
        G[r, 1] = P[r, 0] * i01 + P[r, 1] * i11
    dx, dy = zx - tab[k, X], zy - tab[k, Y]
    for r in range(4):
        tab[k, X + r] += G[r, 0] * dx + G[r, 1] * dy
        for s in range(4):
            I_KH[r, s] = (1.0 if r == s else 0.0) - (G[r, s] if s < 2 else 0.0)
    for r in range(4):
        for s in range(4):
            acc = 0.0
            for u in range(4):
                acc += I_KH[r, u] * P[u, s]
            T[r, s] = acc
    for r in range(4):
        for s in range(4):
            acc = 0.0
            for u in range(4):
                acc += T[r, u] * I_KH[s, u]
            P[r, s] = acc + v * (G[r, 0] * G[s, 0] + G[r, 1] * G[s, 1])


@njit(cache=True)
def restart(tab, k, zx, zy, sigma, prm):
    """Track k's filter restarted at (zx, zy): no velocity, position sigma m, speed sigma initial_speed_sigma."""
    tab[k, X], tab[k, Y], tab[k, VX], tab[k, VY] = zx, zy, 0.0, 0.0
    tab[k, P0:P0 + 16] = 0.0
    tab[k, P0 + 0] = tab[k, P0 + 5] = sigma**2
    tab[k, P0 + 10] = tab[k, P0 + 15] = prm[P_INITIAL_SPEED_SIGMA]**2


# -------------------------------------------------------------------------------------------- phases
@njit(cache=True)
def off_background(mx, my, msize, mkind, mlegs, raw, mprob, bg_score, ctx, px, py, prm):
    """The measurements with leg candidates on the background made blobs and the other legs paired again
    (tracker._off_background); the same arrays when none is."""
    if ctx[C_BG_READY] == 0 or len(raw) == 0:
        return mx, my, msize, mkind, mlegs, raw, mprob
    nbg = int(np.sqrt(len(bg_score)) + 0.5)
    bg = _kernels.on_background(bg_score, raw[:, 0].copy(), raw[:, 1].copy(), raw[:, 2].copy(), px, py,
                                ctx[C_BG_X0], ctx[C_BG_Y0], nbg, prm)
    if not bg.any():
        return mx, my, msize, mkind, mlegs, raw, mprob
    keep = raw[~bg]
    lx, ly, ls, kind, legs = _kernels.legs_to_measurements(keep[:, 0].copy(), keep[:, 1].copy(), keep[:, 2].copy(),
                                                           prm)
    n_bg = 0
    for i in range(len(bg)):
        if bg[i]:
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
    m = 0
    for i in range(len(lx)):
        x[m], y[m], size[m], knd[m] = lx[i], ly[i], ls[i], kind[i]
        lg[m] = legs[i]
        m += 1
    for i in range(len(bg)):
        if bg[i]:
            x[m], y[m], size[m], knd[m] = raw[i, 0], raw[i, 1], raw[i, 2], K_BLOB
            m += 1
    for j in range(len(mx)):
        if mkind[j] > K_LEG:
            x[m], y[m], size[m], knd[m], prob[m] = mx[j], my[j], msize[j], mkind[j], mprob[j]
            lg[m] = mlegs[j]
            m += 1
    return x, y, size, knd, lg, keep, prob


@njit(cache=True)
def leggy_tracks(tab, n, prm):
    """The confirmed tracks of legs or people (legs a share >= person_votes of their hits) that may take leg
    candidates first."""
    out = np.empty(n, np.int64)
    q = 0
    for k in range(n):
        legs = tab[k, VOTES + K_PERSON] + tab[k, VOTES + K_LEG]
        total = 0.0
        for j in range(5):
            total += tab[k, VOTES + j]
        if (legs >= prm[P_PERSON_VOTES] * max(total, 1.0) and legs > 0 and tab[k, CLS] <= CLASS_PERSON
                and tab[k, CONFIRMED] != 0):
            out[q] = k
            q += 1
    return out[:q]


@njit(cache=True)
def legs_stage(tab, n, mx, my, msize, mkind, mlegs, raw, mprob, prm):
    """Tracks of legs or people take up to two leg candidates each (tracker._legs). Returns the measurements
    (rebuilt when some track took legs: theirs first) and rows0, the tracks owning the first len(rows0)."""
    none = np.zeros(0, np.int64)
    if n == 0 or len(raw) == 0:
        return mx, my, msize, mkind, mlegs, mprob, none
    leggy = leggy_tracks(tab, n, prm)
    if len(leggy) == 0:
        return mx, my, msize, mkind, mlegs, mprob, none
    tx = np.empty(len(leggy))
    ty = np.empty(len(leggy))
    for q in range(len(leggy)):
        tx[q], ty[q] = tab[leggy[q], X], tab[leggy[q], Y]
    owner, x, y, size, kind, legs = _kernels.leg_stage_measurements(
        tx, ty, raw[:, 0].copy(), raw[:, 1].copy(), raw[:, 2].copy(), mx, my, msize, mkind, mlegs, prm)
    if len(owner) == 0:
        return mx, my, msize, mkind, mlegs, mprob, none
    prob = np.zeros(len(x))
    n_other = 0
    for j in range(len(mx)):
        if mkind[j] > K_LEG:
            n_other += 1
    m = len(x) - n_other
    for j in range(len(mx)):
        if mkind[j] > K_LEG:
            prob[m] = mprob[j]
            m += 1
    return x, y, size, kind, legs, prob, leggy[owner]


@njit(cache=True)
def gated_costs(tab, n, mx, my, mkind, compat, crow, prm):
    """Costs (n, M) d2 + ln det S and which pairs pass the gate, the distance bound and kind compatibility
    (reference_tracking.gated_costs on the table; the cost of a pair that does not pass is inf, not computed)."""
    M = len(mx)
    cost = np.full((n, M), np.inf)
    ok = np.zeros((n, M), np.bool_)
    far = prm[P_MAX_GATE_DISTANCE]
    for k in range(n):
        row = crow[k]
        for j in range(M):
            dx, dy = mx[j] - tab[k, X], my[j] - tab[k, Y]
            if not compat[row, mkind[j]] or abs(dx) > far or abs(dy) > far:   # then hypot(dx, dy) > far too
                continue
            s = prm[P_LEG_MEASUREMENT_NOISE] if mkind[j] == K_LEG else prm[P_MEASUREMENT_NOISE]
            v = s * s
            a, b, c = tab[k, P0] + v, tab[k, P0 + 1], tab[k, P0 + 5] + v
            det = a * c - b * b
            d2 = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det
            ok[k, j] = compat[row, mkind[j]] and d2 <= prm[P_GATE] and np.hypot(dx, dy) <= prm[P_MAX_GATE_DISTANCE]
            # the GNN prices a pair outside the gate INFEASIBLE whatever its cost: its log is not needed
            cost[k, j] = d2 + np.log(det) if ok[k, j] else np.inf
    return cost, ok


@njit(cache=True)
def associate(tab, n, mx, my, mkind, rows0, compat, crow, prm):
    """Tracks rows0 own measurements 0..len(rows0)-1; the others are gated and assigned by GNN. (rows, cols)."""
    n0 = len(rows0)
    cols0 = np.arange(n0)
    if n == 0 or len(mx) == n0:
        return rows0, cols0
    cost, ok = gated_costs(tab, n, mx, my, mkind, compat, crow, prm)
    if n0:
        for q in range(n0):
            ok[rows0[q], :] = False
        ok[:, :n0] = False
    r, c = _assign.gnn(cost, ok)
    return np.concatenate((rows0, r)), np.concatenate((cols0, c))


@njit(cache=True)
def hit_background(tab, n, rows, cols, mx, my, msize, mkind, bg_score, ctx, px, py, prm):
    """Mark (column ON_BG) the tracks that take (rows, cols) a measurement on the background this scan: their
    motion does not count (tracker._hit_background)."""
    for k in range(n):
        tab[k, ON_BG] = 0.0
    if ctx[C_BG_READY] == 0:
        return
    nbg = int(np.sqrt(len(bg_score)) + 0.5)
    on_bg = _kernels.tracks_on_background(bg_score, mx, my, msize, mkind, rows, cols, n, px, py, ctx[C_BG_X0],
                                          ctx[C_BG_Y0], nbg, prm)
    for k in range(n):
        tab[k, ON_BG] = 1.0 if on_bg[k] else 0.0


@njit(cache=True)
def update(tab, n, rows, cols, mx, my, mkind, msize, mlegs, prm):
    """Kalman-update tracks rows with measurements cols and record the hits (reference_tracking.apply_updates)."""
    for k in range(n):
        tab[k, HIT] = 0.0
    scratch = np.empty((3, 4, 4))
    for q in range(len(rows)):
        k, j = rows[q], cols[q]
        moving = tab[k, MOVING_TIME] >= prm[P_WALKING_AFTER]
        kalman_update(tab, k, mx[j], my[j], prm[P_LEG_MEASUREMENT_NOISE] if mkind[j] == K_LEG
                      else prm[P_MEASUREMENT_NOISE], scratch)
        tab[k, LAST_X], tab[k, LAST_Y] = tab[k, X], tab[k, Y]
        tab[k, HIT] = 1.0
        tab[k, VOTES + mkind[j]] += 1
        tab[k, SIZE] = max(tab[k, SIZE], msize[j])
        if mkind[j] == K_PERSON and moving:
            vx, vy = tab[k, VX], tab[k, VY]
            speed = np.hypot(vx, vy)
            if speed > prm[P_MOVING_SPEED]:
                ux, uy = vx / speed, vy / speed
                dx, dy = mlegs[j, 0] - mlegs[j, 2], mlegs[j, 1] - mlegs[j, 3]
                along = dx * ux + dy * uy
                lead = along if (ux * dy - uy * dx) > 0 else -along   # left leg minus right leg
                if abs(lead) <= prm[P_STEP_MAX]:
                    if lead > prm[P_STEP_MIN]:
                        tab[k, LEAD_LEFT] = 1.0
                    elif lead < -prm[P_STEP_MIN]:
                        tab[k, LEAD_RIGHT] = 1.0


@njit(cache=True)
def reacquire(tab, n, rows, cols, mx, my, mkind, stamp, reacq, crow, prm):
    """Confirmed tracks lost while occluded take the nearest free measurement they could have reached since
    their last hit, their filter restarted there (tracker._reacquire). Returns (rows2, cols2)."""
    none = np.zeros(0, np.int64)
    M = len(mx)
    nl = 0
    lost = np.empty(n, np.int64)
    for k in range(n):
        if tab[k, HIT] == 0 and tab[k, CONFIRMED] != 0 and tab[k, OCCLUDED] != 0:
            lost[nl] = k
            nl += 1
    if nl == 0 or M == 0:
        return none, none
    lost = lost[:nl]
    free = np.empty(M, np.bool_)
    for j in range(M):
        free[j] = mkind[j] != K_LEG
    tentative = np.zeros(M, np.bool_)
    for q in range(len(cols)):
        free[cols[q]] = False
        if tab[rows[q], CONFIRMED] == 0:
            tentative[cols[q]] = True
    cand = np.empty(M, np.int64)
    nc = 0
    for j in range(M):
        near = False
        for k in range(n):
            if (tab[k, HIT] != 0 and tab[k, CONFIRMED] != 0
                    and np.hypot(mx[j] - tab[k, X], my[j] - tab[k, Y]) <= prm[P_LEG_BESIDE]):
                near = True
                break
        free[j] = free[j] and not near
        if free[j] or (tentative[j] and not near):
            cand[nc] = j
            nc += 1
    if nc == 0:
        return none, none
    cand = cand[:nc]
    dist = np.empty((nl, nc))
    ok = np.empty((nl, nc), np.bool_)
    for a in range(nl):
        k = lost[a]
        reach = min(prm[P_REACQUIRE_SPEED] * (stamp - np.int64(tab[k, LAST_HIT])) * 1e-9 + prm[P_MAX_GATE_DISTANCE],
                    prm[P_REACQUIRE_DISTANCE])
        for b in range(nc):
            j = cand[b]
            dist[a, b] = np.hypot(mx[j] - tab[k, LAST_X], my[j] - tab[k, LAST_Y])
            ok[a, b] = (dist[a, b] <= reach and reacq[crow[k], mkind[j]]
                        and (free[j] or tab[k, MOBILITY] == MOBILITY_DYNAMIC))
    r, c = _assign.gnn(dist, ok)
    rows2 = np.empty(len(r), np.int64)
    cols2 = np.empty(len(r), np.int64)
    for q in range(len(r)):
        k, j = lost[r[q]], cand[c[q]]
        rows2[q], cols2[q] = k, j
        sigma = prm[P_LEG_MEASUREMENT_NOISE] if mkind[j] == K_LEG else prm[P_MEASUREMENT_NOISE]
        restart(tab, k, mx[j], my[j], sigma, prm)
        tab[k, LAST_X], tab[k, LAST_Y] = tab[k, X], tab[k, Y]
        tab[k, HIT] = 1.0
        tab[k, VOTES + mkind[j]] += 1
    return rows2, cols2


@njit(cache=True)
def merge_reacquired(rows, cols, rows2, cols2):
    """The association with the reacquisitions (rows2, cols2) in: pairs whose measurement a lost track took
    back leave it, and their tracks (tentative, started on it) are superseded. (rows, cols, superseded)."""
    if len(rows2) == 0:
        return rows, cols, np.zeros(0, np.int64)
    keep = np.ones(len(cols), np.bool_)
    for q in range(len(cols)):
        for b in range(len(cols2)):
            if cols[q] == cols2[b]:
                keep[q] = False
    return np.concatenate((rows[keep], rows2)), np.concatenate((cols[keep], cols2)), rows[~keep]


@njit(cache=True)
def leg_evidence(tab, rows, cols, mx, my, mkind, mlegs, mprob, raw, has_prob, prm):
    """Fold the leg probability of each hit (rows took cols) into the tracks' running mean LEG_SCORE."""
    a = prm[P_LEG_EVIDENCE_RATE]
    for q in range(len(rows)):
        k = rows[q]
        tab[k, LEG_SCORE] = (1.0 - a) * tab[k, LEG_SCORE] + a * leg_probability(mx, my, mkind, mlegs, mprob, raw,
                                                                               has_prob, cols[q])


@njit(cache=True)
def occlusion(tab, n, ranges, has_ranges, geo, has_pose, pose, prm):
    """Mark each missed track occluded when a nearer return covers its bearing or it is out of view
    (tracker._occlusion; geo: angle_min, increment, range_max, has geometry)."""
    all_hit = True
    for k in range(n):
        tab[k, OCCLUDED] = 0.0
        if tab[k, HIT] == 0:
            all_hit = False
    if not has_ranges or geo[3] == 0 or all_hit:
        return
    sx = np.empty(n)
    sy = np.empty(n)
    size = np.empty(n)
    missed = np.empty(n, np.bool_)
    for k in range(n):
        sx[k], sy[k] = to_sensor(tab[k, X], tab[k, Y], has_pose, pose)
        size[k] = tab[k, SIZE]
        missed[k] = tab[k, HIT] == 0
    occ = _kernels.occlusion(sx, sy, size, missed, ranges, geo[0], geo[1], geo[2], prm)
    for k in range(n):
        tab[k, OCCLUDED] = 1.0 if occ[k] else 0.0


@njit(cache=True)
def duplicates(tab, n, prm):
    """Tracks of legs or people within merge_distance of a higher-ranked such track, unless both are
    confirmed and move differently (tracker._duplicates)."""
    x, y, vx, vy = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    candidate = np.empty(n, np.bool_)
    confirmed = np.empty(n, np.bool_)
    rank = np.empty(n, np.int64)
    for k in range(n):
        x[k], y[k], vx[k], vy[k] = tab[k, X], tab[k, Y], tab[k, VX], tab[k, VY]
        legs = tab[k, VOTES + K_PERSON] + tab[k, VOTES + K_LEG]
        candidate[k] = legs > 0 and tab[k, CLS] <= CLASS_PERSON
        confirmed[k] = tab[k, CONFIRMED] != 0
        rank[k] = (np.int64(tab[k, HITS]) * 2 + np.int64(tab[k, CONFIRMED])
                   + (np.int64(1) << 40 if tab[k, MOBILITY] == MOBILITY_DYNAMIC else 0)
                   + (np.int64(1) << 41 if tab[k, CLS] == CLASS_PERSON else 0))
    return _kernels.duplicates(x, y, vx, vy, candidate, confirmed, rank, prm)


@njit(cache=True)
def life_cycle(tab, n, stamp, superseded, prm):
    """Count the scan for every track, confirm, and delete the tracks past their timeout, the duplicates and
    the `superseded` ones, keeping the others' order. Returns the new number of tracks."""
    mask = (1 << int(prm[P_CONFIRM_WINDOW])) - 1
    dead = np.zeros(n, np.bool_)
    for k in range(n):
        tab[k, AGE] += 1
        hit = tab[k, HIT] != 0
        if hit:
            tab[k, HITS] += 1
            tab[k, MISSES] = 0.0
            tab[k, LAST_HIT] = stamp
        else:
            tab[k, MISSES] += 1
        h = ((np.int64(tab[k, HISTORY]) << 1) | (1 if hit else 0)) & mask
        tab[k, HISTORY] = h
        count = 0
        while h:
            count += h & 1
            h >>= 1
        if count >= prm[P_CONFIRM_HITS]:
            tab[k, CONFIRMED] = 1.0
        since = (stamp - np.int64(tab[k, LAST_HIT])) * 1e-9
        if tab[k, CONFIRMED] != 0:
            limit = prm[P_DELETE_AFTER_OCCLUDED] if tab[k, OCCLUDED] != 0 else prm[P_DELETE_AFTER]
        else:
            limit = prm[P_TENTATIVE_DELETE_AFTER]
        dead[k] = since > limit + 1e-9
    dead |= duplicates(tab, n, prm)
    for q in range(len(superseded)):
        dead[superseded[q]] = True
    keep = 0
    for k in range(n):
        if not dead[k]:
            if keep != k:
                tab[keep, :] = tab[k, :]
            keep += 1
    return keep


@njit(cache=True)
def spawn(tab, n, cols, mx, my, msize, mkind, mlegs, mprob, raw, has_prob, stamp, has_pose, pose, px, py, ctx,
          prm):
    """Start tentative tracks on measurements no track took, except legs beside a track that took a leg and
    measurements on top of a track (tracker._spawn). Returns the table (grown when full) and its row count."""
    M = len(mx)
    free = np.ones(M, np.bool_)
    for q in range(len(cols)):
        free[cols[q]] = False
    new = np.empty(M, np.int64)
    nn = 0
    for j in range(M):
        if not free[j]:
            continue
        small = mkind[j] == K_LEG or mkind[j] == K_BLOB
        blocked = False
        for k in range(n):
            d = np.hypot(mx[j] - tab[k, X], my[j] - tab[k, Y])
            legged = tab[k, HIT] != 0 and (tab[k, VOTES + K_PERSON] + tab[k, VOTES + K_LEG]) > 0
            if (small and legged and d <= prm[P_LEG_BESIDE]) or d <= prm[P_SPAWN_CLEARANCE]:
                blocked = True
                break
        if not blocked:
            new[nn] = j
            nn += 1
    if nn == 0:
        return tab, n
    if n + nn > len(tab):
        grown = np.zeros((max(2 * len(tab), n + nn), tab.shape[1]))
        grown[:n] = tab[:n]
        tab = grown
    for q in range(nn):
        j = new[q]
        k = n + q
        tab[k, :] = 0.0
        tab[k, ID] = ctx[C_NEXT_ID] + q
        sigma = prm[P_LEG_MEASUREMENT_NOISE] if mkind[j] == K_LEG else prm[P_MEASUREMENT_NOISE]
        restart(tab, k, mx[j], my[j], sigma, prm)
        tab[k, BORN] = tab[k, LAST_HIT] = stamp
        tab[k, AGE] = tab[k, HITS] = tab[k, HISTORY] = 1.0
        tab[k, VOTES + mkind[j]] = 1.0
        tab[k, SIZE] = msize[j]
        tab[k, FIRST_X], tab[k, FIRST_Y] = tab[k, X], tab[k, Y]
        tab[k, LAST_X], tab[k, LAST_Y] = tab[k, X], tab[k, Y]
        tab[k, HIT] = 1.0
        tab[k, MOBILITY] = 2.0
        tab[k, LEG_SCORE] = leg_probability(mx, my, mkind, mlegs, mprob, raw, has_prob, j)
        tab[k, SENSOR_REF_X], tab[k, SENSOR_REF_Y] = to_sensor(tab[k, X], tab[k, Y], has_pose, pose)
        tab[k, POSE_FIRST_X], tab[k, POSE_FIRST_Y] = px, py
    ctx[C_NEXT_ID] += nn
    return tab, n + nn


@njit(cache=True)
def classify(tab, n, dt, stamp, learned, has_pose, pose, px, py, prm):
    """Class and mobility of every track (references: tests/reference_tracking's ReferenceTracker._classify
    and classify_tracks; with the leg detector, a person is what its evidence says and the scanner does not carry)."""
    for k in range(n):
        speed = np.hypot(tab[k, VX], tab[k, VY])
        if tab[k, HIT] != 0 and tab[k, ON_BG] == 0 and speed > prm[P_MOVING_SPEED]:
            tab[k, MOVING_TIME] = tab[k, MOVING_TIME] + dt
        else:
            tab[k, MOVING_TIME] = 0.0
        if not tab[k, MOVING_TIME] >= prm[P_MOVING_TIME]:
            speed = 0.0
        moved = np.hypot(tab[k, X] - tab[k, FIRST_X], tab[k, Y] - tab[k, FIRST_Y])
        age_s = (stamp - np.int64(tab[k, BORN])) * 1e-9
        confirmed = tab[k, CONFIRMED] != 0
        dynamic = tab[k, MOBILITY] == MOBILITY_DYNAMIC or (confirmed and moved > prm[P_MOVING_DISTANCE]
                                                  and speed > prm[P_MOVING_SPEED])
        if dynamic:
            mob = 1
        elif tab[k, SIZE] > prm[P_D_MAX] or age_s >= prm[P_UNDEFINED_WINDOW]:
            mob = 0
        else:
            mob = 2
        person, leg = tab[k, VOTES + K_PERSON], tab[k, VOTES + K_LEG]
        circle, rect, blob = tab[k, VOTES + K_CIRCLE], tab[k, VOTES + K_RECT], tab[k, VOTES + K_BLOB]
        total = person + leg + circle + rect + blob
        walking = tab[k, LEAD_LEFT] != 0 and tab[k, LEAD_RIGHT] != 0
        if person + leg >= prm[P_PERSON_VOTES] * max(total, 1.0):
            if walking and person > 0:
                cls = CLASS_PERSON
            elif person == 0 and not dynamic:
                cls = CLASS_CIRCLE_OBJECT
            else:
                cls = CLASS_UNKNOWN
        elif circle + rect + blob == 0:
            cls = CLASS_UNKNOWN
        elif circle >= rect and circle >= blob:
            cls = CLASS_CIRCLE_OBJECT
        elif rect >= blob:
            cls = CLASS_RECTANGULAR_OBJECT
        else:
            cls = CLASS_UNKNOWN
        tab[k, MOBILITY] = mob
        if learned:
            if circle + rect + blob == 0:
                cls = CLASS_UNKNOWN
            elif circle >= rect and circle >= blob:
                cls = CLASS_CIRCLE_OBJECT
            elif rect >= blob:
                cls = CLASS_RECTANGULAR_OBJECT
            else:
                cls = CLASS_UNKNOWN
            sx, sy = to_sensor(tab[k, X], tab[k, Y], has_pose, pose)
            a = prm[P_LEG_EVIDENCE_RATE] if tab[k, HIT] != 0 else 0.0
            dev = np.hypot(sx - tab[k, SENSOR_REF_X], sy - tab[k, SENSOR_REF_Y])
            tab[k, SENSOR_DEV] = (1.0 - a) * tab[k, SENSOR_DEV] + a * dev
            tab[k, SENSOR_REF_X] = (1.0 - a) * tab[k, SENSOR_REF_X] + a * sx
            tab[k, SENSOR_REF_Y] = (1.0 - a) * tab[k, SENSOR_REF_Y] + a * sy
            travel = np.hypot(px - tab[k, POSE_FIRST_X], py - tab[k, POSE_FIRST_Y])
            carried = travel >= prm[P_CARRIED_TRAVEL] and tab[k, SENSOR_DEV] <= prm[P_CARRIED_RADIUS]
            dyn = mob == MOBILITY_DYNAMIC
            need = prm[P_MOVING_PERSON_EVIDENCE] if dyn else prm[P_PERSON_EVIDENCE]
            pairs = prm[P_MOVING_PERSON_PAIRS] if dyn else prm[P_PERSON_PAIRS]
            if tab[k, LEG_SCORE] >= need and person >= pairs and not carried:
                cls = CLASS_PERSON
        tab[k, CLS] = cls


@njit(cache=True)
def push_tail(tab, n, prm):
    """Append every track's position to its tail (ring buffer of tail_length points)."""
    T = int(prm[P_TAIL_LENGTH])
    for k in range(n):
        i = int(tab[k, TAIL_COUNT]) % T
        tab[k, TAIL + 2 * i], tab[k, TAIL + 2 * i + 1] = tab[k, X], tab[k, Y]
        tab[k, TAIL_COUNT] += 1


@njit(cache=True)
def background_update(score, mark, active, cache, n_active, scan, ranges, cos_a, sin_a, angle_min, increment,
                      range_min, range_max, px, py, pc, ps, dt, x0, y0, cell, n, margin, settled, fresh):
    """reference_tracking.background_update with each active cell's range and beam kept beside it (cache[a] = r, beam
    for active[a], beam -2: not yet computed), valid while the sensor pose does not change (`fresh`: it
    changed, compute them all again). The same arithmetic on the same numbers: the same grid. An inactive
    cell's mark is 0 here, not -1 (scans count from 1), so a new grid is all zeros (no 5 MB to fill)."""
    B = len(ranges)
    keep = 0
    for a in range(n_active):
        c = active[a]
        r, jf = cache[a, 0], cache[a, 1]
        if score[c] >= settled and (c + scan) % 4 != 0:
            active[keep] = c
            cache[keep, 0], cache[keep, 1] = r, -2.0 if fresh else jf   # not tested: computed when it is
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
        i = int(np.floor((pc * sx - ps * sy + px - x0) / cell))
        k = int(np.floor((ps * sx + pc * sy + py - y0) / cell))
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
def background(bg_score, bg_mark, bg_active, bg_cache, ctx, ranges, has_ranges, cos_a, sin_a, geo, px, py, pc, ps,
               dt, prm):
    """Add the scan's returns to the background grid (tracker._background; geo: angle_min, increment,
    range_max, has geometry, range_min)."""
    if (not has_ranges or geo[3] == 0 or prm[P_BACKGROUND_TIME] <= 0 or len(ranges) != len(cos_a)
            or len(bg_score) == 0):
        return
    if ctx[C_BG_READY] == 0:
        ctx[C_BG_READY] = 1.0
        ctx[C_BG_X0] = px - prm[P_BACKGROUND_EXTENT]
        ctx[C_BG_Y0] = py - prm[P_BACKGROUND_EXTENT]
        lo = geo[4] if np.isfinite(geo[4]) else 0.0
        ctx[C_BG_LO] = lo
        ctx[C_BG_HI] = geo[2] if np.isfinite(geo[2]) and geo[2] > lo else np.inf
    ctx[C_BG_SCAN] += 1
    fresh = not (ctx[C_BG_CACHED] != 0 and ctx[C_BG_PX] == px and ctx[C_BG_PY] == py and ctx[C_BG_PC] == pc
                 and ctx[C_BG_PS] == ps)
    ctx[C_BG_CACHED], ctx[C_BG_PX], ctx[C_BG_PY], ctx[C_BG_PC], ctx[C_BG_PS] = 1.0, px, py, pc, ps
    nbg = int(np.sqrt(len(bg_score)) + 0.5)
    ctx[C_BG_COUNT] = background_update(
        bg_score, bg_mark, bg_active, bg_cache, int(ctx[C_BG_COUNT]), int(ctx[C_BG_SCAN]), ranges, cos_a, sin_a,
        geo[0], geo[1], ctx[C_BG_LO], ctx[C_BG_HI], px, py, pc, ps, max(dt, 0.0), ctx[C_BG_X0], ctx[C_BG_Y0],
        prm[P_BACKGROUND_CELL], nbg, prm[P_OCCLUSION_MARGIN], 4.0 * prm[P_BACKGROUND_TIME], fresh)


@njit(cache=True)
def write_tracks(out, o, tab, n, has_pose, pose):
    """Track elements of tracks 0..n-1 into out[o:o + n] (tracker.output). Fields by r["name"], which numba
    compiles as r.name and plain Python (NUMBA_DISABLE_JIT=1) understands on a numpy record."""
    c, s = (np.cos(pose[2]), np.sin(pose[2])) if has_pose else (1.0, 0.0)
    for k in range(n):
        r = out[o + k]
        r["id"] = np.uint32(tab[k, ID])
        r["age"] = np.uint32(tab[k, AGE])
        r["hits"] = np.uint32(tab[k, HITS])
        r["misses"] = np.uint32(tab[k, MISSES])
        sx, sy = to_sensor(tab[k, X], tab[k, Y], has_pose, pose)
        r["x"], r["y"] = sx, sy
        if has_pose:
            r["vx"] = c * tab[k, VX] + s * tab[k, VY]
            r["vy"] = -s * tab[k, VX] + c * tab[k, VY]
            r["world_x"], r["world_y"], r["world_vx"], r["world_vy"] = tab[k, X], tab[k, Y], tab[k, VX], tab[k, VY]
        else:
            r["vx"], r["vy"] = tab[k, VX], tab[k, VY]
            r["world_x"] = r["world_y"] = r["world_vx"] = r["world_vy"] = np.nan
        for i in range(16):
            r["covariance"][i] = tab[k, P0 + i]
        r["size"] = tab[k, SIZE]
        r["classification"] = np.uint8(tab[k, CLS])
        r["mobility"] = np.uint8(tab[k, MOBILITY])
        confirmed, hit = tab[k, CONFIRMED] != 0, tab[k, HIT] != 0
        r["status"] = np.uint8((1 if hit else 2) if confirmed else 0)
        r["occluded"] = np.uint8(tab[k, OCCLUDED])


# -------------------------------------------------------------------------------------------- the step
@njit(cache=True)
def track_scan(tab, ctx, prm, stamp, mx, my, msize, mkind, mlegs, raw, mprob, has_prob, ranges, has_ranges,
               has_pose, pose, geo, cos_a, sin_a, bg_score, bg_mark, bg_active, bg_cache, learned, compat, reacq):
    """One scan (measurements in the sensor frame, stamp in ns since the first scan) through every phase;
    returns the table (a new one when it grew). ctx[C_N_TRACKS] holds the number of live tracks."""
    n = int(ctx[C_N_TRACKS])
    dt = max((stamp - np.int64(ctx[C_STAMP])) * 1e-9, 0.0) if ctx[C_HAS_STAMP] != 0 else 0.0
    ctx[C_HAS_STAMP], ctx[C_STAMP] = 1.0, stamp
    if has_pose:
        px, py, pc, ps = pose[0], pose[1], np.cos(pose[2]), np.sin(pose[2])
        mx, my, mlegs, raw = moved(mx, my, mlegs, raw, px, py, pc, ps)
    else:
        px, py, pc, ps = 0.0, 0.0, 1.0, 0.0
    crow = np.empty(n, np.int64)
    for k in range(n):
        crow[k] = kind_group(tab, k) if tab[k, CONFIRMED] != 0 else ANY_ROW
    predict(tab, n, dt, prm)
    mx, my, msize, mkind, mlegs, raw, mprob = off_background(mx, my, msize, mkind, mlegs, raw, mprob, bg_score, ctx,
                                                             px, py, prm)
    mx, my, msize, mkind, mlegs, mprob, rows0 = legs_stage(tab, n, mx, my, msize, mkind, mlegs, raw, mprob, prm)
    rows, cols = associate(tab, n, mx, my, mkind, rows0, compat, crow, prm)
    hit_background(tab, n, rows, cols, mx, my, msize, mkind, bg_score, ctx, px, py, prm)
    update(tab, n, rows, cols, mx, my, mkind, msize, mlegs, prm)
    rows2, cols2 = reacquire(tab, n, rows, cols, mx, my, mkind, stamp, reacq, crow, prm)
    rows, cols, superseded = merge_reacquired(rows, cols, rows2, cols2)
    leg_evidence(tab, rows, cols, mx, my, mkind, mlegs, mprob, raw, has_prob, prm)
    occlusion(tab, n, ranges, has_ranges, geo, has_pose, pose, prm)
    n = life_cycle(tab, n, stamp, superseded, prm)
    tab, n = spawn(tab, n, cols, mx, my, msize, mkind, mlegs, mprob, raw, has_prob, stamp, has_pose, pose, px, py,
                   ctx, prm)
    classify(tab, n, dt, stamp, learned, has_pose, pose, px, py, prm)
    push_tail(tab, n, prm)
    background(bg_score, bg_mark, bg_active, bg_cache, ctx, ranges, has_ranges, cos_a, sin_a, geo, px, py, pc, ps, dt,
               prm)
    ctx[C_N_TRACKS] = n
    return tab


@njit(cache=True)
def step_measurements(tab, ctx, prm, stamp, mx, my, msize, mkind, mlegs, raw, mprob, has_prob, ranges, has_ranges,
                      has_pose, pose, geo, cos_a, sin_a, bg_score, bg_mark, bg_active, bg_cache, learned, compat, reacq,
                      out):
    """track_scan on one scan's measurements, then its live tracks as Track elements in `out` (a new, larger
    array when it is too small). Returns (table, out)."""
    tab = track_scan(tab, ctx, prm, stamp, mx, my, msize, mkind, mlegs, raw, mprob, has_prob, ranges, has_ranges,
                     has_pose, pose, geo, cos_a, sin_a, bg_score, bg_mark, bg_active, bg_cache, learned, compat, reacq)
    n = int(ctx[C_N_TRACKS])
    if n > len(out):
        out = np.empty(2 * n, out.dtype)
    write_tracks(out, 0, tab, n, has_pose, pose)
    return tab, out


@njit(cache=True)
def track_block(tab, ctx, prm, stamps, circles, blobs, lines, legs, learned, ranges, has_ranges, poses,
                has_pose, geo, cos_a, sin_a, bg_score, bg_mark, bg_active, bg_cache, compat, reacq, out, tails,
                out_tail, out_tail_count, offsets):
    """Track scans 0..len(stamps)-1 of a block of features (flat per kind, with per-scan offsets) in one call.

    circles: (offsets, first, last, x, y, radius); blobs: (offsets, first, last, x, y, size, kind); lines:
    (offsets, segment, first, last, x_ini, y_ini, x_end, y_end); legs: (offsets, first, last, x, y, width,
    probability); sensor frame, m; beam indices inclusive. ranges (N, B) float32 m; poses (N, 3). Writes the
    live tracks of scan i to out[offsets[i]:offsets[i + 1]] and, when `tails`, their tails (tracking frame) to
    out_tail and tail counts to out_tail_count (each grown when full). Returns (table, out, out_tail,
    out_tail_count)."""
    T = int(prm[P_TAIL_LENGTH])
    co, cf, cl, cx, cy, cr = circles
    bo, bf, bl, bx, by, bs, bk = blobs
    lo, ls, lf, ll, lx0, ly0, lx1, ly1 = lines
    go, gf, gl, gx, gy, gw, gp = legs
    offsets[0] = 0
    for i in range(len(stamps)):
        a0, a1, b0, b1, l0, l1, g0, g1 = co[i], co[i + 1], bo[i], bo[i + 1], lo[i], lo[i + 1], go[i], go[i + 1]
        if learned:
            mx, my, msize, mkind, mlegs, raw, mprob = learned_measurements(
                cf[a0:a1], cl[a0:a1], cx[a0:a1], cy[a0:a1], cr[a0:a1], bf[b0:b1], bl[b0:b1], bx[b0:b1], by[b0:b1],
                bs[b0:b1], ls[l0:l1], lf[l0:l1], ll[l0:l1], lx0[l0:l1], ly0[l0:l1], lx1[l0:l1], ly1[l0:l1],
                gf[g0:g1], gl[g0:g1], gx[g0:g1], gy[g0:g1], gw[g0:g1], gp[g0:g1], prm)
        else:
            mx, my, msize, mkind, mlegs, raw, mprob = paper_measurements(
                cx[a0:a1], cy[a0:a1], cr[a0:a1], bx[b0:b1], by[b0:b1], bs[b0:b1], bk[b0:b1], ls[l0:l1], lx0[l0:l1],
                ly0[l0:l1], lx1[l0:l1], ly1[l0:l1], prm)
        tab = track_scan(tab, ctx, prm, stamps[i], mx, my, msize, mkind, mlegs, raw, mprob, learned, ranges[i],
                         has_ranges, has_pose, poses[i], geo, cos_a, sin_a, bg_score, bg_mark, bg_active, bg_cache,
                         learned, compat, reacq)
        n = int(ctx[C_N_TRACKS])
        o = offsets[i]
        if o + n > len(out):
            size = max(2 * len(out), o + n)
            grown = np.empty(size, out.dtype)
            grown[:o] = out[:o]
            out = grown
            if tails:
                gt = np.empty((size, T, 2))
                gt[:o] = out_tail[:o]
                out_tail = gt
                gc = np.empty(size, np.int64)
                gc[:o] = out_tail_count[:o]
                out_tail_count = gc
        write_tracks(out, o, tab, n, has_pose, poses[i])
        if tails:
            for k in range(n):
                for t in range(T):
                    out_tail[o + k, t, 0] = tab[k, TAIL + 2 * t]
                    out_tail[o + k, t, 1] = tab[k, TAIL + 2 * t + 1]
                out_tail_count[o + k] = np.int64(tab[k, TAIL_COUNT])
        offsets[i + 1] = o + n
    return tab, out, out_tail, out_tail_count
