"""`datmo run`'s outputs on every sample log, message for message (tests/run_cases.py, markers and the tracks'
covariance aside): the same as tests/run_digests.json records, and the same whatever the perception threads
(--threads) and the streaming block size. Speed work must leave these alone; a deliberate change of the
tracker or of perception writes the digests again (`make run-digests`) with the reason in its commit."""

from __future__ import annotations

import json

import pytest
from run_cases import DIGESTS, digests, run_outputs, sample_logs

from datmo_cli import pipeline
from datmo_cli.pipeline import process_file

pytestmark = pytest.mark.cli


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[str, dict]:
    out = run_outputs(tmp_path_factory.mktemp("threads1"), "--threads", "1")
    return {name: digests(path) for name, path in out.items()}


def test_every_sample_log_is_covered(reference):
    assert set(reference) == {p.name for p in sample_logs()} and len(reference) >= 6
    for name, channels in reference.items():
        assert "/datmo/tracks" in channels and "/datmo/features" in channels, name
        assert not any(t.startswith("/datmo/markers/") for t in channels), name


def test_outputs_match_the_stored_digests(reference):
    stored = json.loads(DIGESTS.read_text())
    for name in sorted(reference):
        assert reference[name] == stored.get(name), (
            f"{name}: datmo run's output differs from {DIGESTS.name}; if the change is meant (a tracker or "
            "perception change), run `make run-digests` and give the reason in the commit"
        )
    assert set(stored) == set(reference)


def test_same_outputs_with_two_threads(reference, tmp_path):
    out = run_outputs(tmp_path, "--threads", "2")
    assert {name: digests(path) for name, path in out.items()} == reference


@pytest.mark.parametrize("block", [7, 100])
def test_same_outputs_for_any_block_size(reference, tmp_path, block):
    for log in sample_logs():
        out = tmp_path / log.name
        process_file(log, out, force=True, block_scans=block)
        assert digests(out) == reference[log.name], (log.name, block)


@pytest.mark.parametrize("ahead", [1, pipeline.PERCEIVE_AHEAD, 5])
def test_same_outputs_with_the_next_blocks_perceived_on_their_own_thread(reference, tmp_path, monkeypatch, ahead):
    """Two threads or more: RunStages.pipelined perceives blocks k + 1 .. k + ahead on a thread beside the
    tracking of block k; on many small blocks, whatever the machine's cores, the outputs stay the same."""
    from datmo_cli.perception import threads

    monkeypatch.setattr(pipeline, "PERCEIVE_AHEAD", ahead)
    monkeypatch.setattr(threads, "available", lambda: 2)
    monkeypatch.setattr(threads, "_DEFAULT", 2)
    for log in sample_logs():
        out = tmp_path / log.name
        process_file(log, out, force=True, block_scans=50)
        assert digests(out) == reference[log.name], log.name
