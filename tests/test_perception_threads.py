"""Perception on several threads: extract_run gives the same arrays on 1 and 2 threads
(sample logs, given segments, the CARMEN logs of the speed figures), `--threads` on datmo features and datmo
run changes neither the messages nor the recorded parameters, and perception.threads resolves counts."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import SAMPLE_LOGS, shared_path

from datmo_cli.cli import cli
from datmo_cli.logs import mcapio
from datmo_cli.perception import threads as TH
from datmo_cli.perception.features import extract_run, segment_run
from datmo_cli.perception.params import FeatureParams

pytestmark = pytest.mark.cli

ARRAYS = (
    "seg_start",
    "seg_end",
    "seg_offsets",
    "lines",
    "line_offsets",
    "circles",
    "circle_offsets",
    "blobs",
    "blob_offsets",
    "legs",
    "leg_offsets",
)


@pytest.fixture(autouse=True)
def default_threads():
    """CLI tests run in this process: give later tests the default back."""
    yield
    TH.set_default(None)


def assert_same(a, b) -> None:
    for name in ARRAYS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert x.tobytes() == y.tobytes(), name  # bit for bit (NaN-safe)


@pytest.mark.parametrize("log", ["hall", "crowd6", "csail-excerpt", "static"])
def test_one_and_two_threads_give_the_same_features(log):
    run = mcapio.read_run(SAMPLE_LOGS / f"{log}.mcap")
    one = extract_run(run, landmarks=False, threads=1)
    two = extract_run(run, landmarks=False, threads=2)
    assert len(one.lines) and len(one.legs)
    assert_same(one, two)
    # the smallest block that runs on two threads, and the paper's rule too
    p = FeatureParams(leg_model="paper")
    short = run.slice(0, 2 * TH.MIN_SCANS_PER_THREAD + 1)
    assert_same(extract_run(short, p, landmarks=False, threads=1), extract_run(short, p, landmarks=False, threads=2))


def test_given_segments_on_two_threads():
    run = mcapio.read_run(SAMPLE_LOGS / "hall.mcap")
    start, end, off = segment_run(run, FeatureParams(c0=0.15))
    one = extract_run(run, landmarks=False, segments=(start, end, off), threads=1)
    two = extract_run(run, landmarks=False, segments=(start, end, off), threads=2)
    assert np.array_equal(one.seg_start, start)
    assert_same(one, two)


@pytest.mark.shared
@pytest.mark.parametrize("name", ["csail", "intel", "freiburg-079"])
def test_carmen_logs_on_one_and_two_threads(name):
    from datmo_cli.logs.importers import import_log

    run = import_log(shared_path("carmen", f"{name}-corrected.log.gz")).run
    assert_same(extract_run(run, landmarks=False, threads=1), extract_run(run, landmarks=False, threads=2))


def test_resolve():
    n = TH.available()
    assert TH.resolve(1) == 1
    assert TH.resolve(0) == n and TH.resolve(10_000) == n
    TH.set_default(1)
    assert TH.resolve() == 1 and TH.resolve(None) == 1
    TH.set_default(None)
    assert TH.resolve() == n
    with pytest.raises(ValueError):
        TH.resolve(-1)
    with pytest.raises(ValueError):
        TH.set_default(-2)


def test_a_few_scans_run_on_one_thread():
    assert TH.for_scans(2, 2 * TH.MIN_SCANS_PER_THREAD) == 2
    assert TH.for_scans(2, 2 * TH.MIN_SCANS_PER_THREAD - 1) == 1
    assert TH.for_scans(4, 0) == 1 and TH.for_scans(1, 10_000) == 1


def test_a_process_forked_after_the_pool_started_runs_one_thread(monkeypatch):
    """GNU OpenMP's pool cannot serve a forked child (numba terminates it): such a child runs one thread."""
    monkeypatch.setattr(TH, "_POOL_PID", os.getpid() + 1)  # as if this process had been forked from it
    assert TH.resolve(2) == 1
    monkeypatch.setattr(TH, "_POOL_PID", os.getpid())
    assert TH.resolve(2) == min(2, TH.available())


def test_features_threads_option_changes_nothing_but_speed(tmp_path):
    src = SAMPLE_LOGS / "hall.mcap"
    outs = []
    for n in ("1", "2"):
        out = tmp_path / f"f{n}.mcap"
        result = CliRunner().invoke(cli, ["features", str(src), "-o", str(out), "--threads", n])
        assert result.exit_code == 0, result.output
        outs.append(out)
    a, b = (mcapio.read_log(o, topics=None) for o in outs)
    for topic in (mcapio.TOPIC_SEGMENTS, mcapio.TOPIC_FEATURES, mcapio.TOPIC_LANDMARKS):
        assert list(a.messages[topic][1]) == list(b.messages[topic][1]), topic
    params = [json.loads(mcapio.summary(o).metadata["datmo.params"]["features"]) for o in outs]
    assert params[0] == params[1] and "threads" not in params[0]
    bad = CliRunner().invoke(cli, ["features", str(src), "-o", str(tmp_path / "x.mcap"), "--threads", "0"])
    assert bad.exit_code == 2 and "--threads" in bad.output


def test_run_accepts_threads(tmp_path):
    result = CliRunner().invoke(
        cli, ["run", str(SAMPLE_LOGS / "static.mcap"), "-o", str(tmp_path), "--threads", "1", "--no-report"]
    )
    assert result.exit_code == 0, result.output
    assert (tmp_path / "static.mcap").exists()
