"""Per-cluster figures of a leg detector on held-out recordings: precision, recall, average precision (pure
numpy, as scikit-learn computes it) on the labelled recording's clusters within `METRIC_RANGE_M` of the
scanner, false legs per scan of an empty recording, the same for the paper's circle rule on the same clusters,
and recall by range. Metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tables import SegmentTable

METRIC_RANGE_M = 5.0  # figures count clusters whose centroid is at most this far from the scanner


@dataclass
class Figures:
    """Per-cluster figures of one held-out pair (labelled recording, empty recording) at one threshold.
    precision/recall/ap: on the labelled recording's clusters within METRIC_RANGE_M; false_per_scan: clusters
    called legs per scan of the empty recording within METRIC_RANGE_M (None without one)."""

    precision: float
    recall: float
    ap: float
    false_per_scan: float | None
    legs: int
    clusters: int
    empty_scans: int


def precision_recall(y: np.ndarray, called: np.ndarray) -> tuple[float, float]:
    """Precision and recall of boolean calls against boolean labels (1.0 precision when nothing is called)."""
    tp = int(np.sum(y & called))
    n_called, n_pos = int(called.sum()), int(y.sum())
    return (tp / n_called if n_called else 1.0), (tp / n_pos if n_pos else float("nan"))


def average_precision(y: np.ndarray, score: np.ndarray) -> float:
    """Average precision (the area under the precision-recall steps, as scikit-learn computes it: ties share
    a step); NaN without positives. Pure numpy so evaluation needs no scikit-learn."""
    y = np.asarray(y, bool)
    if not y.any():
        return float("nan")
    order = np.argsort(-np.asarray(score, np.float64), kind="stable")
    s, yy = np.asarray(score)[order], y[order]
    last = np.r_[np.flatnonzero(np.diff(s)), len(s) - 1]  # the last index of each group of tied scores
    tp = np.cumsum(yy)[last]
    fp = (last + 1) - tp
    precision = tp / (tp + fp)
    recall = tp / y.sum()
    return float(np.sum(np.diff(np.r_[0.0, recall]) * precision))


def figures(
    labelled: SegmentTable,
    score: np.ndarray,
    threshold: float,
    empty: SegmentTable | None = None,
    empty_score: np.ndarray | None = None,
) -> Figures:
    """Figures (see Figures) of scores on a held-out labelled table (and an empty one); a cluster is called a
    leg when its score >= threshold."""
    near = labelled.range_m <= METRIC_RANGE_M
    y, s = labelled.label[near], np.asarray(score)[near]
    p, r = precision_recall(y, s >= threshold)
    fps = None
    scans = 0
    if empty is not None:
        e_near = empty.range_m <= METRIC_RANGE_M
        scans = empty.n_scans
        fps = float(np.sum(np.asarray(empty_score)[e_near] >= threshold)) / max(scans, 1)
    return Figures(p, r, average_precision(y, s), fps, int(y.sum()), int(near.sum()), scans)


def circle_figures(labelled: SegmentTable, empty: SegmentTable | None = None) -> Figures:
    """The paper's circle rule on the same clusters: a leg when a circle of radius <= 0.13 m was found on the
    segment; its r_acc ranks the circles for AP (0 for the others)."""
    score = np.where(labelled.circle_leg, np.maximum(labelled.circle_score, 1e-9), 0.0)
    e_score = None if empty is None else np.where(empty.circle_leg, 1.0, 0.0)
    return figures(labelled, score, 1e-9, empty, e_score)


RANGE_BINS_M = (0.0, 2.0, 3.0, 4.0, 5.0)


def recall_by_range(table: SegmentTable, score: np.ndarray, threshold: float) -> tuple[float | None, ...]:
    """Recall at `threshold` of the labelled legs in each range bin of RANGE_BINS_M (None: no leg there)."""
    r = table.range_m
    out = []
    for lo, hi in zip(RANGE_BINS_M[:-1], RANGE_BINS_M[1:], strict=True):
        legs = table.label & (r >= lo) & (r < hi)
        out.append(float(np.mean(np.asarray(score)[legs] >= threshold)) if legs.any() else None)
    return tuple(out)
