"""People over time on real scans (make accuracy): `datmo track`'s people on the legtracker bags, with the
learned leg detector and with the paper's rule beside it. Held out by recording: each positive bag and
each empty-room scanner is tracked with a model trained without it (the folds of `datmo train-legs`: the
shipped model has seen them all); the demo bag, in no training set, with the shipped model.

- negative_2 (rooms without people; each of its three scanners a log; a moving robot without odometry, so
  tracked in poses from scan matching): the longest time a track stays a confirmed person from scan to
  scan (target: none over 2 s).
- positive_*_extracted (labelled legs): the share of labelled legs within 0.5 m of a confirmed person track,
  counting a leg once its person has been in view for 1 s (target: at least 0.85).
- demo_stationary_simple_environment: person tracks confirmed, and confirmed person or dynamic tracks
  that stay on a wall (target: 0).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from benchmarks.accuracy_tracking import LEGTRACKER, demo_figures, learned_legs, read_leg_labels, read_ros1_scans
from benchmarks.common import print_lines
from datmo_cli.logs.vocabulary import CLASS_PERSON, STATUS_TENTATIVE
from datmo_cli.passes.stages import leg_threshold_of, run_features, track_run
from datmo_cli.perception.egomotion import odometry_for

NEGATIVE_TOPICS = ("/left_scan", "/right_scan", "/rear_scan")
PERSON_RADIUS = 0.5  # m, a labelled leg this near a confirmed person track is covered
CONFIRM_TIME = 1.0  # s a person is in view before their legs count
LINK = 0.6  # m, a label this near one of the scan before (within LINK_GAP s) is the same person's
LINK_GAP = 0.5  # s


def fold_models(folder: Path, quick: bool = False) -> tuple[dict[str, str], dict[str, str]]:
    """Models trained as `datmo train-legs` trains the shipped one, threshold included (tuned on the fold's own
    training recordings: the tracker takes a model's threshold), each without one positive bag and one
    empty-room scanner (training.leave_one_out_folds), saved in `folder`: ({positive bag name: model path},
    {negative_2 topic: model path}; a topic held out by several folds takes the first). `quick`: ensembles of
    a quarter of the trees, for tests."""
    import dataclasses

    from datmo_cli.passes.simulated import simulated_recordings
    from datmo_cli.perception import training as TR

    positives = sorted(LEGTRACKER.glob("positive_*_extracted.bag"))
    lab = TR.tables_of([TR.read_labelled(p) for p in positives])
    empty = TR.read_empty(LEGTRACKER / "negative_2.bag")
    emp = TR.tables_of(empty)
    extra = TR.tables_of(simulated_recordings())
    by_bag, by_topic = {}, {}
    for i, fold in enumerate(TR.leave_one_out_folds(len(lab), len(emp))):
        spec = TR.EstimatorSpec()
        if quick:
            spec = dataclasses.replace(spec, n_estimators=max(10, spec.n_estimators // 4))
        model = TR.fold_model(lab, emp, fold, spec, extra=extra, tune=True)
        path = folder / f"fold{i}.npz"
        model.save(path)
        by_bag[positives[fold.test_labelled].name] = str(path)
        by_topic.setdefault(empty[fold.test_empty].topic, str(path))
    return by_bag, by_topic


def tracked(run, leg_model: str):
    """`datmo track` as it runs on a log without odometry (poses from scan matching when the scanner moves), with
    the leg model's own threshold."""
    params = {"leg_model": leg_model}
    odometry, _ = odometry_for(run, None, "auto")
    return track_run(
        run,
        run_features(run, odometry, params),
        odometry=odometry,
        markers=False,
        learned=learned_legs(params),
        leg_threshold=leg_threshold_of(leg_model),
    )


def longest_person(stamps: np.ndarray, tracks: list[np.ndarray]) -> tuple[float, int]:
    """(longest time, s, that one track stays a confirmed person from scan to scan; number of tracks that
    do so for longer than 2 s). A scan in which the track is not a confirmed person ends the stretch."""
    since: dict[int, int] = {}
    longest: dict[int, float] = {}
    for s, t in zip(stamps.tolist(), tracks, strict=True):
        now = set(t["id"][(t["status"] != STATUS_TENTATIVE) & (t["classification"] == CLASS_PERSON)].tolist())
        since = {i: since.get(i, s) for i in now}
        for i, s0 in since.items():
            longest[i] = max(longest.get(i, 0.0), (s - s0) * 1e-9)
    spans = np.array(list(longest.values()))
    return (float(spans.max()) if len(spans) else 0.0), int((spans > 2.0).sum())


def established(stamps: np.ndarray, labels: list[np.ndarray]) -> list[np.ndarray]:
    """Per scan, which labelled legs belong to a person in view for at least CONFIRM_TIME s: labels are
    chained from scan to scan (nearest within LINK m, scans at most LINK_GAP s apart)."""
    out, prev, prev_first, prev_t = [], np.zeros((0, 2)), np.zeros(0), None
    for t, lab in zip((stamps * 1e-9).tolist(), labels, strict=True):
        lab = np.asarray(lab, np.float64).reshape(-1, 2)
        first = np.full(len(lab), t)
        if prev_t is not None and t - prev_t <= LINK_GAP and len(prev) and len(lab):
            d = np.hypot(lab[:, 0:1] - prev[None, :, 0], lab[:, 1:2] - prev[None, :, 1])
            j = np.argmin(d, axis=1)
            near = d[np.arange(len(lab)), j] <= LINK
            first[near] = prev_first[j[near]]
        out.append(t - first >= CONFIRM_TIME)
        prev, prev_first, prev_t = lab, first, t
    return out


def covered(labels: list[np.ndarray], ready: list[np.ndarray], tracks: list[np.ndarray]) -> tuple[int, int]:
    """(established labelled legs within PERSON_RADIUS of a confirmed person track, established legs)."""
    hit = total = 0
    for lab, ok, t in zip(labels, ready, tracks, strict=True):
        lab = np.asarray(lab, np.float64).reshape(-1, 2)[ok]
        if not len(lab):
            continue
        total += len(lab)
        p = t[(t["status"] != STATUS_TENTATIVE) & (t["classification"] == CLASS_PERSON)]
        if len(p):
            d = np.hypot(lab[:, 0:1] - p["x"][None, :], lab[:, 1:2] - p["y"][None, :])
            hit += int((d <= PERSON_RADIUS).any(axis=1).sum())
    return hit, total


def negative_figures(leg_model: str | dict[str, str]) -> dict[str, tuple[float, int]]:
    """Per negative_2 topic, longest_person with `leg_model` (or {topic: model})."""
    out = {}
    for topic in NEGATIVE_TOPICS:
        run, _ = read_ros1_scans(LEGTRACKER / "negative_2.bag", topic)
        model = leg_model[topic] if isinstance(leg_model, dict) else leg_model
        out[topic] = longest_person(run.stamps, tracked(run, model).tracks)
    return out


def positive_figures(leg_model: str | dict[str, str]) -> dict[str, tuple[int, int]]:
    """Per positive bag, `covered` with `leg_model` (or {bag name: model})."""
    out = {}
    for path in sorted(LEGTRACKER.glob("positive_*_extracted.bag")):
        run, log_times = read_ros1_scans(path, "/training_scan")
        labels = read_leg_labels(path, log_times)
        model = leg_model[path.name] if isinstance(leg_model, dict) else leg_model
        out[path.name] = covered(labels, established(run.stamps, labels), tracked(run, model).tracks)
    return out


def figures(folder: Path, quick: bool = False) -> dict:
    """Every figure of this module: {"negative"|"positive": {"held out"|"paper": ...}, "demo": {...}}."""
    by_bag, by_topic = fold_models(folder, quick)
    demo = LEGTRACKER / "demo_stationary_simple_environment.bag"
    return {
        "negative": {"held out": negative_figures(by_topic), "paper": negative_figures("paper")},
        "positive": {"held out": positive_figures(by_bag), "paper": positive_figures("paper")},
        "demo": {m: demo_figures(demo, {"leg_model": m}) for m in ("default", "paper")},
    }


def lines() -> list[str]:
    import tempfile

    out = []
    models = ("held out", "paper")
    with tempfile.TemporaryDirectory() as tmp:
        f = figures(Path(tmp))
    neg = f["negative"]
    for topic in NEGATIVE_TOPICS:
        cells = [f"{m}: longest person {neg[m][topic][0]:.1f} s, {neg[m][topic][1]} over 2 s" for m in models]
        out.append(f"negative_2 {topic:11s} " + " | ".join(cells))
    pos = f["positive"]
    for name in pos["held out"]:
        cells = [
            f"{m}: {pos[m][name][0]}/{pos[m][name][1]} ({pos[m][name][0] / max(pos[m][name][1], 1):.3f})"
            for m in models
        ]
        out.append(f"{name:27s} legs covered " + " | ".join(cells))
    totals = {m: np.sum(list(pos[m].values()), axis=0) for m in models}
    out.append(
        "all positive bags: "
        + " | ".join(f"{m}: {totals[m][0] / max(totals[m][1], 1):.3f} of {totals[m][1]}" for m in models)
    )
    for m, d in f["demo"].items():
        out.append(
            f"demo_stationary ({m}): {d['people']} person tracks, {d['on_walls']} person/dynamic tracks on walls"
        )
    return out


def main() -> None:
    if not Path(LEGTRACKER).exists():
        print_lines("People over time on real scans", [f"{LEGTRACKER}: absent"])
        return
    print_lines(
        "People over time on real scans (targets: empty rooms no person over 2 s; >= 0.85 of labelled legs "
        "covered 1 s after the person appears; no person on a wall)",
        lines(),
    )


if __name__ == "__main__":
    main()
