"""A learned leg detector: geometric features of each scan segment and a tree ensemble's leg probability.

The features are those of Arras, Mozos and Burgard (2007) and Leigh et al. (2015, leg_tracker), computed by
numba kernels (leg_features.py) over the points of each segment, sensor frame (x forward, y left), metres and
radians. The ensemble (a random forest / extra trees or gradient boosting, trained offline with scikit-learn)
is shipped as plain node arrays in one .npz (leg_model.LegModel) and evaluated by a numba kernel
(leg_forest.py), so run time needs neither scikit-learn nor pickles.

Candidate rule (`candidate_mask`): a segment of fewer than CANDIDATE_MIN_POINTS points or wider than
CANDIDATE_MAX_WIDTH (first to last point) cannot be a leg; `leg_probabilities` gives it 0 without evaluating
the ensemble. Train on candidates only (apply `candidate_mask` to the training rows), so the model never
has to learn what the rule already decides.

Clusters: a model scores the clusters it was trained on, named by its provenance["clusters"]: datmo's segments
({"method": "segments"}, also models without the key) or leg_tracker's gap clusters (`gap_clusters`, {"method":
"gap", "gap": 0.13, "min_points": 3}); `model_clusters` gives them for a scan block.
"""

from __future__ import annotations

import math

import numpy as np

from datmo_cli.base import libm

from .leg_model import LegModel
from .leg_rules import (  # noqa: F401 (the detector's vocabulary, read from here by its callers)
    CANDIDATE_MAX_WIDTH,
    CANDIDATE_MIN_POINTS,
    DENSITY_CLIP,
    FEATURE_NAMES,
    GAP_M,
    GAP_MIN_POINTS,
    JUMP_CLIP,
    NEIGHBOUR_CLIP,
    OCCLUSION_MARGIN,
    RADIUS_CLIP,
)


def candidate_mask(features: np.ndarray) -> np.ndarray:
    """Rows of features (M, len(FEATURE_NAMES)) that may be legs: n_points >= CANDIDATE_MIN_POINTS and
    width <= CANDIDATE_MAX_WIDTH (m). Other rows get probability 0 in leg_probabilities; train on these only."""
    f = np.asarray(features, np.float64).reshape(-1, len(FEATURE_NAMES))
    return (f[:, 0] >= CANDIDATE_MIN_POINTS) & (f[:, 1] <= CANDIDATE_MAX_WIDTH)


def _scan_arrays(ranges, angles) -> tuple[np.ndarray, np.ndarray]:
    """ranges (N, B) as contiguous float32 and angles (B,) as contiguous float64, or ValueError."""
    ranges = np.ascontiguousarray(ranges, np.float32)
    if ranges.ndim != 2:
        raise ValueError(f"ranges must be (N, B), got shape {ranges.shape}")
    angles = np.ascontiguousarray(angles, np.float64)
    if angles.shape != (ranges.shape[1],):
        raise ValueError(f"angles must have shape ({ranges.shape[1]},), got {angles.shape}")
    return ranges, angles


def _scan_inputs(ranges, angles, seg_start, seg_end, seg_offsets):
    from . import leg_features as LF

    ranges, angles = _scan_arrays(ranges, angles)
    N, B = ranges.shape
    start = np.ascontiguousarray(seg_start, np.int64)
    end = np.ascontiguousarray(seg_end, np.int64)
    offsets = np.ascontiguousarray(seg_offsets, np.int64)
    if start.ndim != 1 or end.shape != start.shape:
        raise ValueError("seg_start and seg_end must be 1-D arrays of the same length")
    if offsets.shape != (N + 1,):
        raise ValueError(f"seg_offsets must be N + 1 = {N + 1} non-decreasing indices from 0 to {len(start)}")
    problem = LF.check_segments(start, end, offsets, B)
    if problem == 1:
        raise ValueError(f"seg_offsets must be N + 1 = {N + 1} non-decreasing indices from 0 to {len(start)}")
    if problem == 2:
        raise ValueError(f"segments must be beam ranges [start, end) within 0..{B}")
    cos_a, sin_a = _trig(angles)
    return ranges, angles, cos_a, sin_a, start, end, offsets


_TRIG: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}


