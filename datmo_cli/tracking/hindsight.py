"""Hindsight for batch outputs: a fixed-lag Rauch–Tung–Striebel smoother over the tracker's constant-velocity
model, and person labels back-filled over the same lag (docs/method.md §6.3).

A batch run (`datmo run`, `datmo track`) sees the whole log, so the state it writes for scan k may use the scans
that follow it. With a lag L (s), the output state of a track at time t is its RTS-smoothed state given every scan
up to t + L (the track's end when it dies before): exact fixed-lag smoothing, the same whatever the blocks the log
is read in. The live paths (`datmo node`, `play`, `record --live`) write the tracker's causal states.

Pure functions over arrays, no state: the caller (stages.TrackStream) keeps the last L seconds of track rows and
releases the scans older than the newest minus L. Rows are one track at one scan; a track has a row at every scan
from its birth to its death (the tracker's live tracks).

Frames and units: states [x, y, vx, vy] in the tracking frame (the world frame when the scans have poses, else the
sensor frame), m and m/s; covariances of those (4x4); stamps int64 ns; q the white-noise acceleration spectral
density of the constant-velocity model ((m/s²)²/Hz, TrackingParams.process_noise and person_process_noise).
"""

from __future__ import annotations

import numpy as np

from datmo_cli.base import libm


