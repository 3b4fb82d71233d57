"""Every cluster of a recording as a row to learn from (SegmentTable). Each scan is cut into clusters, by
default as leg_tracker does (`legs.gap_clusters`: a gap of more than 0.13 m between consecutive returns; the
labels are the centroids of exactly such clusters) or by datmo's own segmentation (`features.segment_run`);
the choice is recorded in the model's provenance["clusters"] (see `legs.model_clusters`). Each cluster gets the
features of `legs.cluster_features` and a label: a leg when a labelled leg lies within `MATCH_RADIUS_M` of its
centroid; beside them, what the paper's circle rule makes of the same cluster. Metres, sensor frame of each
scan (x forward, y left).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...logs.scan import ScanRun
from ..params import FeatureParams
from .recordings import Recording

MATCH_RADIUS_M = 0.15  # a segment is a leg when a labelled leg is this close to its centroid
CIRCLE_LEG_RADIUS_M = 0.13  # the paper's rule: a circle of at most this radius is a leg
SEGMENT_CLUSTERS = {"method": "segments"}  # datmo's own segments (features.segment_run)
GAP_CLUSTERS = {"method": "gap", "gap": 0.13, "min_points": 3}  # leg_tracker's clusters (legs.gap_clusters)
DEFAULT_CLUSTERS = GAP_CLUSTERS

#: progress(description, done, total)
Progress = Callable[[str, int, int], None]


@dataclass
class SegmentTable:
    """Every segment of one recording: features (M x F), label (a leg), candidate (legs.candidate_mask),
    scan index, centroid (M x 2, metres, sensor frame) and range (m), and the paper's circle rule
    (circle_leg: a circle of radius <= 0.13 m; circle_score: its r_acc, 0 for the others)."""

    name: str
    labelled: bool
    n_scans: int
    features: np.ndarray
    label: np.ndarray
    candidate: np.ndarray
    scan: np.ndarray
    centroid: np.ndarray
    circle_leg: np.ndarray
    circle_score: np.ndarray

    @property
    def range_m(self) -> np.ndarray:
        return np.hypot(self.centroid[:, 0], self.centroid[:, 1])

    def __len__(self) -> int:
        return len(self.label)


def segment_centroids(
    ranges: np.ndarray,
    angles: np.ndarray,
    seg_start: np.ndarray,
    seg_end: np.ndarray,
    seg_offsets: np.ndarray,
    range_min: float = 0.0,
    range_max: float = np.inf,
) -> np.ndarray:
    """The centroid (mean of the valid returns, metres, sensor frame) of every segment (M x 2); NaN for a
    segment without a valid return. ranges N x B, angles B (radians), segments as segment_run gives them."""
    ranges = np.asarray(ranges, np.float64)
    n_seg = len(seg_start)
    scan = np.repeat(np.arange(len(seg_offsets) - 1), np.diff(seg_offsets))
    lengths = np.asarray(seg_end, np.int64) - np.asarray(seg_start, np.int64)
    seg_of = np.repeat(np.arange(n_seg), lengths)
    beam = (
        np.arange(lengths.sum())
        - np.repeat(np.cumsum(lengths) - lengths, lengths)
        + np.repeat(np.asarray(seg_start, np.int64), lengths)
    )
    r = ranges[scan[seg_of], beam]
    ok = np.isfinite(r) & (r > range_min) & (r < range_max)
    x = np.where(ok, r * np.cos(angles[beam]), 0.0)
    y = np.where(ok, r * np.sin(angles[beam]), 0.0)
    n = np.bincount(seg_of, ok, minlength=n_seg)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.stack(
            [np.bincount(seg_of, x, minlength=n_seg) / n, np.bincount(seg_of, y, minlength=n_seg) / n], axis=1
        )


def label_segments(
    centroid: np.ndarray, scan: np.ndarray, legs: Sequence[np.ndarray], radius: float = MATCH_RADIUS_M
) -> np.ndarray:
    """True for each segment (centroid M x 2, scan index M) with a labelled leg of its scan (legs[k], K x 2)
    within `radius` metres of its centroid. Several segments may match one leg (a leg split in two) and one
    segment several legs (two legs merged)."""
    out = np.zeros(len(scan), bool)
    if not len(scan):
        return out
    order = np.argsort(scan, kind="stable")
    bounds = np.searchsorted(scan[order], np.arange(len(legs) + 1))
    for k, lk in enumerate(legs):
        a, b = bounds[k], bounds[k + 1]
        if a == b or not len(lk):
            continue
        idx = order[a:b]
        d = np.hypot(centroid[idx, None, 0] - lk[None, :, 0], centroid[idx, None, 1] - lk[None, :, 1])
        out[idx] = (d <= radius).any(axis=1)
    return out


def _paper_rule(p: FeatureParams) -> FeatureParams:
    """`p` without a learned leg detector (circles alone; no model file needed)."""
    import dataclasses

    names = {f.name for f in dataclasses.fields(p)}
    return dataclasses.replace(p, leg_model="paper") if "leg_model" in names else p


def recording_clusters(
    run: ScanRun, params: FeatureParams | None = None, clusters: dict | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, end, offsets) of the clusters of every scan of `run`: datmo's segments (features.segment_run with
    params) for clusters {"method": "segments"}, leg_tracker's gap clusters (legs.gap_clusters) for
    {"method": "gap", "gap": m, "min_points": n}; None: DEFAULT_CLUSTERS."""
    from .. import legs
    from ..features import _range_limits, segment_run

    c: dict[str, Any] = DEFAULT_CLUSTERS if clusters is None else clusters
    if c.get("method") == "segments":
        return segment_run(run, params or FeatureParams())
    if c.get("method") == "gap":
        lo, hi = _range_limits(run)
        return legs.gap_clusters(
            run.ranges,
            run.geometry.angles(),
            lo,
            hi,
            float(c.get("gap", legs.GAP_M)),
            int(c.get("min_points", legs.GAP_MIN_POINTS)),
        )
    raise ValueError(f"unknown cluster method {c.get('method')!r}: 'segments' or 'gap'")


