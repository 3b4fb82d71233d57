"""Legs and people: leg candidates given to the tracks of legs or people first, and the leg evidence that
makes a confirmed track a person (tracker.Tracker's docstring has the rules; classification is _classify.py).

Tracking frame, m. Leg probabilities are the leg detector's (0..1); NOT_A_LEG marks a candidate found on the
background or carried. References: tests/reference_tracking.ReferenceTracker's _legs and _leg_evidence.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from ..logs.vocabulary import CLASS_PERSON
from . import _kernels
from ._scan_measurements import CARRIED_LEG, K_LEG, K_PERSON, NOT_A_LEG, R_COVER, R_P, R_W, R_X, R_Y
from .bundles import ScanMeasurements
from .state import (
    C_KEPT_N,
    C_KEPT_NEXT,
    C_KEPT_STAMP,
    CLS,
    CONFIRMED,
    FREE,
    IS_PERSON,
    LEG_HITS,
    LEG_SCORE,
    P_BACKGROUND_SHIELD,
    P_FREE_SPACE_INTERVAL,
    P_FREE_SPACE_MIN,
    P_FREE_SPACE_SHARE,
    P_LEG_EVIDENCE_RATE,
    P_OCCLUSION_MARGIN,
    P_PERSON_MAINTAIN,
    P_PERSON_VOTES,
    VOTES,
    X,
    Y,
)

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read


@njit(cache=True)
def sure_person(tab, k, prm):
    """Whether track k is a person: its returns are its own, never background, and a candidate near it is its
    leg even on the background (a person standing still, whose evidence may dip at range, is not swallowed)."""
    return tab[k, IS_PERSON] != 0


@njit(cache=True)
def owns_returns(tab, k, prm):
    """Whether the returns near track k are its own, never background: a person, or a track of leg evidence at
    least background_shield (a person not yet promoted, standing still from the start, is not swallowed first)."""
    return tab[k, IS_PERSON] != 0 or (tab[k, LEG_HITS] > 0 and tab[k, LEG_SCORE] >= prm[P_BACKGROUND_SHIELD])


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
def legs_stage(tab, n, meas, prm):
    """Tracks of legs or people take up to two leg candidates each, weak ones too when the detector gives them at
    least person_maintain (below it, no hit keeps a person) (tracker._legs). Returns (the measurements, rows0): the
    measurements rebuilt when some track took legs (theirs first, the same raw candidates; meas itself when none
    did) and rows0, the tracks owning the first len(rows0). meas: bundles.ScanMeasurements, tracking frame."""
    raw = meas.raw
    none = np.zeros(0, np.int64)
    if n == 0 or len(raw) == 0:
        return meas, none
    leggy = leggy_tracks(tab, n, prm)
    if len(leggy) == 0:
        return meas, none
    tx = np.empty(len(leggy))
    ty = np.empty(len(leggy))
    for q in range(len(leggy)):
        tx[q], ty[q] = tab[leggy[q], X], tab[leggy[q], Y]
    use = (raw[:, R_COVER] < 0) | (raw[:, R_P] >= prm[P_PERSON_MAINTAIN])
    cand = raw[use]
    strong = cand[:, R_COVER] < 0
    got = _kernels.leg_stage_measurements(
        tx,
        ty,
        (cand[:, R_X].copy(), cand[:, R_Y].copy(), cand[:, R_W].copy(), strong, cand[:, R_COVER].astype(np.int64)),
        (meas.x, meas.y, meas.size, meas.kind, meas.legs),
        prm,
    )
    if len(got.owner) == 0:
        return meas, none
    prob = np.zeros(len(got.x))
    m = len(got.x) - len(got.other)
    for q in range(len(got.other)):
        prob[m + q] = meas.prob[got.other[q]]
    return ScanMeasurements(got.x, got.y, got.size, got.kind, got.legs, raw, prob), leggy[got.owner]


@njit(cache=True)
def fold_evidence(tab, k, p, prm):
    """Fold a leg-candidate hit of leg probability p into track k's evidence LEG_SCORE: the plain mean of its
    first 1/leg_evidence_rate such hits, then a running mean of that rate; a candidate found on the background or
    carried (p = NOT_A_LEG or CARRIED_LEG) sets it to 0 (folding it as one hit of p 0 instead, as leg_tracker's
    confidence would, was measured: worse identities on the simulated hall and corridor, IDF1 0.74 -> 0.57 and
    0.86 -> 0.68 with every other change of that round undone)."""
    tab[k, LEG_HITS] += 1
    if p == NOT_A_LEG or p == CARRIED_LEG:
        tab[k, LEG_SCORE] = 0.0
        return
    a = max(prm[P_LEG_EVIDENCE_RATE], 1.0 / tab[k, LEG_HITS])
    tab[k, LEG_SCORE] = (1.0 - a) * tab[k, LEG_SCORE] + a * p


@njit(cache=True)
def in_free_space(x, y, kept_ranges, kept_poses, n_kept, geo, prm):
    """Whether the point (x, y) (tracking frame, m) lies where the kept scans saw through: at least free_space_min
    of them returned more than occlusion_margin beyond it on its bearing (or nothing within range), and at least
    free_space_share of those that had it in view did. kept_ranges (K, B) m and kept_poses (K, 3: x, y m, theta
    rad, tracking frame) of n_kept scans; geo: angle_min, increment, range_max, has geometry, range_min."""
    B = kept_ranges.shape[1]
    seen = through = 0
    for s in range(n_kept):
        c, sn = np.cos(kept_poses[s, 2]), np.sin(kept_poses[s, 2])
        dx, dy = x - kept_poses[s, 0], y - kept_poses[s, 1]
        sx, sy = c * dx + sn * dy, -sn * dx + c * dy
        r = np.hypot(sx, sy)
        b = int(np.rint((np.arctan2(sy, sx) - geo[0]) / geo[1]))
        if b < 0 or b >= B or r >= geo[2]:
            continue
        rj = np.float64(kept_ranges[s, b])
        if rj >= geo[2]:
            seen += 1
            through += 1
        elif rj > geo[4]:
            seen += 1
            if rj > r + prm[P_OCCLUSION_MARGIN]:
                through += 1
    return through >= prm[P_FREE_SPACE_MIN] and through >= prm[P_FREE_SPACE_SHARE] * seen


@njit(cache=True)
def keep_scan(kept_ranges, kept_poses, ranges, has_ranges, pose, stamp, ctx, prm):
    """Keep this scan's ranges and sensor pose (tracking frame) for the free-space test when free_space_interval s
    have passed since the last one kept: a ring of len(kept_ranges) scans (ctx[C_KEPT_*])."""
    K = len(kept_ranges)
    if K == 0 or not has_ranges or len(ranges) != kept_ranges.shape[1]:
        return
    last = ctx[C_KEPT_STAMP]
    if last >= 0 and (stamp - np.int64(last)) * 1e-9 < prm[P_FREE_SPACE_INTERVAL] - 1e-9:
        return
    i = int(ctx[C_KEPT_NEXT])
    kept_ranges[i, :] = ranges
    kept_poses[i, 0], kept_poses[i, 1], kept_poses[i, 2] = pose[0], pose[1], pose[2]
    ctx[C_KEPT_NEXT] = (i + 1) % K
    ctx[C_KEPT_N] = min(ctx[C_KEPT_N] + 1, K)
    ctx[C_KEPT_STAMP] = stamp


@njit(cache=True)
def free_legs(tab, rows, cols, mx, my, mkind, mlegs, kept, geo, ctx, prm):
    """Mark FREE (sticky) the tracks that took a leg or a pair (rows took cols) one of whose legs lies in free space
    (in_free_space against the kept scans kept = (ranges, poses)); without kept scans (no geometry, no ranges, or
    free_space_scans 0) every leg counts as in free space."""
    kept_ranges, kept_poses = kept
    n_kept = int(ctx[C_KEPT_N])
    test = len(kept_ranges) > 0 and geo[3] != 0
    for q in range(len(rows)):
        k, j = rows[q], cols[q]
        if tab[k, FREE] != 0 or mkind[j] > K_LEG:
            continue
        if not test:
            tab[k, FREE] = 1.0
        elif mkind[j] == K_PERSON:
            if in_free_space(mlegs[j, 0], mlegs[j, 1], kept_ranges, kept_poses, n_kept, geo, prm) or in_free_space(
                mlegs[j, 2], mlegs[j, 3], kept_ranges, kept_poses, n_kept, geo, prm
            ):
                tab[k, FREE] = 1.0
        elif in_free_space(mx[j], my[j], kept_ranges, kept_poses, n_kept, geo, prm):
            tab[k, FREE] = 1.0


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
