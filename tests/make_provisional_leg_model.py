"""Write the PROVISIONAL packaged leg model, datmo_cli/perception/models/legs.npz.

A stand-in so the code and tests work until the proper training module replaces it: a small random forest
fitted on leg_tracker's labelled bags (../shared/data/legtracker). Positives: datmo segments (default
FeatureParams segmentation) of the positive_*_extracted bags whose centroid lies within 5 cm of a labelled
leg (/leg_cluster_positions, the centroids of leg_tracker's clusters); segments 5-50 cm from a label are
ambiguous (merged or split legs) and left out. Negatives: every segment of negative_2.bag (no people).
Only candidate_mask rows are used. No held-out evaluation beyond a quick cross-validation printed below.

    .venv/bin/python tests/make_provisional_leg_model.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.accuracy_tracking import read_leg_labels, read_ros1_scans  # noqa: E402
from datmo_cli.perception.features import segment_run  # noqa: E402
from datmo_cli.perception.legs import (  # noqa: E402
    DEFAULT_MODEL_PATH,
    FEATURE_NAMES,
    candidate_mask,
    cluster_features,
    from_sklearn,
)

DATA = ROOT.parent / "shared" / "data" / "legtracker"
POSITIVE = [f"positive_{i}_extracted.bag" for i in (1, 2, 3, 4, 6, 7)]
NEGATIVE = ("negative_2.bag", ("/left_scan", "/right_scan", "/rear_scan"))
POSITIVE_WITHIN = 0.05   # m
AMBIGUOUS_WITHIN = 0.5   # m


def run_features(run):
    g = run.geometry
    start, end, offsets = segment_run(run)
    feats = cluster_features(run.ranges, g.angles(), start, end, offsets, g.range_min, g.range_max)
    return feats, (start, end, offsets)


def label_distances(run, segments, labels) -> np.ndarray:
    """Distance (m) of each segment's centroid to the nearest labelled leg of its scan (inf: none)."""
    g = run.geometry
    start, end, offsets = segments
    angles = g.angles()
    out = np.full(len(start), np.inf)
    for k, legs in enumerate(labels):
        if not len(legs):
            continue
        for j in range(offsets[k], offsets[k + 1]):
            r = run.ranges[k, start[j]:end[j]].astype(float)
            a = angles[start[j]:end[j]]
            ok = np.isfinite(r) & (r > g.range_min) & (r < g.range_max)
            c = np.array([np.mean(r[ok] * np.cos(a[ok])), np.mean(r[ok] * np.sin(a[ok]))])
            out[j] = np.min(np.linalg.norm(legs - c, axis=1))
    return out


def main() -> None:
    import sklearn
    from sklearn.ensemble import RandomForestClassifier
    from sklearn.model_selection import cross_val_score

    X, y = [], []
    for name in POSITIVE:
        run, log_times = read_ros1_scans(DATA / name, "/training_scan")
        feats, segments = run_features(run)
        dist = label_distances(run, segments, read_leg_labels(DATA / name, log_times))
        keep = candidate_mask(feats) & (dist < POSITIVE_WITHIN)
        X.append(feats[keep])
        y.append(np.ones(keep.sum()))
    name, topics = NEGATIVE
    for topic in topics:
        run, _ = read_ros1_scans(DATA / name, topic)
        feats, _ = run_features(run)
        keep = candidate_mask(feats)
        X.append(feats[keep])
        y.append(np.zeros(keep.sum()))
    X = np.concatenate(X)
    y = np.concatenate(y)
    params = {"n_estimators": 25, "max_depth": 10, "min_samples_leaf": 3, "class_weight": "balanced",
              "random_state": 0}
    forest = RandomForestClassifier(**params)
    cv = cross_val_score(forest, X, y, cv=5, scoring="roc_auc")
    forest.fit(X, y)
    provenance = {
        "status": "PROVISIONAL: a stand-in for tests, to be replaced by the properly trained model",
        "script": "tests/make_provisional_leg_model.py",
        "estimator": "sklearn.ensemble.RandomForestClassifier", "params": params,
        "sklearn": sklearn.__version__,
        "data": {"positive": POSITIVE, "negative": [f"{name}:{t}" for t in topics],
                 "source": "github.com/angusleigh/leg_tracker e6cbb2bb (BSD-3-Clause)"},
        "labels": f"positive: segment centroid within {POSITIVE_WITHIN} m of a labelled leg; "
                  f"{POSITIVE_WITHIN}-{AMBIGUOUS_WITHIN} m left out; negatives: all segments of the negative bag",
        "segmentation": "datmo FeatureParams() defaults", "rows": {"positive": int(y.sum()),
                                                                    "negative": int((y == 0).sum())},
        "cv_roc_auc_5fold": [round(float(v), 4) for v in cv],
        "feature_names": list(FEATURE_NAMES),
    }
    model = from_sklearn(forest, 0.5, provenance)
    DEFAULT_MODEL_PATH.parent.mkdir(exist_ok=True)
    model.save(DEFAULT_MODEL_PATH)
    print(f"{DEFAULT_MODEL_PATH}: {model.n_trees} trees, {len(model.feature)} nodes; rows {provenance['rows']}; "
          f"5-fold ROC AUC {np.mean(cv):.4f}")


if __name__ == "__main__":
    main()
