"""The landmark database (docs/method.md §6.2): a run's landmark detections (landmarks.py) accumulated over
its scans, in the world frame (with odometry) or the sensor frame.

A detection within `landmark_match` of a landmark of the same type is that landmark (count, last seen, running
mean position); a landmark enters the database after `landmark_min_count` scans, and a column candidate that
drifts more than `column_max_drift` (a moving circle object) never does.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..base.numba_runtime import key_kernel_cache_on_sources
from .feature_layout import (
    FP_COLUMN_MAX_DRIFT,
    FP_COLUMN_MIN_TIME,
    FP_COLUMN_RADIUS_MIN,
    FP_LANDMARK_MATCH,
    FP_LANDMARK_MIN_COUNT,
)
from .landmarks import DET_SCAN, LANDMARK_DTYPE
from .params import FeatureParams

key_kernel_cache_on_sources()  # before any kernel is declared: their cache stamps cover what they read

# columns of the database rows: type, x, y, orientation, size, count, first scan, last scan, x0, y0, moved,
# confirmed, hidden (a column candidate at a bench's support: part of the bench, never listed)
DB_COLUMNS = 13
DB_MOVED, DB_CONFIRMED, DB_HIDDEN = 10, 11, 12
# counters of a database carried from block to block: rows used, live rows, confirmed rows
COUNT_ROWS, COUNT_LIVE, COUNT_CONFIRMED = 0, 1, 2
FORGET_SCANS = 10  # a candidate seen fewer than landmark_min_count times and not for this many scans is forgotten


# inlined into accumulate (one compiled function, as before it was cut out)
@njit(cache=True, inline="always")
def _fold(d, k, stamp, p, state, used):
    """Fold the detection d (DET_*) of scan k, stamped `stamp` ns, into the database (p and state as
    accumulate takes them): it is the nearest live landmark of its type within the gate not already seen in
    scan k (count, last seen, running mean; a bench: its most complete view), or a new row. used = (rows, live
    rows, confirmed rows) before it; returns them after it."""
    match = p[FP_LANDMARK_MATCH]
    min_count = p[FP_LANDMARK_MIN_COUNT]
    max_drift = p[FP_COLUMN_MAX_DRIFT]
    column_time = p[FP_COLUMN_MIN_TIME] * 1e9  # ns
    db, first_ns, last_ns, live, confirmed, _ = state
    n, nlive, nconf = used
    t = d[1]
    x = d[2]
    y = d[3]
    best = -1
    bd = 2 * match
    # a column does not move: a tight gate; a bench's visible middle moves with what hides its ends
    gate = max_drift if t == 4.0 else (2 * match if t == 5.0 else match)
    for u in range(nlive):
        q = live[u]
        if db[q, 0] == t:
            dq = np.hypot(db[q, 1] - x, db[q, 2] - y)
            if t == 5.0:
                # a bench is seen whole or in parts (people and columns hide its ends): a detection
                # belongs to it when it lies on the bench's axis within its length
                ux = np.cos(db[q, 3])
                uy = np.sin(db[q, 3])
                along = abs((x - db[q, 1]) * ux + (y - db[q, 2]) * uy)
                across = abs(-(x - db[q, 1]) * uy + (y - db[q, 2]) * ux)
                dq = across + max(0.0, along - 0.5 * db[q, 4])
            if dq <= min(bd, gate) and db[q, 7] != k:
                bd = dq
                best = q
    if best < 0 and n < db.shape[0]:
        for c in range(DB_COLUMNS):
            db[n, c] = 0.0
        db[n, 0] = t
        db[n, 1] = x
        db[n, 2] = y
        db[n, 3] = d[4]
        db[n, 4] = d[5]
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
            confirmed[nconf] = n - 1
            nconf += 1
    elif best >= 0:
        c = db[best, 5] + 1.0
        if t == 5.0:
            if d[5] > db[best, 4]:  # the most complete view of a bench stands for it
                db[best, 1] = x
                db[best, 2] = y
                db[best, 3] = d[4]
                db[best, 4] = d[5]
        else:
            db[best, 1] += (x - db[best, 1]) / c
            db[best, 2] += (y - db[best, 2]) / c
            db[best, 3] = d[4]
            db[best, 4] += (d[5] - db[best, 4]) / c
        db[best, 5] = c
        db[best, 7] = k
        last_ns[best] = stamp
        # a column that drifts from where it was first seen is a mover, not a landmark
        if t == 4.0 and np.hypot(x - db[best, 8], y - db[best, 9]) > max_drift:
            db[best, DB_MOVED] = 1.0
        if db[best, DB_CONFIRMED] == 0.0 and c >= min_count and (t != 4.0 or stamp - first_ns[best] >= column_time):
            db[best, DB_CONFIRMED] = 1.0
            confirmed[nconf] = best
            nconf += 1
    return n, nlive, nconf


@njit(cache=True)
def accumulate(det, stamps, k0, p, state, snap):
    """Fold one block of scans' detections (rows DET_*, sorted by scan; scans k0 .. k0 + len(stamps) - 1,
    stamped `stamps` ns) into the database.

    p: the feature parameter vector (FeatureParams.kernel_vector; FP_LANDMARK_*, FP_COLUMN_*); state = (db, first_ns,
    last_ns, live, confirmed, counters): the database `db` (rows as DB_COLUMNS; first_ns/last_ns: the stamps
    its row was first and last seen), carrying `live`, `confirmed` and `counters` (COUNT_*) from the blocks
    before; snap = (snap_idx, snap_vals, snap_last, snap_count). After each scan k, the landmarks in the
    database (confirmed, not moved, not hidden) are appended to snap_idx (row index), snap_vals (x, y,
    orientation, size, count, last scan: their state then) and snap_last (last seen, ns), and their number
    stored in snap_count[k - k0]. A candidate seen fewer than landmark_min_count times and not for FORGET_SCANS
    scans is forgotten; a column enters the database only once seen over column_min_time (a circle object that
    stops for a moment is not a column); a column candidate by a confirmed bench's support (its end,
    column_radius_min in) is hidden. Capacities: db rows >= counters[COUNT_ROWS] + len(det), snapshot entries >=
    len(stamps) * (counters[COUNT_CONFIRMED] + len(det)). Returns the snapshot entries written."""
    min_count = p[FP_LANDMARK_MIN_COUNT]
    column_radius_min = p[FP_COLUMN_RADIUS_MIN]
    db, first_ns, last_ns, live, confirmed, counters = state
    snap_idx, snap_vals, snap_last, snap_count = snap
    n_scans = stamps.shape[0]
    nd = det.shape[0]
    n = counters[COUNT_ROWS]
    nlive = counters[COUNT_LIVE]
    nconf = counters[COUNT_CONFIRMED]
    ns = 0
    j = 0
    for kk in range(n_scans):
        k = k0 + kk
        while j < nd and det[j, 0] == k:
            n, nlive, nconf = _fold(det[j], k, stamps[kk], p, state, (n, nlive, nconf))
            j += 1
        u = 0
        while u < nlive:  # forget stale candidates and moved columns
            q = live[u]
            if (db[q, DB_CONFIRMED] == 0.0 and k - db[q, 7] > FORGET_SCANS) or db[q, DB_MOVED] != 0.0:
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
    counters[COUNT_ROWS] = n
    counters[COUNT_LIVE] = nlive
    counters[COUNT_CONFIRMED] = nconf
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
        self.vec = p.kernel_vector()
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
        return self.db[: self.counters[COUNT_ROWS]]

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
        nb = len(stamps)
        det[:, DET_SCAN] += self.scans
        self._reserve(int(self.counters[COUNT_ROWS]) + len(det) + 1)
        cap = nb * (int(self.counters[COUNT_CONFIRMED]) + len(det)) + 1
        snap_idx, snap_vals = np.zeros(cap, np.int64), np.zeros((cap, 6))
        snap_last, snap_count = np.zeros(cap, np.int64), np.zeros(nb, np.int64)
        state = (self.db, self.first_ns, self.last_ns, self.live, self.confirmed, self.counters)
        ns = accumulate(det, stamps, self.scans, self.vec, state, (snap_idx, snap_vals, snap_last, snap_count))
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
