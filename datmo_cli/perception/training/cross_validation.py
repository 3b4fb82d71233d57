"""Honest evaluation of the leg detector: leave-one-recording-out. Each labelled recording is held out in turn
together with one empty recording (cycling through them), the model is trained on the others only, and its
decision threshold is chosen on the training recordings only (inner leave-one-out: `tuned_threshold`, by
`choose_threshold`). Figures (see metrics) are per cluster, on clusters within `METRIC_RANGE_M` of the scanner,
beside the paper's circle rule on the same clusters.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .fitting import EstimatorSpec, fit, scores, to_model
from .metrics import METRIC_RANGE_M, Figures, circle_figures, figures, recall_by_range
from .tables import DEFAULT_CLUSTERS, Progress, SegmentTable

EMPTY_FALSE_BUDGET = 0.5  # false legs per empty scan allowed when choosing the threshold (the target)


@dataclass(frozen=True)
class Fold:
    """One split by recording: indices into the labelled and the empty recordings. Train and test never share
    a recording."""

    test_labelled: int
    test_empty: int | None
    train_labelled: tuple[int, ...]
    train_empty: tuple[int, ...]


def leave_one_out_folds(n_labelled: int, n_empty: int) -> list[Fold]:
    """Fold i holds out labelled recording i and empty recording i mod n_empty (cycling), and trains on every
    other recording. No folds with fewer than two labelled recordings (nothing would be left to train on).
    With one empty recording, it is held out in turn and training has no empty recording."""
    if n_labelled < 2:
        return []
    out = []
    for i in range(n_labelled):
        j = i % n_empty if n_empty else None
        out.append(
            Fold(i, j, tuple(k for k in range(n_labelled) if k != i), tuple(k for k in range(n_empty) if k != j))
        )
    return out


def choose_threshold(
    y: np.ndarray,
    score: np.ndarray,
    empty_score: np.ndarray | None = None,
    empty_scans: int = 0,
    budget: float = EMPTY_FALSE_BUDGET,
) -> float:
    """The threshold (a segment is a leg when its score >= it) of highest F1 on labelled clusters (y, score),
    among those giving at most `budget` false legs per empty scan on empty clusters (empty_score over
    empty_scans scans); the lowest threshold meeting the budget when none scores. Scores in [0, 1]."""
    y = np.asarray(y, bool)
    s = np.asarray(score, np.float64)
    cand = np.unique(np.r_[s[s > 0], 1.0])  # thresholds worth trying: each distinct positive score
    order = np.sort(s)
    n_at_or_above = len(s) - np.searchsorted(order, cand, side="left")
    tp = len(s[y]) - np.searchsorted(np.sort(s[y]), cand, side="left")
    f1 = 2.0 * tp / np.maximum(n_at_or_above + y.sum(), 1)
    ok = np.ones(len(cand), bool)
    if empty_score is not None and empty_scans:
        e = np.sort(np.asarray(empty_score, np.float64))
        ok = (len(e) - np.searchsorted(e, cand, side="left")) / empty_scans <= budget
    if not ok.any():
        return 1.0
    f1 = np.where(ok, f1, -1.0)
    return float(cand[int(np.argmax(f1))])


@dataclass
class HeldOut:
    """Figures on one held-out pair of recordings, of the model trained without them (at the threshold chosen
    on its training recordings) and of the paper's circle rule."""

    labelled: str
    empty: str | None
    threshold: float
    learned: Figures
    circle: Figures
    thinned_recall: float | None = None  # on the held-out recording thinned 2x
    recall_by_range: tuple[float | None, ...] = ()  # per RANGE_BINS_M bin, at the threshold

    def to_dict(self) -> dict:
        return {
            "labelled": self.labelled,
            "empty": self.empty,
            "threshold": self.threshold,
            "learned": asdict(self.learned),
            "circle": asdict(self.circle),
        }


def _step(progress: Progress | None, total: int) -> Callable[[], None]:
    done = [0]
    if progress is not None:
        progress("training", 0, total)

    def step() -> None:
        done[0] += 1
        if progress is not None:
            progress("training", done[0], total)

    return step


def _near(t: SegmentTable) -> np.ndarray:
    return t.range_m <= METRIC_RANGE_M


