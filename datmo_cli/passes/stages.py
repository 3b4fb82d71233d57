"""The stages of the pipeline as channels, {topic: (msgtype, stamps, payloads)}: segmentation
(`derive_segments`), features (`derive_features`, through feature_channels.FeatureStream) and tracking
(`TrackStream` block by block, `track_run`), with the glue between perception and tracking
(features decoded from a log or taken from a RunFeatures, one ScanFeatures per scan). With odometry,
tracking runs in the world frame and every track also carries its world position.

The core packages never import each other; this module (and pipeline, which runs these stages over files)
is where perception's output becomes tracking's input.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

import numpy as np

from ..logs import cdr, mcapio, types
from ..logs.scan import Odometry, ScanRun
from ..perception.features import RunFeatures, extract_run, segment_run
from ..perception.params import FeatureParams
from ..tracking.hindsight import Hindsight, smoothed_tails
from ..tracking.markers import track_markers
from ..tracking.measurements import ScanFeatures
from ..tracking.params import TrackingParams
from ..tracking.tracker import TRACK_DTYPE, Tracker
from .feature_channels import FeatureStream, segment_payloads


def derive_segments(run: ScanRun, params: FeatureParams | None = None) -> dict[str, tuple]:
    """The channel `datmo segment` adds: {topic: (msgtype, stamps, payloads)}."""
    start, end, offsets = segment_run(run, params)
    return {mcapio.TOPIC_SEGMENTS: (types.SEGMENTS, run.stamps, segment_payloads(run, start, end, offsets))}


def derive_features(
    run: ScanRun,
    *,
    odometry: Odometry | None = None,
    params: FeatureParams | None = None,
    segments: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[dict[str, tuple], RunFeatures]:
    """The channels `datmo features` adds ({topic: (msgtype, stamps, payloads)}: segments, features,
    landmarks and feature markers) and the RunFeatures they came from. Given `segments` (a log's own),
    they are used and /datmo/segments is not among the channels returned."""
    return FeatureStream(params, odometry).block(run, segments, progress)


def iter_run_features(features) -> Iterator[ScanFeatures]:
    """Scan by scan views of a RunFeatures (lines/circles/blobs with line_/circle_/blob_offsets)."""
    lo, co, bo, go = (
        np.asarray(features.line_offsets),
        np.asarray(features.circle_offsets),
        np.asarray(features.blob_offsets),
        np.asarray(features.leg_offsets),
    )
    lines, circles, blobs, legs = features.lines, features.circles, features.blobs, features.legs
    for i in range(len(lo) - 1):
        yield ScanFeatures(
            lines[lo[i] : lo[i + 1]], circles[co[i] : co[i + 1]], blobs[bo[i] : bo[i + 1]], legs[go[i] : go[i + 1]]
        )


def decode_features(payloads: list[bytes], first: int = 0) -> list[ScanFeatures]:
    """ScanFeatures of datmo_msgs/msg/Features CDR payloads (a log's /datmo/features channel, messages first..;
    cdr.DecodeError names a damaged one)."""
    return [
        ScanFeatures(msg["lines"], msg["circles"], msg["blobs"], msg["legs"])
        for msg in cdr.decode_many(types.FEATURES, payloads, first)
    ]


@dataclass
class TrackedRun:
    """What tracking a run gave: per scan, the live tracks (Track elements) and the markers payload."""

    stamps: np.ndarray  # (N,) int64 ns
    frame_id: str  # the scans' sensor frame
    world: bool  # tracks carry world positions (the log had odometry)
    tracks: list[np.ndarray] = field(default_factory=list)
    markers: list[bytes] = field(default_factory=list)
    # the same tracks as the tracker gave them, every scan's of a compiled call in one array: `tracks` holds
    # views into these, and concatenating a few of them is far cheaper than one structured array per scan
    flat: list[np.ndarray] = field(default_factory=list)

    def track_payloads(self) -> list[bytes]:
        """datmo_msgs/msg/Tracks CDR payloads, one per scan."""
        offsets, items = self.all_tracks()
        return cdr.encode_block(types.TRACKS, self.stamps, self.frame_id, {"tracks": (items, offsets)})

    def all_tracks(self) -> tuple[np.ndarray, np.ndarray]:
        """(offsets (N+1,), every scan's tracks concatenated), as evaluate.track_frames takes them."""
        counts = [len(t) for t in self.tracks]
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        parts = self.flat if sum(map(len, self.flat)) == offsets[-1] else self.tracks
        return offsets, join_tracks(parts)


def join_tracks(parts: list[np.ndarray]) -> np.ndarray:
    """Track element arrays concatenated: as bytes (np.concatenate of structured arrays costs ~20 µs each, and a
    block's scans are a thousand of them), the same elements."""
    if not parts:
        return np.zeros(0, TRACK_DTYPE)
    if not all(p.dtype is TRACK_DTYPE or p.dtype == TRACK_DTYPE for p in parts):
        return np.concatenate(parts)
    return np.concatenate([np.ascontiguousarray(p).view(np.uint8) for p in parts]).view(TRACK_DTYPE)


def split_tracked(pieces: list[TrackedRun], n: int) -> tuple[TrackedRun, list[TrackedRun]]:
    """(the first n scans of consecutive TrackedRuns, the rest of them), e.g. a block's scans of the runs a
    TrackStream with hindsight gave; a run of exactly n scans is given as it is."""
    pieces = [p for p in pieces if len(p.stamps)]
    if pieces and len(pieces[0].stamps) == n:
        return pieces[0], pieces[1:]
    head = pieces[0] if pieces else None
    out = TrackedRun(np.zeros(0, np.int64), head.frame_id if head else "", head.world if head else False)
    stamps, rest, need = [], [], n
    for p in pieces:
        if need <= 0:
            rest.append(p)
            continue
        k = min(need, len(p.stamps))
        stamps.append(p.stamps[:k])
        out.tracks += p.tracks[:k]
        out.markers += p.markers[:k]
        if k < len(p.stamps):
            more = TrackedRun(p.stamps[k:], p.frame_id, p.world, p.tracks[k:], p.markers[k:])
            rest.append(more)
        need -= k
    if need > 0:
        raise ValueError(f"{n} scans asked of tracked runs holding {n - need}")
    out.stamps = np.concatenate(stamps) if stamps else out.stamps
    return out, rest


# scans per compiled tracking call: at least _CHUNK (a call costs ~0.4 ms of Python around it), at most
# _CHUNK_MAX (the tails a block gives for the markers take 320 B per track and scan); progress between calls
_CHUNK, _CHUNK_MAX = 512, 4096


class TrackStream:
    """Tracking of a log block by block, in order: `block(run, features)` tracks the next scans (one
    ScanFeatures each, sensor frame) and returns their TrackedRun; the tracker's state carries over, so the
    blocks' results are those of the whole run at once. `learned`: the features' legs come from a leg
    detector whose threshold is `leg_threshold` (else people by the paper's rule, see Tracker); odometry, when
    given, puts tracking in its world frame. `markers`: draw the Foxglove markers; `covariance`: keep each
    track's covariance (else NaN: a file stores it only when asked, and sixteen NaN cost next to nothing
    compressed)."""

    def __init__(
        self,
        geometry,
        *,
        odometry: Odometry | None = None,
        params: TrackingParams | None = None,
        markers: bool = True,
        learned: bool = False,
        leg_threshold: float = 0.5,
        covariance: bool = True,
        hindsight: bool = False,
    ) -> None:
        self.params = params or TrackingParams()
        self.tracker = Tracker(self.params, geometry, learned=learned, leg_threshold=leg_threshold)
        self.odometry = odometry if odometry is not None and len(odometry) else None
        self.learned = learned
        self.markers = markers
        self.covariance = covariance
        self.frame = geometry.frame_id
        self.marker_frame = self.odometry.frame_id if self.odometry is not None else self.frame
        lag = self.params.hindsight_lag if hindsight else 0.0
        p = self.params
        self.held = Hindsight(lag, p.process_noise, p.person_process_noise, covariance=covariance) if lag > 0 else None
        self._rings: dict = {}  # with hindsight, each track's marker tail of smoothed positions (smoothed_tails)

    def block(
        self,
        run: ScanRun,
        features: list[ScanFeatures] | Iterator[ScanFeatures],
        *,
        progress: Callable[[int], None] | None = None,
    ) -> TrackedRun:
        """Track the scans of `run` (the next block of the log) given their features. `progress(i)` is
        called now and then with the scans of this block done."""
        tracker = self.tracker
        poses = self.odometry.at(run.stamps) if self.odometry is not None else None
        out = TrackedRun(run.stamps, self.frame, poses is not None)
        n = len(run)
        feats = list(features)[:n]
        if len(feats) != n:
            raise ValueError(f"features for {len(feats)} scans, the run has {n}")
        step = min(max(n // 10, _CHUNK), _CHUNK_MAX)
        given = []
        for a in range(0, n, step):  # one compiled call per chunk of scans (Tracker.track_block)
            b = min(a + step, n)
            part = None if poses is None else poses[a:b]
            block = tracker.track_block(
                run.stamps[a:b], feats[a:b], run.ranges[a:b], part, tails=self.markers and self.held is None
            )
            if self.held is None:
                given.append(run.stamps[a:b])
                self._add(out, run.stamps[a:b], block)
            else:  # hindsight: the scans whose tracks are final, smoothed and labelled (see tracking.hindsight)
                self.held.push(run.stamps[a:b], block, part)
                stamps, final, _ = self.held.release()
                given.append(stamps)
                self._add(out, stamps, final)
            if progress is not None:
                progress(b)
        out.stamps = np.concatenate(given) if given else run.stamps[:0]
        return out

    def finish(self) -> TrackedRun:
        """The tracks of the scans hindsight still holds (none without hindsight): call once after the last
        block."""
        out = TrackedRun(np.zeros(0, np.int64), self.frame, self.odometry is not None)
        if self.held is not None:
            stamps, final, _ = self.held.release(final=True)
            out.stamps = stamps
            self._add(out, stamps, final)
        return out

    def _add(self, out: TrackedRun, stamps: np.ndarray, block) -> None:
        """Append a TrackBlock of the scans at `stamps` to `out`, with their markers."""
        if not self.covariance:
            block.items["covariance"] = np.nan
        o = block.offsets.tolist()
        out.flat.append(block.items[o[0] : o[-1]])
        world = out.world
        for i, stamp in enumerate(stamps.tolist()):
            tracks = block.items[o[i] : o[i + 1]]
            out.tracks.append(tracks)
            if not self.markers:
                continue
            if self.held is None:
                tail, count = block.tail[o[i] : o[i + 1]], block.tail_count[o[i] : o[i + 1]]
            else:  # the tails of the smoothed positions, as a player draws them from the stored tracks
                tail, count = smoothed_tails(self._rings, tracks, world, self.params.tail_length)
            out.markers.append(track_markers(stamp, self.marker_frame, tracks, tail, count, world=world))

    def channels(self, tracked: TrackedRun) -> dict[str, tuple[str, np.ndarray, list]]:
        """The channels `datmo track` adds for a TrackedRun: {topic: (msgtype, stamps, payloads)}."""
        out = {mcapio.TOPIC_TRACKS: (types.TRACKS, tracked.stamps, tracked.track_payloads())}
        if self.markers:
            out[mcapio.TOPIC_MARKERS_TRACKS] = (types.MARKER_ARRAY, tracked.stamps, tracked.markers)
        return out


def track_run(
    run: ScanRun,
    features: list[ScanFeatures] | Iterator[ScanFeatures],
    *,
    odometry: Odometry | None = None,
    params: TrackingParams | None = None,
    markers: bool = True,
    learned: bool = False,
    leg_threshold: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> TrackedRun:
    """Track every scan of `run` given its features (one ScanFeatures per scan, sensor frame). `learned`:
    the features' legs come from a leg detector, whose threshold is `leg_threshold` (None: the shipped model's;
    else people by the paper's rule, see Tracker)."""
    if leg_threshold is None:
        leg_threshold = leg_threshold_of("default") if learned else 0.5
    stream = TrackStream(
        run.geometry, odometry=odometry, params=params, markers=markers, learned=learned, leg_threshold=leg_threshold
    )
    n = len(run)
    return stream.block(run, features, progress=(lambda d: progress(d, n)) if progress is not None else None)


def leg_threshold_of(leg_model: str) -> float:
    """The leg threshold of the leg detector `leg_model` names (FeatureParams.leg_model): its model's tuned
    threshold_p (0.5 for the paper's rule, which has none)."""
    from ..perception.leg_model import load_leg_model

    model = load_leg_model(leg_model)
    return 0.5 if model is None else float(model.threshold_p)


def run_features(run: ScanRun, odometry: Odometry | None = None, params=None) -> list[ScanFeatures]:
    """Segment `run` and extract its features with datmo_cli.perception (`params`: a FeatureParams, a dict
    of overrides of its defaults, or None for the defaults)."""
    if isinstance(params, dict):
        params = FeatureParams().replace(**params)
    return list(iter_run_features(extract_run(run, params=params, odometry=odometry)))
