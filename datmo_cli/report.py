"""The per-run report: what a processed log saw, summarised from its decoded channels, and its formats.

A RunAccumulator gathers the report from decoded messages fed block by block (O(1) numbers per track, per
distinct scan period and per feature kind; nothing per scan), then gives a RunSummary of plain dicts.
`summarise_file` (and `stream_run`) walk a log once, BLOCK_MESSAGES messages at a time, so the report of a
log of any length fits in bounded memory: the one place here that reads a file. `RunData.from_log` decodes
an already-read log whole (for the plot and evaluate) and `summarise` feeds it to the same accumulator,
so both give the same summary. `tables`, `render_rich`, `render_markdown`, `render_csv` and `to_json`
format summaries. Times in the report are seconds from the first scan; positions and distances in metres,
in the world (odometry) frame when every track state has finite world coordinates, else in the sensor
frame; speeds in m/s.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .csvsafe import neutralise
from .errors import InputError, MissingChannelError
from .log import cdr, mcapio, types
from .log.vocabulary import (
    CLASS_CIRCLE_OBJECT,
    CLASS_NAMES,
    CLASS_PERSON,
    CLASS_RECTANGULAR_OBJECT,
    CLASS_UNKNOWN,
    LANDMARK_NAMES,
    MOBILITY_DYNAMIC,
    MOBILITY_NAMES,
    MOBILITY_STATIC,
    MOBILITY_UNDEFINED,
    STATUS_CONFIRMED,
)
from .text import printable

SORT_KEYS = ("lifetime", "distance", "speed", "first", "id")
FORMATS = ("rich", "json", "csv", "markdown")


# ------------------------------------------------------------------------------------------- decoding


@dataclass
class Decoded:
    """One channel decoded into arrays: message k's elements of sequence field f are
    `items[f][offsets[f][k]:offsets[f][k + 1]]`; `scalars[name][k]` are its numeric scalar fields."""

    stamps: np.ndarray  # (N,) int64, header stamps, ns
    frame_id: str
    scalars: dict[str, np.ndarray] = field(default_factory=dict)
    items: dict[str, np.ndarray] = field(default_factory=dict)
    offsets: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.stamps)

    def counts(self, name: str) -> np.ndarray:
        """Elements of sequence `name` in each message, (N,) int64."""
        return np.diff(self.offsets[name])

    def message_index(self, name: str) -> np.ndarray:
        """For each element of sequence `name`, the index of its message."""
        return np.repeat(np.arange(len(self.stamps)), self.counts(name))


def decode_channel(msgtype: str, payloads: list[bytes], first: int = 0) -> Decoded:
    """Decode every CDR payload of a flat datmo_msgs type into a Decoded (cdr.DecodeError names a damaged one,
    counted from `first`: wrap the call in mcapio.decoding to name the file and topic too)."""
    decoded = cdr.decode_many(msgtype, payloads, first)
    stamps = np.array([d["stamp_ns"] for d in decoded], np.int64)
    out = Decoded(stamps, decoded[0]["frame_id"] if decoded else "")
    if not decoded:
        return out
    for name, value in decoded[0].items():
        if name in ("stamp_ns", "frame_id") or isinstance(value, str):
            continue
        if isinstance(value, np.ndarray) and value.dtype.names:
            parts = [d[name] for d in decoded]  # joined as bytes: np.concatenate promotes the dtype per part
            out.items[name] = np.frombuffer(b"".join([p.tobytes() for p in parts]), value.dtype).copy()
            out.offsets[name] = np.concatenate([[0], np.cumsum([len(p) for p in parts])]).astype(np.int64)
        elif not isinstance(value, np.ndarray):
            out.scalars[name] = np.array([d[name] for d in decoded])
    return out


def require(log: mcapio.LogContents, topic: str) -> None:
    """Raise MissingChannelError naming the command that makes `topic` when the log has no messages on it."""
    if not log.has(topic):
        maker = mcapio.PRODUCER.get(topic)
        hint = f"; run {maker} first" if maker else ""
        raise MissingChannelError(f"{log.path}: no messages on {topic}{hint}")


@dataclass
class RunData:
    """The decoded channels of one processed log that the report, the plot and evaluate use."""

    name: str
    metadata: dict[str, dict[str, str]]
    scan_stamps: np.ndarray  # (N,) int64 ns
    n_beams: int
    tracks: Decoded
    features: Decoded | None = None
    landmarks: Decoded | None = None
    ground_truth: Decoded | None = None
    scans: object | None = None  # log.scan.ScanRun, for the plot
    odometry: object | None = None  # log.scan.Odometry or None

    @classmethod
    def from_log(cls, log: mcapio.LogContents, *, keep_scans: bool = False) -> RunData:
        """Decode a log read with (at least) /scan and /datmo/tracks; the other channels when present.

        Raises MissingChannelError naming the command to run first when /scan or /datmo/tracks is absent.
        """
        require(log, mcapio.TOPIC_SCAN)
        require(log, mcapio.TOPIC_TRACKS)
        run = mcapio.run_from_log(log)

        def channel(topic: str, msgtype: str) -> Decoded | None:
            stamps, payloads = log.messages.get(topic, ([], []))
            with mcapio.decoding(log.path, topic):
                return decode_channel(msgtype, payloads) if payloads else None

        return cls(
            name=str(log.path),
            metadata=log.metadata,
            scan_stamps=run.stamps,
            n_beams=run.geometry.n_beams,
            tracks=channel(mcapio.TOPIC_TRACKS, types.TRACKS),
            features=channel(mcapio.TOPIC_FEATURES, types.FEATURES),
            landmarks=channel(mcapio.TOPIC_LANDMARKS, types.LANDMARKS),
            ground_truth=channel(mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH),
            scans=run if keep_scans else None,
            odometry=mcapio.odometry_from_log(log),
        )


# -------------------------------------------------------------------------------------------- summary


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


def class_rows(tracks: list[dict]) -> list[dict]:
    """Confirmed tracks grouped by (class, mobility): counts, lifetimes (s), distance (m), speeds (m/s)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in tracks:
        if r["confirmed"]:
            groups.setdefault((r["class"], r["mobility"]), []).append(r)
    order = {name: i for i, name in enumerate(CLASS_NAMES.values())}
    morder = {MOBILITY_NAMES[m]: i for i, m in enumerate((MOBILITY_DYNAMIC, MOBILITY_UNDEFINED, MOBILITY_STATIC))}
    out = []
    for (cls, mob), rs in sorted(groups.items(), key=lambda kv: (order[kv[0][0]], morder[kv[0][1]])):
        life = np.array([r["lifetime_s"] for r in rs])
        out.append(
            {
                "class": cls,
                "mobility": mob,
                "tracks": len(rs),
                "mean_lifetime_s": round(float(life.mean()), 3),
                "max_lifetime_s": round(float(life.max()), 3),
                "distance_m": round(float(sum(r["distance_m"] for r in rs)), 3),
                "mean_speed_mps": round(float(np.mean([r["mean_speed_mps"] for r in rs])), 3),
                "max_speed_mps": round(float(max(r["max_speed_mps"] for r in rs)), 3),
                "occlusions": int(sum(r["occlusions"] for r in rs)),
            }
        )
    return out


