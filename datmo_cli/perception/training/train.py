"""Training the shipped leg detector (`datmo train-legs`, `make legs-model`): cross-validate (see
cross_validation), then train on every recording with the threshold tuned on them all; the model's provenance
says what it was trained on and how it did on recordings held out.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ...base.errors import InputError
from ..params import FeatureParams
from .cross_validation import (
    EMPTY_FALSE_BUDGET,
    HeldOut,
    _fits,
    _step,
    cross_validate,
    cv_fits,
    mean_figures,
    tuned_threshold,
)
from .fitting import EstimatorSpec, fit, require_sklearn, to_model
from .metrics import METRIC_RANGE_M
from .recordings import DEFAULT_LABELS_TOPIC, LABEL_WINDOW_NS, Recording
from .tables import DEFAULT_CLUSTERS, MATCH_RADIUS_M, Progress, SegmentTable, tables_of

if TYPE_CHECKING:
    from ..leg_model import LegModel


@dataclass
class TrainingResult:
    """The model trained on every recording (threshold and provenance inside) and the held-out figures that
    estimate how it does on recordings it has not seen (empty with one labelled recording)."""

    model: LegModel
    held_out: list[HeldOut]
    mean: dict
    threshold: float
    tables: list[SegmentTable] = field(default_factory=list, repr=False)


THRESHOLD_RULE = (
    f"highest F1 on the training recordings' inner leave-one-recording-out scores (clusters within "
    f"{METRIC_RANGE_M:g} m) with at most {EMPTY_FALSE_BUDGET:g} false legs per empty scan"
)


def total_fits(n_lab: int, n_emp: int) -> int:
    """Models train_leg_model fits: the cross-validation's and the final model's."""
    return cv_fits(n_lab, n_emp) + _fits(n_lab, n_emp)


def _sources(recordings: Sequence[Recording]) -> list[dict]:
    from ...logs.mcapio import sha256_of

    out: list[dict] = []
    seen: dict[str, dict[str, Any]] = {}
    for r in recordings:
        key = str(r.path)
        if key not in seen:
            seen[key] = {
                "file": r.path.name,
                "path": key,
                "sha256": sha256_of(r.path),
                "role": "labelled" if r.labelled else "empty",
                "topics": [],
                "scans": 0,
                "legs": 0,
            }
            out.append(seen[key])
        entry = seen[key]
        entry["topics"].append(r.topic)
        entry["scans"] += len(r.run)
        entry["legs"] += int(sum(len(x) for x in r.legs)) if r.legs is not None else 0
    return out


def train_leg_model(
    labelled: Sequence[Recording],
    empty: Sequence[Recording],
    spec: EstimatorSpec | None = None,
    params: FeatureParams | None = None,
    progress: Progress | None = None,
    labels_topic: str = DEFAULT_LABELS_TOPIC,
    clusters: dict | None = None,
    extra: Sequence[Recording] = (),
) -> TrainingResult:
    """Cross-validate (see cross_validate), then train on every recording with the threshold tuned on them
    all (see tuned_threshold); the model's provenance holds the data files and their SHA-256, the features,
    the estimator, the threshold and its rule, the held-out figures, scikit-learn's version, the date and the
    clusters the model scores (clusters, default DEFAULT_CLUSTERS; see legs.model_clusters). `extra`
    labelled recordings (simulated ones: datmo_cli.passes.simulated) are in every training set, never held out or scored."""
    sklearn = require_sklearn()

    from ... import __version__
    from ..legs import CANDIDATE_MAX_WIDTH, CANDIDATE_MIN_POINTS, FEATURE_NAMES

    if not labelled:
        raise InputError("no labelled recording: give at least one file with leg labels")
    spec = spec or EstimatorSpec()
    p = params or FeatureParams()
    clusters = dict(DEFAULT_CLUSTERS if clusters is None else clusters)
    tables = tables_of(list(labelled) + list(empty) + list(extra), p, progress=progress, clusters=clusters)
    lab, emp = tables[: len(labelled)], tables[len(labelled) : len(labelled) + len(empty)]
    more = tables[len(labelled) + len(empty) :]
    if not any(t.label.any() for t in lab):
        raise InputError(
            f"no segment lies within {MATCH_RADIUS_M:g} m of a labelled leg: are the labels in the scans' frame?"
        )
    step = _step(progress, total_fits(len(lab), len(emp)))
    held_out = cross_validate(lab, emp, spec, step=step, extra=more)
    threshold = tuned_threshold(lab, emp, spec, step, extra=more)
    estimator = fit(lab + emp + more, spec)
    step()
    mean = mean_figures(held_out)
    provenance = {
        "tool": f"datmo {__version__} train-legs",
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "sklearn_version": sklearn.__version__,
        "data": _sources(list(labelled) + list(empty)),
        "simulated": [
            {"name": r.name, "scans": len(r.run), "legs": int(sum(len(g) for g in r.legs or ()))} for r in extra
        ],
        "feature_names": list(FEATURE_NAMES),
        "candidate_rule": {"min_points": CANDIDATE_MIN_POINTS, "max_width_m": CANDIDATE_MAX_WIDTH},
        "estimator": {"class": type(estimator).__name__, **spec.to_dict()},
        "segmentation": {"c0": p.c0, "min_points": p.min_points},
        "clusters": clusters,
        "labels": {"topic": labels_topic, "match_radius_m": MATCH_RADIUS_M, "window_ms": LABEL_WINDOW_NS / 1e6},
        "threshold": {"value": threshold, "rule": THRESHOLD_RULE},
        "held_out": {
            "scheme": "leave one labelled recording out, with one empty recording in turn",
            "metric_range_m": METRIC_RANGE_M,
            "mean": mean,
            "folds": [h.to_dict() for h in held_out],
        },
    }
    model = to_model(estimator, threshold, provenance)
    return TrainingResult(model, held_out, mean, threshold, tables)
