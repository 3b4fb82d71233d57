"""`datmo train-legs` through Click's CliRunner: refused inputs (one-line errors), a model written from small
synthetic labelled bags, no overwrite without --force."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli
from tests.synthetic_legs import scene, write_bag, write_mcap

pytestmark = pytest.mark.cli


def _run(*args: str):
    return CliRunner().invoke(cli, ["train-legs", *args])


def _one_line_error(result, text: str) -> None:
    assert result.exit_code != 0
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("datmo: error: ") and text in lines[0], result.output


def test_an_unlabelled_positive_file_is_refused(tmp_path):
    path = write_bag(tmp_path / "u.bag", scene(5)[0])
    result = _run("--positive", str(path), "-o", str(tmp_path / "m.npz"))
    _one_line_error(result, f"{path}: no leg labels: no topic /leg_cluster_positions")
    assert not (tmp_path / "m.npz").exists()


def test_a_positive_file_with_only_empty_label_messages_is_refused(tmp_path):
    ranges, _ = scene(5)
    path = write_bag(tmp_path / "e.bag", ranges, [np.zeros((0, 2))] * 5)
    _one_line_error(_run("--positive", str(path), "-o", str(tmp_path / "m.npz")), "no labelled leg")


def test_an_empty_file_is_refused(tmp_path):
    (tmp_path / "empty.bag").write_bytes(b"")
    _one_line_error(
        _run("--positive", str(tmp_path / "empty.bag"), "-o", str(tmp_path / "m.npz")),
        f"{tmp_path / 'empty.bag'}: empty file",
    )
    good = write_bag(tmp_path / "p.bag", *scene(5))
    _one_line_error(
        _run("--positive", str(good), "--negative", str(tmp_path / "empty.bag"), "-o", str(tmp_path / "m.npz")),
        "empty file",
    )


def test_no_positive_file_is_refused(tmp_path):
    _one_line_error(_run("-o", str(tmp_path / "m.npz")), "give at least one with --positive")
    result = _run("--positive", "-o", str(tmp_path / "m.npz"))
    assert result.exit_code == 2 and "--positive needs at least one file" in result.output


@pytest.mark.slow
def test_writes_a_model_from_synthetic_labelled_files_and_refuses_to_overwrite(tmp_path):
    pytest.importorskip("sklearn")
    from datmo_cli.perception.leg_model import LegModel

    positives = [
        str(write_bag(tmp_path / "p0.bag", *scene(20, seed=0))),
        str(write_mcap(tmp_path / "p1", *scene(20, seed=1))),
    ]
    negative = str(write_bag(tmp_path / "n.bag", scene(15, seed=5, people=False)[0], extra_scan_topics=("/rear",)))
    out = tmp_path / "legs.npz"
    result = _run("--positive", *positives, "--negative", negative, "-o", str(out))
    assert result.exit_code == 0, result.output
    assert "Held-out figures" in result.output and "p0.bag" in result.output and "mean" in result.output
    model = LegModel.load(out)
    prov = model.provenance
    assert [d["file"] for d in prov["data"]] == ["p0.bag", "p1.mcap", "n.bag"]
    assert prov["data"][2]["topics"] == ["/rear", "/scan"]
    assert len(prov["held_out"]["folds"]) == 2 and 0.0 < model.threshold_p <= 1.0
    assert not list(tmp_path.glob("*.tmp"))
    before = out.read_bytes()
    again = _run("--positive", *positives, "-o", str(out))
    _one_line_error(again, f"{out}: exists; use --force to overwrite it")
    assert out.read_bytes() == before
    one = _run("--positive", positives[0], "-o", str(out), "--force")
    assert one.exit_code == 0, one.output
    assert "no held-out figures: they need two or more --positive files" in one.output
    assert LegModel.load(out).provenance["held_out"]["folds"] == []


def test_with_simulated_recordings_always_in_training(tmp_path, monkeypatch):
    """--with-simulated adds simulated LMS200 recordings (exact legs) to every training set, never held out."""
    from datmo_cli.passes import simulated
    from datmo_cli.perception.leg_model import LegModel

    monkeypatch.setattr(simulated, "SIMULATED", (("crowd", 21, 3, 0.5, 4.0),))  # a short one, for speed
    positives = [
        str(write_bag(tmp_path / "p0.bag", *scene(20, seed=0))),
        str(write_bag(tmp_path / "p1.bag", *scene(20, seed=1))),
    ]
    out = tmp_path / "legs.npz"
    result = _run("--positive", *positives, "-o", str(out), "--with-simulated")
    assert result.exit_code == 0, result.output
    prov = LegModel.load(out).provenance
    assert [s["name"] for s in prov["simulated"]] == ["simulated crowd seed 21 3 people 0.5°"]
    assert prov["simulated"][0]["legs"] > 0
    assert [f["labelled"] for f in prov["held_out"]["folds"]] == ["p0.bag", "p1.bag"]  # real ones only
