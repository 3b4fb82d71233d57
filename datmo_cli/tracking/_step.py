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
from ..numba_runtime import key_kernel_cache_on_sources
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
    C_CARRY_POSED,
    C_CARRY_PX,
    C_CARRY_PY,
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
    IS_PERSON,
    LAST_HIT,
    LAST_X,
    LAST_Y,
    LEAD_LEFT,
    LEAD_RIGHT,
    LEG_HITS,
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
    P_LEG_RADIUS_MAX,
    P_LEG_REACH,
    P_LEG_THRESHOLD,
    P_MAX_GATE_DISTANCE,
    P_MEASUREMENT_NOISE,
    P_MOVING_DISTANCE,
    P_MOVING_SPEED,
    P_MOVING_TIME,
    P_OCCLUSION_MARGIN,
    P_PERSON_COAST,
    P_PERSON_EVIDENCE,
    P_PERSON_MAINTAIN,
    P_PERSON_PAIRS,
    P_PERSON_PROCESS_NOISE,
    P_PERSON_RADIUS,
    P_PERSON_VOTES,
    P_PROCESS_NOISE,
    P_REACQUIRE_DISTANCE,
    P_REACQUIRE_SPEED,
    P_SPAWN_CLEARANCE,
    P_STEP_MAX,
    P_STEP_MIN,
    P_STILL_TIME,
    P_TAIL_LENGTH,
    P_TENTATIVE_DELETE_AFTER,
    P_UNDEFINED_WINDOW,
    P_WALKING_AFTER,
    SIZE,
    STILL_TIME,
    TAIL,
    TAIL_COUNT,
    VOTES,
    VX,
    VY,
    X,
    Y,
)

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

K_PERSON, K_LEG, K_CIRCLE, K_RECT, K_BLOB = 0, 1, 2, 3, 4
# the raw leg candidates of a scan, (L, RAW_COLS): x, y (m), width (m), leg probability (0 without a detector),
# cover: -1 for a strong candidate (a leg), else the index of the measurement made of the weaker candidate's beams
R_X, R_Y, R_W, R_P, R_COVER = 0, 1, 2, 3, 4
RAW_COLS = 5
# the leg probability of a leg candidate found on the background or carried: a candidate (its hit moves a track's
# evidence), and not a leg
NOT_A_LEG = 1e-6
ANY_ROW = 4  # the compatibility row of tentative tracks (tracker._COMPAT)


# ------------------------------------------------------------------------------------- measurements
@njit(cache=True)
def paper_measurements(cx, cy, cr, bx, by, bsize, bkind, lseg, lx0, ly0, lx1, ly1, prm):
    """One scan's measurements by the paper's rule (reference: tests/reference_tracking.reference_measurements,
    learned=False), sensor frame: x, y, size, kind, legs (M, 4), raw leg candidates (L, RAW_COLS: x, y, size, 0,
    -1), prob (M,: zeros)."""
    x, y, size, kind, legs, lx, ly, ls = _kernels.measurements(
        cx, cy, cr, bx, by, bsize, bkind, lseg, lx0, ly0, lx1, ly1, prm
    )
    raw = np.zeros((len(lx), RAW_COLS))
    for i in range(len(lx)):
        raw[i, R_X], raw[i, R_Y], raw[i, R_W], raw[i, R_COVER] = lx[i], ly[i], ls[i], -1.0
    return x, y, size, kind, legs, raw, np.zeros(len(x))


