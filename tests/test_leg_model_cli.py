"""--leg-model on features, track and run: the shipped detector by default, 'paper' for the paper's rule, a
model file; the model in use is in each output's provenance; bad models are one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.perception.leg_model import DEFAULT_MODEL_PATH
from datmo_cli.sim.simulate import simulate_scene

pytestmark = pytest.mark.cli


@pytest.fixture(scope="module")
def crowd(tmp_path_factory):
    path = tmp_path_factory.mktemp("legs") / "crowd.mcap"
    sim = simulate_scene("crowd", seed=5, duration=6.0, people=3)
    with mcapio.LogWriter(path) as w:
        w.write_scans(sim.run)
    return path


def _legs(path) -> list[np.ndarray]:
    _, payloads = mcapio.read_messages(path, mcapio.TOPIC_FEATURES)
    return [cdr.decode(types.FEATURES, p)["legs"] for p in payloads]


def _model(path) -> dict:
    return json.loads(mcapio.read_log(path, topics=()).metadata["datmo.params"]["leg_model"])


def test_features_lists_the_detectors_legs_and_records_the_model(crowd, tmp_path):
    out = tmp_path / "f.mcap"
    r = CliRunner().invoke(cli, ["features", str(crowd), "-o", str(out)])
    assert r.exit_code == 0, r.output
    legs = _legs(out)
    assert sum(len(g) for g in legs) > 0
    allg = np.concatenate(legs)
    # every cluster the model scores above 0 is listed, the weak ones too (the tracker takes the threshold)
    assert ((allg["probability"] > 0) & (allg["probability"] <= 1)).all()
    assert (allg["last"] >= allg["first"]).all() and (allg["n_points"] == allg["last"] - allg["first"] + 1).all()
    m = _model(out)
    assert m["model"] == "default" and m["path"] == str(DEFAULT_MODEL_PATH) and len(m["sha256"]) == 64
    assert (allg["probability"] < m["threshold"]).any() and (allg["probability"] >= m["threshold"]).any()


def test_paper_rule_lists_no_legs_and_track_keeps_the_features_rule(crowd, tmp_path):
    feats, tracks = tmp_path / "paper.mcap", tmp_path / "paper-tracks.mcap"
    r = CliRunner().invoke(cli, ["features", str(crowd), "-o", str(feats), "--leg-model", "paper"])
    assert r.exit_code == 0, r.output
    assert sum(len(g) for g in _legs(feats)) == 0
    assert _model(feats)["model"] == "paper"
    r = CliRunner().invoke(cli, ["track", str(feats), "-o", str(tracks)])
    assert r.exit_code == 0, r.output
    assert _model(tracks)["model"] == "paper"
    # asking track for another detector than the features were made with is refused, in one line
    r = CliRunner().invoke(cli, ["track", str(feats), "-o", str(tmp_path / "x.mcap"), "--leg-model", "default"])
    assert r.exit_code != 0
    assert "made with leg model 'paper'" in r.output and "Traceback" not in r.output
    assert len(r.output.strip().splitlines()) == 1


@pytest.mark.parametrize("bad, why", [("missing.npz", "missing"), ("garbage.npz", "garbage")])
def test_a_bad_model_is_a_one_line_error(crowd, tmp_path, bad, why):
    model = tmp_path / bad
    if why == "garbage":
        model.write_bytes(b"not a model at all")
    for cmd in (
        ["features", str(crowd), "-o", str(tmp_path / "o.mcap")],
        ["track", str(crowd), "-o", str(tmp_path / "o.mcap")],
        ["run", str(crowd), "-o", str(tmp_path / "out"), "--no-report"],
    ):
        r = CliRunner().invoke(cli, [*cmd, "--leg-model", str(model)])
        assert r.exit_code != 0, cmd
        assert str(model) in r.output and "Traceback" not in r.output, r.output
        assert not (tmp_path / "o.mcap").exists()


def test_a_model_file_is_used_and_recorded(crowd, tmp_path):
    out = tmp_path / "run"
    r = CliRunner().invoke(
        cli, ["run", str(crowd), "-o", str(out), "--no-report", "--leg-model", str(DEFAULT_MODEL_PATH)]
    )
    assert r.exit_code == 0, r.output
    m = _model(out / "crowd.mcap")
    assert m["model"] == str(DEFAULT_MODEL_PATH) and m["threshold"] > 0


def test_a_leg_cluster_where_no_segment_is_kept():
    """The shipped model scores leg_tracker's clusters: one may stand where segmentation kept no segment (here
    3 points and min_points 4); its leg has no segment (found by a random example)."""
    from datmo_cli.logs.scan import ScanGeometry, ScanRun
    from datmo_cli.perception.features import NO_SEGMENT, extract_run
    from datmo_cli.perception.params import FeatureParams

    g = ScanGeometry(-np.radians(1.0), np.radians(1.0), 3, 0.0, 8.0, 0.0, 0.2, "laser")
    f = extract_run(
        ScanRun(np.zeros(1, np.int64), np.ones((1, 3), np.float32), g), FeatureParams(min_points=4)
    )  # every cluster the model scores above 0 is a leg candidate
    assert len(f.seg_start) == 0
    assert len(f.legs) == 1 and f.legs["segment"][0] == NO_SEGMENT