def chains(ids: np.ndarray, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(next, prev): for each row, the row of the same track at its next (previous) stamp, or -1."""
    n = len(ids)
    nxt, prv = np.full(n, -1, np.int64), np.full(n, -1, np.int64)
    if n < 2:
        return nxt, prv
    order = np.lexsort((t_ns, ids))
    same = ids[order[1:]] == ids[order[:-1]]
    a, b = order[:-1][same], order[1:][same]
    nxt[a], prv[b] = b, a
    return nxt, prv


RESET_TOLERANCE = 1e-3  # share of the predicted covariance's trace a filtered one may exceed it by (float32 rounding)


def smooth(
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
    horizon's filtered state, with the gain C_r = P_r F' Pp_n^-1, the prediction xp(n) = F x(r) of the next row n
    and its covariance Pp(n) = F P_r F' + Q. Every row of those tracks up to that horizon must be given (a track's
    rows end at its death). A reset ends a track's chain as its death would: a next row that is no Kalman step from
    r (a re-initialised or merged track), whose filtered covariance exceeds the prediction's (an update never
    increases it) made with q_most (m/s²)²/Hz at least, the largest q the tracker may have stepped with, by more
    than RESET_TOLERANCE of that prediction's trace. q: each row's q for the step to its next row. Returns
    (states (len(rows), 4), covariances (len(rows), 4, 4), or None without `covariance`). One compiled call
    (_rts.smooth_rows)."""
    from ._rts import smooth_rows

    t_ns = np.ascontiguousarray(t_ns, np.int64)
    nxt, prv = chains(np.asarray(ids), t_ns)
    xs, Ps = smooth_rows(
        t_ns,
        nxt,
        prv,
        np.ascontiguousarray(state, np.float64),
        np.ascontiguousarray(cov, np.float64).reshape(-1, 4, 4),
        np.ascontiguousarray(q, np.float64),
        np.ascontiguousarray(rows, np.int64),
        int(lag_ns),
        bool(covariance),
        float(q_most),
        RESET_TOLERANCE,
    )
    return xs, (Ps if covariance else None)


def promoted_within_lag(t_ns: np.ndarray, confirmed_ns: np.ndarray, person_ns: np.ndarray, lag_ns: int) -> np.ndarray:
    """Rows to label person in hindsight: those of a track that became a person within lag_ns of its first
    confirmed scan, from that scan (confirmed_ns) until the promotion (person_ns). Per row: its stamp, its
    track's first confirmed stamp and first person stamp (int64 ns; the largest int64 for never)."""
    never = np.iinfo(np.int64).max
    promoted = (person_ns != never) & (confirmed_ns != never)
    soon = promoted & (person_ns - np.where(promoted, confirmed_ns, 0) <= lag_ns)
    return soon & (t_ns >= confirmed_ns) & (t_ns < person_ns)


_NEVER = np.iinfo(np.int64).max


class Hindsight:
    """The last `lag` s of a stream of tracker outputs, given back smoothed and labelled once final: `push` each
    chunk of scans (their stamps, the tracker's TrackBlock, the sensor poses or None), then `release` gives the
    scans stamped at least `lag` s before the newest pushed (all of them when `final`) as (stamps, TrackBlock,
    poses). Memory holds the scans of the last `lag` s and of one chunk. `q`, `q_person`: the process noise of the
    tracker's predict (TrackingParams.process_noise, person_process_noise; a track classified person steps with
    q_person, any other with q). `covariance`: give the smoothed covariances (else the filter's are left)."""

    def __init__(self, lag: float, q: float, q_person: float, *, covariance: bool = True) -> None:
        if not lag > 0:
            raise ValueError(f"hindsight lag {lag!r} s: not positive")
        self.lag_ns = int(round(lag * 1e9))
        self.q, self.q_person, self.covariance = float(q), float(q_person), covariance
        self.stamps = np.zeros(0, np.int64)
        self.offsets = np.zeros(1, np.int64)
        self.items: np.ndarray | None = None
        self.tail = np.zeros((0, 0, 2))
        self.tail_count = np.zeros(0, np.int64)
        self.poses: np.ndarray | None = None
        self.confirmed: dict[int, int] = {}  # track id -> first confirmed stamp (ns)
        self.person: dict[int, int] = {}  # track id -> first stamp classified person (ns)

    def __len__(self) -> int:
        """Scans held."""
        return len(self.stamps)

    def push(self, stamps: np.ndarray, block, poses: np.ndarray | None) -> None:
        """Hold the next scans' tracks: stamps (N,) ns, the tracker's TrackBlock of them, poses (N, 3) or None."""
        from .tracker import TRACK_DTYPE

        stamps = np.asarray(stamps, np.int64)
        items = block.items[: block.offsets[-1]]
        if self.items is None:
            self.items = np.zeros(0, TRACK_DTYPE)
            self.tail = np.zeros((0, *block.tail.shape[1:])) if block.tail.ndim == 3 else np.zeros((0, 0, 2))
        self.offsets = np.concatenate([self.offsets, self.offsets[-1] + block.offsets[1:] - block.offsets[0]])
        self.stamps = np.concatenate([self.stamps, stamps])
        self.items = np.concatenate([self.items, items])
        if len(block.tail):
            self.tail = np.concatenate([self.tail, block.tail])
            self.tail_count = np.concatenate([self.tail_count, block.tail_count])
        if poses is not None:
            self.poses = poses.copy() if self.poses is None else np.concatenate([self.poses, poses])
        t = np.repeat(stamps, np.diff(block.offsets))
        ids = items["id"].astype(np.int64)
        from ..logs.vocabulary import CLASS_PERSON, STATUS_TENTATIVE

        for book, rows in ((self.confirmed, items["status"] != STATUS_TENTATIVE), (self.person, None)):
            if rows is None:
                rows = (items["classification"] == CLASS_PERSON) & (items["status"] != STATUS_TENTATIVE)
            for i, first in zip(*_first_stamps(ids[rows], t[rows]), strict=True):
                book.setdefault(i, first)

    def release(self, final: bool = False) -> tuple[np.ndarray, object, np.ndarray | None]:
        """(stamps, TrackBlock, poses or None) of the scans now final, smoothed and labelled, oldest first; they
        leave the buffer."""
        from .tracker import TrackBlock

        if not len(self.stamps):
            m = 0
        elif final:
            m = len(self.stamps)
        else:
            m = int(np.searchsorted(self.stamps, self.stamps[-1] - self.lag_ns, side="right"))
        r = int(self.offsets[m])
        items = self.items[:r].copy() if self.items is not None else np.zeros(0)
        if r:
            self._finish(items, m)
        out = (
            self.stamps[:m],
            TrackBlock(self.offsets[: m + 1].copy(), items, self.tail[:r], self.tail_count[:r]),
            None if self.poses is None else self.poses[:m],
        )
        self.stamps, self.offsets = self.stamps[m:], self.offsets[m:] - r
        if self.items is not None:
            self.items = self.items[r:]
            self.tail, self.tail_count = self.tail[r:], self.tail_count[r:]
        if self.poses is not None:
            self.poses = self.poses[m:]
        alive = set(self.items["id"].tolist()) if self.items is not None else set()
        self.confirmed = {i: v for i, v in self.confirmed.items() if i in alive}
        self.person = {i: v for i, v in self.person.items() if i in alive}
        return out

    def _finish(self, items: np.ndarray, m: int) -> None:
        """Smooth and label the first m scans' rows (`items`, a copy of them) in place."""
        from ..logs.vocabulary import CLASS_PERSON, STATUS_COASTING

        all_items, poses = self.items, self.poses
        assert all_items is not None
        world = poses is not None
        names = ("world_x", "world_y", "world_vx", "world_vy") if world else ("x", "y", "vx", "vy")
        state = np.stack([all_items[k].astype(np.float64) for k in names], axis=1)
        cov = all_items["covariance"].astype(np.float64).reshape(-1, 4, 4)
        t = np.repeat(self.stamps, np.diff(self.offsets))
        ids = all_items["id"].astype(np.int64)
        q = np.where(all_items["classification"] == CLASS_PERSON, self.q_person, self.q)
        rows = np.arange(len(items))
        q_most = max(self.q, self.q_person)
        xs, Ps = smooth(t, ids, state, cov, q, rows, self.lag_ns, covariance=self.covariance, q_most=q_most)
        for k, name in enumerate(names):
            items[name] = xs[:, k]
        if poses is not None:
            per_scan = np.diff(self.offsets[: m + 1])
            pose = np.repeat(poses[:m], per_scan, axis=0)
            c = np.repeat(libm.cos(poses[:m, 2]), per_scan)  # once a scan, not once a track row
            s = np.repeat(libm.sin(poses[:m, 2]), per_scan)
            dx, dy = xs[:, 0] - pose[:, 0], xs[:, 1] - pose[:, 1]
            items["x"], items["y"] = c * dx + s * dy, -s * dx + c * dy
            items["vx"], items["vy"] = c * xs[:, 2] + s * xs[:, 3], -s * xs[:, 2] + c * xs[:, 3]
        if Ps is not None:
            items["covariance"] = Ps.reshape(-1, 16)
        mine = ids[: len(items)].tolist()
        confirmed = np.array([self.confirmed.get(i, _NEVER) for i in mine], np.int64)
        person = np.array([self.person.get(i, _NEVER) for i in mine], np.int64)
        label = promoted_within_lag(t[: len(items)], confirmed, person, self.lag_ns)
        items["classification"][label] = CLASS_PERSON
        items["occluded"][label & (items["status"] == STATUS_COASTING)] = 1


def _first_stamps(ids: np.ndarray, t: np.ndarray) -> tuple[list[int], list[int]]:
    """(each id once, the smallest stamp of its rows)."""
    if not len(ids):
        return [], []
    order = np.lexsort((t, ids))
    first = np.concatenate([[True], ids[order[1:]] != ids[order[:-1]]])
    return ids[order][first].tolist(), t[order][first].tolist()


def smoothed_tails(
    rings: dict[int, tuple[np.ndarray, int]], tracks: np.ndarray, world: bool, length: int
) -> tuple[np.ndarray, np.ndarray]:
    """One scan's tracks' marker tails from their released (smoothed) positions, as the tracker keeps its own:
    each track's ring of its last `length` positions (tracking frame, m) with this scan's written at
    count % length, and the positions written (`rings`, track id -> (ring, count), carried from scan to scan;
    tracks gone are forgotten). Returns (tail (K, length, 2), count (K,))."""
    T = max(int(length), 1)
    xs, ys = tracks["world_x" if world else "x"].tolist(), tracks["world_y" if world else "y"].tolist()
    tail, count = np.zeros((len(tracks), T, 2)), np.zeros(len(tracks), np.int64)
    kept = {}
    for k, tid in enumerate(tracks["id"].tolist()):
        ring, n = rings.get(tid) or (np.zeros((T, 2)), 0)
        ring[n % T] = xs[k], ys[k]
        kept[tid] = (ring, n + 1)
        tail[k], count[k] = ring, n + 1
    rings.clear()
    rings.update(kept)
    return tail, count