def moving(row: dict) -> bool:
    """Whether a track row is reported in full: a person (whatever its mobility) or a dynamic track."""
    return row["class"] == CLASS_NAMES[CLASS_PERSON] or row["mobility"] == MOBILITY_NAMES[MOBILITY_DYNAMIC]


def static_rows(tracks: list[dict]) -> list[dict]:
    """The confirmed tracks that are neither people nor dynamic (static or undecided pieces of walls and
    furniture), summarised per (class, mobility): how many, their mean lifetime (s) and where their last
    confirmed positions are: bounding box and centroid (m, the report's frame)."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for r in tracks:
        if r["confirmed"] and not moving(r):
            groups.setdefault((r["class"], r["mobility"]), []).append(r)
    order = {name: i for i, name in enumerate(CLASS_NAMES.values())}
    out = []
    static = MOBILITY_NAMES[MOBILITY_STATIC]
    for (cls, mob), rs in sorted(groups.items(), key=lambda kv: (order[kv[0][0]], kv[0][1] != static)):
        xy = np.array(
            [(r["x_m"], r["y_m"]) for r in rs if r["x_m"] is not None and r["y_m"] is not None], np.float64
        ).reshape(-1, 2)
        where = dict.fromkeys(("centroid_x_m", "centroid_y_m", "x_min_m", "x_max_m", "y_min_m", "y_max_m"))
        if len(xy):
            (cx, cy), (x0, y0), (x1, y1) = xy.mean(0), xy.min(0), xy.max(0)
            where = {k: round(float(v), 3) for k, v in zip(where, (cx, cy, x0, x1, y0, y1), strict=True)}
        out.append(
            {
                "class": cls,
                "mobility": mob,
                "tracks": len(rs),
                "mean_lifetime_s": round(float(np.mean([r["lifetime_s"] for r in rs])), 3),
                **where,
            }
        )
    return out


@dataclass
class RunSummary:
    """Everything `datmo report` prints about one run (see the module docstring for units and frames)."""

    run: dict
    features: dict | None
    landmarks: list[dict] | None
    classes: list[dict]
    tracks: list[dict]  # every track, confirmed or not
    frame: str  # "world" or "sensor": the frame of track positions and distances

    def confirmed(self) -> list[dict]:
        return [r for r in self.tracks if r["confirmed"]]

    def shown(self, top: int | None, sort: str, all_tracks: bool = False) -> list[dict]:
        """The tracks reported in full: the moving ones (every confirmed one with `all_tracks`), ordered by
        `sort`, the first `top` (all when None or 0)."""
        rows = sort_tracks([r for r in self.confirmed() if all_tracks or moving(r)], sort)
        return rows[:top] if top else rows

    def to_dict(self, top: int | None = None, sort: str = "lifetime") -> dict:
        """The file's entry of the JSON report: its file_row, then its details (see REPORT_SCHEMA)."""
        return {
            **self.file_row(),
            "run": self.run,
            "features": self.features,
            "landmark_list": self.landmarks,
            "frame": self.frame,
            "tentative_only": len(self.tracks) - len(self.confirmed()),
            "classes": self.classes,
            "moving_tracks": self.shown(top, sort),
            "static_by_class": static_rows(self.tracks),
        }

    def file_row(self) -> dict:
        """The file's row of the report (FILE_COLUMNS' keys, in order)."""
        conf = self.confirmed()
        f = self.features or {}
        row = {"file": self.run["file"], "duration_s": self.run["duration_s"], "scans": self.run["scans"]}
        for name in ("lines", "circles", "blobs"):
            row[f"{name}_per_scan"] = f[name]["per_scan"] if name in f else None
        row["landmarks"] = len(self.landmarks) if self.landmarks is not None else None
        row["tracks"] = len(conf)
        row["moving"] = sum(moving(r) for r in conf)
        row["static_pieces"] = len(conf) - row["moving"]
        for c in (CLASS_PERSON, CLASS_CIRCLE_OBJECT, CLASS_RECTANGULAR_OBJECT, CLASS_UNKNOWN):
            row[CLASS_NAMES[c].replace(" ", "_")] = sum(r["class"] == CLASS_NAMES[c] for r in conf)
        row["dynamic"] = sum(r["mobility"] == MOBILITY_NAMES[MOBILITY_DYNAMIC] for r in conf)
        row["distance_m"] = round(sum(r["distance_m"] for r in conf), 3)
        return row


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


