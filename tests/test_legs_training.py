"""Leg detector training (the datmo_cli.perception.training package): label matching, segment labels,
leave-one-recording-out folds (no held-out recording ever trains), metrics on hand-made cases, reading labelled
bags and MCAP files, and the packaged model's provenance against ../shared/data."""

from __future__ import annotations

import json

import numpy as np
import pytest

from datmo_cli.base.errors import InputError
from datmo_cli.perception import training as TR
from datmo_cli.perception.legs import FEATURE_NAMES
from datmo_cli.perception.training import cross_validation as CV
from tests.conftest import shared_path
from tests.synthetic_legs import scene, write_bag, write_mcap

pytestmark = pytest.mark.unit

# ------------------------------------------------------------------------------------------------- labels


def test_each_scan_takes_the_label_message_nearest_in_log_time_within_50_ms():
    labels = [np.array([[1.0, 0.0]]), np.array([[2.0, 0.0]]), np.array([[3.0, 0.0]])]
    times = np.array([1_000, 1_100, 1_200]) * 1_000_000  # ms -> ns, out of order below
    scans = np.array([1_010, 1_140, 1_160, 1_260, 900]) * 1_000_000
    got = TR.match_labels(scans, times[[2, 0, 1]], [labels[2], labels[0], labels[1]])
    assert [g[:, 0].tolist() for g in got] == [[1.0], [2.0], [3.0], [], []]  # 1260 and 900: more than 50 ms


def test_no_label_message_gives_no_legs():
    got = TR.match_labels(np.array([5, 6]), np.zeros(0, np.int64), [])
    assert [g.shape for g in got] == [(0, 2), (0, 2)]


def test_segments_are_legs_within_the_match_radius_of_a_label_of_their_own_scan():
    centroid = np.array([[1.0, 0.0], [1.14, 0.0], [1.2, 0.0], [3.0, 3.0], [1.0, 0.0]])
    scan = np.array([0, 0, 0, 0, 1])
    legs = [np.array([[1.0, 0.0], [3.0, 3.1]]), np.zeros((0, 2))]
    assert TR.label_segments(centroid, scan, legs, 0.15).tolist() == [True, True, False, True, False]


def test_segment_centroids_are_the_mean_of_valid_returns():
    angles = np.array([0.0, np.pi / 2, np.pi])
    ranges = np.array([[1.0, 2.0, np.inf], [np.nan, 3.0, 4.0]], np.float32)
    c = TR.segment_centroids(ranges, angles, np.array([0, 1]), np.array([3, 3]), np.array([0, 1, 2]), 0.0, 10.0)
    np.testing.assert_allclose(c, [[0.5, 1.0], [-2.0, 1.5]], atol=1e-12)


# -------------------------------------------------------------------------------------------------- folds


@pytest.mark.parametrize(("n_lab", "n_emp"), [(6, 3), (2, 1), (3, 0), (4, 5)])
def test_folds_hold_each_labelled_recording_out_once_and_cycle_the_empty_ones(n_lab, n_emp):
    folds = TR.leave_one_out_folds(n_lab, n_emp)
    assert [f.test_labelled for f in folds] == list(range(n_lab))
    assert [f.test_empty for f in folds] == [i % n_emp if n_emp else None for i in range(n_lab)]
    for f in folds:
        assert f.test_labelled not in f.train_labelled and f.test_empty not in f.train_empty
        assert len(f.train_labelled) == n_lab - 1
        assert len(f.train_empty) == n_emp - (1 if n_emp else 0)


def test_one_labelled_recording_gives_no_folds():
    assert TR.leave_one_out_folds(1, 3) == []


def _table(name: str, labelled: bool, label, score=None, n_scans: int = 2, rng_m=None, circle=None) -> TR.SegmentTable:
    label = np.asarray(label, bool)
    m = len(label)
    feats = np.zeros((m, len(FEATURE_NAMES)))
    feats[:, 0] = 5 if score is None else np.asarray(score) * 10 + 3  # a feature that orders the segments
    r = np.full(m, 1.0) if rng_m is None else np.asarray(rng_m, float)
    circle = np.zeros(m, bool) if circle is None else np.asarray(circle, bool)
    return TR.SegmentTable(
        name,
        labelled,
        n_scans,
        feats,
        label,
        np.ones(m, bool),
        np.arange(m) % n_scans,
        np.c_[r, np.zeros(m)],
        circle,
        np.where(circle, 0.9, 0.0),
    )


