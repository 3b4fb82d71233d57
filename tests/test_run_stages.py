"""`datmo run` (one pass, no intermediate files) against the stages run one by one: datmo segment, then
datmo features on its output, then datmo track on that. Every channel must be byte for byte the same."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli
from datmo_cli.logs import mcapio
from datmo_cli.passes import pipeline

pytestmark = pytest.mark.cli


@pytest.fixture
def hall_log(tmp_path):
    src = tmp_path / "hall.mcap"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "hall", "--duration", "12", "-o", str(src)])
    assert result.exit_code == 0, result.output
    return src


def invoke(*args: str) -> None:
    result = CliRunner().invoke(cli, list(args))
    assert result.exit_code == 0, result.output


def test_one_pass_equals_the_stages_one_by_one(tmp_path, hall_log):
    seg, feat, staged = tmp_path / "seg.mcap", tmp_path / "feat.mcap", tmp_path / "tracked.mcap"
    invoke("segment", str(hall_log), "-o", str(seg))
    invoke("features", str(seg), "-o", str(feat), "--markers")
    invoke("track", str(feat), "-o", str(staged), "--markers", "--covariance")
    direct = tmp_path / "direct.mcap"
    invoke("track", str(hall_log), "-o", str(direct), "--markers", "--covariance")  # segments, features itself

    scans = pipeline.process_file(hall_log, tmp_path / "one-pass.mcap", markers=True, covariance=True)
    a = mcapio.read_log(staged, topics=None).messages
    b = mcapio.read_log(tmp_path / "one-pass.mcap", topics=None).messages
    c = mcapio.read_log(direct, topics=None).messages
    assert scans == 60
    assert sorted(a) == sorted(b) == sorted(c)
    for topic in (
        mcapio.TOPIC_SEGMENTS,
        mcapio.TOPIC_FEATURES,
        mcapio.TOPIC_LANDMARKS,
        mcapio.TOPIC_TRACKS,
        mcapio.TOPIC_MARKERS_FEATURES,
        mcapio.TOPIC_MARKERS_TRACKS,
    ):
        assert topic in b
    for topic in a:
        assert a[topic] == b[topic] == c[topic], topic
    meta = mcapio.summary(tmp_path / "one-pass.mcap").metadata
    assert meta["datmo"]["command"] == "run"
    assert "track" in meta["datmo.params"] and "features" in meta["datmo.params"]


def test_cli_run_in_parallel_then_evaluate(tmp_path, hall_log):
    src = hall_log
    other = tmp_path / "copy.mcap"
    other.write_bytes(src.read_bytes())
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["run", str(src), str(other), "-o", str(out), "--jobs", "2", "--format", "csv"])
    assert result.exit_code == 0, result.output
    rows = result.stdout.strip().splitlines()
    assert rows[0].startswith("file,duration_s,scans") and rows[-1].startswith("total,") and len(rows) == 4
    assert "scans/s)" in result.stderr
    a = mcapio.read_log(out / "hall.mcap", topics=[mcapio.TOPIC_TRACKS]).messages
    b = mcapio.read_log(out / "copy.mcap", topics=[mcapio.TOPIC_TRACKS]).messages
    assert a == b  # the same input gives the same tracks in any worker
    ev = CliRunner().invoke(cli, ["evaluate", str(out / "hall.mcap"), "--format", "json"])
    assert ev.exit_code == 0, ev.output
    assert '"mota"' in ev.stdout


@pytest.mark.slow
def test_first_parallel_run_with_an_empty_numba_cache(tmp_path, hall_log):
    """After an install or upgrade the numba cache is empty: the kernels are compiled once, before the worker
    processes start, not by every worker at once."""
    import os
    import subprocess
    import sys

    other = tmp_path / "copy.mcap"
    other.write_bytes(hall_log.read_bytes())
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache")}
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "datmo_cli",
            "run",
            str(hall_log),
            str(other),
            "-o",
            str(tmp_path / "out"),
            "--jobs",
            "2",
            "--no-report",
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "out" / "hall.mcap").exists() and (tmp_path / "out" / "copy.mcap").exists()
    assert any((tmp_path / "numba-cache").rglob("*.nbi"))


def test_derive_and_the_streamed_stages_take_one_configuration(tmp_path, hall_log):
    """A DatmoConfig reaches every stage in one convention: in memory (derive), streamed (process_file), and
    both record it whole, with the tracks it changes."""
    from datmo_cli.passes.config import DatmoConfig

    cfg = DatmoConfig().replace(track={"confirm_hits": 5, "confirm_window": 6})
    run, odometry = mcapio.read_run(hall_log), mcapio.read_odometry(hall_log)
    derived, effective = pipeline.derive(run, odometry, cfg)
    default, _ = pipeline.derive(run, odometry)
    assert effective["config"] == cfg.to_dict() and effective["track"]["confirm_hits"] == 5

    def payloads(channels: dict, topic: str) -> list[bytes]:
        return [bytes(p) for p in channels[topic][-1]]

    assert payloads(derived, mcapio.TOPIC_FEATURES) == payloads(default, mcapio.TOPIC_FEATURES)
    assert payloads(derived, mcapio.TOPIC_TRACKS) != payloads(default, mcapio.TOPIC_TRACKS)
    pipeline.process_file(hall_log, tmp_path / "run.mcap", config=cfg, markers=False)
    b = mcapio.read_log(tmp_path / "run.mcap", topics=None)
    assert payloads(b.messages, mcapio.TOPIC_TRACKS) == payloads(derived, mcapio.TOPIC_TRACKS)
    assert mcapio.TOPIC_MARKERS_TRACKS not in b.messages


def test_the_tracker_is_built_with_the_stages_from_the_logs_geometry(hall_log):
    """open_stages builds the tracker once the stream's geometry is known (its first scan), before any block;
    a block's step is its perceive, track and give."""
    from datmo_cli.passes.stages import TrackStream
    from datmo_cli.passes.streaming import LogStream

    stream = LogStream(hall_log)
    stages = pipeline.open_stages(stream, markers=False)
    assert isinstance(stages.tracking, TrackStream)
    assert stages.tracking.frame == stream.geometry.frame_id == mcapio.read_run(hall_log).geometry.frame_id
    assert stream.geometry.same_beams(mcapio.read_run(hall_log).geometry)

    causal = pipeline.RunStages(stages.odometry, stream.geometry, markers=False)
    block = next(stream.blocks(50))
    perceived = causal.perceive(block)
    again = pipeline.RunStages(stages.odometry, stream.geometry, markers=False)
    one, other = causal.give(block, perceived, causal.track(block, perceived)), again.step(block)
    assert list(one) == list(other) and [c[2] for c in one.values()] == [c[2] for c in other.values()]