class ScanStats:
    """Scan count, first and last header stamps (ns), beams, and the histogram of the periods between
    consecutive stamps (file order; distinct periods in ns and their counts), from which the median period
    and the dropped scans come exactly. Memory: one entry per distinct period, a handful for a scanner's
    regular clock (stamps jittered to the nanosecond can make it one per scan, 16 bytes each)."""

    def __init__(self) -> None:
        self.count = 0
        self.first_ns = self.last_ns = 0
        self.n_beams = 0
        self.periods = np.zeros(0, np.int64)  # distinct stamp differences, ns, ascending
        self.period_counts = np.zeros(0, np.int64)

    def add(self, stamps: np.ndarray, n_beams: int) -> None:
        """Add the header stamps (ns, int64, file order) of a block of scans with `n_beams` beams."""
        if not len(stamps):
            return
        stamps = np.asarray(stamps, np.int64)
        if not self.count:
            self.first_ns, self.n_beams = int(stamps[0]), int(n_beams)
            diffs = np.diff(stamps)
        else:
            diffs = np.diff(np.r_[np.int64(self.last_ns), stamps])
        self.count += len(stamps)
        self.last_ns = int(stamps[-1])
        values, inverse = np.unique(np.r_[self.periods, diffs], return_inverse=True)
        counts = np.zeros(len(values), np.int64)
        np.add.at(counts, inverse, np.r_[self.period_counts, np.ones(len(diffs), np.int64)])
        self.periods, self.period_counts = values, counts

    def facts(self) -> dict:
        """Duration (s), scans, rate (Hz, from the median period), beams, dropped scans (missing periods in
        the stamps' gaps) and the first stamp (ns)."""
        n = int(self.period_counts.sum())
        dt = self.periods / 1e9
        period = 0.0
        if n:
            ends = np.cumsum(self.period_counts)
            middle = [(n - 1) // 2] if n % 2 else [n // 2 - 1, n // 2]
            period = float(np.mean(dt[np.searchsorted(ends, middle, side="right")]))
        dropped = int(np.sum(self.period_counts * np.maximum(np.round(dt / period) - 1, 0))) if period > 0 else 0
        duration = (np.int64(self.last_ns) - np.int64(self.first_ns)) / 1e9
        return {
            "duration_s": round(float(duration), 3) if self.count else 0.0,
            "scans": self.count,
            "rate_hz": round(1 / period, 3) if period > 0 else None,
            "beams": self.n_beams,
            "dropped_scans": dropped,
            "start_ns": self.first_ns if self.count else 0,
        }


FEATURE_KINDS = ("lines", "circles", "blobs")


class RunAccumulator:
    """The report of one run, accumulated from its decoded messages block by block (`add_scans`,
    `add_features`, `add_landmarks`, `add_tracks`; any split in blocks gives the same summary), then
    `summary()`. Holds O(1) numbers per track (TrackStats), per distinct scan period (ScanStats) and per
    feature kind, and the landmark database of the last /datmo/landmarks message; nothing per scan.
    `summarise` feeds it a whole RunData, `summarise_file` a log streamed a block of messages at a time."""

    def __init__(self, name: str, metadata: dict[str, dict[str, str]] | None = None) -> None:
        self.name = name
        self.metadata = metadata or {}
        self.scans = ScanStats()
        self.tracks = TrackStats()
        self.feature_scans: int | None = None  # None: no /datmo/features message
        self.feature_total = dict.fromkeys(FEATURE_KINDS, 0)
        self.feature_max = dict.fromkeys(FEATURE_KINDS, 0)
        self.landmark_frame: str | None = None  # frame of the first /datmo/landmarks message
        self.landmarks: np.ndarray | None = None  # the database of the last one (Landmark elements)
        self.peak_messages = 0  # most messages held at once (stream_run)

    def add_scans(self, stamps: np.ndarray, n_beams: int) -> None:
        """Scan header stamps (ns, file order) and the scans' beam count."""
        self.scans.add(stamps, n_beams)

    def add_features(self, n: int, counts: dict[str, np.ndarray]) -> None:
        """`n` consecutive /datmo/features messages: their per-message counts ({kind: (n,) int} for lines,
        circles, blobs; a kind absent counts 0)."""
        if not n:
            return
        self.feature_scans = (self.feature_scans or 0) + n
        for kind in FEATURE_KINDS:
            c = counts.get(kind)
            if c is not None and len(c):
                self.feature_total[kind] += int(np.sum(c))
                self.feature_max[kind] = max(self.feature_max[kind], int(np.max(c)))

    def add_landmarks(self, frame_id: str, last: np.ndarray) -> None:
        """A block of /datmo/landmarks messages: the frame of its first message, the database of its last."""
        if self.landmark_frame is None:
            self.landmark_frame = frame_id
        self.landmarks = last

    def add_tracks(self, stamps: np.ndarray, states: np.ndarray) -> None:
        """Track states (Track elements, file order) with the header stamp (ns) of their /datmo/tracks message."""
        self.tracks.add(stamps, states)

    def run_facts(self) -> dict:
        """Duration (s), scans, rate (Hz, from the median period), beams, dropped scans (missing periods in
        the stamps' gaps), and the tool version, command and parameters of the file's provenance metadata."""
        meta = self.metadata.get("datmo", {})
        params = {}
        for k, v in self.metadata.get("datmo.params", {}).items():
            try:
                params[k] = json.loads(v)
            except ValueError:
                params[k] = v
        return {
            "file": self.name,
            **self.scans.facts(),
            "version": meta.get("version"),
            "command": meta.get("command_line") or meta.get("command"),
            "parameters": params,
        }

    def feature_facts(self) -> dict | None:
        """Lines, circles and blobs: totals, mean and max per scan; None when the log has no features."""
        n = self.feature_scans
        if n is None:
            return None
        return {
            "scans": n,
            **{
                k: {
                    "total": self.feature_total[k],
                    "per_scan": round(self.feature_total[k] / n, 3),
                    "max_per_scan": self.feature_max[k],
                }
                for k in FEATURE_KINDS
            },
        }

    def landmark_rows(self, t0_ns: int) -> list[dict] | None:
        """The landmark database after the last scan: id, type, position (m, in the channel's frame), first
        and last seen (s from t0), scans seen; None when the log has no landmarks channel."""
        if self.landmarks is None:
            return None

        def secs(t: np.ndarray) -> float:
            return round((int(t["sec"]) * 1_000_000_000 + int(t["nanosec"]) - t0_ns) / 1e9, 3)

        return [
            {
                "id": int(lm["id"]),
                "type": LANDMARK_NAMES.get(int(lm["type"]), str(int(lm["type"]))),
                "x_m": round(float(lm["x"]), 3),
                "y_m": round(float(lm["y"]), 3),
                "size_m": round(float(lm["size"]), 3),
                "first_seen_s": secs(lm["first_seen"]),
                "last_seen_s": secs(lm["last_seen"]),
                "scans": int(lm["count"]),
                "frame": self.landmark_frame,
            }
            for lm in self.landmarks
        ]

    def summary(self) -> RunSummary:
        """The report of what was added."""
        facts = self.run_facts()
        t0 = facts["start_ns"]
        tracks = self.tracks.rows(t0)
        return RunSummary(
            facts,
            self.feature_facts(),
            self.landmark_rows(t0),
            class_rows(tracks),
            tracks,
            "world" if self.tracks.world else "sensor",
        )


def summarise(data: RunData) -> RunSummary:
    """The report of one decoded run: the same RunSummary as `summarise_file` of its log."""
    acc = RunAccumulator(data.name, data.metadata)
    acc.add_scans(data.scan_stamps, data.n_beams)
    f = data.features
    if f is not None:
        acc.add_features(len(f), {k: f.counts(k) for k in FEATURE_KINDS if k in f.offsets})
    lm = data.landmarks
    if lm is not None:
        off = lm.offsets.get("landmarks")
        acc.add_landmarks(
            lm.frame_id,
            lm.items["landmarks"][off[-2] : off[-1]]
            if off is not None and len(lm)
            else np.zeros(0, cdr.element_dtype(types.LANDMARK)),
        )
    t = data.tracks.items.get("tracks")
    if t is not None and len(t):
        acc.add_tracks(data.tracks.stamps[data.tracks.message_index("tracks")], t)
    return acc.summary()


BLOCK_MESSAGES = 1000  # messages decoded at once by summarise_file
SUMMARY_TOPICS = (mcapio.TOPIC_SCAN, mcapio.TOPIC_FEATURES, mcapio.TOPIC_LANDMARKS, mcapio.TOPIC_TRACKS)


def summarise_file(
    path: str | Path, *, block: int = BLOCK_MESSAGES, progress: Callable[[int], None] | None = None
) -> RunSummary:
    """The report of the processed log at `path`, read in one streaming pass (see `stream_run`) in memory
    that does not grow with the log's length: the same RunSummary as `summarise(RunData.from_log(...))`
    (but where a track's header stamps go back across blocks, never in a log datmo writes: see TrackStats).

    Raises as RunData.from_log: MissingChannelError naming the command to run first when /scan or
    /datmo/tracks is absent, InputError for a /scan channel that is not LaserScans or whose geometry changes.
    """
    return stream_run(path, block=block, progress=progress).summary()


def stream_run(
    path: str | Path, *, block: int = BLOCK_MESSAGES, progress: Callable[[int], None] | None = None
) -> RunAccumulator:
    """Walk the log at `path` once (mcapio.iter_messages, file order) and feed a RunAccumulator its /scan,
    /datmo/features, /datmo/landmarks and /datmo/tracks messages, `block` messages at a time: it holds at
    most `block` payloads and their decoded forms at once (`peak_messages` says how many it held), so
    memory does not depend on the log's length. Scans are decoded block by block for their header stamps
    and geometry (a change of geometry is refused as RunData.from_log refuses it). `progress(scans)` is
    called after each block with the number of scans read so far."""
    contents = mcapio.LogContents(path=Path(path))
    acc = RunAccumulator(str(Path(path)))
    pending: dict[str, list[bytes]] = {t: [] for t in SUMMARY_TOPICS}
    state: dict = {"geometry": None, "first": 0, "error": None, "seen": dict.fromkeys(SUMMARY_TOPICS, 0)}

    def flush() -> None:
        acc.peak_messages = max(acc.peak_messages, sum(len(p) for p in pending.values()))
        scans = pending[mcapio.TOPIC_SCAN]
        if scans and state["error"] is None:
            try:
                mcapio.check_scan_channel(contents)
                run = mcapio.decode_scan_block(contents.path, scans, state["first"], state["geometry"])
            except InputError as exc:  # raised after the channel checks, as RunData.from_log orders them
                state["error"] = exc
            else:
                state["geometry"] = run.geometry
                acc.add_scans(run.stamps, run.geometry.n_beams)
        state["first"] += len(scans)
        if progress is not None and scans:
            progress(state["first"])
        seen = state["seen"]  # messages of each topic before this block's (to name a damaged one)
        if pending[mcapio.TOPIC_FEATURES]:
            with mcapio.decoding(contents.path, mcapio.TOPIC_FEATURES):
                decoded = cdr.decode_many(types.FEATURES, pending[mcapio.TOPIC_FEATURES], seen[mcapio.TOPIC_FEATURES])
            acc.add_features(
                len(decoded),
                {k: np.array([len(d[k]) for d in decoded], np.int64) for k in FEATURE_KINDS if k in decoded[0]},
            )
        landmarks = pending[mcapio.TOPIC_LANDMARKS]
        if landmarks:
            k = seen[mcapio.TOPIC_LANDMARKS]
            with mcapio.decoding(contents.path, mcapio.TOPIC_LANDMARKS):  # the first and last: frame, database
                (head,) = cdr.decode_many(types.LANDMARKS, landmarks[:1], k)
                (last,) = cdr.decode_many(types.LANDMARKS, landmarks[-1:], k + len(landmarks) - 1)
            acc.add_landmarks(head["frame_id"] if acc.landmark_frame is None else "", last["landmarks"])
        if pending[mcapio.TOPIC_TRACKS]:
            with mcapio.decoding(contents.path, mcapio.TOPIC_TRACKS):
                tracks = decode_channel(types.TRACKS, pending[mcapio.TOPIC_TRACKS], seen[mcapio.TOPIC_TRACKS])
            if "tracks" in tracks.items:
                acc.add_tracks(tracks.stamps[tracks.message_index("tracks")], tracks.items["tracks"])
        for topic, payloads in pending.items():
            seen[topic] += len(payloads)
            payloads.clear()

    held = 0
    for topic, _, payload in mcapio.iter_messages(path, SUMMARY_TOPICS, contents):
        pending[topic].append(payload)
        held += 1
        if held == block:
            flush()
            held = 0
    flush()
    require(contents, mcapio.TOPIC_SCAN)
    require(contents, mcapio.TOPIC_TRACKS)
    if state["error"] is not None:
        raise state["error"]
    if acc.tracks.late:
        import warnings

        warnings.warn(
            f"{contents.path}: {acc.tracks.late} track state(s) come in the file after a later-stamped "
            "state of their track, blocks before; the report takes them in file order (occlusions, "
            "distances)",
            UserWarning,
            stacklevel=2,
        )
    acc.metadata = contents.metadata
    return acc


def sort_tracks(rows: list[dict], key: str) -> list[dict]:
    """Tracks ordered by `key` (one of SORT_KEYS): longest, farthest, fastest first; `first` and `id` ascending."""
    col = {
        "lifetime": "lifetime_s",
        "distance": "distance_m",
        "speed": "max_speed_mps",
        "first": "first_s",
        "id": "id",
    }[key]
    descending = key in ("lifetime", "distance", "speed")
    return sorted(rows, key=lambda r: ((-r[col] if descending else r[col]), r["id"]))


def total_row(rows: list[dict]) -> dict:
    """Sum of file rows (per-scan figures weighted by scans); zeros and None when there are none."""
    out: dict = {"file": "total"}
    for k in FILE_COLUMNS:
        if k == "file":
            continue
        vals = [r[k] for r in rows if r[k] is not None]
        if k.endswith("_per_scan"):
            ws = [r["scans"] for r in rows if r[k] is not None]
            out[k] = round(sum(v * w for v, w in zip(vals, ws, strict=True)) / sum(ws), 3) if sum(ws) else None
        elif not vals:
            out[k] = None if rows else (0.0 if k.endswith(("_s", "_m")) else 0)
        else:
            out[k] = round(sum(vals), 3) if isinstance(vals[0], float) else sum(vals)
    return out


# ----------------------------------------------------------------------------------------- formatting


@dataclass
class Table:
    """A titled table of plain values; formatted by render_rich, render_markdown and render_csv."""

    title: str
    columns: list[str]
    rows: list[list]
    numeric: set[int] = field(default_factory=set)  # column indices aligned right


def _cell(v: object) -> str:
    """A value as the rich and markdown tables show it (text with its control characters escaped)."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:,.2f}"
    if isinstance(v, int):
        return f"{v:,}"
    return printable(v)


def _table(title: str, rows: list[dict], columns: dict[str, str]) -> Table:
    keys = list(columns)
    values = [[r.get(k) for k in keys] for r in rows]
    numeric = {
        i
        for i, k in enumerate(keys)
        if any(isinstance(v[i], int | float) and not isinstance(v[i], bool) for v in values)
    }
    return Table(title, [columns[k] for k in keys], values, numeric)


SCHEMA = "datmo.report/1"
TRACK_COLUMNS = {
    "id": "id",
    "class": "class",
    "mobility": "mobility",
    "first_s": "first s",
    "last_s": "last s",
    "lifetime_s": "lifetime s",
    "distance_m": "distance m",
    "mean_speed_mps": "mean m/s",
    "max_speed_mps": "max m/s",
    "occlusions": "occlusions",
    "x_m": "last x m",
    "y_m": "last y m",
}
STATIC_COLUMNS = {
    "class": "class",
    "mobility": "mobility",
    "tracks": "tracks",
    "mean_lifetime_s": "mean lifetime s",
    "centroid_x_m": "centroid x m",
    "centroid_y_m": "centroid y m",
    "x_min_m": "x min m",
    "x_max_m": "x max m",
    "y_min_m": "y min m",
    "y_max_m": "y max m",
}
LANDMARK_COLUMNS = {
    "id": "id",
    "type": "type",
    "x_m": "x m",
    "y_m": "y m",
    "size_m": "size m",
    "first_seen_s": "first seen s",
    "last_seen_s": "last seen s",
    "scans": "scans",
}
FILE_COLUMNS = {
    "file": "file",
    "duration_s": "duration s",
    "scans": "scans",
    "lines_per_scan": "lines/scan",
    "circles_per_scan": "circles/scan",
    "blobs_per_scan": "blobs/scan",
    "landmarks": "landmarks",
    "tracks": "tracks",
    "moving": "moving",
    "static_pieces": "static pieces",
    "person": "people",
    "circle_object": "circle obj.",
    "rectangular_object": "rect. obj.",
    "unknown": "unknown",
    "dynamic": "dynamic",
    "distance_m": "distance m",
}
# `--format csv --tracks`: one row per track of every file
TRACK_CSV_KEYS = ["file", *TRACK_COLUMNS, "occluded_scans", "scans"]
REPORT_SCHEMA = f"""The report's shapes, the same for one file, several files, batch folders and datmo run's report:

csv            one row per file, then a row whose file is "total"; header:
               {",".join(FILE_COLUMNS)}
csv --tracks   one row per confirmed track (static pieces too), with a file column; header:
               {",".join(TRACK_CSV_KEYS)}
json           {{"schema": "{SCHEMA}", "files": [FILE...], "total": ROW, "batches": [BATCH...],
                 "tracks": [TRACK...] (with --tracks only)}}
               FILE: the file's csv row plus "run" (facts, provenance), "features", "landmark_list" (the
               landmark database; null without /datmo/landmarks), "frame", "tentative_only", "classes"
               (confirmed tracks by class and mobility), "moving_tracks" (people and dynamic tracks in full)
               and "static_by_class" (the other confirmed tracks per class and mobility: count, centroid,
               bounding box); BATCH: {{"folder", "summary", "inputs"}} of a batch folder's manifest.jsonl;
               TRACK: a csv --tracks row.
