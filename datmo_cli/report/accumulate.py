"""Gathering the report of one run from its decoded messages, block by block: `ScanStats` (scan stamps and
periods), `RunAccumulator` (scans, features, landmarks and tracks, then a RunSummary) and `summarise` (a whole
RunData fed to the same accumulator)."""

from __future__ import annotations

import json

import numpy as np

from ..logs import cdr, types
from ..logs.vocabulary import LANDMARK_NAMES
from .decode import RunData
from .summary import RunSummary, class_rows
from .tracks import TrackStats


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