def segment_table(
    rec: Recording, params: FeatureParams | None = None, radius: float = MATCH_RADIUS_M, clusters: dict | None = None
) -> SegmentTable:
    """Cluster a recording (recording_clusters: datmo's segments or gap clusters) and tabulate its clusters
    (see SegmentTable); the circle rule runs on the same clusters."""
    from .. import legs
    from ..features import _range_limits, extract_run

    p = params or FeatureParams()
    run = rec.run
    start, end, offsets = recording_clusters(run, p, clusters)
    lo, hi = _range_limits(run)
    angles = run.geometry.angles()
    feats = np.asarray(legs.cluster_features(run.ranges, angles, start, end, offsets, lo, hi), np.float64)
    scan = np.repeat(np.arange(len(run)), np.diff(offsets))
    centroid = segment_centroids(run.ranges, angles, start, end, offsets, lo, hi)
    label = label_segments(centroid, scan, rec.legs, radius) if rec.legs is not None else np.zeros(len(scan), bool)
    rf = extract_run(run, _paper_rule(p), landmarks=False, segments=(start, end, offsets))
    circles = rf.circles
    circle_leg = np.zeros(len(scan), bool)
    circle_score = np.zeros(len(scan))
    if len(circles):
        c_scan = np.repeat(np.arange(len(run)), np.diff(rf.circle_offsets))
        idx = offsets[c_scan] + circles["segment"].astype(np.int64)
        small = circles["radius"] <= CIRCLE_LEG_RADIUS_M
        circle_leg[idx[small]] = True
        circle_score[idx[small]] = circles["r_acc"][small]
    return SegmentTable(
        rec.name,
        rec.labelled,
        len(run),
        feats,
        label,
        np.asarray(legs.candidate_mask(feats), bool),
        scan,
        centroid,
        circle_leg,
        circle_score,
    )


def tables_of(
    recordings: Sequence[Recording],
    params: FeatureParams | None = None,
    radius: float = MATCH_RADIUS_M,
    progress: Progress | None = None,
    clusters: dict | None = None,
) -> list[SegmentTable]:
    """segment_table of each recording, reporting progress("segments", done, total)."""
    out = []
    for i, rec in enumerate(recordings):
        if progress is not None:
            progress("segments", i, len(recordings))
        out.append(segment_table(rec, params, radius, clusters))
    if progress is not None:
        progress("segments", len(recordings), len(recordings))
    return out
