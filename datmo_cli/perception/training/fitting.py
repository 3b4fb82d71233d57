"""Fitting the leg detector: the scikit-learn tree ensemble (EstimatorSpec), the rows it is trained on (the
candidate clusters of SegmentTables, weighted), and the run-time model (legs.LegModel) made of it.
scikit-learn is imported only inside the functions that fit (the `train` extra).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from ...base.errors import InputError
from ...base.extras import require
from .tables import SegmentTable


def require_sklearn():
    """scikit-learn, or MissingExtraError naming the train extra."""
    return require("sklearn", for_="training a leg model")


@dataclass(frozen=True)
class EstimatorSpec:
    """A scikit-learn tree ensemble and how its training rows are chosen and weighted.

    kind: "extra_trees", "random_forest" or "gradient_boosting". Training rows: candidate segments
    (legs.candidate_mask) of the training recordings within train_range_m of the scanner (None: all);
    the unlabelled clusters of labelled recordings are negatives too (people outside the labelling box
    among them, the price of more hard negatives) with weight unlabelled_weight; empty_weight multiplies the
    weight of empty recordings' rows; class_weight "balanced" weighs legs and non-legs equally in total;
    ignore_features: FEATURE_NAMES columns held constant in training, so no tree uses them; negative_fraction:
    the share of non-leg rows kept (at random, weighted up by its inverse) to train faster."""

    kind: str = "gradient_boosting"
    n_estimators: int = 200
    max_depth: int | None = 5
    min_samples_leaf: int = 3
    max_features: float | str | None = 0.5
    learning_rate: float = 0.1
    class_weight: str | None = "balanced"
    train_range_m: float | None = None
    empty_weight: float = 1.0
    unlabelled_weight: float = 1.0
    ignore_features: tuple[str, ...] = ("n_points",)
    negative_fraction: float = 0.3
    seed: int = 0

    def build(self):
        require_sklearn()
        from sklearn.ensemble import ExtraTreesClassifier, GradientBoostingClassifier, RandomForestClassifier

        if self.kind == "gradient_boosting":
            return GradientBoostingClassifier(
                n_estimators=self.n_estimators,
                max_depth=self.max_depth,
                learning_rate=self.learning_rate,
                min_samples_leaf=self.min_samples_leaf,
                max_features=self.max_features,
                subsample=0.8,
                random_state=self.seed,
            )
        cls = {"extra_trees": ExtraTreesClassifier, "random_forest": RandomForestClassifier}.get(self.kind)
        if cls is None:
            raise ValueError(f"unknown estimator kind {self.kind!r}")
        return cls(
            n_estimators=self.n_estimators,
            max_depth=self.max_depth,
            min_samples_leaf=self.min_samples_leaf,
            max_features=self.max_features,
            random_state=self.seed,
            n_jobs=1,
        )

    def for_threshold(self) -> EstimatorSpec:
        """The spec of the inner models that only score recordings for choosing the threshold: a forest of a
        quarter of the trees (at least 10; a forest's probabilities keep their expectation with fewer trees,
        and the inner folds are most of the fitting time); boosting unchanged (its scores depend on the count)."""
        import dataclasses

        if self.kind == "gradient_boosting":
            return self
        return dataclasses.replace(self, n_estimators=max(10, self.n_estimators // 4))

    def to_dict(self) -> dict:
        out = asdict(self)
        out["ignore_features"] = list(self.ignore_features)
        return out


def training_rows(tables: Sequence[SegmentTable], spec: EstimatorSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(X, y, sample weight) of the candidate segments of `tables` (see EstimatorSpec)."""
    xs, ys, ws = [], [], []
    for t in tables:
        keep = t.candidate.copy()
        if spec.train_range_m is not None:
            keep &= t.range_m <= spec.train_range_m
        xs.append(t.features[keep])
        ys.append(t.label[keep])
        if t.labelled:
            ws.append(np.where(t.label[keep], 1.0, spec.unlabelled_weight))
        else:
            ws.append(np.full(int(keep.sum()), spec.empty_weight))
    X = np.concatenate(xs) if xs else np.zeros((0, 0))
    y = np.concatenate(ys) if ys else np.zeros(0, bool)
    w = np.concatenate(ws) if ws else np.zeros(0)
    if spec.negative_fraction < 1.0:  # a random share of the non-legs, weighted up to stand for the rest
        rng = np.random.default_rng(spec.seed)
        drop = ~y & (rng.random(len(y)) >= spec.negative_fraction)
        w = np.where(drop, 0.0, np.where(y, w, w / spec.negative_fraction))
    X, y, w = X[w > 0], y[w > 0], w[w > 0]
    if spec.ignore_features:
        from ..legs import FEATURE_NAMES

        X = X.copy()
        X[:, [FEATURE_NAMES.index(n) for n in spec.ignore_features]] = 0.0  # constant: no tree splits on it
    if spec.class_weight == "balanced" and y.any() and (~y).any():
        w = w * np.where(y, 0.5 * w.sum() / w[y].sum(), 0.5 * w.sum() / w[~y].sum())
    return X, y.astype(np.int64), w


def fit(tables: Sequence[SegmentTable], spec: EstimatorSpec):
    """The estimator of `spec` fitted on the candidate segments of `tables`."""
    X, y, w = training_rows(tables, spec)
    if not y.any() or y.all():
        raise InputError("the training data need both legs and other segments")
    est = spec.build()
    est.fit(X.astype(np.float32), y, sample_weight=w)
    return est


def to_model(estimator, threshold: float = 0.5, provenance: dict | None = None):
    """The legs.LegModel of a fitted estimator (what run time evaluates)."""
    from ..leg_model import from_sklearn

    return from_sklearn(estimator, float(threshold), provenance or {})


def scores(model, table: SegmentTable) -> np.ndarray:
    """Leg probability of every segment of `table` by the run-time evaluator (0 for non-candidates)."""
    return model.probabilities(table.features)