Moving: a person, or a track whose mobility is dynamic. Times in s from the file's first scan; positions
in m in the world frame when every track state has one, else the sensor frame; speeds in m/s."""


PARAM_WIDTH = 160  # characters of a parameter's value in the run table; `datmo info FILE --json` has it whole


def param_text(name: str, value) -> str:
    """A parameter's value as the run table shows it: the leg model by its name, digest and threshold (its
    record holds the training figures), any other value as JSON cut at PARAM_WIDTH characters."""
    if name == "leg_model" and isinstance(value, dict) and "sha256" in value:
        threshold = value.get("threshold")
        about = f", threshold {threshold:.2f}" if isinstance(threshold, float) else ""
        return f"{value.get('model') or value.get('path')} (sha256 {str(value['sha256'])[:12]}{about})"
    text = value if isinstance(value, str) else json.dumps(value)
    return text if len(text) <= PARAM_WIDTH else text[: PARAM_WIDTH - 1] + "…"


def file_tables(
    summary: RunSummary, top: int | None = 20, sort: str = "lifetime", all_tracks: bool = False
) -> list[Table]:
    """The tables of one file: run facts, features, landmarks, the tracks in full (the moving ones, or every
    confirmed one with `all_tracks`) and the static pieces per class."""
    r = summary.run
    name = Path(r["file"]).name
    facts = [
        ["file", r["file"]],
        ["duration", f"{r['duration_s']:.1f} s"],
        ["scans", r["scans"]],
        ["rate", f"{r['rate_hz']:.2f} Hz" if r["rate_hz"] else "-"],
        ["beams", r["beams"]],
        ["dropped scans", r["dropped_scans"]],
        ["datmo version", r["version"]],
        ["command", r["command"]],
    ]
    facts += [[f"param {k}", param_text(k, v)] for k, v in r["parameters"].items()]
    out = [Table(f"{name}: run", ["what", "value"], facts)]
    f = summary.features
    if f is not None:
        out.append(
            Table(
                f"{name}: features ({f['scans']:,} scans)",
                ["feature", "total", "per scan", "max per scan"],
                [[n, f[n]["total"], f[n]["per_scan"], f[n]["max_per_scan"]] for n in ("lines", "circles", "blobs")],
                {1, 2, 3},
            )
        )
    if summary.landmarks is not None:
        frame = summary.landmarks[0]["frame"] if summary.landmarks else ""
        out.append(
            _table(
                f"{name}: landmarks ({len(summary.landmarks)}, frame {frame or '-'})",
                summary.landmarks,
                LANDMARK_COLUMNS,
            )
        )
    conf = summary.confirmed()
    n_moving = sum(moving(t) for t in conf)
    shown = summary.shown(top, sort, all_tracks)
    what = "confirmed tracks" if all_tracks else "people and dynamic tracks"
    of = len(conf) if all_tracks else n_moving
    out.append(
        _table(
            f"{name}: {what} ({len(shown)} of {of}, by {sort}; {len(conf)} confirmed, "
            f"{len(summary.tracks) - len(conf)} never confirmed; {summary.frame} frame)",
            shown,
            TRACK_COLUMNS,
        )
    )
    statics = static_rows(summary.tracks)
    out.append(
        _table(
            f"{name}: static pieces by class ({len(conf) - n_moving} tracks; where they were last seen)",
            statics,
            STATIC_COLUMNS,
        )
    )
    return out


def file_table(summaries: list[RunSummary]) -> Table:
    """One row per file and a total row."""
    rows = [s.file_row() for s in summaries]
    return _table(f"{len(rows)} file{'s' if len(rows) != 1 else ''}", rows + [total_row(rows)], FILE_COLUMNS)


def console():
    """A rich console on stdout: the terminal's width on a terminal, else a plain, unlimited width (no
    wrapping, no colour) so piped names stay whole (progress.console)."""
    from .progress import console as make

    return make()


def render_rich(tabs: list[Table], console) -> None:
    """Print tables with rich."""
    from .progress import table as rich_table

    for t in tabs:
        rt = rich_table(console, title=t.title, title_justify="left")
        for i, c in enumerate(t.columns):
            rt.add_column(c, justify="right" if i in t.numeric else "left", overflow="fold")
        for row in t.rows:
            style = "bold" if row and row[0] == "total" else None
            rt.add_row(*(_cell(v) for v in row), style=style)
        if not t.rows:
            rt.add_row(*(["(none)"] + [""] * (len(t.columns) - 1)))
        console.print(rt)


def render_markdown(tabs: list[Table]) -> str:
    """GitHub-flavoured markdown: a heading and a pipe table per table."""
    parts = []
    for t in tabs:
        head = "| " + " | ".join(t.columns) + " |"
        rule = "|" + "|".join("---:" if i in t.numeric else "---" for i in range(len(t.columns))) + "|"
        body = ["| " + " | ".join(_cell(v).replace("|", "\\|") for v in row) + " |" for row in t.rows]
        parts.append("\n".join([f"### {printable(t.title)}", "", head, rule, *body]))
    return "\n\n".join(parts) + "\n"


def render_csv(table: Table, keys: list[str] | None = None) -> str:
    """One table as CSV with raw (unformatted) values; header = `keys` when given, else the column titles.
    Text cells have their control characters escaped (text.printable: the CSV is often printed) and, when a
    spreadsheet would run them as a formula (`=`, `+`, `@`, or `-` not a number), an apostrophe in front
    (csvsafe.neutralise, as every CSV writer)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(keys or table.columns)
    for row in table.rows:
        w.writerow(["" if v is None else neutralise(printable(v)) if isinstance(v, str) else v for v in row])
    return buf.getvalue()


