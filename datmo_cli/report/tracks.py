"""Per-track figures of the report: `track_history` (every state of every track, grouped by id, for the plot)
and `TrackStats` (O(1) numbers per track accumulated block by block). Times in ns (header stamps), positions in
m and speeds in m/s, in the sensor frame and, when every state has finite world coordinates, the world frame."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..logs import cdr, types
from ..logs.vocabulary import CLASS_NAMES, MOBILITY_NAMES, STATUS_CONFIRMED
from .decode import Decoded


@dataclass
class TrackHistory:
    """Every reported state of every track, sorted by track id then stamp; track ids[g] is rows
    starts[g]:starts[g + 1] of the per-state arrays below."""

    ids: np.ndarray  # (G,) track ids
    starts: np.ndarray  # (G + 1,)
    stamps: np.ndarray  # (M,) ns
    x: np.ndarray  # (M,) m, world frame when finite for the whole run, else sensor frame
    y: np.ndarray
    speed: np.ndarray  # (M,) m/s, |velocity| in the same frame
    states: np.ndarray  # (M,) Track elements
    world: bool  # True when x, y are world-frame


def track_history(tracks: Decoded, *, world: bool = True) -> TrackHistory:
    """Group the states of a /datmo/tracks channel by track id (for the plot, which draws every state);
    positions in the world frame when `world` and every state has finite world coordinates, else in the
    sensor frame."""
    t = tracks.items.get("tracks", np.zeros(0, cdr.element_dtype(types.TRACK)))
    stamps = tracks.stamps[tracks.message_index("tracks")] if len(t) else np.zeros(0, np.int64)
    order = np.lexsort((stamps, t["id"]))
    t, stamps = t[order], stamps[order]
    world = world and bool(len(t)) and bool(np.isfinite(t["world_x"]).all() and np.isfinite(t["world_y"]).all())
    px, py, vx, vy = ("world_x", "world_y", "world_vx", "world_vy") if world else ("x", "y", "vx", "vy")
    ids, starts = np.unique(t["id"], return_index=True)
    return TrackHistory(
        ids,
        np.append(starts, len(t)).astype(np.int64),
        stamps,
        t[px].astype(np.float64),
        t[py].astype(np.float64),
        np.hypot(t[vx], t[vy]).astype(np.float64),
        t,
        world,
    )


FRAMES = (("x", "y", "vx", "vy"), ("world_x", "world_y", "world_vx", "world_vy"))  # sensor, world
_I64_MIN, _I64_MAX = np.iinfo(np.int64).min, np.iinfo(np.int64).max


class TrackStats:
    """What the report says of each track, accumulated from its states block by block: O(1) numbers per
    track (arrays indexed by slot, slots in ascending track id), nothing per state or per scan.

    Per track: first and last header stamp (ns; min and max over its states) and the class and mobility of
    the state at the last stamp (the later in the file on a tie); states; occluded states and occlusion
    episodes (runs of consecutive occluded states); confirmed states; and in both frames (row 0 sensor,
    row 1 world; m, m/s) the distance over consecutive confirmed positions, the sum and max of the filter
    speed |v| over confirmed states and the last confirmed position (NaN before the first).

    Each block's states are taken in each track's stamp order (the file order on a tie) and sums are added
    state by state (np.add.at), so the figures do not depend on how the states are split in blocks, as long
    as no state comes in a later block than a state of its track with a later stamp: `late` counts those
    (never in a log datmo writes, whose messages are in stamp order); they are taken in file order.
    """

    def __init__(self) -> None:
        self.ids = np.zeros(0, np.int64)
        self.first_ns = np.zeros(0, np.int64)
        self.last_ns = np.zeros(0, np.int64)
        self.classification = np.zeros(0, np.uint8)
        self.mobility = np.zeros(0, np.uint8)
        self.states = np.zeros(0, np.int64)
        self.occluded = np.zeros(0, np.int64)
        self.occlusions = np.zeros(0, np.int64)
        self.last_occluded = np.zeros(0, bool)
        self.confirmed = np.zeros(0, np.int64)
        self.distance = np.zeros((2, 0))
        self.speed_sum = np.zeros((2, 0))
        self.speed_max = np.zeros((2, 0))
        self.last_x = np.zeros((2, 0))
        self.last_y = np.zeros((2, 0))
        self.n_states = 0  # every state of every track
        self.late = 0  # states added after a later-stamped state of their track's (a block before)
        self.world_finite = True  # every state so far has finite world_x, world_y

    _FILL = {"first_ns": _I64_MAX, "last_ns": _I64_MIN, "speed_max": -np.inf, "last_x": np.nan, "last_y": np.nan}
    _PER_TRACK = (
        "ids",
        "first_ns",
        "last_ns",
        "classification",
        "mobility",
        "states",
        "occluded",
        "occlusions",
        "last_occluded",
        "confirmed",
        "distance",
        "speed_sum",
        "speed_max",
        "last_x",
        "last_y",
    )

    def __len__(self) -> int:
        return len(self.ids)

    def _slots(self, ids: np.ndarray) -> np.ndarray:
        """The slot of each track id, new ids given slots (every per-track array grows by one per new id)."""
        new = np.setdiff1d(ids, self.ids)
        if len(new):
            merged = np.union1d(self.ids, new)
            old = np.searchsorted(merged, self.ids)
            for name in self._PER_TRACK:
                a = getattr(self, name)
                grown = np.full(a.shape[:-1] + (len(merged),), self._FILL.get(name, 0), a.dtype)
                grown[..., old] = a
                setattr(self, name, grown)
            self.ids = merged
        return np.searchsorted(self.ids, ids)

    def add(self, stamps: np.ndarray, states: np.ndarray) -> None:
        """Add a block of track states (Track elements, file order) with the header stamp (ns) of their message."""
        if not len(states):
            return
        self.n_states += len(states)
        self.world_finite = self.world_finite and bool(
            np.isfinite(states["world_x"]).all() and np.isfinite(states["world_y"]).all()
        )
        slot = self._slots(states["id"].astype(np.int64))
        n = len(self.ids)
        self.states += np.bincount(slot, minlength=n)
        np.minimum.at(self.first_ns, slot, stamps)
        self.late += int(np.count_nonzero(stamps < self.last_ns[slot]))
        # each track's states in stamp order (file order on a tie); its last: class and mobility
        order = np.lexsort((np.arange(len(slot)), stamps, slot))
        s = slot[order]
        ends = order[np.r_[s[1:] != s[:-1], True]]
        later = stamps[ends] >= self.last_ns[slot[ends]]
        ends = ends[later]
        self.last_ns[slot[ends]] = stamps[ends]
        self.classification[slot[ends]] = states["classification"][ends]
        self.mobility[slot[ends]] = states["mobility"][ends]
        # occlusion episodes, then distances and speeds of confirmed states
        st = states[order]
        occ = st["occluded"].astype(bool)
        prev = np.r_[False, occ[:-1]]
        first = np.r_[True, s[1:] != s[:-1]]
        prev[first] = self.last_occluded[s[first]]
        self.occluded += np.bincount(s, weights=occ, minlength=n).astype(np.int64)
        self.occlusions += np.bincount(s, weights=occ & ~prev, minlength=n).astype(np.int64)
        last = np.r_[s[1:] != s[:-1], True]
        self.last_occluded[s[last]] = occ[last]
        conf = st["status"] == STATUS_CONFIRMED
        s, st = s[conf], st[conf]
        if not len(s):
            return
        first = np.r_[True, s[1:] != s[:-1]]
        last = np.r_[s[1:] != s[:-1], True]
        step = ~first  # a step from the track's previous confirmed position
        step[first] = self.confirmed[s[first]] > 0
        self.confirmed += np.bincount(s, minlength=n)
        for f, (px, py, vx, vy) in enumerate(FRAMES):
            x, y = st[px].astype(np.float64), st[py].astype(np.float64)
            x0, y0 = np.r_[np.nan, x[:-1]], np.r_[np.nan, y[:-1]]
            x0[first], y0[first] = self.last_x[f, s[first]], self.last_y[f, s[first]]
            speed = np.hypot(st[vx], st[vy]).astype(np.float64)
            with np.errstate(invalid="ignore"):  # NaN world states of a log without odometry
                np.add.at(self.distance[f], s[step], np.hypot(x[step] - x0[step], y[step] - y0[step]))
                np.add.at(self.speed_sum[f], s, speed)
                np.maximum.at(self.speed_max[f], s, speed)
            self.last_x[f, s[last]], self.last_y[f, s[last]] = x[last], y[last]

    @property
    def world(self) -> bool:
        """Whether positions are reported in the world frame: every state has finite world coordinates."""
        return bool(self.n_states) and self.world_finite

    def rows(self, t0_ns: int) -> list[dict]:
        """One dict per track, in id order: class and mobility (its last state's); first, last and lifetime
        (s from t0, over every reported state); and over its confirmed states only (coasting predictions and
        tentative states are not observations): distance travelled (m, sum of steps between consecutive
        confirmed positions), mean and max filter speed (m/s), in the world frame when `world` else the
        sensor frame; occlusions (episodes of consecutive occluded scans), whether it was ever confirmed, and
        its last confirmed position x_m, y_m (m, same frame; None when never confirmed)."""
        f = int(self.world)
        rows = []
        for g, tid in enumerate(self.ids.tolist()):
            t_first, t_last = (self.first_ns[g] - t0_ns) / 1e9, (self.last_ns[g] - t0_ns) / 1e9
            n_conf = int(self.confirmed[g])
            rows.append(
                {
                    "id": tid,
                    "class": CLASS_NAMES.get(int(self.classification[g]), "unknown"),
                    "mobility": MOBILITY_NAMES.get(int(self.mobility[g]), "undefined"),
                    "first_s": round(float(t_first), 3),
                    "last_s": round(float(t_last), 3),
                    "lifetime_s": round(float(t_last - t_first), 3),
                    "scans": int(self.states[g]),
                    "distance_m": round(float(self.distance[f, g]), 3),
                    "mean_speed_mps": round(float(self.speed_sum[f, g] / n_conf), 3) if n_conf else 0.0,
                    "max_speed_mps": round(float(self.speed_max[f, g]), 3) if n_conf else 0.0,
                    "occlusions": int(self.occlusions[g]),
                    "occluded_scans": int(self.occluded[g]),
                    "confirmed": bool(n_conf),
                    "x_m": _metres(self.last_x[f, g]),
                    "y_m": _metres(self.last_y[f, g]),
                }
            )
        return rows


def _metres(v: float) -> float | None:
    """A position rounded to the millimetre; None when not finite."""
    return round(float(v), 3) if np.isfinite(v) else None