def tuned_threshold(
    lab: Sequence[SegmentTable],
    emp: Sequence[SegmentTable],
    spec: EstimatorSpec,
    step: Callable[[], None] = lambda: None,
    budget: float = EMPTY_FALSE_BUDGET,
    extra: Sequence[SegmentTable] = (),
) -> float:
    """The threshold for a model trained on (lab, emp), chosen on those recordings alone: each is scored by a
    model trained without it (inner leave-one-out, as leave_one_out_folds), and choose_threshold picks on
    the pooled out-of-fold scores of clusters within METRIC_RANGE_M (inner models: spec.for_threshold()). With
    one labelled recording there is no inner fold: the model's own training scores are used (optimistic).
    `extra` recordings (simulated ones) are in every training set and never scored."""
    folds = leave_one_out_folds(len(lab), len(emp))
    ys, ss, es, scans = [], [], [], 0
    if not folds:
        model = to_model(fit(list(lab) + list(emp) + list(extra), spec))
        step()
        folds_scored = [(t, scores(model, t)) for t in list(lab) + list(emp)]
    else:
        folds_scored = []
        inner = spec.for_threshold()
        for f in folds:
            model = to_model(
                fit([lab[i] for i in f.train_labelled] + [emp[j] for j in f.train_empty] + list(extra), inner)
            )
            step()
            folds_scored.append((lab[f.test_labelled], scores(model, lab[f.test_labelled])))
            if f.test_empty is not None:
                folds_scored.append((emp[f.test_empty], scores(model, emp[f.test_empty])))
    for t, s in folds_scored:
        near = _near(t)
        if t.labelled:
            ys.append(t.label[near])
            ss.append(s[near])
        else:
            es.append(s[near])
            scans += t.n_scans
    return choose_threshold(np.concatenate(ys), np.concatenate(ss), np.concatenate(es) if es else None, scans, budget)


def _fits(n_lab: int, n_emp: int) -> int:
    """Model fits of tuned_threshold plus the model itself, for n_lab labelled recordings."""
    return (n_lab if n_lab >= 2 else 1) + 1


def cross_validate(
    lab: Sequence[SegmentTable],
    emp: Sequence[SegmentTable],
    spec: EstimatorSpec,
    progress: Progress | None = None,
    *,
    step: Callable[[], None] | None = None,
    extra: Sequence[SegmentTable] = (),
    thin: Sequence[SegmentTable] = (),
) -> list[HeldOut]:
    """Leave-one-recording-out figures (see leave_one_out_folds): for each fold a model trained on the other
    recordings (and `extra`, always), its threshold tuned on them alone, scored on the held-out pair beside
    the circle rule, with its recall by range; `thin[i]`, when given, is labelled recording i thinned
    (`thinned`): the held-out one's recall at the same threshold is scored too. Empty list with fewer than two
    labelled recordings."""
    folds = leave_one_out_folds(len(lab), len(emp))
    if step is None:
        step = _step(progress, cv_fits(len(lab), len(emp)))
    out = []
    for f in folds:
        tr_lab = [lab[i] for i in f.train_labelled]
        tr_emp = [emp[j] for j in f.train_empty]
        threshold = tuned_threshold(tr_lab, tr_emp, spec, step, extra=extra)
        model = to_model(fit(tr_lab + tr_emp + list(extra), spec))
        step()
        test = lab[f.test_labelled]
        empty = emp[f.test_empty] if f.test_empty is not None else None
        test_scores = scores(model, test)
        learned = figures(test, test_scores, threshold, empty, None if empty is None else scores(model, empty))
        thin_recall = None
        if thin:
            t = thin[f.test_labelled]
            thin_recall = figures(t, scores(model, t), threshold).recall
        out.append(
            HeldOut(
                test.name,
                None if empty is None else empty.name,
                threshold,
                learned,
                circle_figures(test, empty),
                thin_recall,
                recall_by_range(test, test_scores, threshold),
            )
        )
    return out


def fold_model(
    lab: Sequence[SegmentTable],
    emp: Sequence[SegmentTable],
    fold: Fold,
    spec: EstimatorSpec | None = None,
    extra: Sequence[SegmentTable] = (),
    clusters: dict | None = None,
    tune: bool = False,
):
    """A model trained as the shipped one without `fold`'s held-out recordings, as a LegModel run time can use
    (its provenance names the clusters it scores), to track the held-out recordings with. Its threshold is
    tuned on the rest only with `tune` (tracking does not use it: it takes legs by TrackingParams.leg_probability);
    else 0.5."""
    spec = spec or EstimatorSpec()
    tr_lab = [lab[i] for i in fold.train_labelled]
    tr_emp = [emp[j] for j in fold.train_empty]
    threshold = tuned_threshold(tr_lab, tr_emp, spec, extra=extra) if tune else 0.5
    c = dict(DEFAULT_CLUSTERS if clusters is None else clusters)
    return to_model(
        fit(tr_lab + tr_emp + list(extra), spec),
        threshold,
        {"clusters": c, "note": f"fold model: {lab[fold.test_labelled].name} held out"},
    )


def cv_fits(n_lab: int, n_emp: int) -> int:
    """How many models cross_validate fits."""
    return sum(_fits(n_lab - 1, n_emp) for _ in leave_one_out_folds(n_lab, n_emp))


def mean_figures(held_out: Sequence[HeldOut]) -> dict:
    """Means over held-out pairs of each figure, learned and circle rule ({} without folds)."""
    if not held_out:
        return {}
    out: dict[str, Any] = {}
    for which in ("learned", "circle"):
        rows = [asdict(getattr(h, which)) for h in held_out]
        out[which] = {
            k: float(np.nanmean([r[k] for r in rows if r[k] is not None]))
            for k in ("precision", "recall", "ap", "false_per_scan")
            if any(r[k] is not None for r in rows)
        }
    out["threshold"] = float(np.mean([h.threshold for h in held_out]))
    return out