def to_json(obj: object) -> str:
    """JSON text; NaN and infinities become null."""

    def clean(o: object) -> object:
        if isinstance(o, float):
            return o if np.isfinite(o) else None
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, list | tuple):
            return [clean(v) for v in o]
        if isinstance(o, Path):
            return str(o)
        if isinstance(o, np.generic):
            return clean(o.item())
        return o

    return json.dumps(clean(obj), indent=2)


def track_rows(summaries: list[RunSummary], top: int | None, sort: str) -> list[dict]:
    """The `--tracks` rows, TRACK_CSV_KEYS: every confirmed track of each file (a table for scripts, which
    filter on class and mobility themselves), ordered by `sort`, the first `top` of each file."""
    return [
        {"file": s.run["file"], **{k: t[k] for k in TRACK_CSV_KEYS[1:]}}
        for s in summaries
        for t in s.shown(top, sort, True)
    ]


def report_dict(
    summaries: list[RunSummary], *, top: int | None, sort: str, tracks: bool = False, batches: list[dict] | None = None
) -> dict:
    """The JSON report (REPORT_SCHEMA): schema, files, total, batches and, with `tracks`, tracks."""
    out = {
        "schema": SCHEMA,
        "files": [s.to_dict(top, sort) for s in summaries],
        "total": total_row([s.file_row() for s in summaries]),
        "batches": batches or [],
    }
    if tracks:
        out["tracks"] = track_rows(summaries, top, sort)
    return out


