"""The tracks' filters and their association with a scan's measurements, on the track table (state.py).

Constant-velocity prediction, gating (Mahalanobis distance, a distance bound and the kind compatibility of the
kind group that fed a track most), global nearest neighbour (_assign.gnn), the Joseph-form Kalman update and the
reacquisition of tracks lost while occluded. Tracking frame, m and m/s; stamps in ns since the tracker's first
scan; dt in s. References: tests/reference_tracking.py (cv_predict, gated_costs, joseph_update, and the
ReferenceTracker's _associate, _update and _reacquire).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from ..logs.vocabulary import MOBILITY_DYNAMIC
from . import _assign
from ._scan_measurements import K_LEG, K_PERSON
from .state import (
    CONFIRMED,
    HIT,
    IS_PERSON,
    LAST_HIT,
    LAST_X,
    LAST_Y,
    LEAD_LEFT,
    LEAD_RIGHT,
    MISSES,
    MOBILITY,
    MOVING_TIME,
    OCCLUDED,
    P0,
    P_GATE,
    P_INITIAL_SPEED_SIGMA,
    P_LEG_BESIDE,
    P_LEG_MEASUREMENT_NOISE,
    P_LEG_REACH,
    P_MAX_GATE_DISTANCE,
    P_MEASUREMENT_NOISE,
    P_MOVING_SPEED,
    P_PERSON_HOLD,
    P_PERSON_PROCESS_NOISE,
    P_PROCESS_NOISE,
    P_REACQUIRE_DISTANCE,
    P_REACQUIRE_SPEED,
    P_RESTART_JUMP,
    P_STEP_MAX,
    P_STEP_MIN,
    P_WALKING_AFTER,
    SIZE,
    VOTES,
    VX,
    VY,
    X,
    Y,
)

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


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
def hold_people(ok, tab, n, mkind, mprob, raw, prm):
    """A person with a leg candidate (raw: x, y, ..., tracking frame) within leg_reach of its prediction does not
    take a measurement that is no leg candidate (neither leg nor pair, leg probability 0): its legs are there, and
    the segment beside them is someone or something else."""
    for k in range(n):
        if tab[k, IS_PERSON] == 0:
            continue
        there = False
        for i in range(len(raw)):
            if np.hypot(raw[i, 0] - tab[k, X], raw[i, 1] - tab[k, Y]) <= prm[P_LEG_REACH]:
                there = True
                break
        if there:
            for j in range(len(mkind)):
                if mkind[j] > K_LEG and mprob[j] == 0:
                    ok[k, j] = False


@njit(cache=True)
def associate(tab, n, mx, my, mkind, mprob, raw, rows0, compat, crow, prm):
    """Tracks rows0 own measurements 0..len(rows0)-1; the others are gated and assigned by GNN (a person keeps to
    its legs: hold_people; raw: the scan's leg candidates, mprob: each measurement's leg probability).
    (rows, cols)."""
    n0 = len(rows0)
    cols0 = np.arange(n0)
    if n == 0 or len(mx) == n0:
        return rows0, cols0
    cost, ok = gated_costs(tab, n, mx, my, mkind, compat, crow, prm)
    if prm[P_PERSON_HOLD] != 0:
        hold_people(ok, tab, n, mkind, mprob, raw, prm)
    if n0:
        for q in range(n0):
            ok[rows0[q], :] = False
        ok[:, :n0] = False
    r, c = _assign.gnn(cost, ok)
    return np.concatenate((rows0, r)), np.concatenate((cols0, c))


@njit(cache=True)
def update(tab, n, rows, cols, mx, my, mkind, msize, mlegs, prm):
    """Kalman-update tracks rows with measurements cols and record the hits (reference_tracking.apply_updates); a
    track that missed and is taken back more than restart_jump from its prediction restarts there (no velocity)."""
    for k in range(n):
        tab[k, HIT] = 0.0
    scratch = np.empty((3, 4, 4))
    for q in range(len(rows)):
        k, j = rows[q], cols[q]
        moving = tab[k, MOVING_TIME] >= prm[P_WALKING_AFTER]
        sigma = prm[P_LEG_MEASUREMENT_NOISE] if mkind[j] == K_LEG else prm[P_MEASUREMENT_NOISE]
        jump = np.hypot(mx[j] - tab[k, X], my[j] - tab[k, Y])
        if tab[k, MISSES] > 0 and prm[P_RESTART_JUMP] > 0 and jump > prm[P_RESTART_JUMP]:
            # taken back more than a stride from its prediction: the jump is no velocity, start again there
            restart(tab, k, mx[j], my[j], sigma, prm)
        else:
            kalman_update(tab, k, mx[j], my[j], sigma, scratch)
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
