"""The plain statements of the tracking rules, and the tracker as it was before the compiled step, kept as the
references the package's kernels (datmo_cli/tracking/_kernels.py, _step.py and the modules of its phases,
_assign.py) are checked against, phase by phase and run by run. Not part of the package: tests only.

- People (docs/method.md §6.1): `pair_legs`, `leg_lead`. Classification (docs/method.md §6): `classify`, `mobility`.
  Kalman model (filterpy's): `transition`, `process_noise`; gating: `gate`; global nearest neighbour:
  `reference_gnn` (scipy's linear_sum_assignment).
- The person life cycle with a leg detector: `fold_evidence` (a track's leg evidence),
  `carried_update` and `carried_beams` (beams that see a part of the robot), `cover` (which measurement a weak
  leg candidate was measured as), `leg_stage_measurements` (tracks taking strong and weak candidates).
- The per-scan arithmetic of the tracker before the compiled step (`cv_predict`, `joseph_update`,
  `mahalanobis2`, `gated_costs`, `apply_updates`, `life_cycle`, `kind_groups`, `classify_tracks`,
  `background_update`): loops over arrays, compiled with numba here for the speed of the run-long
  comparisons (plain Python under NUMBA_DISABLE_JIT=1); each is checked against the plain rules above.
- `reference_measurements` (features to measurements) and `ReferenceTracker` (the whole scan).
- Hindsight's fixed-lag RTS smoother as batched numpy (`reference_smooth`, with `rts_gains`, `rts_horizon` and
  the written-out algebra `rts_mm`, `rts_mv`, `rts_solve_spd`, `rts_largest_eigenvalue_above`).

Frames and units as datmo_cli/tracking/tracker.py says.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np
from numba import njit

from datmo_cli.logs import cdr, types
from datmo_cli.logs.scan import ScanGeometry
from datmo_cli.logs.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    MOBILITY_DYNAMIC,
    MOBILITY_STATIC,
    MOBILITY_UNDEFINED,
    STATUS_COASTING,
    STATUS_CONFIRMED,
    STATUS_TENTATIVE,
)
from datmo_cli.tracking import _kernels, hindsight
from datmo_cli.tracking.bundles import Blobs, Circles, Legs, Lines
from datmo_cli.tracking.measurements import (
    KIND_BLOB,
    KIND_CIRCLE,
    KIND_LEG,
    KIND_PERSON,
    KIND_RECT,
    N_KINDS,
    Measurements,
    ScanFeatures,
)
from datmo_cli.tracking.params import TrackingParams

INFEASIBLE = 1e12
_LEG_DTYPE = cdr.element_dtype(types.LEG)


# ------------------------------------------------------------------------------- people (docs/method.md §6.1)
def pair_legs(x: np.ndarray, y: np.ndarray, stride_max: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pair leg candidates greedily, nearest pairs first, each leg at most once, pairs at most
    `stride_max` m apart. Returns (a, b, single): index arrays of the pairs' legs and of unpaired legs."""
    n = len(x)
    if n < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.arange(n)
    d = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :])
    i, j = np.nonzero(np.triu(d <= stride_max, 1))
    if not len(i):
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.arange(n)
    order = np.argsort(d[i, j], kind="stable")
    used = np.zeros(n, bool)
    a, b = [], []
    for k in order.tolist():
        p, q = i[k], j[k]
        if not used[p] and not used[q]:
            used[p] = used[q] = True
            a.append(p)
            b.append(q)
    return np.array(a, np.int64), np.array(b, np.int64), np.flatnonzero(~used)


def leg_lead(legs: np.ndarray, vx: np.ndarray, vy: np.ndarray) -> np.ndarray:
    """How far the left leg leads the right one along the direction of travel (m), for rows of
    legs (ax, ay, bx, by) and velocities (vx, vy); NaN where the speed is zero. Left is the leg on the
    left of the direction of travel, so the sign alternates from step to step while walking."""
    speed = np.hypot(vx, vy)
    with np.errstate(invalid="ignore", divide="ignore"):
        ux, uy = vx / speed, vy / speed
    dx, dy = legs[:, 0] - legs[:, 2], legs[:, 1] - legs[:, 3]  # a minus b
    along = dx * ux + dy * uy
    left_is_a = (ux * dy - uy * dx) > 0  # a lies left of b
    return np.where(left_is_a, along, -along)


# ------------------------------------------------------------------------- classification (docs/method.md §6)
def classify(votes: np.ndarray, walking: np.ndarray, moving: np.ndarray, params: TrackingParams) -> np.ndarray:
    """Class of each track from `votes` (K, N_KINDS: hits per measurement kind), `walking` (the walking
    pattern was seen) and `moving` (mobility is dynamic).

    Legs: a person once walking is seen; a pair of legs that never walked stays unknown; a lone small
    circle that does not move is a circle object (a bench support, a bin). Otherwise the kind with most
    hits: circles give circle objects, lines rectangular objects, blobs unknown."""
    total = votes.sum(axis=1)
    legs = votes[:, KIND_PERSON] + votes[:, KIND_LEG]
    leggy = legs >= params.person_votes * np.maximum(total, 1)
    shape = np.stack([votes[:, KIND_CIRCLE], votes[:, KIND_RECT], votes[:, KIND_BLOB]], axis=1)
    by_shape = np.array([CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT, CLASS_UNKNOWN])[np.argmax(shape, axis=1)]
    by_shape = np.where(shape.sum(axis=1) > 0, by_shape, CLASS_UNKNOWN)
    lone_static_leg = (votes[:, KIND_PERSON] == 0) & ~moving
    leg_class = np.where(
        walking & (votes[:, KIND_PERSON] > 0),
        CLASS_PERSON,
        np.where(lone_static_leg, CLASS_CIRCLE_OBJECT, CLASS_UNKNOWN),
    )
    return np.where(leggy, leg_class, by_shape).astype(np.uint8)


def mobility(
    previous: np.ndarray,
    age_s: np.ndarray,
    size: np.ndarray,
    displacement: np.ndarray,
    speed: np.ndarray,
    confirmed: np.ndarray,
    params: TrackingParams,
) -> np.ndarray:
    """New mobility of each track: `previous` mobility, age (s), largest extent seen (m), distance from
    where it was first seen (m), filtered speed (m/s), and whether it is confirmed."""
    dynamic = (previous == MOBILITY_DYNAMIC) | (
        confirmed & (displacement > params.moving_distance) & (speed > params.moving_speed)
    )
    static = (size > params.d_max) | (age_s >= params.undefined_window)
    out = np.where(static, MOBILITY_STATIC, MOBILITY_UNDEFINED)
    return np.where(dynamic, MOBILITY_DYNAMIC, out).astype(np.uint8)


def legs_to_measurements(lx: np.ndarray, ly: np.ndarray, ls: np.ndarray, stride_max: float) -> tuple[np.ndarray, ...]:
    """Leg candidates (x, y, extent; m) as measurements: each pair of `pair_legs` a person (kind KIND_PERSON)
    at the centre of its legs, its size their distance plus their mean extent; each unpaired leg a single leg
    (KIND_LEG). People first, in pairing order, then single legs. Returns x, y, size, kind, legs (M, 4: the
    pair's legs, NaN for single legs)."""
    a, b, single = pair_legs(lx, ly, stride_max)
    x = np.concatenate([0.5 * (lx[a] + lx[b]), lx[single]])
    y = np.concatenate([0.5 * (ly[a] + ly[b]), ly[single]])
    size = np.concatenate([np.hypot(lx[a] - lx[b], ly[a] - ly[b]) + 0.5 * (ls[a] + ls[b]), ls[single]])
    kind = np.concatenate([np.full(len(a), KIND_PERSON), np.full(len(single), KIND_LEG)]).astype(np.int64)
    legs = np.full((len(x), 4), np.nan)
    legs[: len(a)] = np.stack([lx[a], ly[a], lx[b], ly[b]], axis=1)
    return x, y, size, kind, legs