def render(
    summaries: list[RunSummary],
    fmt: str,
    *,
    top: int | None,
    sort: str,
    tracks: bool = False,
    all_tracks: bool = False,
    batches: list[dict] | None = None,
    console=None,
    before: list[Table] | None = None,
) -> str | None:
    """The report of any number of runs in `fmt` (one of FORMATS), in the shapes REPORT_SCHEMA gives.
    Returns the text, or prints to `console` (rich). `top` limits each file's track table (None: 20 for rich
    and markdown, all for json and csv); rich and markdown show the files table, then each file's tables,
    after the tables `before` (a batch folder's)."""
    if fmt == "json":
        return to_json(report_dict(summaries, top=top, sort=sort, tracks=tracks, batches=batches))
    if fmt == "csv":
        if tracks:
            rows = track_rows(summaries, top, sort)
            return render_csv(Table("tracks", TRACK_CSV_KEYS, [[r[k] for k in TRACK_CSV_KEYS] for r in rows]))
        return render_csv(file_table(summaries), list(FILE_COLUMNS))
    top = 20 if top is None else top
    tabs = list(before or []) + [file_table(summaries)]
    for s in summaries:
        tabs += file_tables(s, top, sort, all_tracks)
    if fmt == "markdown":
        return render_markdown(tabs)
    render_rich(tabs, console)
    return None
