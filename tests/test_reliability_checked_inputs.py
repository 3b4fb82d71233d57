"""Inputs checked where they are read: a batch's manifest records each output's size and SHA-256 and resume
redoes an output that no longer matches; odometry poses must be finite and within MAX_POSE_M (the others
dropped, counted in a warning); two channels on the odometry topic are refused as two scan channels are;
a CARMEN log's bad timestamps are repaired alone, each named."""

from __future__ import annotations

import json
import os

import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli

pytestmark = pytest.mark.cli


@pytest.fixture
def fake_batch(tmp_path, monkeypatch):
    from test_batch import CALLS, fake_process

    from datmo_cli import pipeline

    monkeypatch.setattr(pipeline, "process_file", fake_process)
    monkeypatch.setattr(pipeline, "warm_up", lambda: None)
    CALLS.clear()
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("a.mcap", "b.mcap", "c.mcap"):
        (logs / name).write_bytes(name.encode())
    return logs, CALLS


def test_resume_redoes_a_done_output_that_was_truncated_or_changed_since(fake_batch, tmp_path):
    logs, calls = fake_batch
    out = tmp_path / "out"

    def run():
        calls.clear()
        r = CliRunner().invoke(cli, ["run", str(logs), "-o", str(out), "--no-report", "--jobs", "1"])
        assert r.exit_code == 0, r.output
        return sorted(calls)

    assert run() == ["a.mcap", "b.mcap", "c.mcap"]
    lines = [json.loads(x) for x in (out / "manifest.jsonl").read_text().splitlines()]
    for line in lines:
        assert line["output_size"] == os.path.getsize(line["output"]) and len(line["output_sha256"]) == 64
    with open(out / "a.mcap", "r+b") as f:  # truncated afterwards
        f.truncate(100)
    data = bytearray((out / "b.mcap").read_bytes())  # one byte changed, the size kept
    data[-1] ^= 0xFF
    (out / "b.mcap").write_bytes(bytes(data))
    assert run() == ["a.mcap", "b.mcap"]  # c.mcap, unchanged, is skipped
    assert run() == []