def test_no_held_out_recording_ever_trains_its_own_fold_or_threshold(monkeypatch):
    """cross_validate through a spy fit: every model scoring a recording was trained without it, and every
    training set of a fold (inner threshold folds included) lacks that fold's held-out pair."""
    rng = np.random.default_rng(0)
    lab = [_table(f"L{i}", True, rng.random(20) < 0.3) for i in range(4)]
    emp = [_table(f"E{j}", False, np.zeros(20, bool)) for j in range(3)]
    trained: list[set[str]] = []

    class Model:
        def __init__(self, names: set[str]) -> None:
            self.names = names

        def probabilities(self, features: np.ndarray) -> np.ndarray:
            return np.full(len(features), 0.5)

    def spy_fit(tables, spec):
        names = {t.name for t in tables}
        trained.append(names)
        return names

    scored: list[tuple[str, set[str]]] = []

    def spy_scores(model, table):
        scored.append((table.name, model.names))
        return np.full(len(table), 0.5)

    monkeypatch.setattr(CV, "fit", spy_fit)  # where cross_validate and tuned_threshold look them up
    monkeypatch.setattr(CV, "to_model", lambda est, *a, **k: Model(est))
    monkeypatch.setattr(CV, "scores", spy_scores)
    held = TR.cross_validate(lab, emp, TR.EstimatorSpec())
    assert [(h.labelled, h.empty) for h in held] == [("L0", "E0"), ("L1", "E1"), ("L2", "E2"), ("L3", "E0")]
    assert all(name not in names for name, names in scored)
    assert len(trained) == TR.cv_fits(4, 3) == 4 * (3 + 1)
    # each outer fold's fits come in a block: 3 inner + 1 outer, none with the held-out pair
    for i, h in enumerate(held):
        for names in trained[4 * i : 4 * i + 4]:
            assert h.labelled not in names and h.empty not in names
        assert trained[4 * i + 3] == {f"L{k}" for k in range(4) if k != i} | {f"E{j}" for j in range(3)} - {h.empty}


# ------------------------------------------------------------------------------------------------ metrics


def test_average_precision_on_a_hand_made_case_and_against_scikit_learn():
    y = np.array([1, 0, 1, 0], bool)
    s = np.array([0.9, 0.8, 0.7, 0.1])
    assert TR.average_precision(y, s) == pytest.approx(0.5 * 1.0 + 0.5 * 2 / 3)
    assert np.isnan(TR.average_precision(np.zeros(3, bool), np.ones(3)))
    sk = pytest.importorskip("sklearn.metrics")
    rng = np.random.default_rng(1)
    for _ in range(20):
        y = rng.random(50) < 0.3
        s = np.round(rng.random(50), 1)  # ties
        assert TR.average_precision(y, s) == pytest.approx(sk.average_precision_score(y, s))


def test_figures_count_clusters_within_5_m_and_false_legs_per_empty_scan():
    lab = _table("L", True, [1, 1, 0, 0, 1], rng_m=[1, 2, 3, 4, 6])  # the last (a leg) is beyond 5 m
    score = np.array([0.9, 0.2, 0.8, 0.1, 0.0])
    emp = _table("E", False, [0, 0, 0, 0], n_scans=4, rng_m=[1, 1, 1, 7])
    f = TR.figures(lab, score, 0.5, emp, np.array([0.6, 0.4, 0.7, 0.99]))
    assert (f.precision, f.recall) == (0.5, 0.5)
    assert f.ap == pytest.approx(0.5 * 1.0 + 0.5 * 2 / 3)
    assert f.false_per_scan == 2 / 4 and f.legs == 2 and f.clusters == 4 and f.empty_scans == 4


def test_recall_by_range_counts_the_legs_of_each_bin_at_the_threshold():
    lab = _table("L", True, [1, 1, 0, 1, 1, 1], rng_m=[1.0, 1.5, 1.5, 2.5, 3.5, 6.0])
    score = np.array([0.9, 0.2, 0.9, 0.6, 0.4, 0.99])
    assert TR.recall_by_range(lab, score, 0.5) == (0.5, 1.0, 0.0, None)  # 6 m is beyond the last bin


