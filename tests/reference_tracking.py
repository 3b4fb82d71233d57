"""The tracker as it was before the compiled step (issue #13 point 2): today's rules as numpy statements over
the tracking kernels, kept as the reference the compiled tracker (datmo_cli/tracking/_step.py) is checked
against, phase by phase and run by run. Features to measurements (`reference_measurements`) and the global
nearest neighbour (`reference_gnn`, scipy's linear_sum_assignment) are the reference's too.

Frames and units as datmo_cli/tracking/tracker.py says. Not part of the package: tests only.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from datmo_cli.log import cdr, types
from datmo_cli.log.scan import ScanGeometry
from datmo_cli.tracking import _kernels, kalman
from datmo_cli.tracking.classification import (
    CLASS_CIRCLE_OBJECT,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    MOBILITY_DYNAMIC,
)
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


def reference_measurements(features: ScanFeatures, params: TrackingParams, learned: bool = False) -> Measurements:
    """The measurements of one scan's features, as datmo_cli.tracking.measurements.measurements made them."""
    c, b, li = features.circles, features.blobs, features.lines
    f8 = np.float64
    if learned:
        g = features.legs if features.legs is not None else np.zeros(0, _LEG_DTYPE)
        strong = g["probability"] >= params.leg_probability
        big = c[c["radius"] > params.leg_radius_max]   # a leg is no wider than this: that is a column's arc
        for f, e in zip(big["first"].tolist(), big["last"].tolist(), strict=True):
            strong &= (g["last"] < f) | (g["first"] > e)
        weak, g = g[~strong], g[strong]
        i8 = np.int64
        x, y, size, kind, legs, prob = _kernels.learned_measurements(
            c["first"].astype(i8), c["last"].astype(i8), c["x"].astype(f8), c["y"].astype(f8),
            c["radius"].astype(f8), b["first"].astype(i8), b["last"].astype(i8), b["x"].astype(f8),
            b["y"].astype(f8), b["size"].astype(f8), li["segment"].astype(i8), li["first"].astype(i8),
            li["last"].astype(i8), li["x_ini"].astype(f8), li["y_ini"].astype(f8), li["x_end"].astype(f8),
            li["y_end"].astype(f8), g["first"].astype(i8), g["last"].astype(i8), g["x"].astype(f8),
            g["y"].astype(f8), g["width"].astype(f8), weak["first"].astype(i8), weak["last"].astype(i8),
            weak["probability"].astype(f8), params.stride_max, params.d_max)
        raw = np.stack([g["x"].astype(f8), g["y"].astype(f8), g["width"].astype(f8), g["probability"].astype(f8)],
                       axis=1).reshape(-1, 4)
        return Measurements(x, y, size, kind, legs, raw, prob)
    x, y, size, kind, legs, lx, ly, ls = _kernels.measurements(
        c["x"].astype(f8), c["y"].astype(f8), c["radius"].astype(f8), b["x"].astype(f8), b["y"].astype(f8),
        b["size"].astype(f8), b["kind"].astype(np.int64), li["segment"].astype(np.int64), li["x_ini"].astype(f8),
        li["y_ini"].astype(f8), li["x_end"].astype(f8), li["y_end"].astype(f8), params.leg_radius_max,
        params.leg_blob_max, params.stride_max, params.d_max)
    return Measurements(x, y, size, kind, legs, np.stack([lx, ly, ls], axis=1))


