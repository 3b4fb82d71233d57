"""Training and honest evaluation of the learned leg detector (`datmo train-legs`, `make legs-model`), one
module a step:

- recordings: the labelled and empty recordings (scans, and the legs of each scan matched by log time), read
  through log.importers.scans_and_poses;
- tables: every cluster of a recording (leg_tracker's gap clusters or datmo's segments) with its features, its
  label and what the paper's circle rule makes of it;
- fitting: the scikit-learn ensemble, its training rows and the run-time model made of it;
- metrics: per-cluster precision, recall, average precision and false legs per empty scan;
- cross_validation: leave-one-recording-out folds, the threshold tuned on training recordings only;
- train: train_leg_model, the shipped model with its provenance.

The names callers use are re-exported here. scikit-learn is imported only inside the functions that fit (the
`train` extra). Units: metres, sensor frame of each scan (x forward, y left), times in ns.
"""

from __future__ import annotations

from .cross_validation import (
    EMPTY_FALSE_BUDGET,
    Fold,
    HeldOut,
    choose_threshold,
    cross_validate,
    cv_fits,
    fold_model,
    leave_one_out_folds,
    mean_figures,
    tuned_threshold,
)
from .fitting import EstimatorSpec, fit, require_sklearn, scores, to_model, training_rows
from .metrics import (
    METRIC_RANGE_M,
    RANGE_BINS_M,
    Figures,
    average_precision,
    circle_figures,
    figures,
    precision_recall,
    recall_by_range,
)
from .recordings import (
    DEFAULT_LABELS_TOPIC,
    LABEL_WINDOW_NS,
    Recording,
    match_labels,
    read_empty,
    read_labelled,
    thinned,
)
from .tables import (
    CIRCLE_LEG_RADIUS_M,
    DEFAULT_CLUSTERS,
    GAP_CLUSTERS,
    MATCH_RADIUS_M,
    SEGMENT_CLUSTERS,
    Progress,
    SegmentTable,
    label_segments,
    recording_clusters,
    segment_centroids,
    segment_table,
    tables_of,
)
from .train import THRESHOLD_RULE, TrainingResult, total_fits, train_leg_model

__all__ = [
    "CIRCLE_LEG_RADIUS_M",
    "DEFAULT_CLUSTERS",
    "DEFAULT_LABELS_TOPIC",
    "EMPTY_FALSE_BUDGET",
    "GAP_CLUSTERS",
    "LABEL_WINDOW_NS",
    "MATCH_RADIUS_M",
    "METRIC_RANGE_M",
    "RANGE_BINS_M",
    "SEGMENT_CLUSTERS",
    "THRESHOLD_RULE",
    "EstimatorSpec",
    "Figures",
    "Fold",
    "HeldOut",
    "Progress",
    "Recording",
    "SegmentTable",
    "TrainingResult",
    "average_precision",
    "choose_threshold",
    "circle_figures",
    "cross_validate",
    "cv_fits",
    "figures",
    "fit",
    "fold_model",
    "label_segments",
    "leave_one_out_folds",
    "match_labels",
    "mean_figures",
    "precision_recall",
    "read_empty",
    "read_labelled",
    "recall_by_range",
    "recording_clusters",
    "require_sklearn",
    "scores",
    "segment_centroids",
    "segment_table",
    "tables_of",
    "thinned",
    "to_model",
    "total_fits",
    "train_leg_model",
    "training_rows",
    "tuned_threshold",
]
