"""Leg detector accuracy (make accuracy; alone: python -m benchmarks accuracy legs): the leave-one-bag-out
figures of the learned detector on the legtracker bags, rerun from scratch with the shipped model's estimator
settings and clusters (datmo's segments or leg_tracker's gap clusters, its provenance), beside the paper's
circle rule on the same clusters.

Each positive bag is held out in turn with one of negative_2's three scanners (cycling); the model is trained
on the other bags and scanners, its threshold tuned on them alone (the rule the shipped model's threshold
comes from). Per cluster within 5 m: precision, recall and average precision on the held-out bag, false legs
per scan on the held-out empty scanner.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from benchmarks.common import print_lines

ROOT = Path(__file__).resolve().parent.parent
LEGTRACKER = ROOT.parent / "shared" / "data" / "legtracker"
TARGETS = {"ap": 0.80, "ap_vs_circle": 4.0, "false_per_scan": 0.5, "thinned_vs_full": 0.8}


def shipped_spec():
    """The estimator settings of the packaged model (its provenance), or the defaults without one."""
    import dataclasses

    from datmo_cli.perception import training as TR
    from datmo_cli.perception.leg_model import DEFAULT_MODEL_PATH, LegModel

    if not DEFAULT_MODEL_PATH.exists():
        return TR.EstimatorSpec(), None
    model = LegModel.load(DEFAULT_MODEL_PATH)
    names = {f.name for f in dataclasses.fields(TR.EstimatorSpec)}
    given = {k: v for k, v in model.provenance.get("estimator", {}).items() if k in names}
    return TR.EstimatorSpec(**given), model


def _f(v: float | None, digits: int = 3) -> str:
    return "  n/a" if v is None or v != v else f"{v:.{digits}f}"


def figure_lines() -> list[str]:
    from datmo_cli.perception import training as TR

    positives = sorted(LEGTRACKER.glob("positive_*_extracted.bag"))
    negative = LEGTRACKER / "negative_2.bag"
    spec, model = shipped_spec()
    t0 = time.perf_counter()
    labelled = [TR.read_labelled(p) for p in positives]
    empty = TR.read_empty(negative)
    clusters = TR.DEFAULT_CLUSTERS if model is None else model.provenance.get("clusters", TR.SEGMENT_CLUSTERS)
    lab, emp = TR.tables_of(labelled, clusters=clusters), TR.tables_of(empty, clusters=clusters)
    extra = []
    if model is not None and model.provenance.get("simulated"):  # trained with --with-simulated: so here
        from datmo_cli.passes.simulated import simulated_recordings

        extra = TR.tables_of(simulated_recordings(), clusters=clusters)
    thin = TR.tables_of([TR.thinned(r, 2) for r in labelled], clusters=clusters)
    held_out = TR.cross_validate(lab, emp, spec, extra=extra, thin=thin)
    seconds = time.perf_counter() - t0
    how = (
        "datmo's segments"
        if clusters.get("method") == "segments"
        else f"gap clusters ({clusters.get('gap')} m, >= {clusters.get('min_points')} points)"
    )
    lines = [
        f"estimator {spec.kind}, {spec.n_estimators} trees, depth {spec.max_depth}; clusters: {how}; "
        f"threshold rule: {TR.THRESHOLD_RULE}",
        f"{'held out':26s} {'empty scanner':27s} thr   | precision     recall        AP            "
        f"false/scan   (learned | circle rule)",
    ]
    for h in held_out:
        L, C = h.learned, h.circle
        lines.append(
            f"{h.labelled:26s} {h.empty or '-':27s} {h.threshold:.2f} | {_f(L.precision)} | "
            f"{_f(C.precision)}  {_f(L.recall)} | {_f(C.recall)}  {_f(L.ap)} | {_f(C.ap)}  "
            f"{_f(L.false_per_scan, 2)} | {_f(C.false_per_scan, 2)}"
        )
    m = TR.mean_figures(held_out)
    L, C = m["learned"], m["circle"]
    lines.append(
        f"{'mean':54s} {m['threshold']:.2f} | {_f(L['precision'])} | {_f(C['precision'])}  "
        f"{_f(L['recall'])} | {_f(C['recall'])}  {_f(L['ap'])} | {_f(C['ap'])}  "
        f"{_f(L['false_per_scan'], 2)} | {_f(C['false_per_scan'], 2)}"
    )
    ratio = L["ap"] / C["ap"] if C["ap"] > 0 else float("inf")
    ok = (L["ap"] >= TARGETS["ap"], ratio >= TARGETS["ap_vs_circle"], L["false_per_scan"] <= TARGETS["false_per_scan"])
    lines.append(
        f"targets: mean AP >= {TARGETS['ap']:.2f} ({'met' if ok[0] else 'NOT met'}: {L['ap']:.3f}), "
        f">= {TARGETS['ap_vs_circle']:g}x the circle rule's ({'met' if ok[1] else 'NOT met'}: "
        f"{ratio:.2f}x), <= {TARGETS['false_per_scan']:g} false legs per empty scan "
        f"({'met' if ok[2] else 'NOT met'}: {L['false_per_scan']:.2f})"
    )
    bins = TR.RANGE_BINS_M
    lines.append(
        "recall at the fold's threshold by range (m) "
        + "  ".join(f"{lo:g}-{hi:g}" for lo, hi in zip(bins[:-1], bins[1:], strict=True))
        + "   | on the held-out recording thinned 2x (every other beam)"
    )
    for h in held_out:
        lines.append(
            f"  {h.labelled:26s} "
            + "  ".join(_f(v) for v in h.recall_by_range)
            + f"   | {_f(h.thinned_recall)} (full {_f(h.learned.recall)})"
        )
    full = float(np.mean([h.learned.recall for h in held_out]))
    thin_mean = float(np.mean([h.thinned_recall for h in held_out]))
    share = thin_mean / full if full > 0 else float("nan")
    lines.append(
        f"target: recall on 2x-thinned held-out scans >= {TARGETS['thinned_vs_full']:g}x full "
        f"({'met' if share >= TARGETS['thinned_vs_full'] else 'NOT met'}: {thin_mean:.3f} / {full:.3f} "
        f"= {share:.2f}x)"
    )
    if model is not None:
        shipped = model.provenance.get("held_out", {}).get("mean", {}).get("learned", {})
        lines.append(
            f"shipped model: threshold {model.threshold_p:.2f}, {model.n_trees} trees; its recorded mean "
            f"held-out AP {_f(shipped.get('ap'))} (this rerun: {_f(L['ap'])})"
        )
    lines.append(f"{len(held_out)} folds, {TR.cv_fits(len(lab), len(emp))} fits, {seconds:.0f} s")
    return lines


def main() -> None:
    title = "Leg detector, leave-one-bag-out on the legtracker bags (learned | paper's circle rule)"
    if not LEGTRACKER.exists():
        print_lines(title, [f"skipped: {LEGTRACKER} is absent"])
        return
    try:
        import sklearn  # noqa: F401
    except ImportError:
        print_lines(title, ["skipped: scikit-learn is not installed (pip install 'datmo-cli[train]')"])
        return
    np.seterr(all="ignore")
    print_lines(title, figure_lines())


if __name__ == "__main__":
    main()