def test_a_thinned_recording_keeps_every_other_beam_at_twice_the_step_and_its_labels():
    from pathlib import Path

    from datmo_cli.logs.scan import ScanGeometry, ScanRun

    g = ScanGeometry(-1.0, 0.01, 201, 0.02, 30.0)
    ranges = np.arange(2 * 201, dtype=np.float32).reshape(2, 201) / 100
    legs = [np.array([[1.0, 0.5]]), np.zeros((0, 2))]
    rec = TR.Recording("r", Path("r.bag"), "/scan", ScanRun(np.array([0, 10**8]), ranges, g), legs)
    t = TR.thinned(rec, 2)
    assert t.run.geometry.n_beams == 101 and t.run.geometry.angle_increment == pytest.approx(0.02)
    assert t.run.geometry.angle_min == g.angle_min
    assert np.array_equal(t.run.ranges, ranges[:, ::2]) and t.legs is legs and t.labelled
    assert t.run.geometry.angle_min + 100 * t.run.geometry.angle_increment == pytest.approx(
        g.angle_min + 200 * g.angle_increment
    )  # the last beam keeps its direction


def test_circle_rule_figures_call_the_small_circles_legs():
    lab = _table("L", True, [1, 1, 0, 0], circle=[1, 0, 1, 0])
    emp = _table("E", False, [0, 0, 0], n_scans=3, circle=[1, 1, 0])
    f = TR.circle_figures(lab, emp)
    assert (f.precision, f.recall, f.false_per_scan) == (0.5, 0.5, 2 / 3)


def test_threshold_maximises_f1_within_the_empty_scan_budget():
    y = np.array([1, 1, 1, 0, 0, 0], bool)
    s = np.array([0.9, 0.8, 0.4, 0.7, 0.3, 0.2])
    assert TR.choose_threshold(y, s) == pytest.approx(0.4)  # all three legs, one false: F1 6/7
    empty = np.array([0.85, 0.5, 0.45])
    # at 0.4 three false legs in 2 empty scans (1.5 > 0.25), at 0.8 one: 0.5; only 0.9 and 1.0 are within
    assert TR.choose_threshold(y, s, empty, 2, budget=0.25) == pytest.approx(0.9)


# ------------------------------------------------------------------------------------------------ reading


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_labelled_files_read_with_their_labels(tmp_path, kind):
    ranges, legs = scene(12, seed=3)
    path = write_bag(tmp_path / "p.bag", ranges, legs) if kind == "ros1" else write_mcap(tmp_path / "p", ranges, legs)
    rec = TR.read_labelled(path)
    assert rec.labelled and rec.topic == "/scan" and rec.run.ranges.shape == ranges.shape
    assert [x.tolist() for x in rec.legs] == [x.tolist() for x in legs]
    table = TR.segment_table(rec)
    assert table.label.sum() >= 2 * 12 - 2  # both legs of (nearly) every scan
    assert not table.label[table.range_m > 4.0].any()


def test_a_file_without_labels_is_refused(tmp_path):
    ranges, _ = scene(5)
    path = write_bag(tmp_path / "u.bag", ranges)
    with pytest.raises(InputError, match=r"u\.bag: no leg labels: no topic /leg_cluster_positions"):
        TR.read_labelled(path)
    with pytest.raises(InputError, match="no labelled leg on /legs within 50 ms"):
        TR.read_labelled(
            write_bag(tmp_path / "e.bag", ranges, [np.zeros((0, 2))] * 5, labels_topic="/legs"), labels_topic="/legs"
        )


def test_every_scan_topic_of_an_empty_file_is_a_recording(tmp_path):
    ranges, _ = scene(4, people=False)
    recs = TR.read_empty(write_bag(tmp_path / "n.bag", ranges, extra_scan_topics=("/rear",)))
    assert [(r.name, r.labelled, len(r.run)) for r in recs] == [("n.bag:/rear", False, 4), ("n.bag:/scan", False, 4)]


# ------------------------------------------------------------------------------------------ training, shared