STATUS_TENTATIVE, STATUS_CONFIRMED, STATUS_COASTING = 0, 1, 2
TRACK_DTYPE = cdr.element_dtype(types.TRACK)
# which measurement kinds (columns) a confirmed track may take, by the kind group that fed it most (rows:
# legs, circles, lines, blobs, -, a lone leg; see _kernels.kind_groups); tentative tracks (row 4) take any
_COMPAT = np.ones((6, N_KINDS), bool)
_COMPAT[0, [KIND_CIRCLE, KIND_RECT]] = False
_COMPAT[1, [KIND_PERSON, KIND_RECT]] = False   # a circle partly seen may pass for a leg
_COMPAT[2, [KIND_PERSON, KIND_LEG, KIND_CIRCLE]] = False
_ANY, _LONE_LEG = 4, 5
_COMPAT[_LONE_LEG, [KIND_PERSON, KIND_CIRCLE, KIND_RECT]] = False
# with a leg detector, a leg it was less sure of is a small circle or blob: people may take those too
_COMPAT_LEARNED = _COMPAT.copy()
_COMPAT_LEARNED[[0, _LONE_LEG], KIND_CIRCLE] = True
# which kinds a lost track may be reacquired on (rows as _COMPAT's): only its own, since with real perception
# the clutter around (pieces of walls and benches as blobs, short lines and small circles) is near everywhere
_REACQUIRE = np.zeros((6, N_KINDS), bool)
_REACQUIRE[0, KIND_PERSON] = _REACQUIRE[1, KIND_CIRCLE] = _REACQUIRE[2, KIND_RECT] = True
_REACQUIRE[3, KIND_BLOB] = _REACQUIRE[_ANY] = _REACQUIRE[_LONE_LEG, KIND_LEG] = True


@dataclass
class TrackArrays:
    """The state of K tracks as arrays (tracking frame, m, m/s, ns)."""

    id: np.ndarray          # (K,) int64
    x: np.ndarray           # (K, 4) float64: x, y, vx, vy
    P: np.ndarray           # (K, 4, 4)
    born_ns: np.ndarray     # (K,) int64
    last_hit_ns: np.ndarray
    age: np.ndarray         # (K,) int64, scans
    hits: np.ndarray
    misses: np.ndarray
    history: np.ndarray     # (K,) int64 bit mask of hits in the last confirm_window scans
    votes: np.ndarray       # (K, N_KINDS) int64
    lead_left: np.ndarray   # (K,) bool: the left leg was seen leading
    lead_right: np.ndarray
    moving_time: np.ndarray  # (K,) float64, s of consecutive hits with a speed above moving_speed
    size: np.ndarray        # (K,) float64, largest extent seen, m
    first: np.ndarray       # (K, 2) position when created
    last: np.ndarray        # (K, 2) position after the last hit
    confirmed: np.ndarray   # (K,) bool
    occluded: np.ndarray
    hit: np.ndarray         # (K,) bool: matched in the last step
    cls: np.ndarray         # (K,) uint8
    mobility: np.ndarray    # (K,) uint8
    tail: np.ndarray        # (K, T, 2) ring buffer of positions
    tail_count: np.ndarray  # (K,) int64, positions written so far
    leg_score: np.ndarray   # (K,) float64: running mean of the leg detector's probability of its recent hits
    sensor_ref: np.ndarray  # (K, 2) running mean of its position in the sensor frame, m
    pose_first: np.ndarray  # (K, 2) the sensor's position (tracking frame) when created
    sensor_dev: np.ndarray  # (K,) running mean of its distance from sensor_ref at its hits, m

    @classmethod
    def empty(cls, tail_length: int) -> TrackArrays:
        return cls(np.zeros(0, np.int64), np.zeros((0, 4)), np.zeros((0, 4, 4)), np.zeros(0, np.int64),
                   np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64),
                   np.zeros(0, np.int64), np.zeros((0, N_KINDS), np.int64), np.zeros(0, bool), np.zeros(0, bool),
                   np.zeros(0),
                   np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, bool), np.zeros(0, bool),
                   np.zeros(0, bool),
                   np.zeros(0, np.uint8), np.zeros(0, np.uint8), np.zeros((0, max(tail_length, 1), 2)),
                   np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))

    def __len__(self) -> int:
        return len(self.id)

    def take(self, keep: np.ndarray) -> TrackArrays:
        return TrackArrays(*(getattr(self, f.name)[keep] for f in fields(self)))

    def extend(self, other: TrackArrays) -> TrackArrays:
        return TrackArrays(*(np.concatenate([getattr(self, f.name), getattr(other, f.name)]) for f in fields(self)))

    @property
    def walking(self) -> np.ndarray:
        return self.lead_left & self.lead_right