def line_boxes(
    lseg: np.ndarray, lx0: np.ndarray, ly0: np.ndarray, lx1: np.ndarray, ly1: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rectangular objects: per segment (in segment order) the centre and diagonal (m) of the bounding box
    of its lines' end points. Returns the segments, x, y, size."""
    segs = np.unique(lseg)
    x, y, size = np.zeros(len(segs)), np.zeros(len(segs)), np.zeros(len(segs))
    for q, g in enumerate(segs):
        on = lseg == g
        xs, ys = np.concatenate([lx0[on], lx1[on]]), np.concatenate([ly0[on], ly1[on]])
        x[q], y[q] = 0.5 * (xs.min() + xs.max()), 0.5 * (ys.min() + ys.max())
        size[q] = np.hypot(xs.max() - xs.min(), ys.max() - ys.min())
    return segs, x, y, size


def paper_measurements(
    cx, cy, cr, bx, by, bsize, bkind, lseg, lx0, ly0, lx1, ly1, leg_radius_max, leg_blob_max, stride_max, d_max
) -> tuple[np.ndarray, ...]:
    """The paper's rule for one scan's features (measurements.py's docstring): leg candidates are circles of
    radius <= leg_radius_max (extent: the diameter), blobs of kind 0 no larger than leg_blob_max, and
    segments whose lines' box is no larger than leg_blob_max; they become people and single legs
    (`legs_to_measurements`), followed by the other circles (KIND_CIRCLE), blobs (KIND_BLOB) and boxes
    (KIND_RECT); measurements larger than d_max are dropped. Returns x, y, size, kind, legs and the leg
    candidates lx, ly, ls."""
    _, ox, oy, osize = line_boxes(lseg, lx0, ly0, lx1, ly1)
    c_leg = cr <= leg_radius_max
    b_leg = (bsize <= leg_blob_max) & (bkind == 0)
    o_leg = osize <= leg_blob_max
    lx = np.concatenate([cx[c_leg], bx[b_leg], ox[o_leg]])
    ly = np.concatenate([cy[c_leg], by[b_leg], oy[o_leg]])
    ls = np.concatenate([2.0 * cr[c_leg], bsize[b_leg], osize[o_leg]])
    px, py, psize, pkind, plegs = legs_to_measurements(lx, ly, ls, stride_max)
    x = np.concatenate([px, cx[~c_leg], bx[~b_leg], ox[~o_leg]])
    y = np.concatenate([py, cy[~c_leg], by[~b_leg], oy[~o_leg]])
    size = np.concatenate([psize, 2.0 * cr[~c_leg], bsize[~b_leg], osize[~o_leg]])
    kind = np.concatenate(
        [
            pkind,
            np.full((~c_leg).sum(), KIND_CIRCLE),
            np.full((~b_leg).sum(), KIND_BLOB),
            np.full((~o_leg).sum(), KIND_RECT),
        ]
    ).astype(np.int64)
    legs = np.concatenate([plegs, np.full((len(x) - len(px), 4), np.nan)])
    keep = size <= d_max
    return x[keep], y[keep], size[keep], kind[keep], legs[keep], lx, ly, ls


def beam_marks(first: np.ndarray, last: np.ndarray, value: np.ndarray, top: int) -> np.ndarray:
    """Per beam 0..top-1, the largest `value` of the inclusive beam intervals [first, last] covering it
    (0 where none does)."""
    beams = np.arange(top)
    cover = (beams[None, :] >= first[:, None]) & (beams[None, :] <= last[:, None])
    return np.where(cover, value[:, None], 0.0).max(axis=0, initial=0.0)


def leg_stage(tx, ty, lx, ly, ls, reach, stride_max) -> tuple[np.ndarray, ...]:
    """Leg candidates to the tracks predicted at (tx, ty) (see _kernels.leg_stage): repeatedly the nearest
    (track, leg) pair still allowed, in row-major order on ties: a track's first leg within `reach`, its
    second within `stride_max` of the track and of its first leg; each leg once, each track two at most.
    Returns owner, x, y, size, kind, legs (as legs_to_measurements, one per track that took legs) and taken."""
    d = np.hypot(lx[None, :] - tx[:, None], ly[None, :] - ty[:, None])
    first = np.full(len(tx), -1)
    second = np.full(len(tx), -1)
    taken = np.zeros(len(lx), bool)
    while len(lx):
        limit = np.where(first < 0, reach, stride_max)[:, None]
        ok = (d <= limit) & ~taken[None, :] & (second < 0)[:, None]
        has = first >= 0
        f = np.where(has, first, 0)
        ok &= ~has[:, None] | (np.hypot(lx[None, :] - lx[f][:, None], ly[None, :] - ly[f][:, None]) <= stride_max)
        if not ok.any():
            break
        k, j = np.unravel_index(int(np.argmin(np.where(ok, d, np.inf))), d.shape)
        taken[j] = True
        if first[k] < 0:
            first[k] = j
        else:
            second[k] = j
    owner = np.flatnonzero(first >= 0)
    i, j = first[owner], second[owner]
    pair = j >= 0
    jj = np.where(pair, j, i)
    x = np.where(pair, 0.5 * (lx[i] + lx[jj]), lx[i])
    y = np.where(pair, 0.5 * (ly[i] + ly[jj]), ly[i])
    size = np.where(pair, np.hypot(lx[i] - lx[jj], ly[i] - ly[jj]) + 0.5 * (ls[i] + ls[jj]), ls[i])
    kind = np.where(pair, KIND_PERSON, KIND_LEG).astype(np.int64)
    legs = np.where(pair[:, None], np.stack([lx[i], ly[i], lx[jj], ly[jj]], axis=1), np.nan)
    return owner, x, y, size, kind, legs, taken


def duplicates(x, y, vx, vy, vvar, victim, candidate, confirmed, rank, merge_distance, merge_speed) -> np.ndarray:
    """`victim` tracks within merge_distance of a `candidate` track of higher rank (ties: the lower index ranks
    higher), unless both are confirmed and their velocities differ by merge_speed plus the standard deviation of
    that difference or more (vvar: each track's velocity variance, m²/s²; a restarted track's velocity is not
    known and moves like anything)."""
    K = len(x)
    idx = np.arange(K)
    higher = (rank[None, :] > rank[:, None]) | ((rank[None, :] == rank[:, None]) & (idx[None, :] < idx[:, None]))
    near = np.hypot(x[:, None] - x[None, :], y[:, None] - y[None, :]) < merge_distance
    spread = merge_speed + np.sqrt(vvar[:, None] + vvar[None, :])
    alike = ~(confirmed[:, None] & confirmed[None, :]) | (
        np.hypot(vx[:, None] - vx[None, :], vy[:, None] - vy[None, :]) < spread
    )
    both = victim[:, None] & candidate[None, :] & (idx[None, :] != idx[:, None])
    return (both & higher & near & alike).any(axis=1)


def leggy_tracks(
    votes: np.ndarray,
    cls: np.ndarray,
    confirmed: np.ndarray,
    person: np.ndarray,
    leg_hits: np.ndarray,
    leg_score: np.ndarray,
    person_votes: float,
    person_maintain: float,
) -> np.ndarray:
    """The tracks that may take leg candidates first: every person, and the confirmed tracks of legs (legs,
    pairs and single ones, are at least person_votes of their hits, and their class is unknown or person) or
    whose leg evidence is at least person_maintain (a person the detector was less sure of, measured as circles
    or blobs)."""
    legs = votes[:, KIND_PERSON] + votes[:, KIND_LEG]
    leggy = (legs >= person_votes * np.maximum(votes.sum(axis=1), 1)) & (legs > 0) & (cls <= CLASS_PERSON)
    evident = (leg_hits > 0) & (leg_score >= person_maintain)
    return np.flatnonzero(person | (confirmed & (leggy | evident)))


def leg_stage_measurements(
    tx, ty, lx, ly, ls, strong, cover, mx, my, msize, mkind, mlegs, reach, stride_max
) -> tuple[np.ndarray, ...]:
    """Leg candidates (lx, ly, ls; `strong`: legs, else weak candidates whose measurement is mx[cover]) taken by
    the tracks predicted at (tx, ty) (`leg_stage`), then the scan's measurements rebuilt: one per track that took
    legs, then the strong candidates no track took paired (`legs_to_measurements`: a weak one no track took
    stays the measurement it was made), then the measurements of other kinds (circles, boxes, blobs) but those
    that were a taken weak candidate. Returns owner, x, y, size, kind, legs and `other`, the indices of the
    other-kind measurements kept, in order."""
    owner, ox, oy, osize, okind, olegs, taken = leg_stage(tx, ty, lx, ly, ls, reach, stride_max)
    free = ~taken & strong
    rx, ry, rsize, rkind, rlegs = legs_to_measurements(lx[free], ly[free], ls[free], stride_max)
    dropped = np.zeros(len(mx), bool)
    dropped[cover[taken & (cover >= 0)]] = True
    other = np.flatnonzero((mkind > KIND_LEG) & ~dropped)
    return (
        owner,
        np.concatenate([ox, rx, mx[other]]),
        np.concatenate([oy, ry, my[other]]),
        np.concatenate([osize, rsize, msize[other]]),
        np.concatenate([okind, rkind, mkind[other]]).astype(np.int64),
        np.concatenate([olegs, rlegs, mlegs[other]]).reshape(-1, 4),
        other,
    )


def duplicate_ranks(
    votes, hits, confirmed, mobility, cls, leg_hits, leg_score, person_maintain
) -> tuple[np.ndarray, ...]:
    """Which tracks may be a duplicate (victims: fed legs with class unknown or person, or took leg candidates),
    which may make one (candidates: fed legs with class unknown or person, or with leg evidence of at least
    person_maintain), and their rank: a person before anything else, then a dynamic track, then more hits, then
    confirmed. Returns victim, candidate, rank."""
    candidate = (((votes[:, KIND_PERSON] + votes[:, KIND_LEG]) > 0) & (cls <= CLASS_PERSON)) | (
        (leg_hits > 0) & (leg_score >= person_maintain)
    )
    rank = (
        hits.astype(np.int64) * 2
        + confirmed
        + (mobility == MOBILITY_DYNAMIC) * (1 << 40)
        + (cls == CLASS_PERSON) * (1 << 41)
    )
    return candidate | (leg_hits > 0), candidate, rank


def occlusion(sx, sy, size, missed, ranges, angle_min, increment, range_max, margin) -> np.ndarray:
    """How missed tracks (sensor-frame centres, extents in m) are unseen: 2 (out of view) when their bearing is
    outside the beams or their range at least range_max, 1 (hidden) when a return more than `margin` m nearer
    lies within the beams their extent (at least 0.2 m, at a range of at least 0.1 m) spans either side of their
    bearing, else 0."""
    rng = np.hypot(sx, sy)
    beam = np.rint((np.arctan2(sy, sx) - angle_min) / increment).astype(np.int64)
    view = missed & ((beam < 0) | (beam >= len(ranges)) | (rng >= range_max))
    out = np.where(view, 2, 0).astype(np.int64)
    half = np.ceil(np.arctan2(np.maximum(size, 0.2) / 2, np.maximum(rng, 0.1)) / abs(increment)).astype(np.int64)
    for k in np.flatnonzero(missed & ~view):
        near = ranges[max(beam[k] - half[k], 0) : beam[k] + half[k] + 1]
        out[k] = 1 if (near < rng[k] - margin).any() else 0
    return out


def on_background(score, lx, ly, ls, px, py, x0, y0, cell, n, threshold) -> np.ndarray:
    """Leg candidates (tracking frame; extent ls, m) on the background: one of the 3 x 3 grid cells around the
    point of the candidate facing the sensor at (px, py) has score >= threshold (s). Cell (i, k) has its
    corner at (x0 + i cell, y0 + k cell) and index i n + k."""
    dx, dy = lx - px, ly - py
    d = np.maximum(np.hypot(dx, dy), 1e-6)
    ci = np.floor((lx - 0.5 * ls * dx / d - x0) / cell).astype(np.int64)
    ck = np.floor((ly - 0.5 * ls * dy / d - y0) / cell).astype(np.int64)
    grid = score.reshape(n, n) >= threshold
    return np.array(
        [
            grid[max(i - 1, 0) : min(i + 2, n), max(k - 1, 0) : min(k + 2, n)].any()
            for i, k in zip(ci.tolist(), ck.tolist(), strict=True)
        ],
        bool,
    )


def tracks_on_background(
    score, mx, my, msize, mkind, rows, cols, n_tracks, px, py, x0, y0, cell, n, threshold
) -> np.ndarray:
    """Which of n_tracks tracks took (rows, cols) a measurement on the background: single legs and circles
    tested on their side facing the sensor, other kinds at their centre (`on_background`)."""
    front = np.where((mkind[cols] == KIND_LEG) | (mkind[cols] == KIND_CIRCLE), msize[cols], 0.0)
    out = np.zeros(n_tracks, bool)
    out[rows] = on_background(score, mx[cols], my[cols], front, px, py, x0, y0, cell, n, threshold)
    return out


# ------------------------------------------------------------------------- the person life cycle
# the leg probability a leg candidate on the background or on carried beams keeps: still a leg candidate (a track
# that takes it folds it into its evidence), and no leg
NOT_A_LEG = 1e-6
CARRIED_LEG = 2e-6  # ... and on carried beams: a part of the robot, whose hit takes all of a track's evidence


def sure_people(person: np.ndarray) -> np.ndarray:
    """The tracks that own their returns: the people, whatever their evidence (a person standing still, whose
    evidence may dip at range, is not swallowed): their returns are theirs, never background, and a candidate
    near one is their leg even on the background."""
    return person.copy()


def fold_evidence(leg_score: np.ndarray, leg_hits: np.ndarray, k: int, p: float, rate: float) -> None:
    """Fold a leg-candidate hit of leg probability p into track k's evidence, in place: leg_hits[k] counts the
    hits folded; the evidence is their plain mean over the first 1/rate of them, then a running mean of weight
    `rate`; a candidate found on the background or carried (p = NOT_A_LEG) is folded as such (no single hit undoes
    the evidence); one on carried beams (p = CARRIED_LEG) sets it to 0."""
    leg_hits[k] += 1
    if p == NOT_A_LEG or p == CARRIED_LEG:
        leg_score[k] = 0.0
        return
    a = max(rate, 1.0 / leg_hits[k])
    leg_score[k] = (1.0 - a) * leg_score[k] + a * p


def in_free_space(x, y, kept_ranges, kept_poses, angle_min, increment, range_min, range_max, params) -> bool:
    """Whether the point (x, y) (tracking frame) lies where the kept scans (ranges (K, B), sensor poses (K, 3))
    saw through: of the scans that had it in view (its bearing within the beams, its range under range_max, a
    valid return on that beam), at least free_space_min returned more than occlusion_margin beyond it or
    nothing within range, and at least free_space_share of them did."""
    if not len(kept_ranges):
        return False
    c, s = np.cos(kept_poses[:, 2]), np.sin(kept_poses[:, 2])
    dx, dy = x - kept_poses[:, 0], y - kept_poses[:, 1]
    sx, sy = c * dx + s * dy, -s * dx + c * dy
    r = np.hypot(sx, sy)
    b = np.rint((np.arctan2(sy, sx) - angle_min) / increment).astype(np.int64)
    inside = (b >= 0) & (b < kept_ranges.shape[1]) & (r < range_max)
    rj = kept_ranges[np.arange(len(b))[inside], b[inside]].astype(np.float64)
    r = r[inside]
    none = rj >= range_max
    valid = none | (rj > range_min)
    through = int((none | (valid & (rj > r + params.occlusion_margin))).sum())
    return through >= params.free_space_min and through >= params.free_space_share * int(valid.sum())


def carried_update(
    carry_ref: np.ndarray,
    carry_seen: np.ndarray,
    carry_away: np.ndarray,
    ranges: np.ndarray,
    range_min: float,
    range_max: float,
    tol: float,
    step: float,
) -> None:
    """One scan of the carried beams, in place. Per beam: carry_ref the range (m) it keeps returning (NaN: none),
    carry_seen how far (m) the sensor has travelled while the return was within `tol` of it, carry_away while it
    was not (nearer, farther, or no valid return within (range_min, range_max)). The sensor moved `step` m since
    the last scan. A beam away more than seen starts again: its reference the return (NaN if invalid), both
    travels 0."""
    r = np.asarray(ranges, np.float64)
    ok = (r > range_min) & (r < range_max)
    with np.errstate(invalid="ignore"):  # an invalid return (inf, NaN) is no return
        seen = ok & (np.abs(r - carry_ref) <= tol)
    carry_seen[seen] += step
    carry_away[~seen] += step
    again = ~seen & (carry_away > carry_seen)
    carry_ref[again] = np.where(ok[again], r[again], np.nan)
    carry_seen[again] = 0.0
    carry_away[again] = 0.0


def carried_beams(
    sx: np.ndarray,
    sy: np.ndarray,
    width: np.ndarray,
    ranges: np.ndarray,
    carry_ref: np.ndarray,
    carry_seen: np.ndarray,
    carry_away: np.ndarray,
    angle_min: float,
    increment: float,
    travel: float,
    tol: float,
) -> np.ndarray:
    """Which leg candidates (sensor-frame centres sx, sy and widths, m) lie on carried beams: of the beams their
    width spans either side of their bearing (at a range of at least 0.1 m), more than half are carried: they
    return their carry_ref (within `tol`) now, after `travel` m or more of travel that saw it at least three
    times as far as it did not (carried_update)."""
    B = len(carry_ref)
    with np.errstate(invalid="ignore"):
        carried = (
            (carry_seen >= travel)
            & (carry_seen >= 3.0 * carry_away)
            & (np.abs(np.asarray(ranges, np.float64) - carry_ref) <= tol)
        )
    rng = np.maximum(np.hypot(sx, sy), 0.1)
    beam = np.rint((np.arctan2(sy, sx) - angle_min) / increment).astype(np.int64)
    half = np.ceil(np.arctan2(0.5 * width, rng) / abs(increment)).astype(np.int64)
    out = np.zeros(len(sx), bool)
    for i in range(len(sx)):
        lo, hi = max(beam[i] - half[i], 0), min(beam[i] + half[i] + 1, B)
        if hi > lo:
            out[i] = 2 * int(carried[lo:hi].sum()) > hi - lo
    return out


def cover(cover: np.ndarray, best: np.ndarray, wfirst: np.ndarray, wlast: np.ndarray, f: int, e: int, m: int) -> None:
    """Measurement m, made of beams f..e, covers each weak candidate (beams wfirst..wlast) it shares more beams
    with than any measurement before (best: that count so far), in place."""
    overlap = np.minimum(e, wlast) - np.maximum(f, wfirst) + 1
    more = overlap > best
    best[more] = overlap[more]
    cover[more] = m


# ----------------------------------------------------------------------- Kalman model and association
def transition(dt: float) -> np.ndarray:
    """F for a step of dt seconds (4x4)."""
    F = np.eye(4)
    F[0, 2] = F[1, 3] = dt
    return F


def process_noise(dt: float, q: float) -> np.ndarray:
    """Q for a step of dt seconds and white-noise acceleration of variance q (4x4, filterpy's values)."""
    a, b, c = 0.25 * dt**4 * q, 0.5 * dt**3 * q, dt**2 * q
    return np.array([[a, 0, b, 0], [0, a, 0, b], [b, 0, c, 0], [0, b, 0, c]])


def param_vector(leg_threshold: float = 0.5, **values: float) -> np.ndarray:
    """The kernels' parameter vector (TrackingParams.kernel_vector) of the defaults with `values` set, and the
    leg detector's threshold."""
    return replace(TrackingParams(), **values).kernel_vector(leg_threshold)


def gate(d2: np.ndarray, dist: np.ndarray, gate: float, max_distance: float) -> np.ndarray:
    """Boolean (K, M): pairs whose squared Mahalanobis distance is within `gate` and whose Euclidean
    distance (m) is within `max_distance`."""
    return (d2 <= gate) & (dist <= max_distance)


def reference_gnn(cost: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Global nearest neighbour with scipy: the assignment of rows to columns minimising the summed cost over
    the `allowed` pairs (disallowed pairs cost INFEASIBLE and are dropped). Returns (rows, cols) int64."""
    K, M = cost.shape
    if K == 0 or M == 0 or not allowed.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if K == 1 or M == 1:  # one row or column: the cheapest allowed pair is the optimum
        c = np.where(allowed, cost, np.inf)
        i, j = np.unravel_index(int(np.argmin(c)), c.shape)
        return np.array([i], np.int64), np.array([j], np.int64)
    from scipy.optimize import linear_sum_assignment

    c = np.where(allowed, cost, INFEASIBLE)
    rows, cols = linear_sum_assignment(c)
    ok = allowed[rows, cols]
    return rows[ok].astype(np.int64), cols[ok].astype(np.int64)


gnn = reference_gnn


def moved(m: Measurements, pose: np.ndarray | None) -> Measurements:
    """The same measurements in the world frame of a sensor at pose (x, y, theta); m itself when None."""
    if pose is None:
        return m
    c, s = np.cos(pose[2]), np.sin(pose[2])
    x = c * m.x - s * m.y + pose[0]
    y = s * m.x + c * m.y + pose[1]
    legs = m.legs.copy()
    for i in (0, 2):
        legs[:, i] = c * m.legs[:, i] - s * m.legs[:, i + 1] + pose[0]
        legs[:, i + 1] = s * m.legs[:, i] + c * m.legs[:, i + 1] + pose[1]
    raw = m.raw_legs.copy()
    raw[:, 0] = c * m.raw_legs[:, 0] - s * m.raw_legs[:, 1] + pose[0]
    raw[:, 1] = s * m.raw_legs[:, 0] + c * m.raw_legs[:, 1] + pose[1]
    return Measurements(x, y, m.size, m.kind, legs, raw, m.prob)


def with_candidates(m: Measurements) -> tuple[Measurements, bool]:
    """The measurements with their leg candidates as the tracker takes them, (L, 5): x, y, width, leg
    probability (0 when the candidates carry none: the paper's rule), cover (-1: a leg, strong; else the index of
    the measurement a weak candidate was measured as; -1 when the candidates carry none); and whether they carry a
    probability."""
    raw = np.asarray(m.raw_legs, np.float64)
    out = np.zeros((len(raw), 5))
    out[:, 4] = -1.0
    out[:, : min(raw.shape[1], 5)] = raw[:, :5]
    return Measurements(m.x, m.y, m.size, m.kind, m.legs, out, m.prob), raw.shape[1] >= 4


def reference_measurements(
    features: ScanFeatures, params: TrackingParams, learned: bool = False, leg_threshold: float = 0.5
) -> Measurements:
    """The measurements of one scan's features (the rule of measurements.py's docstring) from the compiled
    features-to-measurements kernels, with the thresholding of learned legs done here in numpy: a candidate of
    probability >= leg_threshold (compared in float32, the features' type) off the beams of any circle wider
    than leg_radius_max is a leg (strong); the others (weak) are measured as what covers their beams. raw_legs:
    with a detector (L, 5), every candidate, strong ones first (see with_candidates); else (L, 3)."""
    c, b, li = features.circles, features.blobs, features.lines
    f8 = np.float64
    if learned:
        g = features.legs if features.legs is not None else np.zeros(0, _LEG_DTYPE)
        strong = g["probability"].astype(np.float32) >= np.float32(leg_threshold)
        big = c[c["radius"].astype(np.float32) > np.float32(params.leg_radius_max)]  # wider: a column's arc
        for f, e in zip(big["first"].tolist(), big["last"].tolist(), strict=True):
            strong &= (g["last"] < f) | (g["first"] > e)
        weak, g = g[~strong], g[strong]
        i8 = np.int64
        x, y, size, kind, legs, prob, covers = _kernels.learned_measurements(
            Circles(*(c[n].astype(i8 if n in ("first", "last") else f8) for n in Circles._fields)),
            Blobs(*(b[n].astype(i8 if n in ("first", "last", "kind") else f8) for n in Blobs._fields)),
            Lines(
                li["segment"].astype(i8),
                li["first"].astype(i8),
                li["last"].astype(i8),
                li["x_ini"].astype(f8),
                li["y_ini"].astype(f8),
                li["x_end"].astype(f8),
                li["y_end"].astype(f8),
            ),
            Legs(*(g[n].astype(i8 if n in ("first", "last") else f8) for n in Legs._fields)),
            (weak["first"].astype(i8), weak["last"].astype(i8), weak["probability"].astype(f8)),
            params.kernel_vector(leg_threshold),
        )
        raw = np.concatenate(
            [
                np.stack(
                    [
                        g["x"].astype(f8),
                        g["y"].astype(f8),
                        g["width"].astype(f8),
                        g["probability"].astype(f8),
                        np.full(len(g), -1.0),
                    ],
                    axis=1,
                ).reshape(-1, 5),
                np.stack(
                    [
                        weak["x"].astype(f8),
                        weak["y"].astype(f8),
                        weak["width"].astype(f8),
                        weak["probability"].astype(f8),
                        covers.astype(f8),
                    ],
                    axis=1,
                ).reshape(-1, 5),
            ]
        )
        return Measurements(x, y, size, kind, legs, raw, prob)
    x, y, size, kind, legs, lx, ly, ls = _kernels.measurements(
        (c["x"].astype(f8), c["y"].astype(f8), c["radius"].astype(f8)),
        (b["x"].astype(f8), b["y"].astype(f8), b["size"].astype(f8), b["kind"].astype(np.int64)),
        (
            li["segment"].astype(np.int64),
            li["x_ini"].astype(f8),
            li["y_ini"].astype(f8),
            li["x_end"].astype(f8),
            li["y_end"].astype(f8),
        ),
        params.kernel_vector(),
    )
    return Measurements(x, y, size, kind, legs, np.stack([lx, ly, ls], axis=1))


# ------------------------------------------------ the per-scan arithmetic of the tracker before _step


@njit(cache=True)
def mahalanobis2(x, P, zx, zy, sigma):
    """(K, M) squared Mahalanobis distances and (K, M) Euclidean distances of measurements (zx, zy) with
    per-measurement sigma from the K tracks' predicted positions."""
    K, M = len(x), len(zx)
    d2 = np.empty((K, M))
    dist = np.empty((K, M))
    for k in range(K):
        for j in range(M):
            v = sigma[j] * sigma[j]
            a, b, c = P[k, 0, 0] + v, P[k, 0, 1], P[k, 1, 1] + v
            det = a * c - b * b
            dx, dy = zx[j] - x[k, 0], zy[j] - x[k, 1]
            d2[k, j] = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det
            dist[k, j] = np.hypot(dx, dy)
    return d2, dist


@njit(cache=True)
def joseph_update(x, P, rows, zx, zy, sigma):
    """Kalman update of tracks `rows` with measurements (zx, zy) and sigmas, in place, Joseph form:
    P = (I - KH) P (I - KH)^T + K R K^T, as filterpy computes it."""
    I_KH = np.empty((4, 4))
    G = np.empty((4, 2))
    T = np.empty((4, 4))
    for n in range(len(rows)):
        k = rows[n]
        v = sigma[n] * sigma[n]
        a, b, c = P[k, 0, 0] + v, P[k, 0, 1], P[k, 1, 1] + v
        det = a * c - b * b
        i00, i01, i11 = c / det, -b / det, a / det
        for r in range(4):
            G[r, 0] = P[k, r, 0] * i00 + P[k, r, 1] * i01
            G[r, 1] = P[k, r, 0] * i01 + P[k, r, 1] * i11
        dx, dy = zx[n] - x[k, 0], zy[n] - x[k, 1]
        for r in range(4):
            x[k, r] += G[r, 0] * dx + G[r, 1] * dy
            for s in range(4):
                I_KH[r, s] = (1.0 if r == s else 0.0) - (G[r, s] if s < 2 else 0.0)
        for r in range(4):
            for s in range(4):
                acc = 0.0
                for u in range(4):
                    acc += I_KH[r, u] * P[k, u, s]
                T[r, s] = acc
        for r in range(4):
            for s in range(4):
                acc = 0.0
                for u in range(4):
                    acc += T[r, u] * I_KH[s, u]
                P[k, r, s] = acc + v * (G[r, 0] * G[s, 0] + G[r, 1] * G[s, 1])


@njit(cache=True)
def cv_predict(x, P, dt, q):
    """Constant-velocity prediction of every track dt seconds ahead, in place (Q of white-noise
    acceleration q[k] for track k)."""
    for k in range(len(x)):
        qa, qb, qc = 0.25 * dt**4 * q[k], 0.5 * dt**3 * q[k], dt**2 * q[k]
        x[k, 0] += dt * x[k, 2]
        x[k, 1] += dt * x[k, 3]
        for s in range(4):
            P[k, 0, s] += dt * P[k, 2, s]
            P[k, 1, s] += dt * P[k, 3, s]
        for r in range(4):
            P[k, r, 0] += dt * P[k, r, 2]
            P[k, r, 1] += dt * P[k, r, 3]
        P[k, 0, 0] += qa
        P[k, 1, 1] += qa
        P[k, 0, 2] += qb
        P[k, 2, 0] += qb
        P[k, 1, 3] += qb
        P[k, 3, 1] += qb
        P[k, 2, 2] += qc
        P[k, 3, 3] += qc


@njit(cache=True)
def classify_tracks(
    votes,
    walking,
    previous,
    age_s,
    size,
    displacement,
    speed,
    confirmed,
    person_votes,
    d_max,
    undefined_window,
    moving_distance,
    moving_speed,
):
    """Class and mobility of every track: the rules of `classify` and `mobility` above, fused
    into one pass."""
    K = len(votes)
    cls = np.empty(K, np.uint8)
    mob = np.empty(K, np.uint8)
    for k in range(K):
        dynamic = previous[k] == 1 or (confirmed[k] and displacement[k] > moving_distance and speed[k] > moving_speed)
        if dynamic:
            mob[k] = 1
        elif size[k] > d_max or age_s[k] >= undefined_window:
            mob[k] = 0
        else:
            mob[k] = 2
        person, leg, circle, rect, blob = votes[k, 0], votes[k, 1], votes[k, 2], votes[k, 3], votes[k, 4]
        total = person + leg + circle + rect + blob
        if person + leg >= person_votes * max(total, 1):
            if walking[k] and person > 0:
                cls[k] = 1
            elif person == 0 and not dynamic:
                cls[k] = 2
            else:
                cls[k] = 0
        elif circle + rect + blob == 0:
            cls[k] = 0
        elif circle >= rect and circle >= blob:
            cls[k] = 2
        elif rect >= blob:
            cls[k] = 3
        else:
            cls[k] = 0
    return cls, mob


@njit(cache=True)
def apply_updates(
    x,
    P,
    last,
    hit,
    votes,
    size,
    lead_left,
    lead_right,
    moving,
    rows,
    zx,
    zy,
    zkind,
    zsize,
    zlegs,
    sigma,
    sigma_leg,
    moving_speed,
    step_min,
    step_max,
    jump,
    speed_sigma,
):
    """Kalman-update tracks `rows` with measurements (zx, zy) of kinds zkind, and record the hit: last
    position, kind votes, largest size, and for people that have been `moving` which leg leads along the
    velocity (the walking pattern; noise on a still pair of posts would fake it). A `jump` row (a track that
    missed, taken back more than a stride from its prediction) restarts at its measurement instead: no
    velocity, position sigma its measurement's, speed sigma speed_sigma."""
    hit[:] = False
    sig = np.empty(len(rows))
    for n in range(len(rows)):
        sig[n] = sigma_leg if zkind[n] == 1 else sigma
    keep = ~jump
    joseph_update(x, P, rows[keep], zx[keep], zy[keep], sig[keep])
    for n in np.flatnonzero(jump):
        k = rows[n]
        x[k] = 0.0
        x[k, 0], x[k, 1] = zx[n], zy[n]
        P[k] = 0.0
        P[k, 0, 0] = P[k, 1, 1] = sig[n] ** 2
        P[k, 2, 2] = P[k, 3, 3] = speed_sigma**2
    for n in range(len(rows)):
        k = rows[n]
        last[k, 0], last[k, 1] = x[k, 0], x[k, 1]
        hit[k] = True
        votes[k, zkind[n]] += 1
        size[k] = max(size[k], zsize[n])
        if zkind[n] == 0 and moving[k]:
            vx, vy = x[k, 2], x[k, 3]
            speed = np.hypot(vx, vy)
            if speed > moving_speed:
                ux, uy = vx / speed, vy / speed
                dx, dy = zlegs[n, 0] - zlegs[n, 2], zlegs[n, 1] - zlegs[n, 3]
                along = dx * ux + dy * uy
                lead = along if (ux * dy - uy * dx) > 0 else -along  # left leg minus right leg
                if abs(lead) <= step_max:
                    if lead > step_min:
                        lead_left[k] = True
                    elif lead < -step_min:
                        lead_right[k] = True


@njit(cache=True)
def life_cycle(
    hit,
    age,
    hits,
    misses,
    last_hit_ns,
    history,
    confirmed,
    occluded,
    person,
    stamp_ns,
    mask,
    popcount,
    confirm_hits,
    delete_after,
    delete_after_occluded,
    delete_after_out_of_view,
    tentative_delete_after,
    person_coast,
):
    """Count the scan for every track (age, hits, misses, hit history, confirmation) and return which
    tracks are past their deletion timeout (s since the last hit: tentative, seen, occluded; a confirmed
    person lives at least person_coast s unseen)."""
    K = len(hit)
    dead = np.zeros(K, np.bool_)
    for k in range(K):
        age[k] += 1
        if hit[k]:
            hits[k] += 1
            misses[k] = 0
            last_hit_ns[k] = stamp_ns
        else:
            misses[k] += 1
        history[k] = ((history[k] << 1) | (1 if hit[k] else 0)) & mask
        if popcount[history[k]] >= confirm_hits:
            confirmed[k] = True
        since = (stamp_ns - last_hit_ns[k]) * 1e-9
        if confirmed[k]:
            if occluded[k] == 1:  # hidden behind a nearer return
                limit = delete_after_occluded
            elif occluded[k] == 2:  # out of the field of view or range
                limit = delete_after_out_of_view
            else:
                limit = delete_after
            if person[k]:
                limit = max(limit, person_coast)
        else:
            limit = tentative_delete_after
        dead[k] = since > limit + 1e-9
    return dead


@njit(cache=True)
def kind_groups(votes, mobility, person):
    """The kind group that fed each track most: 0 legs or people, 1 circles, 2 lines, 3 blobs, 5 a lone
    leg never paired that is not dynamic (ties: the lower group); 0 for a person, whatever fed it."""
    K = len(votes)
    g = np.empty(K, np.int64)
    for k in range(K):
        if person[k]:
            g[k] = 0
            continue
        legs = votes[k, 0] + votes[k, 1]
        best, arg = legs, 0
        for j, v in ((1, votes[k, 2]), (2, votes[k, 3]), (3, votes[k, 4])):
            if v > best:
                best, arg = v, j
        if arg == 0 and votes[k, 0] == 0 and mobility[k] != 1:
            arg = 5
        g[k] = arg
    return g


@njit(cache=True)
def background_update(
    score,
    mark,
    active,
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
    qx,
    qy,
    radius,
):
    """Update the background grid with one scan; returns the new number of active cells.

    score (n * n,): per cell, for how long (s) it has been hit without being seen through since; a cell is seen
    through when the beam at its bearing returns more than `margin` beyond it (or nothing within range).
    mark (n * n,) int64: the last scan (number `scan`) that hit the cell, or -1 when the cell is not active.
    active[:n_active]: the cells with a score (only those are tested for being seen through).
    The sensor is at (px, py) with heading cos/sin (pc, ps); cell (0, 0) has its corner at (x0, y0).
    Cells hit for `settled` s or more (walls) are tested every fourth scan only, which saves time.
    Returns within `radius` of a person (tracking-frame centres qx, qy) are the person's: they add nothing."""
    B = len(ranges)
    keep = 0
    for a in range(n_active):
        c = active[a]
        if score[c] >= settled and (c + scan) % 4 != 0:
            active[keep] = c
            keep += 1
            continue
        wx, wy = x0 + (c // n + 0.5) * cell - px, y0 + (c % n + 0.5) * cell - py
        sx, sy = pc * wx + ps * wy, -ps * wx + pc * wy
        r = np.hypot(sx, sy)
        j = int(np.rint((np.arctan2(sy, sx) - angle_min) / increment))
        if 0 <= j < B and r < range_max:
            rj = ranges[j]
            if (rj > r + margin and rj > range_min) or rj >= range_max:
                score[c] = 0.0
                mark[c] = -1
                continue
        active[keep] = c
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
        if mine:
            continue
        i = int(np.floor((wx - x0) / cell))
        k = int(np.floor((wy - y0) / cell))
        if i < 0 or k < 0 or i >= n or k >= n:
            continue
        c = i * n + k
        if mark[c] == scan:
            continue
        if mark[c] < 0:
            if keep >= len(active):
                continue
            active[keep] = c
            keep += 1
        mark[c] = scan
        score[c] += dt
    return keep


@njit(cache=True)
def gated_costs(x, P, zx, zy, zkind, sigma, sigma_leg, gate, max_distance, compat, compat_row):
    """Association costs (K, M) of measurements from the tracks' predictions, and which pairs pass the gate
    (squared Mahalanobis distance d2 <= gate; measurement sigma by kind: sigma_leg for single legs), the
    distance bound and the kind compatibility compat[compat_row[k], zkind[j]]. The cost is d2 + ln det S
    (twice the negative log-likelihood up to a constant), not d2: a track coasting for long, with a wide
    covariance, would otherwise win every measurement it can reach over the well-tracked object the
    measurement belongs to."""
    K, M = len(x), len(zx)
    cost = np.empty((K, M))
    ok = np.zeros((K, M), np.bool_)
    for k in range(K):
        row = compat_row[k]
        for j in range(M):
            s = sigma_leg if zkind[j] == 1 else sigma
            v = s * s
            a, b, c = P[k, 0, 0] + v, P[k, 0, 1], P[k, 1, 1] + v
            dx, dy = zx[j] - x[k, 0], zy[j] - x[k, 1]
            det = a * c - b * b
            d2 = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det
            cost[k, j] = d2 + np.log(det)
            ok[k, j] = compat[row, zkind[j]] and d2 <= gate and np.hypot(dx, dy) <= max_distance
    return cost, ok


def kalman_predict(x: np.ndarray, P: np.ndarray, dt: float, q: float | np.ndarray) -> None:
    """Predict every track dt seconds ahead, in place: x (K, 4), P (K, 4, 4) float64 C-contiguous;
    q the white-noise acceleration variance, one for all tracks or one per track."""
    if len(x) and dt != 0:
        cv_predict(x, P, float(dt), np.ascontiguousarray(np.broadcast_to(q, (len(x),)), np.float64))


def kalman_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, r: np.ndarray) -> None:
    """Update every track with position measurements z (K, 2), sigmas r (K,) in m, in place (Joseph form)."""
    z = np.asarray(z, np.float64)
    if len(x):
        joseph_update(
            x,
            P,
            np.arange(len(x)),
            np.ascontiguousarray(z[:, 0]),
            np.ascontiguousarray(z[:, 1]),
            np.ascontiguousarray(np.broadcast_to(np.asarray(r, np.float64), (len(x),))),
        )


def components(allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Connected components of the bipartite graph of allowed (row, column) pairs, numbered in the order of
    their smallest row: a label per row and per column (-1 for a column no allowed pair reaches), and the
    number of components."""
    nr, nc = allowed.shape
    crow, ccol = np.full(nr, -1, np.int64), np.full(nc, -1, np.int64)
    n = 0
    for start in range(nr):
        if crow[start] >= 0:
            continue
        rows = np.zeros(nr, bool)
        rows[start] = True
        while True:  # grow the component until no allowed pair adds to it
            cols = allowed[rows].any(axis=0)
            more = rows | allowed[:, cols].any(axis=1)
            if (more == rows).all():
                break
            rows = more
        crow[rows], ccol[cols] = n, n
        n += 1
    return crow, ccol, n


TRACK_DTYPE = cdr.element_dtype(types.TRACK)
# which measurement kinds (columns) a confirmed track may take, by the kind group that fed it most (rows:
# legs, circles, lines, blobs, -, a lone leg; see kind_groups); tentative tracks (the fifth row) take any
_COMPAT = np.ones((6, N_KINDS), bool)
_COMPAT[0, [KIND_CIRCLE, KIND_RECT]] = False
_COMPAT[1, KIND_PERSON] = False  # a circle partly seen may pass for a leg, or for a line
_COMPAT[2, [KIND_PERSON, KIND_LEG, KIND_CIRCLE]] = False
_ANY, _LONE_LEG = 4, 5
_COMPAT[_LONE_LEG, [KIND_PERSON, KIND_CIRCLE, KIND_RECT]] = False
# with a leg detector, a leg it was less sure of is a small circle or blob: people may take those too
_COMPAT_LEARNED = _COMPAT.copy()
_COMPAT_LEARNED[[0, _LONE_LEG], KIND_CIRCLE] = True
# which kinds a lost track may be reacquired on (rows as _COMPAT's): only its own (a person: two legs or one), since
# with real perception the clutter around (pieces of walls and benches as blobs, short lines and small circles) is
# near everywhere
_REACQUIRE = np.zeros((6, N_KINDS), bool)
_REACQUIRE[0, KIND_PERSON] = _REACQUIRE[1, KIND_CIRCLE] = _REACQUIRE[2, KIND_RECT] = True
_REACQUIRE[3, KIND_BLOB] = _REACQUIRE[_ANY] = _REACQUIRE[_LONE_LEG, KIND_LEG] = True
# with a leg detector a lost person may be taken back on one leg too (the detector vouches for it)
_REACQUIRE_LEARNED = _REACQUIRE.copy()
_REACQUIRE_LEARNED[0, KIND_LEG] = True


@dataclass
class TrackArrays:
    """The state of K tracks as arrays (tracking frame, m, m/s, ns)."""

    id: np.ndarray  # (K,) int64
    x: np.ndarray  # (K, 4) float64: x, y, vx, vy
    P: np.ndarray  # (K, 4, 4)
    born_ns: np.ndarray  # (K,) int64
    last_hit_ns: np.ndarray
    age: np.ndarray  # (K,) int64, scans
    hits: np.ndarray
    misses: np.ndarray
    history: np.ndarray  # (K,) int64 bit mask of hits in the last confirm_window scans
    votes: np.ndarray  # (K, N_KINDS) int64
    lead_left: np.ndarray  # (K,) bool: the left leg was seen leading
    lead_right: np.ndarray
    moving_time: np.ndarray  # (K,) float64, s of consecutive hits with a speed above moving_speed
    size: np.ndarray  # (K,) float64, largest extent seen, m
    first: np.ndarray  # (K, 2) position when created
    last: np.ndarray  # (K, 2) position after the last hit
    confirmed: np.ndarray  # (K,) bool
    occluded: np.ndarray  # (K,) int64: 0 seen or should have been, 1 hidden behind a nearer return, 2 out of view
    hit: np.ndarray  # (K,) bool: matched in the last step
    cls: np.ndarray  # (K,) uint8
    mobility: np.ndarray  # (K,) uint8
    tail: np.ndarray  # (K, T, 2) ring buffer of positions
    tail_count: np.ndarray  # (K,) int64, positions written so far
    leg_score: np.ndarray  # (K,) float64: leg evidence, the mean leg probability of its leg-candidate hits
    leg_hits: np.ndarray  # (K,) int64: the leg-candidate hits folded into leg_score (fold_evidence)
    person: np.ndarray  # (K,) bool: a person (with a leg detector: set once from paired legs, kept until
    #                         the evidence falls below person_maintain or the track dies)
    still_time: np.ndarray  # (K,) float64, s of a speed at most moving_speed (a dynamic track this still is
    #                         static again)
    free: np.ndarray  # (K,) bool, sticky: one of its legs was seen in free space (in_free_space)

    @classmethod
    def zeros(cls, n: int, tail_length: int) -> TrackArrays:
        """n tracks with every field zero (False, empty history)."""
        i8 = np.int64
        return cls(
            id=np.zeros(n, i8),
            x=np.zeros((n, 4)),
            P=np.zeros((n, 4, 4)),
            born_ns=np.zeros(n, i8),
            last_hit_ns=np.zeros(n, i8),
            age=np.zeros(n, i8),
            hits=np.zeros(n, i8),
            misses=np.zeros(n, i8),
            history=np.zeros(n, i8),
            votes=np.zeros((n, N_KINDS), i8),
            lead_left=np.zeros(n, bool),
            lead_right=np.zeros(n, bool),
            moving_time=np.zeros(n),
            size=np.zeros(n),
            first=np.zeros((n, 2)),
            last=np.zeros((n, 2)),
            confirmed=np.zeros(n, bool),
            occluded=np.zeros(n, np.int64),
            hit=np.zeros(n, bool),
            cls=np.zeros(n, np.uint8),
            mobility=np.zeros(n, np.uint8),
            tail=np.zeros((n, max(tail_length, 1), 2)),
            tail_count=np.zeros(n, i8),
            leg_score=np.zeros(n),
            leg_hits=np.zeros(n, i8),
            person=np.zeros(n, bool),
            still_time=np.zeros(n),
            free=np.zeros(n, bool),
        )

    @classmethod
    def empty(cls, tail_length: int) -> TrackArrays:
        return cls.zeros(0, tail_length)

    def __len__(self) -> int:
        return len(self.id)

    def take(self, keep: np.ndarray) -> TrackArrays:
        return TrackArrays(*(getattr(self, f.name)[keep] for f in fields(self)))

    def extend(self, other: TrackArrays) -> TrackArrays:
        return TrackArrays(*(np.concatenate([getattr(self, f.name), getattr(other, f.name)]) for f in fields(self)))

    @property
    def walking(self) -> np.ndarray:
        return self.lead_left & self.lead_right


def _leg_probability(m: Measurements, cols: np.ndarray, has_prob: bool | None = None) -> np.ndarray:
    """The leg detector's probability of measurements `cols`: a single leg's own, the mean of a pair's two (each
    the nearest leg candidate's), the segment's for the rest; 1 for legs when the candidates carry no probability
    (the paper's rule; `has_prob` None: they carry one when raw_legs has a 4th column)."""
    out = np.asarray(m.prob, np.float64)[cols].copy()
    legs = np.flatnonzero(m.kind[cols] <= KIND_LEG)
    raw = m.raw_legs
    if has_prob is None:
        has_prob = raw.shape[1] >= 4
    if not len(legs):
        return out
    if not has_prob or not len(raw):
        out[legs] = 1.0
        return out
    c = cols[legs]
    pair = m.kind[c] == KIND_PERSON
    # each leg's own point: a pair's two legs, a single leg's centre (the raw candidates they were made of)
    ax = np.where(pair, m.legs[c, 0], m.x[c])
    ay = np.where(pair, m.legs[c, 1], m.y[c])
    bx = np.where(pair, m.legs[c, 2], m.x[c])
    by = np.where(pair, m.legs[c, 3], m.y[c])
    pa = raw[np.argmin(np.hypot(ax[:, None] - raw[None, :, 0], ay[:, None] - raw[None, :, 1]), axis=1), 3]
    pb = raw[np.argmin(np.hypot(bx[:, None] - raw[None, :, 0], by[:, None] - raw[None, :, 1]), axis=1), 3]
    out[legs] = 0.5 * (pa + pb)
    return out


class ReferenceTracker:
    """Tracks and classifies objects scan by scan. `step` takes one scan's measurements (sensor frame; their
    raw_legs as reference_measurements gives them) and returns the live tracks as Track elements
    (element_dtype(types.TRACK)).

    People, with a leg detector (`learned`; its threshold `leg_threshold` made the measurements), have a life
    cycle with hysteresis:
    - every leg candidate comes with its probability p; those of p >= leg_threshold are legs (strong), paired
      into people or single; the others (weak) are the measurement made of their beams, carrying their p;
    - candidates on the background (unless within leg_reach of a person the detector keeps confirming,
      sure_people) or on beams the scanner carries (carried_update, whoever is near) are no legs (a strong one
      becomes a blob, a weak one's measurement stays), their p NOT_A_LEG;
    - every person, and the confirmed tracks of legs or of evidence at least person_maintain, take candidates
      near them first, strong ones and weak ones of p >= person_maintain;
    - a hit on a leg candidate (a leg, a pair, or a measurement of p > 0) folds its p into the track's
      evidence (fold_evidence; a NOT_A_LEG one sets it to 0); other hits leave it as it is;
    - a confirmed track becomes a person once its evidence is at least person_evidence with person_pairs
      sightings of two legs, and stays one until its evidence falls below person_maintain or it dies;
      mobility plays no part; a person is output as person, the other tracks by the shape of their hits;
    - a confirmed person lives max(its limit, person_coast) s unseen, output occluded while it coasts;
    - returns within person_radius of a person the detector keeps confirming add nothing to the background
      grid;
    - with a leg detector, a dynamic track still (speed at most moving_speed) for still_time s is static again (the
      paper's rule keeps it dynamic for ever).
    With the paper's rule, a person needs paired legs and the walking pattern (legs leading in turn)."""

    def __init__(
        self,
        params: TrackingParams | None = None,
        geometry: ScanGeometry | None = None,
        learned: bool = False,
        leg_threshold: float = 0.5,
    ) -> None:
        self.params = params or TrackingParams()
        self.prm = self.params.kernel_vector(leg_threshold)
        self.learned = learned
        self._reacq = _REACQUIRE_LEARNED if learned else _REACQUIRE
        self.geometry = geometry
        self.tracks = TrackArrays.empty(self.params.tail_length)
        self.stamp_ns: int | None = None
        self._dt = 0.0
        self.next_id = 1
        self.pose: np.ndarray | None = None
        self._has_prob = True
        self._compat_row = np.zeros(0, np.int64)
        self._superseded = np.zeros(0, np.int64)
        w = self.params.confirm_window
        self._mask = (1 << w) - 1
        self._popcount = np.array([bin(i).count("1") for i in range(1 << w)], np.int64)
        self._n = 0
        if geometry is not None:
            self._angle_min, self._inc, self._n = geometry.angle_min, geometry.angle_increment, geometry.n_beams
            angles = geometry.angle_min + geometry.angle_increment * np.arange(geometry.n_beams)
            self._cos, self._sin = np.cos(angles), np.sin(angles)
        self._bg_score: np.ndarray | None = None  # background grid (see _background), made at the first scan
        self._bg_origin = (0.0, 0.0)
        self._on_bg = np.zeros(0, bool)
        # carried beams (carried_update): per beam the range it keeps returning and the travel (m) it was seen
        # there and away; the sensor's position at the last scan that updated them
        self.carry_ref = np.full(self._n, np.nan)
        self.carry_seen = np.zeros(self._n)
        self.carry_away = np.zeros(self._n)
        self._carry_pose: tuple[float, float] | None = None
        self._ranges: np.ndarray | None = None  # this scan's, for the carried beams
        # the scans kept for the free-space test: ranges, sensor poses (tracking frame), how many, the next slot,
        # the stamp of the last one kept
        K = self.params.free_space_scans if geometry is not None else 0
        self.kept_ranges = np.zeros((K, self._n), np.float32)
        self.kept_poses = np.zeros((K, 3))
        self.kept_n = self.kept_next = 0
        self.kept_stamp: int | None = None

    # ---------------------------------------------------------------------------------------- step
    def step(
        self, stamp_ns: int, meas: Measurements, ranges: np.ndarray | None = None, pose: np.ndarray | None = None
    ) -> np.ndarray:
        """Advance to the scan at `stamp_ns` (ns) with its measurements `meas` (sensor frame), its ranges
        (m, for the occlusion test, the background and the carried beams; None: no missed track counts as
        occluded) and the sensor's world pose (x, y in m, theta in rad) when tracking in the world frame.
        Returns the live tracks."""
        p = self.params
        dt = 0.0 if self.stamp_ns is None else max((stamp_ns - self.stamp_ns) * 1e-9, 0.0)
        self._dt = dt
        self.stamp_ns = stamp_ns
        self.pose = None if pose is None else np.asarray(pose, np.float64)
        t = self.tracks
        group = kind_groups(t.votes, t.mobility, t.person)
        self._compat_row = np.where(t.confirmed, group, _ANY)
        kalman_predict(
            t.x, t.P, dt, np.where((group == 0) | (group == _LONE_LEG), p.person_process_noise, p.process_noise)
        )
        meas, self._has_prob = with_candidates(meas)
        m = moved(meas, self.pose)
        self._carried_update(ranges)
        m = self._off_background(t, m)
        m, rows0 = self._legs(t, m)
        rows, cols = self._associate(t, m, rows0)
        self._hit_background(t, m, rows, cols)
        self._update(t, m, rows, cols)
        rows2, cols2 = self._reacquire(t, m, rows, cols, stamp_ns)
        if len(rows2):
            keep = ~np.isin(cols, cols2)  # measurements a lost track took back from tentative tracks
            self._superseded = rows[~keep]  # those tentative tracks were started on it: they go
            rows, cols = np.concatenate([rows[keep], rows2]), np.concatenate([cols[keep], cols2])
        self._leg_evidence(t, m, rows, cols)
        self._free_legs(t, m, rows, cols)
        self._occlusion(t, ranges)
        self._life_cycle(t, stamp_ns)
        self._spawn(m, rows, cols, stamp_ns)
        self._classify()
        self._push_tail()
        self._background(ranges)
        self._keep_scan(ranges, stamp_ns)
        return self.output()

    def _keep_scan(self, ranges: np.ndarray | None, stamp_ns: int) -> None:
        """Keep this scan's ranges and sensor pose for the free-space test, free_space_interval s after the last
        one kept (a ring of free_space_scans)."""
        p = self.params
        if not len(self.kept_ranges) or ranges is None or len(ranges) != self._n:
            return
        if self.kept_stamp is not None and (stamp_ns - self.kept_stamp) * 1e-9 < p.free_space_interval - 1e-9:
            return
        i = self.kept_next
        self.kept_ranges[i] = np.asarray(ranges, np.float32)
        self.kept_poses[i] = np.zeros(3) if self.pose is None else self.pose
        self.kept_next = (i + 1) % len(self.kept_ranges)
        self.kept_n = min(self.kept_n + 1, len(self.kept_ranges))
        self.kept_stamp = stamp_ns

    def _free_legs(self, t: TrackArrays, m: Measurements, rows: np.ndarray, cols: np.ndarray) -> None:
        """Mark free (sticky) the tracks that took a leg or a pair one of whose legs lies in free space (against
        the kept scans); without kept scans (no geometry, or free_space_scans 0) every leg counts as free."""
        if self.geometry is None or not len(self.kept_ranges):
            t.free[rows[m.kind[cols] <= KIND_LEG]] = True
            return
        g, p = self.geometry, self.params
        kr, kp = self.kept_ranges[: self.kept_n], self.kept_poses[: self.kept_n]

        def free(x: float, y: float) -> bool:
            return in_free_space(x, y, kr, kp, g.angle_min, g.angle_increment, g.range_min, g.range_max, p)

        for k, j in zip(rows.tolist(), cols.tolist(), strict=True):
            if t.free[k] or m.kind[j] > KIND_LEG:
                continue
            if m.kind[j] == KIND_PERSON:
                t.free[k] = free(m.legs[j, 0], m.legs[j, 1]) or free(m.legs[j, 2], m.legs[j, 3])
            else:
                t.free[k] = free(m.x[j], m.y[j])

    def _sensor(self) -> tuple[float, float, float, float]:
        """The sensor's position and heading (cos, sin) in the tracking frame."""
        if self.pose is None:
            return 0.0, 0.0, 1.0, 0.0
        return float(self.pose[0]), float(self.pose[1]), float(np.cos(self.pose[2])), float(np.sin(self.pose[2]))

    def _carried_update(self, ranges: np.ndarray | None) -> None:
        """The carried beams (carried_update) with this scan's returns, when the sensor has a pose (only a sensor
        with a pose travels) and its ranges were given."""
        p = self.params
        self._ranges = None if ranges is None else np.asarray(ranges, np.float32)
        if ranges is None or self.pose is None or self.geometry is None or len(ranges) != self._n:
            return
        px, py = float(self.pose[0]), float(self.pose[1])
        step = 0.0 if self._carry_pose is None else float(np.hypot(px - self._carry_pose[0], py - self._carry_pose[1]))
        self._carry_pose = (px, py)
        carried_update(
            self.carry_ref,
            self.carry_seen,
            self.carry_away,
            self._ranges,
            self.geometry.range_min,
            self.geometry.range_max,
            p.carried_radius,
            step,
        )

    def _background(self, ranges: np.ndarray | None) -> None:
        """Add the scan's returns but the people's (within person_radius of a person the detector keeps
        confirming, sure_people) to the background grid: per cell, how long it has been hit without being seen
        through (see background_update)."""
        p = self.params
        if ranges is None or self.geometry is None or p.background_time <= 0 or len(ranges) != self._n:
            return
        px, py, pc, ps = self._sensor()
        if self._bg_score is None:
            n = int(np.ceil(2 * p.background_extent / p.background_cell))
            self._bg_n = n
            self._bg_score = np.zeros(n * n)
            self._bg_mark = np.full(n * n, -1, np.int64)
            self._bg_active = np.zeros(65536, np.int64)
            self._bg_count = 0
            self._bg_scan = 0
            self._bg_origin = (px - p.background_extent, py - p.background_extent)
            g = self.geometry
            self._bg_lo = float(g.range_min) if np.isfinite(g.range_min) else 0.0
            self._bg_hi = float(g.range_max) if np.isfinite(g.range_max) and g.range_max > self._bg_lo else np.inf
        self._bg_scan += 1
        t = self.tracks
        # people, and tracks of evidence enough for a person (one standing from the start is not swallowed first)
        sure = sure_people(t.person) | ((t.leg_hits > 0) & (t.leg_score >= p.background_shield))
        # cells hit for four background times are walls: seen-through tests on them every fourth scan suffice
        self._bg_count = background_update(
            self._bg_score,
            self._bg_mark,
            self._bg_active,
            self._bg_count,
            self._bg_scan,
            np.ascontiguousarray(ranges, np.float32),
            self._cos,
            self._sin,
            self._angle_min,
            self._inc,
            self._bg_lo,
            self._bg_hi,
            px,
            py,
            pc,
            ps,
            max(self._dt, 0.0),
            self._bg_origin[0],
            self._bg_origin[1],
            p.background_cell,
            self._bg_n,
            p.occlusion_margin,
            4.0 * p.background_time,
            np.ascontiguousarray(t.x[sure, 0]),
            np.ascontiguousarray(t.x[sure, 1]),
            p.person_radius,
        )

    def _hit_background(self, t: TrackArrays, m: Measurements, rows: np.ndarray, cols: np.ndarray) -> None:
        """Which tracks take a measurement on the background this scan (their motion does not count: the
        centre of a piece of wall jumps as its ends come and go)."""
        if self._bg_score is None:
            self._on_bg = np.zeros(len(t), bool)
            return
        px, py, _, _ = self._sensor()
        grid = (self._bg_score, self._bg_origin[0], self._bg_origin[1], self._bg_n)
        self._on_bg = _kernels.tracks_on_background(
            grid, m.x, m.y, m.size, m.kind, rows, cols, len(t), px, py, self.prm
        )

    def _carried(self, raw: np.ndarray) -> np.ndarray:
        """Which leg candidates (tracking frame) lie on carried beams (carried_beams); none without a pose or
        this scan's ranges."""
        p = self.params
        if self.pose is None or self.geometry is None or self._ranges is None or len(self._ranges) != self._n:
            return np.zeros(len(raw), bool)
        sx, sy = self._to_sensor(raw[:, 0], raw[:, 1])
        return carried_beams(
            sx,
            sy,
            raw[:, 2],
            self._ranges,
            self.carry_ref,
            self.carry_seen,
            self.carry_away,
            self._angle_min,
            self._inc,
            p.carried_travel,
            p.carried_radius,
        )

    def _off_background(self, t: TrackArrays, m: Measurements) -> Measurements:
        """The leg candidates on the background (a place hit for a long time: a wall, a bench, a column), unless
        within leg_reach of the prediction of a person the detector keeps confirming (sure_people: a person
        standing by a wall keeps their legs), or on carried beams (a part of the robot, whoever is near) taken out
        of the legs: a strong one becomes a blob and a weak one stays the measurement made of it, each of leg
        probability NOT_A_LEG; the other strong ones are paired again."""
        p = self.params
        raw = m.raw_legs
        if not len(raw):
            return m
        px, py, _, _ = self._sensor()
        if self._bg_score is not None:
            bg = _kernels.on_background(
                self._bg_score,
                raw[:, 0].copy(),
                raw[:, 1].copy(),
                raw[:, 2].copy(),
                px,
                py,
                self._bg_origin[0],
                self._bg_origin[1],
                self._bg_n,
                self.prm,
            )
        else:
            bg = np.zeros(len(raw), bool)
        sure = sure_people(t.person)
        if sure.any():
            d = np.hypot(raw[:, 0:1] - t.x[None, sure, 0], raw[:, 1:2] - t.x[None, sure, 1])
            bg &= ~(d <= p.leg_reach).any(axis=1)
        carried = self._carried(raw)
        bg |= carried
        if not bg.any():
            return m
        strong = raw[:, 4] < 0
        keep = strong & ~bg
        lx, ly, ls, kind, legs = legs_to_measurements(raw[keep, 0], raw[keep, 1], raw[keep, 2], p.stride_max)
        blob = bg & strong
        other = np.flatnonzero(m.kind > KIND_LEG)
        n_first = len(lx) + int(blob.sum())
        where = np.full(len(m), -1, np.int64)  # an other-kind measurement's new index
        where[other] = n_first + np.arange(len(other))
        not_a_leg = np.where(carried, CARRIED_LEG, NOT_A_LEG)
        prob = np.concatenate([np.zeros(len(lx)), not_a_leg[blob], m.prob[other]])
        covered = raw[:, 4].astype(np.int64)
        weak = bg & ~strong & (raw[:, 4] >= 0)
        gone = where[covered[weak]]
        prob[gone[gone >= 0]] = not_a_leg[weak][gone >= 0]
        out = raw[~bg].copy()
        c = covered[~bg]
        out[:, 4] = np.where(c >= 0, where[np.maximum(c, 0)], out[:, 4])
        return Measurements(
            np.concatenate([lx, raw[blob, 0], m.x[other]]),
            np.concatenate([ly, raw[blob, 1], m.y[other]]),
            np.concatenate([ls, raw[blob, 2], m.size[other]]),
            np.concatenate([kind, np.full(int(blob.sum()), KIND_BLOB, np.int64), m.kind[other]]),
            np.concatenate([legs, np.full((int(blob.sum()), 4), np.nan), m.legs[other]]),
            out,
            prob,
        )

    def _legs(self, t: TrackArrays, m: Measurements) -> tuple[Measurements, np.ndarray]:
        """Let tracks that are legs or people take up to two leg candidates each near their prediction
        (nearest pairs first, so two people walking side by side keep their own legs): strong candidates, and
        weak ones the detector gives at least person_maintain (below it, no hit keeps a person); then the
        remaining strong candidates are paired by distance alone (leg_stage_measurements). Returns the scan's
        measurements rebuilt, the first len(rows) of them formed for tracks `rows` from their legs."""
        p = self.params
        none = np.zeros(0, np.int64)
        raw = m.raw_legs
        if not len(t) or not len(raw):
            return m, none
        leggy = leggy_tracks(
            t.votes, t.cls, t.confirmed, t.person, t.leg_hits, t.leg_score, p.person_votes, p.person_maintain
        )
        if not len(leggy):
            return m, none
        c = raw[(raw[:, 4] < 0) | (raw[:, 3] >= p.person_maintain)]
        owner, x, y, size, kind, legs, other = leg_stage_measurements(
            t.x[leggy, 0],
            t.x[leggy, 1],
            c[:, 0],
            c[:, 1],
            c[:, 2],
            c[:, 4] < 0,
            c[:, 4].astype(np.int64),
            m.x,
            m.y,
            m.size,
            m.kind,
            m.legs,
            p.leg_reach,
            p.stride_max,
        )
        if not len(owner):
            return m, none
        prob = np.concatenate([np.zeros(len(x) - len(other)), m.prob[other]])
        return Measurements(x, y, size, kind, legs, raw, prob), leggy[owner]

    def _associate(self, t: TrackArrays, m: Measurements, rows0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tracks `rows0` own measurements 0..len(rows0)-1; the others are gated and assigned by GNN."""
        p = self.params
        n0 = len(rows0)
        cols0 = np.arange(n0, dtype=np.int64)
        if not len(t) or len(m) == n0:
            return rows0, cols0
        d2, allowed = gated_costs(
            t.x,
            t.P,
            m.x,
            m.y,
            m.kind,
            p.measurement_noise,
            p.leg_measurement_noise,
            p.gate,
            p.max_gate_distance,
            _COMPAT_LEARNED if self.learned else _COMPAT,
            self._compat_row,
        )
        # a person with a leg candidate within leg_reach takes no measurement that is no leg candidate
        raw = m.raw_legs
        if len(raw) and p.person_hold:
            there = t.person & (
                np.hypot(raw[None, :, 0] - t.x[:, 0:1], raw[None, :, 1] - t.x[:, 1:2]) <= p.leg_reach
            ).any(axis=1)
            allowed[np.ix_(there, (m.kind > KIND_LEG) & (m.prob == 0))] = False
        if n0:
            allowed[rows0, :] = False
            allowed[:, :n0] = False
        rows, cols = gnn(d2, allowed)
        return np.concatenate([rows0, rows]), np.concatenate([cols0, cols])

    def _update(self, t: TrackArrays, m: Measurements, rows: np.ndarray, cols: np.ndarray) -> None:
        p = self.params
        moving = t.moving_time >= p.walking_after
        jump = (t.misses[rows] > 0) & (p.restart_jump > 0)
        jump &= np.hypot(m.x[cols] - t.x[rows, 0], m.y[cols] - t.x[rows, 1]) > p.restart_jump
        apply_updates(
            t.x,
            t.P,
            t.last,
            t.hit,
            t.votes,
            t.size,
            t.lead_left,
            t.lead_right,
            moving,
            rows,
            m.x[cols],
            m.y[cols],
            m.kind[cols],
            m.size[cols],
            m.legs[cols],
            p.measurement_noise,
            p.leg_measurement_noise,
            p.moving_speed,
            p.step_min,
            p.step_max,
            jump,
            p.initial_speed_sigma,
        )

    def _reacquire(
        self, t: TrackArrays, m: Measurements, taken_by: np.ndarray, taken: np.ndarray, stamp_ns: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Give a confirmed track lost while occluded or out of view the nearest free measurement it could
        have reached since its last hit (at `reacquire_speed`), restarting its filter there; a prediction at
        constant velocity does not follow someone who turned while hidden."""
        p = self.params
        lost = np.flatnonzero(~t.hit & t.confirmed & (t.occluded != 0))
        if not len(lost) or not len(m):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        # a lone leg may be someone else's second leg: taken back only where the table lets a person take one
        free = (m.kind != KIND_LEG) | self._reacq[0, KIND_LEG]
        free[taken] = False
        # a tentative track started on someone coming back into view does not keep them from their old track
        # (a mover's: a static object's track does not jump onto a new one)
        tentative = np.zeros(len(m), bool)
        tentative[taken[~t.confirmed[taken_by]]] = True
        near = (t.hit & t.confirmed)[:, None] & (
            np.hypot(m.x[None, :] - t.x[:, 0:1], m.y[None, :] - t.x[:, 1:2]) <= p.leg_beside
        )
        free &= ~near.any(axis=0)
        cand = np.flatnonzero(free | (tentative & ~near.any(axis=0)))
        if not len(cand):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        dist = np.hypot(m.x[cand][None, :] - t.last[lost, 0:1], m.y[cand][None, :] - t.last[lost, 1:2])
        reach = np.minimum(
            p.reacquire_speed * (stamp_ns - t.last_hit_ns[lost]) * 1e-9 + p.max_gate_distance, p.reacquire_distance
        )
        allowed = (dist <= reach[:, None]) & self._reacq[self._compat_row[lost]][:, m.kind[cand]]
        allowed &= free[cand][None, :] | (t.mobility[lost] == MOBILITY_DYNAMIC)[:, None]
        r, c = gnn(dist, allowed)
        if not len(r):
            return r, c
        rows, cols = lost[r], cand[c]
        kind = m.kind[cols]
        sigma = np.where(kind == KIND_LEG, p.leg_measurement_noise, p.measurement_noise)
        t.x[rows] = 0.0
        t.x[rows, 0], t.x[rows, 1] = m.x[cols], m.y[cols]
        t.P[rows] = 0.0
        t.P[rows, 0, 0] = t.P[rows, 1, 1] = sigma**2
        t.P[rows, 2, 2] = t.P[rows, 3, 3] = p.initial_speed_sigma**2
        t.last[rows] = t.x[rows, 0:2]
        t.hit[rows] = True
        t.votes[rows, kind] += 1
        return rows, cols

    def _leg_evidence(self, t: TrackArrays, m: Measurements, rows: np.ndarray, cols: np.ndarray) -> None:
        """Fold each hit on a leg candidate (a leg, a pair, or a measurement the detector scored above 0) into
        its track's evidence; other hits leave it as it is. Without a detector (the paper's rule) no evidence."""
        cand = ((m.kind[cols] <= KIND_LEG) | (m.prob[cols] > 0)) & self._has_prob
        prob = _leg_probability(m, cols[cand], self._has_prob)
        for k, pk in zip(rows[cand].tolist(), prob.tolist(), strict=True):
            fold_evidence(t.leg_score, t.leg_hits, k, pk, self.params.leg_evidence_rate)

    def _occlusion(self, t: TrackArrays, ranges: np.ndarray | None) -> None:
        """Mark each missed track occluded when a return nearer than it covers its bearing, or when it is
        outside the field of view or the range limit."""
        t.occluded[:] = 0
        if ranges is None or self.geometry is None or t.hit.all():
            return
        sx, sy = self._to_sensor(t.x[:, 0], t.x[:, 1])
        t.occluded = _kernels.occlusion(
            np.ascontiguousarray(sx),
            np.ascontiguousarray(sy),
            t.size,
            ~t.hit,
            np.ascontiguousarray(ranges, np.float32),
            self._angle_min,
            self._inc,
            self.geometry.range_max,
            self.prm,
        )

    def _life_cycle(self, t: TrackArrays, stamp_ns: int) -> None:
        p = self.params
        dead = life_cycle(
            t.hit,
            t.age,
            t.hits,
            t.misses,
            t.last_hit_ns,
            t.history,
            t.confirmed,
            t.occluded,
            t.person,
            stamp_ns,
            self._mask,
            self._popcount,
            p.confirm_hits,
            p.delete_after,
            p.delete_after_occluded,
            p.delete_after_out_of_view,
            p.tentative_delete_after,
            p.person_coast,
        )
        dead |= self._duplicates(t)
        if len(self._superseded):
            dead[self._superseded] = True
            self._superseded = np.zeros(0, np.int64)
        if dead.any():
            self.tracks = t.take(~dead)
            if len(self._on_bg) == len(dead):
                self._on_bg = self._on_bg[~dead]

    def _duplicates(self, t: TrackArrays) -> np.ndarray:
        """Tracks of legs or people, or that took leg candidates, closer than `merge_distance` to a
        higher-ranked track of legs or people, unless both are confirmed and move differently (beyond merge_speed,
        and with a leg detector the spread of their velocities): one person's two legs must not keep two tracks
        alive. Rank: a person before anything else, then a dynamic track, then more hits (a person walking past a
        bench keeps its track; the track on the bench's pieces its passing uncovers goes)."""
        victim, candidate, rank = duplicate_ranks(
            t.votes, t.hits, t.confirmed, t.mobility, t.cls, t.leg_hits, t.leg_score, self.params.person_maintain
        )
        x = np.ascontiguousarray(t.x.T)
        vvar = t.P[:, 2, 2] + t.P[:, 3, 3] if self.learned else np.zeros(len(t))
        return duplicates(
            x[0],
            x[1],
            x[2],
            x[3],
            vvar,
            victim,
            candidate,
            t.confirmed,
            rank,
            self.params.merge_distance,
            self.params.merge_speed,
        )

    def _spawn(self, m: Measurements, rows: np.ndarray, cols: np.ndarray, stamp_ns: int) -> None:
        """Start tentative tracks on measurements no track took, except small ones (a leg, a blob, or what
        the detector scored above 0) beside a track that took a leg or a person (the other leg of someone
        tracked) and measurements on top of an existing track. A new track on a leg candidate has that
        hit as its evidence."""
        p = self.params
        free = np.ones(len(m), bool)
        free[cols] = False
        if not free.any():
            return
        idx = np.flatnonzero(free)
        t = self.tracks
        if len(t):
            d = np.hypot(m.x[idx, None] - t.x[None, :, 0], m.y[idx, None] - t.x[None, :, 1])
            legged = t.hit & ((t.votes[:, KIND_PERSON] + t.votes[:, KIND_LEG]) > 0)
            small = (m.kind[idx] == KIND_LEG) | (m.kind[idx] == KIND_BLOB) | (m.prob[idx] > 0)
            beside = small & (d[:, legged] <= p.leg_beside).any(axis=1)
            on_top = (d <= p.spawn_clearance).any(axis=1)
            idx = idx[~(beside | on_top)]
        n = len(idx)
        if not n:
            return
        new = TrackArrays.zeros(n, self.tracks.tail.shape[1])
        new.id = np.arange(self.next_id, self.next_id + n, dtype=np.int64)
        new.x[:, 0], new.x[:, 1] = m.x[idx], m.y[idx]
        r = np.where(m.kind[idx] == KIND_LEG, p.leg_measurement_noise, p.measurement_noise)
        new.P[:, 0, 0] = new.P[:, 1, 1] = r**2
        new.P[:, 2, 2] = new.P[:, 3, 3] = p.initial_speed_sigma**2
        new.born_ns[:] = new.last_hit_ns[:] = stamp_ns
        new.age[:] = new.hits[:] = new.history[:] = 1
        new.votes[np.arange(n), m.kind[idx]] = 1
        new.size = m.size[idx].astype(np.float64)
        new.first, new.last = new.x[:, :2].copy(), new.x[:, :2].copy()
        new.hit[:] = True
        new.mobility[:] = MOBILITY_UNDEFINED
        cand = ((m.kind[idx] <= KIND_LEG) | (m.prob[idx] > 0)) & self._has_prob
        prob = _leg_probability(m, idx[cand], self._has_prob)
        for k, pk in zip(np.flatnonzero(cand).tolist(), prob.tolist(), strict=True):
            fold_evidence(new.leg_score, new.leg_hits, k, pk, p.leg_evidence_rate)
        self.next_id += n
        self.tracks = self.tracks.extend(new)

    def _classify(self) -> None:
        t, p = self.tracks, self.params
        if not len(t):
            return
        speed = np.hypot(t.x[:, 2], t.x[:, 3])
        # motion must be sustained: segment ends that come and go make a static object's centre jump
        on_bg = np.zeros(len(t), bool)
        on_bg[: len(self._on_bg)] = self._on_bg  # tracks spawned this scan come after
        t.moving_time = np.where(t.hit & ~on_bg & (speed > p.moving_speed), t.moving_time + self._dt, 0.0)
        # a dynamic track still for still_time s stopped: static again, and must move moving_distance anew
        t.still_time = np.where(speed > p.moving_speed, 0.0, t.still_time + self._dt)
        stopped = (t.mobility == MOBILITY_DYNAMIC) & (t.still_time >= p.still_time) & self.learned  # paper: for ever
        t.mobility[stopped] = MOBILITY_STATIC
        t.first[stopped] = t.x[stopped, :2]
        speed = np.where(t.moving_time >= p.moving_time, speed, 0.0)
        moved = np.hypot(t.x[:, 0] - t.first[:, 0], t.x[:, 1] - t.first[:, 1])
        age_s = (self.stamp_ns - t.born_ns) * 1e-9
        t.cls, t.mobility = classify_tracks(
            t.votes,
            t.lead_left & t.lead_right,
            t.mobility,
            age_s,
            t.size,
            moved,
            speed,
            t.confirmed,
            p.person_votes,
            p.d_max,
            p.undefined_window,
            p.moving_distance,
            p.moving_speed,
        )
        if self.learned:
            # the person life cycle: set once from paired legs, kept until the evidence falls below
            # person_maintain; the rest by the shape of its hits
            shape = t.votes[:, [KIND_CIRCLE, KIND_RECT, KIND_BLOB]]
            by_shape = np.array([CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT, CLASS_UNKNOWN], np.uint8)[
                np.argmax(shape, axis=1)
            ]
            by_shape[shape.sum(axis=1) == 0] = CLASS_UNKNOWN
            drop = t.person & (t.leg_score < p.person_maintain)
            # legs seen in free space once (a place, not a mobility), or evidence beyond doubt
            need = np.where(t.free, p.person_evidence, p.person_evidence_unfree)
            promote = ~t.person & t.confirmed & (t.leg_score >= need) & (t.votes[:, KIND_PERSON] >= p.person_pairs)
            t.person = (t.person & ~drop) | promote
            t.cls = np.where(t.person, np.uint8(CLASS_PERSON), by_shape).astype(np.uint8)

    def _push_tail(self) -> None:
        t = self.tracks
        if not len(t):
            return
        T = t.tail.shape[1]
        t.tail[np.arange(len(t)), t.tail_count % T] = t.x[:, :2]
        t.tail_count += 1

    # -------------------------------------------------------------------------------------- output
    def _to_sensor(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.pose is None:
            return x, y
        c, s = np.cos(self.pose[2]), np.sin(self.pose[2])
        dx, dy = x - self.pose[0], y - self.pose[1]
        return c * dx + s * dy, -s * dx + c * dy

    def output(self) -> np.ndarray:
        """The live tracks as Track elements: positions in the sensor frame and, with a pose, the world; a
        confirmed person coasting (missed) is flagged occluded."""
        t = self.tracks
        out = np.zeros(len(t), TRACK_DTYPE)
        if not len(t):
            return out
        out["id"], out["age"], out["hits"], out["misses"] = t.id, t.age, t.hits, t.misses
        sx, sy = self._to_sensor(t.x[:, 0], t.x[:, 1])
        out["x"], out["y"] = sx, sy
        if self.pose is None:
            out["vx"], out["vy"] = t.x[:, 2], t.x[:, 3]
            for name in ("world_x", "world_y", "world_vx", "world_vy"):
                out[name] = np.nan
        else:
            c, s = np.cos(self.pose[2]), np.sin(self.pose[2])
            out["vx"], out["vy"] = c * t.x[:, 2] + s * t.x[:, 3], -s * t.x[:, 2] + c * t.x[:, 3]
            out["world_x"], out["world_y"], out["world_vx"], out["world_vy"] = t.x.T
        out["covariance"] = t.P.reshape(len(t), 16)
        out["size"] = t.size
        out["classification"] = t.cls
        out["mobility"] = t.mobility
        out["status"] = np.where(t.confirmed, np.where(t.hit, STATUS_CONFIRMED, STATUS_COASTING), STATUS_TENTATIVE)
        out["occluded"] = (t.occluded != 0) | (t.confirmed & ~t.hit & t.person)
        return out


# ------------------------------------------------------- hindsight's fixed-lag RTS smoother (docs/method.md §6.3)
# The batched numpy statements datmo_cli/tracking/_rts.smooth_rows was written from, in the same order of products
# and sums: tests/test_tracking_hindsight.py checks the kernel against `reference_smooth` bit for bit.


def rts_transition(dt: np.ndarray) -> np.ndarray:
    """F of the constant-velocity model for steps of dt s: (n, 4, 4)."""
    F = np.broadcast_to(np.eye(4), (len(dt), 4, 4)).copy()
    F[:, 0, 2] = F[:, 1, 3] = dt
    return F


def rts_process_noise(dt: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Q of white-noise acceleration of spectral density q over dt s (as the tracker's predict): (n, 4, 4)."""
    Q = np.zeros((len(dt), 4, 4))
    qa, qb, qc = 0.25 * dt**4 * q, 0.5 * dt**3 * q, dt**2 * q
    Q[:, 0, 0] = Q[:, 1, 1] = qa
    Q[:, 0, 2] = Q[:, 2, 0] = Q[:, 1, 3] = Q[:, 3, 1] = qb
    Q[:, 2, 2] = Q[:, 3, 3] = qc
    return Q


# The small batched matrix algebra below is written out in plain products and sums, in a fixed order: numpy's
# matmul, einsum and linalg hand it to BLAS and LAPACK, which pick their code (FMA or not) by the CPU, and the
# outputs must carry the same bits on every CPU (docs/reliability.md).


def rts_mm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched matrix product (n, i, k) x (n, k, j) -> (n, i, j)."""
    out = a[:, :, 0, None] * b[:, None, 0, :]
    for k in range(1, a.shape[2]):
        out = out + a[:, :, k, None] * b[:, None, k, :]
    return out


def rts_mv(a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Batched matrix-vector product (n, i, k) x (n, k) -> (n, i)."""
    out = a[:, :, 0] * x[:, None, 0]
    for k in range(1, a.shape[2]):
        out = out + a[:, :, k] * x[:, None, k]
    return out


def rts_solve_spd(m: np.ndarray, b: np.ndarray) -> np.ndarray:
    """X with m X = b for each of a batch of symmetric positive definite m (n, k, k) and b (n, k, j): Gaussian
    elimination (no pivoting needed for such m), then back substitution."""
    m, x = m.astype(np.float64, copy=True), b.astype(np.float64, copy=True)
    size = m.shape[1]
    for k in range(size):
        for i in range(k + 1, size):
            f = m[:, i, k] / m[:, k, k]
            m[:, i, k:] -= f[:, None] * m[:, k, k:]
            x[:, i, :] -= f[:, None] * x[:, k, :]
    for i in reversed(range(size)):
        acc = x[:, i, :].copy()
        for j in range(i + 1, size):
            acc -= m[:, i, j, None] * x[:, j, :]
        x[:, i, :] = acc / m[:, i, i, None]
    return x


def rts_largest_eigenvalue_above(m: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Per symmetric m (n, k, k): whether its largest eigenvalue exceeds limit (n,), that is whether limit I - m is
    not positive definite: a pivot of its elimination (no pivoting) is not positive."""
    size = m.shape[1]
    a = limit[:, None, None] * np.eye(size) - m
    above = np.zeros(len(m), bool)
    for k in range(size):
        above |= ~(a[:, k, k] > 0)
        pivot = np.where(above, 1.0, a[:, k, k])
        for i in range(k + 1, size):
            f = a[:, i, k] / pivot
            a[:, i, k:] -= f[:, None] * a[:, k, k:]
    return above


def rts_gains(
    t_ns: np.ndarray, state: np.ndarray, cov: np.ndarray, q: np.ndarray, nxt: np.ndarray, q_most: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The RTS terms of each row r that has a next row n (zeros elsewhere): the gain C_r = P_r F' Pp_n^-1 (n, 4, 4),
    the prediction of n from r xp (n, 4), and its covariance Pp (n, 4, 4), stored at row n (xp, Pp) and r (C); and
    the rows r whose next row is no Kalman step from r (a reset: a re-initialised or merged track), whose filtered
    covariance exceeds the prediction's (an update never increases it), predicted with q_most (m/s²)²/Hz at
    least, the largest q the tracker may have stepped with. q: each row's q for the step to its next row."""
    C = np.zeros((len(t_ns), 4, 4))
    xp, Pp = np.zeros((len(t_ns), 4)), np.zeros((len(t_ns), 4, 4))
    r = np.flatnonzero(nxt >= 0)
    if not len(r):
        return C, xp, Pp, r
    n = nxt[r]
    dt = (t_ns[n] - t_ns[r]).astype(np.float64) * 1e-9
    F = rts_transition(dt)
    PFt = rts_mm(cov[r], np.transpose(F, (0, 2, 1)))
    FPFt = rts_mm(F, PFt)
    pred = FPFt + rts_process_noise(dt, q[r])
    pred = 0.5 * (pred + np.transpose(pred, (0, 2, 1)))
    # C = P F' pred^-1, by solving pred' C' = (P F')' (pred symmetric)
    C[r] = np.transpose(rts_solve_spd(pred, np.transpose(PFt, (0, 2, 1))), (0, 2, 1))
    xp[n] = rts_mv(F, state[r])
    Pp[n] = pred
    widest = FPFt + rts_process_noise(dt, np.maximum(q[r], q_most))
    excess = 0.5 * (cov[n] + np.transpose(cov[n], (0, 2, 1))) - widest
    reset = rts_largest_eigenvalue_above(excess, hindsight.RESET_TOLERANCE * np.trace(widest, axis1=1, axis2=2))
    return C, xp, Pp, r[reset]


def rts_horizon(t_ns: np.ndarray, nxt: np.ndarray, rows: np.ndarray, lag_ns: int) -> np.ndarray:
    """For each of `rows`, the last row of its track stamped at most lag_ns after it (the smoother's start)."""
    cur = rows.copy()
    limit = t_ns[rows] + np.int64(lag_ns)
    active = np.arange(len(rows))
    while len(active):
        n = nxt[cur[active]]
        ok = n >= 0
        ok[ok] = t_ns[n[ok]] <= limit[active[ok]]
        active = active[ok]
        cur[active] = n[ok]
    return cur


def reference_smooth(
    t_ns: np.ndarray,
    ids: np.ndarray,
    state: np.ndarray,
    cov: np.ndarray,
    q: np.ndarray,
    rows: np.ndarray,
    lag_ns: int,
    *,
    covariance: bool = True,
    q_most: float = 0.0,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Fixed-lag RTS states of `rows`: each given its track's rows up to lag_ns after it, by the backward
    recursion x_s(r) = x(r) + C_r (x_s(n) - xp(n)), P_s(r) = P(r) + C_r (P_s(n) - Pp(n)) C_r', started at that
    horizon's filtered state. Every row of those tracks up to that horizon must be given (a track's rows end at
    its death). A reset of a track (see `gains`; q_most as there) ends its chain as its death would. Returns
    (states (len(rows), 4), covariances (len(rows), 4, 4), or None without `covariance`)."""
    rows = np.asarray(rows, np.int64)
    nxt, prv = hindsight.chains(ids, t_ns)
    C, xp, Pp, reset = rts_gains(t_ns, state, cov, q, nxt, q_most)
    prv[nxt[reset]] = -1  # a reset starts the track anew: nothing is smoothed across it
    nxt[reset] = -1
    cur = rts_horizon(t_ns, nxt, rows, lag_ns)
    xs = state[cur].copy()
    Ps = cov[cur].copy() if covariance else None
    active = np.flatnonzero(cur != rows)
    while len(active):
        c = cur[active]
        p = prv[c]
        Cp = C[p]
        xs[active] = state[p] + rts_mv(Cp, xs[active] - xp[c])
        if Ps is not None:
            Ps[active] = cov[p] + rts_mm(rts_mm(Cp, Ps[active] - Pp[c]), np.transpose(Cp, (0, 2, 1)))
        cur[active] = p
        active = active[p != rows[active]]
    return xs, Ps