@pytest.mark.slow
def test_a_model_trained_on_synthetic_legs_finds_held_out_legs(tmp_path):
    pytest.importorskip("sklearn")
    lab = [TR.read_labelled(write_bag(tmp_path / f"p{i}.bag", *scene(25, seed=i))) for i in range(3)]
    emp = TR.read_empty(write_bag(tmp_path / "n.bag", scene(20, seed=9, people=False)[0]))
    result = TR.train_leg_model(lab, emp, TR.EstimatorSpec(n_estimators=20, max_depth=6))
    assert len(result.held_out) == 3
    assert result.mean["learned"]["ap"] > 0.9 and result.mean["learned"]["false_per_scan"] <= 0.25
    prov = result.model.provenance
    assert [d["file"] for d in prov["data"]] == ["p0.bag", "p1.bag", "p2.bag", "n.bag"]
    assert prov["threshold"]["value"] == result.model.threshold_p == result.threshold
    assert prov["clusters"] == TR.DEFAULT_CLUSTERS
    json.dumps(prov)


@pytest.mark.parametrize("clusters", [TR.SEGMENT_CLUSTERS, TR.GAP_CLUSTERS])
def test_tables_tabulate_the_clusters_asked_for(tmp_path, clusters):
    from datmo_cli.perception.features import _range_limits, segment_run
    from datmo_cli.perception.legs import cluster_features, gap_clusters

    rec = TR.read_labelled(write_bag(tmp_path / "p.bag", *scene(6, seed=3)))
    run = rec.run
    lo, hi = _range_limits(run)
    if clusters["method"] == "gap":
        start, end, offsets = gap_clusters(run.ranges, run.geometry.angles(), lo, hi, 0.13, 3)
    else:
        start, end, offsets = segment_run(run)
    table = TR.segment_table(rec, clusters=clusters)
    assert len(table) == len(start) and table.scan.tolist() == np.repeat(np.arange(6), np.diff(offsets)).tolist()
    np.testing.assert_array_equal(
        table.features, cluster_features(run.ranges, run.geometry.angles(), start, end, offsets, lo, hi)
    )
    assert table.label.any()
    with pytest.raises(ValueError, match="cluster method"):
        TR.recording_clusters(run, clusters={"method": "dbscan"})


def test_packaged_model_provenance_lists_every_shared_bag_with_its_sha256():
    from datmo_cli.logs.mcapio import sha256_of
    from datmo_cli.perception.leg_model import DEFAULT_MODEL_PATH, LegModel
    from datmo_cli.perception.legs import FEATURE_NAMES

    folder = shared_path("legtracker")
    model = LegModel.load(DEFAULT_MODEL_PATH)
    data = {d["file"]: d for d in model.provenance["data"]}
    bags = sorted(folder.glob("positive_*_extracted.bag")) + [folder / "negative_2.bag"]
    assert sorted(data) == sorted(b.name for b in bags)
    for bag in bags:
        assert data[bag.name]["sha256"] == sha256_of(bag), bag.name
    assert data["negative_2.bag"]["topics"] == ["/left_scan", "/rear_scan", "/right_scan"]
    assert model.provenance["feature_names"] == list(FEATURE_NAMES)
    assert model.provenance["clusters"] == TR.DEFAULT_CLUSTERS
    assert model.provenance["threshold"]["value"] == model.threshold_p
    assert len(model.provenance["held_out"]["folds"]) == 6


def test_simulated_recordings_of_a_finer_scanner_cover_270_degrees_and_people_who_stand():
    from datmo_cli.passes import simulated

    scene, step = simulated._scene_for("crowd", 270 / 768)
    assert step is None and scene.scanner.beams == 768 and scene.scanner.fov_deg == 270.0
    assert (scene.crowd.pause_probability, scene.crowd.max_pause) == simulated.LONG_PAUSE
    assert simulated._scene_for("crowd", 0.5) == ("crowd", 0.5)  # an LMS200 step: the scene as it is
    rec = simulated.simulated_recording("crowd", 15, 3, 270 / 768, 2.0)
    assert rec.run.geometry.n_beams == 768 and rec.labelled and sum(len(g) for g in rec.legs) > 0