def _leg_probability(m: Measurements, cols: np.ndarray) -> np.ndarray:
    """The leg detector's probability of measurements `cols`: a single leg's own, the mean of a pair's two,
    the segment's for the rest (1 for legs without a probability: the paper's rule)."""
    out = np.asarray(m.prob, np.float64)[cols].copy()
    legs = np.flatnonzero(m.kind[cols] <= KIND_LEG)
    raw = m.raw_legs
    if not len(legs):
        return out
    if raw.shape[1] < 4 or not len(raw):
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
    """Tracks and classifies objects scan by scan. `step` takes one scan's measurements (sensor frame)
    and returns the live tracks as Track elements (element_dtype(types.TRACK)).

    People, with a leg detector (`learned`): a track is a person while the running mean of the leg
    probability of its recent hits (two legs paired, one leg whose partner is hidden, or both legs in one
    cluster) is at least person_evidence (moving_person_evidence once it is dynamic: clutter the detector
    likes stays put), it has been seen with two legs person_pairs times (moving_person_pairs when dynamic:
    a table leg is seen alone), and it is not something the moving scanner carries (a part of the robot:
    still in the sensor frame over carried_travel). Walking is not required: a person standing, or
    followed by a robot without odometry, is a person; class and mobility are decided apart. With the
    paper's rule, a person needs paired legs and the walking pattern (legs leading in turn)."""

    def __init__(self, params: TrackingParams | None = None, geometry: ScanGeometry | None = None,
                 learned: bool = False) -> None:
        self.params = params or TrackingParams()
        self.learned = learned
        self.geometry = geometry
        self.tracks = TrackArrays.empty(self.params.tail_length)
        self.stamp_ns: int | None = None
        self._dt = 0.0
        self.next_id = 1
        self.pose: np.ndarray | None = None
        self._compat_row = np.zeros(0, np.int64)
        self._superseded = np.zeros(0, np.int64)
        w = self.params.confirm_window
        self._mask = (1 << w) - 1
        self._popcount = np.array([bin(i).count("1") for i in range(1 << w)], np.int64)
        if geometry is not None:
            self._angle_min, self._inc, self._n = geometry.angle_min, geometry.angle_increment, geometry.n_beams
            angles = geometry.angle_min + geometry.angle_increment * np.arange(geometry.n_beams)
            self._cos, self._sin = np.cos(angles), np.sin(angles)
        self._bg_score: np.ndarray | None = None   # background grid (see _background), made at the first scan
        self._bg_origin = (0.0, 0.0)
        self._on_bg = np.zeros(0, bool)

    # ---------------------------------------------------------------------------------------- step
    def step(self, stamp_ns: int, meas: Measurements, ranges: np.ndarray | None = None,
             pose: np.ndarray | None = None) -> np.ndarray:
        """Advance to the scan at `stamp_ns` (ns) with its measurements `meas` (sensor frame), its ranges
        (m, for the occlusion test; None: no missed track counts as occluded) and the sensor's world pose
        (x, y in m, theta in rad) when tracking in the world frame. Returns the live tracks."""
        p = self.params
        dt = 0.0 if self.stamp_ns is None else max((stamp_ns - self.stamp_ns) * 1e-9, 0.0)
        self._dt = dt
        self.stamp_ns = stamp_ns
        self.pose = None if pose is None else np.asarray(pose, np.float64)
        t = self.tracks
        group = _kernels.kind_groups(t.votes, t.mobility)
        self._compat_row = np.where(t.confirmed, group, _ANY)
        kalman.predict(t.x, t.P, dt, np.where((group == 0) | (group == _LONE_LEG), p.person_process_noise,
                                              p.process_noise))
        m = self._off_background(meas.moved(self.pose))
        m, rows0 = self._legs(t, m)
        rows, cols = self._associate(t, m, rows0)
        self._hit_background(t, m, rows, cols)
        self._update(t, m, rows, cols)
        rows2, cols2 = self._reacquire(t, m, rows, cols, stamp_ns)
        if len(rows2):
            keep = ~np.isin(cols, cols2)   # measurements a lost track took back from tentative tracks
            self._superseded = rows[~keep]  # those tentative tracks were started on it: they go
            rows, cols = np.concatenate([rows[keep], rows2]), np.concatenate([cols[keep], cols2])
        if len(rows):
            a = p.leg_evidence_rate
            t.leg_score[rows] = (1.0 - a) * t.leg_score[rows] + a * _leg_probability(m, cols)
        self._occlusion(t, ranges)
        self._life_cycle(t, stamp_ns)
        self._spawn(m, rows, cols, stamp_ns)
        self._classify()
        self._push_tail()
        self._background(ranges)
        return self.output()

    def _sensor(self) -> tuple[float, float, float, float]:
        """The sensor's position and heading (cos, sin) in the tracking frame."""
        if self.pose is None:
            return 0.0, 0.0, 1.0, 0.0
        return float(self.pose[0]), float(self.pose[1]), float(np.cos(self.pose[2])), float(np.sin(self.pose[2]))

    def _background(self, ranges: np.ndarray | None) -> None:
        """Add the scan's returns to the background grid: per cell, how long it has been hit without being
        seen through (see _kernels.background_update)."""
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
        # cells hit for four background times are walls: seen-through tests on them every fourth scan suffice
        self._bg_count = _kernels.background_update(
            self._bg_score, self._bg_mark, self._bg_active, self._bg_count, self._bg_scan,
            np.ascontiguousarray(ranges, np.float32), self._cos, self._sin, self._angle_min, self._inc, self._bg_lo,
            self._bg_hi, px, py, pc, ps, max(self._dt, 0.0), self._bg_origin[0], self._bg_origin[1],
            p.background_cell, self._bg_n, p.occlusion_margin, 4.0 * p.background_time)

    def _hit_background(self, t: TrackArrays, m: Measurements, rows: np.ndarray, cols: np.ndarray) -> None:
        """Which tracks take a measurement on the background this scan (their motion does not count: the
        centre of a piece of wall jumps as its ends come and go)."""
        if self._bg_score is None:
            self._on_bg = np.zeros(len(t), bool)
            return
        p = self.params
        px, py, _, _ = self._sensor()
        self._on_bg = _kernels.tracks_on_background(self._bg_score, m.x, m.y, m.size, m.kind, rows, cols, len(t), px,
                                                    py, self._bg_origin[0], self._bg_origin[1], p.background_cell,
                                                    self._bg_n, p.background_time)

    def _off_background(self, m: Measurements) -> Measurements:
        """The measurements with leg candidates on the background (a place hit for a long time: a wall, a
        bench, a column) taken out of the legs: each becomes a blob, and the other legs are paired again."""
        p = self.params
        raw = m.raw_legs
        if self._bg_score is None or not len(raw):
            return m
        px, py, _, _ = self._sensor()
        bg = _kernels.on_background(self._bg_score, raw[:, 0].copy(), raw[:, 1].copy(), raw[:, 2].copy(), px, py,
                                    self._bg_origin[0], self._bg_origin[1], p.background_cell, self._bg_n,
                                    p.background_time)
        if not bg.any():
            return m
        keep = raw[~bg]
        lx, ly, ls, kind, legs = _kernels.legs_to_measurements(keep[:, 0].copy(), keep[:, 1].copy(),
                                                               keep[:, 2].copy(), p.stride_max)
        other = m.kind > KIND_LEG
        n_bg = int(bg.sum())
        return Measurements(np.concatenate([lx, raw[bg, 0], m.x[other]]), np.concatenate([ly, raw[bg, 1], m.y[other]]),
                            np.concatenate([ls, raw[bg, 2], m.size[other]]),
                            np.concatenate([kind, np.full(n_bg, KIND_BLOB, np.int64), m.kind[other]]),
                            np.concatenate([legs, np.full((n_bg, 4), np.nan), m.legs[other]]), keep,
                            np.concatenate([np.zeros(len(lx) + n_bg), m.prob[other]]))

    def _legs(self, t: TrackArrays, m: Measurements) -> tuple[Measurements, np.ndarray]:
        """Let tracks that are legs or people take up to two leg candidates each near their prediction
        (nearest pairs first, so two people walking side by side keep their own legs), before the
        remaining legs are paired by distance alone. Returns the scan's measurements rebuilt, the first
        len(rows) of them formed for tracks `rows` from their legs."""
        p = self.params
        none = np.zeros(0, np.int64)
        raw = m.raw_legs
        if not len(t) or not len(raw):
            return m, none
        legs_votes = t.votes[:, KIND_PERSON] + t.votes[:, KIND_LEG]
        leggy = np.flatnonzero((legs_votes >= p.person_votes * np.maximum(t.votes.sum(axis=1), 1))
                               & (legs_votes > 0) & (t.cls <= CLASS_PERSON) & t.confirmed)
        if not len(leggy):
            return m, none
        owner, x, y, size, kind, legs = _kernels.leg_stage_measurements(
            t.x[leggy, 0], t.x[leggy, 1], raw[:, 0].copy(), raw[:, 1].copy(), raw[:, 2].copy(),
            p.leg_reach, p.stride_max, m.x, m.y, m.size, m.kind, m.legs)
        if not len(owner):
            return m, none
        prob = np.zeros(len(x))
        other = m.kind > KIND_LEG
        if other.any():
            prob[len(x) - int(other.sum()):] = m.prob[other]
        return Measurements(x, y, size, kind, legs, raw, prob), leggy[owner]

    def _associate(self, t: TrackArrays, m: Measurements, rows0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Tracks `rows0` own measurements 0..len(rows0)-1; the others are gated and assigned by GNN."""
        p = self.params
        n0 = len(rows0)
        cols0 = np.arange(n0, dtype=np.int64)
        if not len(t) or len(m) == n0:
            return rows0, cols0
        d2, allowed = _kernels.gated_costs(t.x, t.P, m.x, m.y, m.kind, p.measurement_noise,
                                               p.leg_measurement_noise, p.gate, p.max_gate_distance,
                                               _COMPAT_LEARNED if self.learned else _COMPAT, self._compat_row)
        if n0:
            allowed[rows0, :] = False
            allowed[:, :n0] = False
        rows, cols = gnn(d2, allowed)
        return np.concatenate([rows0, rows]), np.concatenate([cols0, cols])

    def _update(self, t: TrackArrays, m: Measurements, rows: np.ndarray, cols: np.ndarray) -> None:
        p = self.params
        moving = t.moving_time >= p.walking_after
        _kernels.apply_updates(t.x, t.P, t.last, t.hit, t.votes, t.size, t.lead_left, t.lead_right, moving, rows,
                               m.x[cols], m.y[cols], m.kind[cols], m.size[cols], m.legs[cols], p.measurement_noise,
                               p.leg_measurement_noise, p.moving_speed, p.step_min, p.step_max)

    def _reacquire(self, t: TrackArrays, m: Measurements, taken_by: np.ndarray, taken: np.ndarray,
                   stamp_ns: int) -> tuple[np.ndarray, np.ndarray]:
        """Give a confirmed track lost while occluded or out of view the nearest free measurement it could
        have reached since its last hit (at `reacquire_speed`), restarting its filter there; a prediction at
        constant velocity does not follow someone who turned while hidden."""
        p = self.params
        lost = np.flatnonzero(~t.hit & t.confirmed & t.occluded)
        if not len(lost) or not len(m):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        free = m.kind != KIND_LEG   # a lone leg may be someone else's second leg: reacquire on pairs
        free[taken] = False
        # a tentative track started on someone coming back into view does not keep them from their old track
        # (a mover's: a static object's track does not jump onto a new one)
        tentative = np.zeros(len(m), bool)
        tentative[taken[~t.confirmed[taken_by]]] = True
        near = (t.hit & t.confirmed)[:, None] & (np.hypot(m.x[None, :] - t.x[:, 0:1], m.y[None, :] - t.x[:, 1:2])
                                 <= p.leg_beside)
        free &= ~near.any(axis=0)
        cand = np.flatnonzero(free | (tentative & ~near.any(axis=0)))
        if not len(cand):
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        dist = np.hypot(m.x[cand][None, :] - t.last[lost, 0:1], m.y[cand][None, :] - t.last[lost, 1:2])
        reach = np.minimum(p.reacquire_speed * (stamp_ns - t.last_hit_ns[lost]) * 1e-9 + p.max_gate_distance,
                           p.reacquire_distance)
        allowed = (dist <= reach[:, None]) & _REACQUIRE[self._compat_row[lost]][:, m.kind[cand]]
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

    def _occlusion(self, t: TrackArrays, ranges: np.ndarray | None) -> None:
        """Mark each missed track occluded when a return nearer than it covers its bearing, or when it is
        outside the field of view or the range limit."""
        t.occluded[:] = False
        if ranges is None or self.geometry is None or t.hit.all():
            return
        sx, sy = self._to_sensor(t.x[:, 0], t.x[:, 1])
        t.occluded = _kernels.occlusion(np.ascontiguousarray(sx), np.ascontiguousarray(sy), t.size, ~t.hit,
                                        np.ascontiguousarray(ranges, np.float32), self._angle_min, self._inc,
                                        self.geometry.range_max, self.params.occlusion_margin)

    def _life_cycle(self, t: TrackArrays, stamp_ns: int) -> None:
        p = self.params
        dead = _kernels.life_cycle(t.hit, t.age, t.hits, t.misses, t.last_hit_ns, t.history, t.confirmed,
                                   t.occluded, stamp_ns, self._mask, self._popcount, p.confirm_hits, p.delete_after,
                                   p.delete_after_occluded, p.tentative_delete_after)
        dead |= self._duplicates(t)
        if len(self._superseded):
            dead[self._superseded] = True
            self._superseded = np.zeros(0, np.int64)
        if dead.any():
            self.tracks = t.take(~dead)
            if len(self._on_bg) == len(dead):
                self._on_bg = self._on_bg[~dead]

    def _duplicates(self, t: TrackArrays) -> np.ndarray:
        """Tracks of legs or people closer than `merge_distance` to a higher-ranked such track, unless both
        are confirmed and move differently: one person's two legs must not keep two tracks alive. Rank: a
        person before anything else, then a dynamic track, then more hits (a person walking past a bench
        keeps its track; the track on the bench's pieces its passing uncovers goes)."""
        legs = t.votes[:, KIND_PERSON] + t.votes[:, KIND_LEG]
        candidate = (legs > 0) & (t.cls <= CLASS_PERSON)
        x = np.ascontiguousarray(t.x.T)
        rank = (t.hits.astype(np.int64) * 2 + t.confirmed + (t.mobility == MOBILITY_DYNAMIC) * (1 << 40)
                + (t.cls == CLASS_PERSON) * (1 << 41))
        return _kernels.duplicates(x[0], x[1], x[2], x[3], candidate, t.confirmed, rank,
                                   self.params.merge_distance, self.params.merge_speed)

    def _spawn(self, m: Measurements, rows: np.ndarray, cols: np.ndarray, stamp_ns: int) -> None:
        """Start tentative tracks on measurements no track took, except legs beside a track that took a
        leg or a person (the other leg of someone tracked) and measurements on top of an existing track."""
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
            small = (m.kind[idx] == KIND_LEG) | (m.kind[idx] == KIND_BLOB)
            beside = small & (d[:, legged] <= p.leg_beside).any(axis=1)
            on_top = (d <= p.spawn_clearance).any(axis=1)
            idx = idx[~(beside | on_top)]
        n = len(idx)
        if not n:
            return
        T = self.tracks.tail.shape[1]
        x = np.zeros((n, 4))
        x[:, 0], x[:, 1] = m.x[idx], m.y[idx]
        P = np.zeros((n, 4, 4))
        r = np.where(m.kind[idx] == KIND_LEG, p.leg_measurement_noise, p.measurement_noise)
        P[:, 0, 0] = P[:, 1, 1] = r**2
        P[:, 2, 2] = P[:, 3, 3] = p.initial_speed_sigma**2
        votes = np.zeros((n, N_KINDS), np.int64)
        votes[np.arange(n), m.kind[idx]] = 1
        ones, zeros = np.ones(n, np.int64), np.zeros(n, np.int64)
        new = TrackArrays(np.arange(self.next_id, self.next_id + n, dtype=np.int64), x, P,
                          np.full(n, stamp_ns, np.int64), np.full(n, stamp_ns, np.int64), ones, ones, zeros, ones,
                          votes, np.zeros(n, bool), np.zeros(n, bool), np.zeros(n), m.size[idx].astype(np.float64),
                          x[:, :2].copy(), x[:, :2].copy(), np.zeros(n, bool), np.zeros(n, bool), np.ones(n, bool),
                          np.zeros(n, np.uint8), np.full(n, 2, np.uint8), np.zeros((n, T, 2)), zeros,
                          _leg_probability(m, idx), np.stack(self._to_sensor(x[:, 0], x[:, 1]), axis=1),
                          np.tile(np.array(self._sensor()[:2]), (n, 1)), np.zeros(n))
        self.next_id += n
        self.tracks = self.tracks.extend(new)

    def _classify(self) -> None:
        t, p = self.tracks, self.params
        if not len(t):
            return
        speed = np.hypot(t.x[:, 2], t.x[:, 3])
        # motion must be sustained: segment ends that come and go make a static object's centre jump
        on_bg = np.zeros(len(t), bool)
        on_bg[:len(self._on_bg)] = self._on_bg   # tracks spawned this scan come after
        t.moving_time = np.where(t.hit & ~on_bg & (speed > p.moving_speed), t.moving_time + self._dt, 0.0)
        speed = np.where(t.moving_time >= p.moving_time, speed, 0.0)
        moved = np.hypot(t.x[:, 0] - t.first[:, 0], t.x[:, 1] - t.first[:, 1])
        age_s = (self.stamp_ns - t.born_ns) * 1e-9
        t.cls, t.mobility = _kernels.classify(t.votes, t.lead_left & t.lead_right, t.mobility, age_s, t.size, moved,
                                              speed, t.confirmed, p.person_votes, p.d_max, p.undefined_window,
                                              p.moving_distance, p.moving_speed)
        if self.learned:
            # a person is what the leg detector keeps seeing, walking or not; the rest by the shape of its hits
            shape = t.votes[:, [KIND_CIRCLE, KIND_RECT, KIND_BLOB]]
            by_shape = np.array([CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT, CLASS_UNKNOWN],
                                np.uint8)[np.argmax(shape, axis=1)]
            by_shape[shape.sum(axis=1) == 0] = CLASS_UNKNOWN
            # a thing the scanner carries (a part of the robot) keeps its place in the sensor frame as it drives
            sx, sy = self._to_sensor(t.x[:, 0], t.x[:, 1])
            a = np.where(t.hit, p.leg_evidence_rate, 0.0)
            dev = np.hypot(sx - t.sensor_ref[:, 0], sy - t.sensor_ref[:, 1])
            t.sensor_dev = (1.0 - a) * t.sensor_dev + a * dev
            t.sensor_ref[:, 0] = (1.0 - a) * t.sensor_ref[:, 0] + a * sx
            t.sensor_ref[:, 1] = (1.0 - a) * t.sensor_ref[:, 1] + a * sy
            px, py, _, _ = self._sensor()
            travel = np.hypot(px - t.pose_first[:, 0], py - t.pose_first[:, 1])
            carried = (travel >= p.carried_travel) & (t.sensor_dev <= p.carried_radius)
            dynamic = t.mobility == MOBILITY_DYNAMIC
            need = np.where(dynamic, p.moving_person_evidence, p.person_evidence)
            pairs = np.where(dynamic, p.moving_person_pairs, p.person_pairs)
            person = (t.leg_score >= need) & (t.votes[:, KIND_PERSON] >= pairs) & ~carried
            t.cls = np.where(person, np.uint8(CLASS_PERSON), by_shape).astype(np.uint8)

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
        """The live tracks as Track elements: positions in the sensor frame and, with a pose, the world."""
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
        out["occluded"] = t.occluded
        return out
