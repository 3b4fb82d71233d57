"""Features as channels: `FeatureStream` runs segmentation, features and the landmark database over a log block
by block and gives the channels `datmo features` (and the one pass of `datmo run`) writes, {topic: (msgtype,
stamps, payloads)}: /datmo/segments, /datmo/features, /datmo/landmarks and /datmo/markers/features. The payload
functions encode a RunFeatures (perception.features) as datmo_msgs CDR messages, one per scan, and
`decode_segments` reads a log's /datmo/segments back. Sensor frame of each scan (x forward, y left), metres;
landmarks in the odometry (world) frame when the log has odometry.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..logs import cdr, mcapio, types
from ..logs.scan import Odometry, ScanRun
from ..perception.features import RunFeatures, extract_run
from ..perception.landmark_database import LandmarkStream
from ..perception.markers import feature_markers
from ..perception.params import FeatureParams


class FeatureStream:
    """Segmentation, features and the landmark database of a log, block by block: `block(run)` gives the
    channels of the next block of scans as datmo features writes them ({topic: (msgtype, stamps, payloads)})
    and its RunFeatures; the landmark database carries over from block to block, so the channels are those of
    the whole run at once. `segments` given with a block are used instead of segmenting (a log's own; the
    segments channel is then not among the channels returned); with `markers` False the Foxglove markers are
    neither drawn nor among them."""

    def __init__(
        self, params: FeatureParams | None = None, odometry: Odometry | None = None, threads: int | None = None
    ) -> None:
        self.params = params or FeatureParams()
        self.odometry = odometry
        self.landmarks = LandmarkStream(self.params)
        self.threads = threads  # the perception kernels' threads (extract_run's; None: the process's default)

    def block(
        self,
        run: ScanRun,
        segments: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        progress: Callable[[int, int], None] | None = None,
        *,
        markers: bool = True,
    ) -> tuple[dict[str, tuple], RunFeatures]:
        f = extract_run(
            run,
            self.params,
            self.odometry,
            segments=segments,
            progress=progress,
            threads=self.threads,
            landmark_stream=self.landmarks,
        )
        stamps = f.stamps
        channels = (
            {}
            if segments is not None
            else {
                mcapio.TOPIC_SEGMENTS: (
                    types.SEGMENTS,
                    stamps,
                    segment_payloads(run, f.seg_start, f.seg_end, f.seg_offsets),
                )
            }
        )
        channels |= {
            mcapio.TOPIC_FEATURES: (types.FEATURES, stamps, feature_payloads(f)),
            mcapio.TOPIC_LANDMARKS: (types.LANDMARKS, stamps, landmark_payloads(f)),
        }
        if markers:
            drawn = feature_markers(run, f, self.odometry)
            channels[mcapio.TOPIC_MARKERS_FEATURES] = (types.MARKER_ARRAY, stamps, drawn)
        return channels, f


def segment_payloads(run: ScanRun, seg_start: np.ndarray, seg_end: np.ndarray, offsets: np.ndarray) -> list[bytes]:
    """datmo_msgs/msg/Segments CDR payloads, one per scan."""
    return cdr.encode_block(
        types.SEGMENTS, run.stamps, run.geometry.frame_id, {"start": (seg_start, offsets), "end": (seg_end, offsets)}
    )


def feature_payloads(f: RunFeatures) -> list[bytes]:
    """datmo_msgs/msg/Features CDR payloads, one per scan."""
    return cdr.encode_block(
        types.FEATURES,
        f.stamps,
        f.frame_id,
        {
            "lines": (f.lines, f.line_offsets),
            "circles": (f.circles, f.circle_offsets),
            "blobs": (f.blobs, f.blob_offsets),
            "legs": (f.legs, f.leg_offsets),
        },
    )


def landmark_payloads(f: RunFeatures) -> list[bytes]:
    """datmo_msgs/msg/Landmarks CDR payloads: the database after each scan."""
    db = f.landmarks
    if db is None:
        raise ValueError("landmark_payloads: features extracted without landmarks")
    elems = db.all_snapshots(f.stamps)
    return cdr.encode_block(types.LANDMARKS, f.stamps, f.landmark_frame, {"landmarks": (elems, db.snap_offsets)})


def decode_segments(payloads: list[bytes], first: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, end, offsets) of datmo_msgs/msg/Segments payloads (a log's /datmo/segments, messages first..;
    cdr.DecodeError names a damaged one)."""
    msgs = cdr.decode_many(types.SEGMENTS, payloads, first)
    starts = [np.asarray(m["start"], np.int64) for m in msgs]
    ends = [np.asarray(m["end"], np.int64) for m in msgs]
    offsets = np.concatenate([[0], np.cumsum(np.array([len(s) for s in starts], np.int64))]).astype(np.int64)
    empty = np.zeros(0, np.int64)
    return (np.concatenate(starts) if starts else empty), (np.concatenate(ends) if ends else empty), offsets
