"""The life of a track: occlusion of the missed ones, confirmation, deletion (timeouts, duplicates,
superseded), new tentative tracks on the measurements no track took, and the tails.

On the track table (state.py); tracking frame, m; stamps in ns since the tracker's first scan. References:
tests/reference_tracking.ReferenceTracker's _occlusion, _life_cycle, _spawn and _push_tail.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from ..logs.vocabulary import CLASS_PERSON, MOBILITY_DYNAMIC
from . import _kernels
from ._association import restart
from ._people import fold_evidence, leg_probability
from ._scan_measurements import K_BLOB, K_LEG, K_PERSON, to_sensor
from .state import (
    AGE,
    BORN,
    C_NEXT_ID,
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
    LEG_HITS,
    LEG_SCORE,
    MISSES,
    MOBILITY,
    OCCLUDED,
    P0,
    P_CONFIRM_HITS,
    P_CONFIRM_WINDOW,
    P_DELETE_AFTER,
    P_DELETE_AFTER_OCCLUDED,
    P_DELETE_AFTER_OUT_OF_VIEW,
    P_LEG_BESIDE,
    P_LEG_MEASUREMENT_NOISE,
    P_MEASUREMENT_NOISE,
    P_PERSON_COAST,
    P_PERSON_MAINTAIN,
    P_SPAWN_CLEARANCE,
    P_TAIL_LENGTH,
    P_TENTATIVE_DELETE_AFTER,
    SIZE,
    TAIL,
    TAIL_COUNT,
    VOTES,
    VX,
    VY,
    X,
    Y,
)

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True)
def occlusion(tab, n, ranges, has_ranges, geo, has_pose, pose, prm):
    """Mark how each missed track is unseen (column OCCLUDED: _kernels.HIDDEN when a nearer return covers its
    bearing, _kernels.OUT_OF_VIEW outside the field of view or the range, else 0) (tracker._occlusion; geo:
    angle_min, increment, range_max, has geometry)."""
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
        tab[k, OCCLUDED] = float(occ[k])


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
    """Count the scan for every track, confirm, and delete the tracks past their timeout (delete_after s unseen,
    delete_after_occluded while hidden behind a nearer return, delete_after_out_of_view outside the field of view
    or range, a person at least person_coast), the duplicates and
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
            count += h & 1  # type: ignore[assignment]  # numba: int64 arithmetic
            h >>= 1
        if count >= prm[P_CONFIRM_HITS]:
            tab[k, CONFIRMED] = 1.0
        since = (stamp - np.int64(tab[k, LAST_HIT])) * 1e-9
        if tab[k, CONFIRMED] != 0:
            # hidden behind a nearer return, out of the field of view or range, or unseen where it should be seen
            if tab[k, OCCLUDED] == _kernels.HIDDEN:
                limit = prm[P_DELETE_AFTER_OCCLUDED]
            elif tab[k, OCCLUDED] == _kernels.OUT_OF_VIEW:
                limit = prm[P_DELETE_AFTER_OUT_OF_VIEW]
            else:
                limit = prm[P_DELETE_AFTER]
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
def spawn(tab, n, cols, meas, has_prob, stamp, ctx, prm):
    """Start tentative tracks on measurements no track took, except legs beside a track that took a leg and
    measurements on top of a track (tracker._spawn). meas: bundles.ScanMeasurements, tracking frame. Returns the
    table (grown when full) and its row count."""
    mx, my, msize, mkind, mprob = meas.x, meas.y, meas.size, meas.kind, meas.prob
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
            fold_evidence(tab, k, leg_probability(mx, my, mkind, meas.legs, mprob, meas.raw, has_prob, j), prm)
    ctx[C_NEXT_ID] += nn
    return tab, n + nn


@njit(cache=True)
def push_tail(tab, n, prm):
    """Append every track's position to its tail (ring buffer of tail_length points)."""
    T = int(prm[P_TAIL_LENGTH])
    for k in range(n):
        i = int(tab[k, TAIL_COUNT]) % T
        tab[k, TAIL + 2 * i], tab[k, TAIL + 2 * i + 1] = tab[k, X], tab[k, Y]
        tab[k, TAIL_COUNT] += 1