@njit(cache=True)
def learned_measurements(
    cfirst,
    clast,
    cx,
    cy,
    cr,
    bfirst,
    blast,
    bx,
    by,
    bsize,
    lseg,
    lfirst,
    llast,
    lx0,
    ly0,
    lx1,
    ly1,
    gfirst,
    glast,
    gx,
    gy,
    gw,
    gp,
    prm,
):
    """One scan's measurements with a leg detector's legs (reference_measurements, learned=True): the candidates
    of probability >= the leg threshold (P_LEG_THRESHOLD, the model's) not on the beams of a circle wider than
    leg_radius_max are legs (strong); the others (weak) are measured as what covers their beams, which takes their
    probability. Returns x, y, size, kind, legs, raw (L, RAW_COLS: every candidate, strong ones first, each with
    its probability and, for a weak one, the measurement covering it), prob. The thresholds compare in float32,
    as numpy compares the features' float32 fields with a Python float."""
    thr = np.float32(prm[P_LEG_THRESHOLD])
    rmax = np.float32(prm[P_LEG_RADIUS_MAX])
    strong = np.empty(len(gx), np.bool_)
    for i in range(len(gx)):
        s = np.float32(gp[i]) >= thr
        for q in range(len(cx)):
            if np.float32(cr[q]) > rmax and not (glast[i] < cfirst[q] or gfirst[i] > clast[q]):
                s = False
        strong[i] = s
    weak = ~strong
    x, y, size, kind, legs, prob, cover = _kernels.learned_measurements(
        cfirst,
        clast,
        cx,
        cy,
        cr,
        bfirst,
        blast,
        bx,
        by,
        bsize,
        lseg,
        lfirst,
        llast,
        lx0,
        ly0,
        lx1,
        ly1,
        gfirst[strong],
        glast[strong],
        gx[strong],
        gy[strong],
        gw[strong],
        gfirst[weak],
        glast[weak],
        gp[weak],
        prm,
    )
    raw = np.empty((len(gx), RAW_COLS))
    q = 0
    for i in range(len(gx)):
        if strong[i]:
            raw[q, R_X], raw[q, R_Y], raw[q, R_W], raw[q, R_P], raw[q, R_COVER] = gx[i], gy[i], gw[i], gp[i], -1.0
            q += 1
    w = 0
    for i in range(len(gx)):
        if not strong[i]:
            raw[q, R_X], raw[q, R_Y], raw[q, R_W], raw[q, R_P], raw[q, R_COVER] = gx[i], gy[i], gw[i], gp[i], cover[w]
            q += 1
            w += 1
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
    5 a lone leg never paired that is not dynamic; a person is 0 whatever fed it."""
    if tab[k, IS_PERSON] != 0:
        return 0
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
def sure_person(tab, k, prm):
    """Whether track k is a person: its returns are its own, never background, and a candidate near it is its
    leg even on the background (a person standing still, whose evidence may dip at range, is not swallowed)."""
    return tab[k, IS_PERSON] != 0


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
        P = tab[k, P0 : P0 + 16].reshape((4, 4))
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
    P = tab[k, P0 : P0 + 16].reshape((4, 4))
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
    tab[k, P0 : P0 + 16] = 0.0
    tab[k, P0 + 0] = tab[k, P0 + 5] = sigma**2
    tab[k, P0 + 10] = tab[k, P0 + 15] = prm[P_INITIAL_SPEED_SIGMA] ** 2


# -------------------------------------------------------------------------------------------- phases
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
def off_background(
    tab,
    n,
    mx,
    my,
    msize,
    mkind,
    mlegs,
    raw,
    mprob,
    bg_score,
    ctx,
    px,
    py,
    ranges,
    carry_ref,
    carry_seen,
    carry_away,
    has_pose,
    pose,
    geo,
    prm,
):
    """The leg candidates on the background or carried (carried_beams) taken out (tracker._off_background): a
    strong one becomes a blob, a weak one stays the measurement covering it, each of leg probability NOT_A_LEG,
    and the other strong legs are paired again; the same arrays when none is. A candidate within leg_reach of a
    person's prediction is that person's leg, background or not (a person standing by a wall keeps their legs), but
    not when carried."""
    if len(raw) == 0:
        return mx, my, msize, mkind, mlegs, raw, mprob
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
    carried_beams(bg, raw, ranges, carry_ref, carry_seen, carry_away, has_pose, pose, geo, prm)
    if not bg.any():
        return mx, my, msize, mkind, mlegs, raw, mprob
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
            x[m], y[m], size[m], knd[m], prob[m] = raw[i, R_X], raw[i, R_Y], raw[i, R_W], K_BLOB, NOT_A_LEG
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
                prob[where[c]] = NOT_A_LEG
            continue
        out[q] = raw[i]
        if c >= 0:
            out[q, R_COVER] = where[c]
        q += 1
    return x, y, size, knd, lg, out, prob


@njit(cache=True)
def leggy_tracks(tab, n, prm):
    """The tracks that may take leg candidates first: people, and confirmed tracks of legs (legs a share >=
    person_votes of their hits) or whose leg evidence is at least person_maintain (a person whose legs the detector
    was less sure of, measured as circles or blobs)."""
    out = np.empty(n, np.int64)
    q = 0
    for k in range(n):
        legs = tab[k, VOTES + K_PERSON] + tab[k, VOTES + K_LEG]
        total = 0.0
        for j in range(5):
            total += tab[k, VOTES + j]
        leggy = legs >= prm[P_PERSON_VOTES] * max(total, 1.0) and legs > 0 and tab[k, CLS] <= CLASS_PERSON
        evident = tab[k, LEG_HITS] > 0 and tab[k, LEG_SCORE] >= prm[P_PERSON_MAINTAIN]
        if tab[k, IS_PERSON] != 0 or (tab[k, CONFIRMED] != 0 and (leggy or evident)):
            out[q] = k
            q += 1
    return out[:q]


@njit(cache=True)
def legs_stage(tab, n, mx, my, msize, mkind, mlegs, raw, mprob, prm):
    """Tracks of legs or people take up to two leg candidates each, weak ones too when the detector gives them at
    least person_maintain (below it, no hit keeps a person) (tracker._legs). Returns the measurements (rebuilt when
    some track took legs: theirs first) and rows0, the tracks owning the first len(rows0)."""
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
    use = (raw[:, R_COVER] < 0) | (raw[:, R_P] >= prm[P_PERSON_MAINTAIN])
    cand = raw[use]
    owner, x, y, size, kind, legs, other = _kernels.leg_stage_measurements(
        tx,
        ty,
        cand[:, R_X].copy(),
        cand[:, R_Y].copy(),
        cand[:, R_W].copy(),
        cand[:, R_COVER] < 0,
        cand[:, R_COVER].astype(np.int64),
        mx,
        my,
        msize,
        mkind,
        mlegs,
        prm,
    )
    if len(owner) == 0:
        return mx, my, msize, mkind, mlegs, mprob, none
    prob = np.zeros(len(x))
    m = len(x) - len(other)
    for q in range(len(other)):
        prob[m + q] = mprob[other[q]]
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
            if not compat[row, mkind[j]] or abs(dx) > far or abs(dy) > far:  # then hypot(dx, dy) > far too
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
    on_bg = _kernels.tracks_on_background(
        bg_score, mx, my, msize, mkind, rows, cols, n, px, py, ctx[C_BG_X0], ctx[C_BG_Y0], nbg, prm
    )
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
        kalman_update(
            tab,
            k,
            mx[j],
            my[j],
            prm[P_LEG_MEASUREMENT_NOISE] if mkind[j] == K_LEG else prm[P_MEASUREMENT_NOISE],
            scratch,
        )
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
                lead = along if (ux * dy - uy * dx) > 0 else -along  # left leg minus right leg
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
    free = np.empty(M, np.bool_)  # a lone leg may be someone else's second leg: taken back only where reacq lets a
    for j in range(M):  # person (row 0) take one; one beside a confirmed track just hit is never free
        free[j] = mkind[j] != K_LEG or reacq[0, K_LEG]
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
            if (
                tab[k, HIT] != 0
                and tab[k, CONFIRMED] != 0
                and np.hypot(mx[j] - tab[k, X], my[j] - tab[k, Y]) <= prm[P_LEG_BESIDE]
            ):
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
        reach = min(
            prm[P_REACQUIRE_SPEED] * (stamp - np.int64(tab[k, LAST_HIT])) * 1e-9 + prm[P_MAX_GATE_DISTANCE],
            prm[P_REACQUIRE_DISTANCE],
        )
        for b in range(nc):
            j = cand[b]
            dist[a, b] = np.hypot(mx[j] - tab[k, LAST_X], my[j] - tab[k, LAST_Y])
            ok[a, b] = (
                dist[a, b] <= reach and reacq[crow[k], mkind[j]] and (free[j] or tab[k, MOBILITY] == MOBILITY_DYNAMIC)
            )
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
def fold_evidence(tab, k, p, prm):
    """Fold a leg-candidate hit of leg probability p into track k's evidence LEG_SCORE: the plain mean of its
    first 1/leg_evidence_rate such hits, then a running mean of that rate; a candidate found on the background or
    carried (p = NOT_A_LEG) sets it to 0."""
    tab[k, LEG_HITS] += 1
    if p == NOT_A_LEG:  # a candidate on the background or carried: whatever fed the evidence was no leg
        tab[k, LEG_SCORE] = 0.0
        return
    a = max(prm[P_LEG_EVIDENCE_RATE], 1.0 / tab[k, LEG_HITS])
    tab[k, LEG_SCORE] = (1.0 - a) * tab[k, LEG_SCORE] + a * p


@njit(cache=True)
def leg_evidence(tab, rows, cols, mx, my, mkind, mlegs, mprob, raw, has_prob, prm):
    """Fold the leg probability of each hit (rows took cols) that was a leg candidate (a leg or pair, or a shape
    the detector scored above 0) into the tracks' evidence; other hits leave it as it is. Without a detector
    (`has_prob` false: the paper's rule) there is no evidence."""
    if not has_prob:
        return
    for q in range(len(rows)):
        j = cols[q]
        if mkind[j] <= K_LEG or mprob[j] > 0:
            fold_evidence(tab, rows[q], leg_probability(mx, my, mkind, mlegs, mprob, raw, has_prob, j), prm)


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
def duplicates(tab, n, learned, prm):
    """Tracks of legs or people, or that took leg candidates, within merge_distance of a higher-ranked track of legs
    or people or with leg evidence of at least person_maintain (two tracks on one person's two legs the detector
    was less sure of are one), unless both are confirmed and move differently (tracker._duplicates; with a leg
    detector, `learned`, differently beyond the spread of their velocities too: the paper's rule, whose legs are
    every small circle, keeps two close tracks apart on merge_speed alone)."""
    x, y, vx, vy, vvar = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    candidate = np.empty(n, np.bool_)
    victim = np.empty(n, np.bool_)
    confirmed = np.empty(n, np.bool_)
    rank = np.empty(n, np.int64)
    for k in range(n):
        x[k], y[k], vx[k], vy[k] = tab[k, X], tab[k, Y], tab[k, VX], tab[k, VY]
        vvar[k] = tab[k, P0 + 10] + tab[k, P0 + 15] if learned else 0.0
        legs = tab[k, VOTES + K_PERSON] + tab[k, VOTES + K_LEG]
        candidate[k] = (legs > 0 and tab[k, CLS] <= CLASS_PERSON) or (
            tab[k, LEG_HITS] > 0 and tab[k, LEG_SCORE] >= prm[P_PERSON_MAINTAIN]
        )
        victim[k] = candidate[k] or tab[k, LEG_HITS] > 0
        confirmed[k] = tab[k, CONFIRMED] != 0
        rank[k] = (
            np.int64(tab[k, HITS]) * 2
            + np.int64(tab[k, CONFIRMED])
            + (np.int64(1) << 40 if tab[k, MOBILITY] == MOBILITY_DYNAMIC else 0)
            + (np.int64(1) << 41 if tab[k, CLS] == CLASS_PERSON else 0)
        )
    return _kernels.duplicates(x, y, vx, vy, vvar, victim, candidate, confirmed, rank, prm)


@njit(cache=True)
def life_cycle(tab, n, stamp, superseded, learned, prm):
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
            if tab[k, IS_PERSON] != 0:
                limit = max(limit, prm[P_PERSON_COAST])
        else:
            limit = prm[P_TENTATIVE_DELETE_AFTER]
        dead[k] = since > limit + 1e-9
    dead |= duplicates(tab, n, learned, prm)
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
def spawn(tab, n, cols, mx, my, msize, mkind, mlegs, mprob, raw, has_prob, stamp, has_pose, pose, px, py, ctx, prm):
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
        small = mkind[j] == K_LEG or mkind[j] == K_BLOB or mprob[j] > 0
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
        if has_prob and (mkind[j] <= K_LEG or mprob[j] > 0):
            fold_evidence(tab, k, leg_probability(mx, my, mkind, mlegs, mprob, raw, has_prob, j), prm)
    ctx[C_NEXT_ID] += nn
    return tab, n + nn


@njit(cache=True)
def classify(tab, n, dt, stamp, learned, prm):
    """Class and mobility of every track (references: tests/reference_tracking's ReferenceTracker._classify
    and classify_tracks). With the leg detector, the person life cycle: a confirmed track becomes a person once
    its evidence reaches person_evidence with person_pairs sightings of two legs, and stays one until its evidence
    falls below person_maintain; the rest are classified by the shape of their hits. Mobility apart."""
    for k in range(n):
        speed = np.hypot(tab[k, VX], tab[k, VY])
        if tab[k, HIT] != 0 and tab[k, ON_BG] == 0 and speed > prm[P_MOVING_SPEED]:
            tab[k, MOVING_TIME] = tab[k, MOVING_TIME] + dt
        else:
            tab[k, MOVING_TIME] = 0.0
        if speed > prm[P_MOVING_SPEED]:
            tab[k, STILL_TIME] = 0.0
        else:
            tab[k, STILL_TIME] = tab[k, STILL_TIME] + dt
        if learned and tab[k, MOBILITY] == MOBILITY_DYNAMIC and tab[k, STILL_TIME] >= prm[P_STILL_TIME]:
            # it stopped: static again (the paper's rule keeps it dynamic), and it must move moving_distance anew
            tab[k, MOBILITY] = 0.0
            tab[k, FIRST_X], tab[k, FIRST_Y] = tab[k, X], tab[k, Y]
        if not tab[k, MOVING_TIME] >= prm[P_MOVING_TIME]:
            speed = 0.0
        moved = np.hypot(tab[k, X] - tab[k, FIRST_X], tab[k, Y] - tab[k, FIRST_Y])
        age_s = (stamp - np.int64(tab[k, BORN])) * 1e-9
        confirmed = tab[k, CONFIRMED] != 0
        dynamic = tab[k, MOBILITY] == MOBILITY_DYNAMIC or (
            confirmed and moved > prm[P_MOVING_DISTANCE] and speed > prm[P_MOVING_SPEED]
        )
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
            if tab[k, IS_PERSON] != 0:
                if tab[k, LEG_SCORE] < prm[P_PERSON_MAINTAIN]:
                    tab[k, IS_PERSON] = 0.0
            elif confirmed and tab[k, LEG_SCORE] >= prm[P_PERSON_EVIDENCE] and person >= prm[P_PERSON_PAIRS]:
                tab[k, IS_PERSON] = 1.0
            if tab[k, IS_PERSON] != 0:
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
def background_update(
    score,
    mark,
    active,
    cache,
    n_active,
    scan,
    ranges,
    cos_a,
    sin_a,
    angle_min,
    increment,
    range_min,
    range_max,
    px,
    py,
    pc,
    ps,
    dt,
    x0,
    y0,
    cell,
    n,
    margin,
    settled,
    fresh,
    qx,
    qy,
    radius,
):
    """reference_tracking.background_update with each active cell's range and beam kept beside it (cache[a] = r, beam
    for active[a], beam -2: not yet computed), valid while the sensor pose does not change (`fresh`: it
    changed, compute them all again). The same arithmetic on the same numbers: the same grid. An inactive
    cell's mark is 0 here, not -1 (scans count from 1), so a new grid is all zeros (no 5 MB to fill). Returns
    within `radius` of a person at (qx, qy) (tracking frame) are the person's and add nothing."""
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
def background(
    bg_score, bg_mark, bg_active, bg_cache, ctx, ranges, has_ranges, cos_a, sin_a, geo, px, py, pc, ps, dt, tab, n, prm
):
    """Add the scan's returns but the people's (within person_radius of a person track) to the background grid
    (tracker._background; geo: angle_min, increment, range_max, has geometry, range_min)."""
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
    people = 0
    for k in range(n):
        if sure_person(tab, k, prm):
            people += 1
    qx, qy = np.empty(people), np.empty(people)
    q = 0
    for k in range(n):
        if sure_person(tab, k, prm):
            qx[q], qy[q] = tab[k, X], tab[k, Y]
            q += 1
    ctx[C_BG_COUNT] = background_update(
        bg_score,
        bg_mark,
        bg_active,
        bg_cache,
        int(ctx[C_BG_COUNT]),
        int(ctx[C_BG_SCAN]),
        ranges,
        cos_a,
        sin_a,
        geo[0],
        geo[1],
        ctx[C_BG_LO],
        ctx[C_BG_HI],
        px,
        py,
        pc,
        ps,
        max(dt, 0.0),
        ctx[C_BG_X0],
        ctx[C_BG_Y0],
        prm[P_BACKGROUND_CELL],
        nbg,
        prm[P_OCCLUSION_MARGIN],
        4.0 * prm[P_BACKGROUND_TIME],
        fresh,
        qx,
        qy,
        prm[P_PERSON_RADIUS],
    )


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
        coasting_person = confirmed and not hit and tab[k, IS_PERSON] != 0
        r["occluded"] = np.uint8(1 if tab[k, OCCLUDED] != 0 or coasting_person else 0)


# -------------------------------------------------------------------------------------------- the step
@njit(cache=True)
def track_scan(
    tab,
    ctx,
    prm,
    stamp,
    mx,
    my,
    msize,
    mkind,
    mlegs,
    raw,
    mprob,
    has_prob,
    ranges,
    has_ranges,
    has_pose,
    pose,
    geo,
    cos_a,
    sin_a,
    bg_score,
    bg_mark,
    bg_active,
    bg_cache,
    carry_ref,
    carry_seen,
    carry_away,
    learned,
    compat,
    reacq,
):
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
    carried_update(carry_ref, carry_seen, carry_away, ranges, has_ranges, has_pose, pose, geo, ctx, prm)
    mx, my, msize, mkind, mlegs, raw, mprob = off_background(
        tab,
        n,
        mx,
        my,
        msize,
        mkind,
        mlegs,
        raw,
        mprob,
        bg_score,
        ctx,
        px,
        py,
        ranges,
        carry_ref,
        carry_seen,
        carry_away,
        has_pose,
        pose,
        geo,
        prm,
    )
    mx, my, msize, mkind, mlegs, mprob, rows0 = legs_stage(tab, n, mx, my, msize, mkind, mlegs, raw, mprob, prm)
    rows, cols = associate(tab, n, mx, my, mkind, rows0, compat, crow, prm)
    hit_background(tab, n, rows, cols, mx, my, msize, mkind, bg_score, ctx, px, py, prm)
    update(tab, n, rows, cols, mx, my, mkind, msize, mlegs, prm)
    rows2, cols2 = reacquire(tab, n, rows, cols, mx, my, mkind, stamp, reacq, crow, prm)
    rows, cols, superseded = merge_reacquired(rows, cols, rows2, cols2)
    leg_evidence(tab, rows, cols, mx, my, mkind, mlegs, mprob, raw, has_prob, prm)
    occlusion(tab, n, ranges, has_ranges, geo, has_pose, pose, prm)
    n = life_cycle(tab, n, stamp, superseded, learned, prm)
    tab, n = spawn(
        tab, n, cols, mx, my, msize, mkind, mlegs, mprob, raw, has_prob, stamp, has_pose, pose, px, py, ctx, prm
    )
    classify(tab, n, dt, stamp, learned, prm)
    push_tail(tab, n, prm)
    background(
        bg_score,
        bg_mark,
        bg_active,
        bg_cache,
        ctx,
        ranges,
        has_ranges,
        cos_a,
        sin_a,
        geo,
        px,
        py,
        pc,
        ps,
        dt,
        tab,
        n,
        prm,
    )
    ctx[C_N_TRACKS] = n
    return tab


@njit(cache=True)
def step_measurements(
    tab,
    ctx,
    prm,
    stamp,
    mx,
    my,
    msize,
    mkind,
    mlegs,
    raw,
    mprob,
    has_prob,
    ranges,
    has_ranges,
    has_pose,
    pose,
    geo,
    cos_a,
    sin_a,
    bg_score,
    bg_mark,
    bg_active,
    bg_cache,
    carry_ref,
    carry_seen,
    carry_away,
    learned,
    compat,
    reacq,
    out,
):
    """track_scan on one scan's measurements, then its live tracks as Track elements in `out` (a new, larger
    array when it is too small). Returns (table, out)."""
    tab = track_scan(
        tab,
        ctx,
        prm,
        stamp,
        mx,
        my,
        msize,
        mkind,
        mlegs,
        raw,
        mprob,
        has_prob,
        ranges,
        has_ranges,
        has_pose,
        pose,
        geo,
        cos_a,
        sin_a,
        bg_score,
        bg_mark,
        bg_active,
        bg_cache,
        carry_ref,
        carry_seen,
        carry_away,
        learned,
        compat,
        reacq,
    )
    n = int(ctx[C_N_TRACKS])
    if n > len(out):
        out = np.empty(2 * n, out.dtype)
    write_tracks(out, 0, tab, n, has_pose, pose)
    return tab, out


@njit(cache=True)
def track_block(
    tab,
    ctx,
    prm,
    stamps,
    circles,
    blobs,
    lines,
    legs,
    learned,
    ranges,
    has_ranges,
    poses,
    has_pose,
    geo,
    cos_a,
    sin_a,
    bg_score,
    bg_mark,
    bg_active,
    bg_cache,
    carry_ref,
    carry_seen,
    carry_away,
    compat,
    reacq,
    out,
    tails,
    out_tail,
    out_tail_count,
    offsets,
):
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
                cf[a0:a1],
                cl[a0:a1],
                cx[a0:a1],
                cy[a0:a1],
                cr[a0:a1],
                bf[b0:b1],
                bl[b0:b1],
                bx[b0:b1],
                by[b0:b1],
                bs[b0:b1],
                ls[l0:l1],
                lf[l0:l1],
                ll[l0:l1],
                lx0[l0:l1],
                ly0[l0:l1],
                lx1[l0:l1],
                ly1[l0:l1],
                gf[g0:g1],
                gl[g0:g1],
                gx[g0:g1],
                gy[g0:g1],
                gw[g0:g1],
                gp[g0:g1],
                prm,
            )
        else:
            mx, my, msize, mkind, mlegs, raw, mprob = paper_measurements(
                cx[a0:a1],
                cy[a0:a1],
                cr[a0:a1],
                bx[b0:b1],
                by[b0:b1],
                bs[b0:b1],
                bk[b0:b1],
                ls[l0:l1],
                lx0[l0:l1],
                ly0[l0:l1],
                lx1[l0:l1],
                ly1[l0:l1],
                prm,
            )
        tab = track_scan(
            tab,
            ctx,
            prm,
            stamps[i],
            mx,
            my,
            msize,
            mkind,
            mlegs,
            raw,
            mprob,
            learned,
            ranges[i],
            has_ranges,
            has_pose,
            poses[i],
            geo,
            cos_a,
            sin_a,
            bg_score,
            bg_mark,
            bg_active,
            bg_cache,
            carry_ref,
            carry_seen,
            carry_away,
            learned,
            compat,
            reacq,
        )
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