def _trig(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """cos and sin of the beam angles, computed once per scan geometry (a few kept)."""
    key = angles.tobytes()
    hit = _TRIG.get(key)
    if hit is None:
        if len(_TRIG) >= 8:
            _TRIG.clear()
        hit = _TRIG[key] = (libm.cos(angles), libm.sin(angles))
    return hit


def _limits(range_min: float, range_max: float) -> tuple[float, float]:
    lo = float(range_min) if math.isfinite(range_min) else 0.0
    hi = float(range_max) if math.isfinite(range_max) and range_max > lo else math.inf
    return lo, hi


def _angle_step(angles: np.ndarray) -> float:
    """The scan's beam spacing (rad, positive): first to last beam over the gaps between them."""
    return abs(float(angles[-1]) - float(angles[0])) / (len(angles) - 1) if len(angles) > 1 else 0.0


def gap_clusters(
    ranges, angles, range_min: float, range_max: float, gap: float = GAP_M, min_points: int = GAP_MIN_POINTS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """leg_tracker's clusters of every scan: consecutive valid returns (finite, strictly between range_min and
    range_max) more than `gap` metres apart start a new cluster, an invalid return ends one, and clusters of
    fewer than `min_points` returns are dropped. ranges (N, B) metres, angles (B,) radians. Returns (start,
    end, offsets) int64 as features.segment_run does: scan k's clusters are beam ranges [start, end) of
    start/end[offsets[k]:offsets[k + 1]], in beam order (every beam inside a cluster is a valid return)."""
    from . import leg_features as LF

    ranges, angles = _scan_arrays(ranges, angles)
    N, B = ranges.shape
    cos_a, sin_a = _trig(angles)
    lo, hi = _limits(range_min, range_max)
    counts = np.zeros(N, np.int64)
    # one pass into room for the most clusters there can be: disjoint, of at least max(min_points, 1) beams
    most = N * (B // max(int(min_points), 1))
    start = np.empty(most, np.int64)
    end = np.empty(most, np.int64)
    if most:
        LF._gap_pass(ranges, cos_a, sin_a, lo, hi, float(gap), int(min_points), start, end, counts)
    offsets = np.zeros(N + 1, np.int64)
    np.cumsum(counts, out=offsets[1:])
    return start[: offsets[-1]].copy(), end[: offsets[-1]].copy(), offsets


def model_clusters(
    ranges, angles, range_min: float, range_max: float, model: LegModel | None, seg_start, seg_end, seg_offsets
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The clusters `model` scores (its provenance["clusters"]): gap_clusters of the scans for a model trained
    on them ({"method": "gap", "gap": m, "min_points": n}), else (method "segments", no such key, or no model)
    the given segments (seg_start, seg_end, seg_offsets as int64 arrays). Inputs as in cluster_features."""
    spec = (model.provenance.get("clusters") if model is not None else None) or {"method": "segments"}
    if spec.get("method") == "gap":
        return gap_clusters(
            ranges,
            angles,
            range_min,
            range_max,
            float(spec.get("gap", GAP_M)),
            int(spec.get("min_points", GAP_MIN_POINTS)),
        )
    if spec.get("method") != "segments":
        raise ValueError(f"unknown cluster method {spec.get('method')!r} in the leg model's provenance")
    return (np.asarray(seg_start, np.int64), np.asarray(seg_end, np.int64), np.asarray(seg_offsets, np.int64))


def cluster_features(ranges, angles, seg_start, seg_end, seg_offsets, range_min: float, range_max: float) -> np.ndarray:
    """Features of every segment, shape (M, len(FEATURE_NAMES)) float64, in the order of seg_start.

    ranges (N, B) metres; angles (B,) radians, sensor frame (x forward, y left), beam i at angles[i]. Scan k's
    segments are seg_start/seg_end[seg_offsets[k]:seg_offsets[k + 1]], beam ranges [start, end) (as
    features.segment_run gives them). Returns count when finite and strictly between range_min and
    range_max; other beams inside a segment are skipped, and a segment with no valid return gets zeros.
    """
    from . import leg_features as LF

    ranges, angles, cos_a, sin_a, start, end, offsets = _scan_inputs(ranges, angles, seg_start, seg_end, seg_offsets)
    lo, hi = _limits(range_min, range_max)
    out = np.zeros((len(start), LF.N_FEATURES), np.float64)
    if len(start):
        beams = (cos_a, sin_a, angles, _angle_step(angles))
        rules = (lo, hi, RADIUS_CLIP, OCCLUSION_MARGIN, CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS)
        LF.block_features(ranges, beams, (start, end, offsets), rules, False, out)
    return out


def leg_probabilities(
    ranges,
    angles,
    seg_start,
    seg_end,
    seg_offsets,
    range_min: float,
    range_max: float,
    model: LegModel,
    threads: int = 1,
) -> np.ndarray:
    """Leg probability (M,) float64 of every segment (inputs as in cluster_features): features and ensemble in
    one compiled call, on `threads` threads (a perception.threads.resolve()d count; the same result for any).
    Segments outside candidate_mask get 0."""
    from . import leg_features as LF
    from . import leg_forest
    from . import threads as TH

    ranges, angles, cos_a, sin_a, start, end, offsets = _scan_inputs(ranges, angles, seg_start, seg_end, seg_offsets)
    lo, hi = _limits(range_min, range_max)
    M = len(start)
    out = np.zeros(M, np.float64)
    if M:
        feats = np.empty((M, LF.N_FEATURES), np.float64)
        beams = (cos_a, sin_a, angles, _angle_step(angles))
        rules = (lo, hi, RADIUS_CLIP, OCCLUSION_MARGIN, CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS)
        args = (beams, (start, end, offsets), rules, model._kernel_args(), feats, out)
        N = len(ranges)
        threads = TH.for_scans(threads, N)
        if threads > 1:
            with TH.numba_threads(threads):
                leg_forest.block_probabilities_parallel(ranges, min(N, 4 * threads), *args)
        else:
            leg_forest.block_probabilities(ranges, *args)
    return out
