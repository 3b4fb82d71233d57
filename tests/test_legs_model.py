"""The leg model: scikit-learn export, the numba ensemble against predict_proba, the .npz file, the packaged
model and leg_probabilities."""

from __future__ import annotations

import numpy as np
import pytest
import reference_perception as ref
from sklearn.ensemble import ExtraTreesClassifier, GradientBoostingClassifier, RandomForestClassifier

from datmo_cli.base.errors import InputError
from datmo_cli.perception import leg_forest as LFO
from datmo_cli.perception.leg_model import DEFAULT_MODEL_PATH, LegModel, from_sklearn, load_leg_model
from datmo_cli.perception.legs import (
    FEATURE_NAMES,
    candidate_mask,
    cluster_features,
    leg_probabilities,
    model_clusters,
)

pytestmark = pytest.mark.unit

F = len(FEATURE_NAMES)


def random_features(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Rows that pass candidate_mask (n_points >= 3, width <= 0.8 m), with a learnable label."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(n, F)) * rng.uniform(0.01, 100, F)
    X[:, 0] = rng.integers(3, 60, n)
    X[:, 1] = rng.uniform(0.0, 0.8, n)
    y = (X[:, 2] + 0.3 * X[:, 5] + rng.normal(0, 0.5, n) * np.abs(X[:, 2]).mean() > 0).astype(int)
    return X, y


ESTIMATORS = [
    RandomForestClassifier(n_estimators=7, max_depth=6, random_state=0),
    RandomForestClassifier(n_estimators=5, min_samples_leaf=4, class_weight="balanced", random_state=1),
    ExtraTreesClassifier(n_estimators=6, random_state=2),
    GradientBoostingClassifier(n_estimators=12, max_depth=3, learning_rate=0.3, random_state=0),
    GradientBoostingClassifier(n_estimators=8, init="zero", subsample=0.8, random_state=3),
]


@pytest.mark.parametrize("estimator", ESTIMATORS, ids=lambda e: type(e).__name__)
def test_probabilities_equal_predict_proba(estimator):
    X, y = random_features(400, 0)
    estimator.fit(X, y)
    model = from_sklearn(estimator, 0.5, {"test": True})
    X_test, _ = random_features(300, 1)
    # values on the thresholds themselves: the float32 comparison decides which way they go
    inner = np.flatnonzero(model.feature >= 0)[:100]
    X_test[np.arange(len(inner)), model.feature[inner]] = model.threshold[inner]
    np.testing.assert_allclose(model.probabilities(X_test), estimator.predict_proba(X_test)[:, 1], atol=1e-6, rtol=0)


def test_ensemble_matches_naive_walk():
    X, y = random_features(300, 4)
    model = from_sklearn(RandomForestClassifier(n_estimators=4, random_state=0).fit(X, y), 0.5, {})
    want = [np.mean([model.value[ref.tree_leaf(model, root, x)] for root in model.roots]) for x in X]
    np.testing.assert_allclose(model.probabilities(X), want, atol=1e-12)


def test_non_candidates_get_zero():
    X, y = random_features(200, 5)
    model = from_sklearn(RandomForestClassifier(n_estimators=3, random_state=0).fit(X, y), 0.5, {})
    X[:20, 1] = 0.9  # too wide
    X[20:40, 0] = 2  # too few points
    p = model.probabilities(X)
    assert not candidate_mask(X)[:40].any() and candidate_mask(X)[40:].all()
    assert np.all(p[:40] == 0)


def test_from_sklearn_refuses_other_inputs():
    X, y = random_features(100, 6)
    with pytest.raises(ValueError, match="columns"):
        from_sklearn(RandomForestClassifier(n_estimators=2).fit(X[:, :5], y), 0.5, {})
    with pytest.raises(ValueError, match="binary"):
        from_sklearn(RandomForestClassifier(n_estimators=2).fit(X, np.arange(100) % 3), 0.5, {})


def test_save_load_round_trip(tmp_path):
    X, y = random_features(300, 7)
    gb = GradientBoostingClassifier(n_estimators=5, random_state=0).fit(X, y)
    model = from_sklearn(gb, 0.42, {"data": ["a.bag"], "note": "test"})
    path = tmp_path / "m.npz"
    model.save(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]
    back = LegModel.load(path)
    assert (back.kind, back.threshold_p, back.feature_names) == ("boosting", 0.42, FEATURE_NAMES)
    assert back.provenance == {"data": ["a.bag"], "note": "test"}
    assert (back.base, back.scale) == (model.base, model.scale)
    for name in ("feature", "threshold", "left", "right", "value", "roots"):
        np.testing.assert_array_equal(getattr(back, name), getattr(model, name))
    np.testing.assert_array_equal(back.probabilities(X), model.probabilities(X))
    assert load_leg_model(str(path)).n_trees == 5


def test_a_model_file_read_before_and_unchanged_is_not_read_again(tmp_path):
    X, y = random_features(300, 7)
    path = tmp_path / "m.npz"
    from_sklearn(GradientBoostingClassifier(n_estimators=5, random_state=0).fit(X, y), 0.42, {}).save(path)
    first = load_leg_model(str(path))
    assert load_leg_model(str(path)) is first and load_leg_model("default") is load_leg_model("default")
    from_sklearn(GradientBoostingClassifier(n_estimators=3, random_state=0).fit(X, y), 0.5, {}).save(path, force=True)
    again = load_leg_model(str(path))  # rewritten: another size (and mtime), so read anew
    assert again is not first and (again.n_trees, again.threshold_p) == (3, 0.5)


def test_bad_files(tmp_path):
    with pytest.raises(InputError, match="absent.npz"):
        LegModel.load(tmp_path / "absent.npz")
    with pytest.raises(InputError, match="absent.npz"):
        load_leg_model(str(tmp_path / "absent.npz"))
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(InputError, match="junk.npz"):
        LegModel.load(junk)
    model = LegModel.load(DEFAULT_MODEL_PATH)
    good = tmp_path / "good.npz"
    model.save(good)
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(good.read_bytes()[:200])
    with pytest.raises(InputError, match="truncated.npz"):
        LegModel.load(truncated)

    def rewrite(name, **changes):
        with np.load(good) as z:
            data = {k: z[k] for k in z.files}
        data.update(changes)
        data = {k: v for k, v in data.items() if v is not None}
        path = tmp_path / name
        with open(path, "wb") as f:
            np.savez(f, **data)
        return path

    with pytest.raises(InputError, match="other features"):
        LegModel.load(rewrite("names.npz", feature_names=np.array(FEATURE_NAMES[:-1])))
    with pytest.raises(InputError, match="cycle.npz"):
        LegModel.load(rewrite("cycle.npz", left=np.zeros_like(model.left)))
    with pytest.raises(InputError, match="missing.npz"):
        LegModel.load(rewrite("missing.npz", roots=None))
    with pytest.raises(InputError, match="format"):
        LegModel.load(rewrite("version.npz", format_version=np.int64(99)))


def test_packaged_model_loads_and_gives_probabilities(sample_logs):
    model = load_leg_model("default")
    assert load_leg_model("paper") is None
    assert model.feature_names == FEATURE_NAMES and model.n_trees > 0
    assert isinstance(model.provenance, dict) and model.provenance
    from datmo_cli.logs.mcapio import read_log, run_from_log
    from datmo_cli.perception.features import segment_run

    run = run_from_log(read_log(sample_logs / "hall.mcap", topics=["/scan"]))
    g = run.geometry
    start, end, offsets = model_clusters(run.ranges, g.angles(), g.range_min, g.range_max, model, *segment_run(run))
    assert model.provenance["clusters"] == {"method": "gap", "gap": 0.13, "min_points": 3}
    p = leg_probabilities(run.ranges, g.angles(), start, end, offsets, g.range_min, g.range_max, model)
    feats = cluster_features(run.ranges, g.angles(), start, end, offsets, g.range_min, g.range_max)
    assert p.shape == (len(start),) and np.all((p >= 0) & (p <= 1))
    np.testing.assert_array_equal(p, model.probabilities(feats))
    assert np.all(p[~candidate_mask(feats)] == 0)
    assert (p > model.threshold_p).any()


def test_kind_codes_match_the_kernel():

    X, y = random_features(100, 8)
    forest = from_sklearn(RandomForestClassifier(n_estimators=2, random_state=0).fit(X, y), 0.5, {})
    boost = from_sklearn(GradientBoostingClassifier(n_estimators=2).fit(X, y), 0.5, {})
    assert (forest._kernel_args().kind, boost._kernel_args().kind) == (LFO.KIND_FOREST, LFO.KIND_BOOSTING)


def test_leg_probabilities_equal_the_model_on_all_features():
    """The hot path computes features for candidates only: its probabilities must not change for that."""
    model = load_leg_model("default")
    rng = np.random.default_rng(9)
    angles = np.radians(np.linspace(-90.0, 90.0, 181))
    for _ in range(20):
        ranges = rng.uniform(0.5, 4.0, (3, 181)).astype(np.float32)
        ranges = np.where(rng.random((3, 181)) < 0.8, np.repeat(ranges[:, ::6], 6, axis=1)[:, :181], ranges)
        ranges[rng.random((3, 181)) < 0.05] = np.inf
        cuts = [np.unique(rng.integers(0, 182, 12)) for _ in range(3)]
        start = np.concatenate([c[:-1] for c in cuts])
        end = np.concatenate([c[1:] for c in cuts])
        offsets = np.concatenate([[0], np.cumsum([len(c) - 1 for c in cuts])])
        feats = cluster_features(ranges, angles, start, end, offsets, 0.1, 5.0)
        p = leg_probabilities(ranges, angles, start, end, offsets, 0.1, 5.0, model)
        np.testing.assert_array_equal(p, model.probabilities(feats))
