"""The one pass against `datmo track` with a stand-in perception stage (the ideal features of the ground
truth), so the tracking half of `datmo run` is checked even where datmo_cli.perception is not built:
tracks from in-memory RunFeatures must equal, byte for byte, tracks from the /datmo/features channel."""

from __future__ import annotations

import importlib.machinery
import sys
import types as pytypes
from dataclasses import dataclass

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli import pipeline
from datmo_cli.cli import cli
from datmo_cli.log import cdr, mcapio, types
from datmo_cli.report import decode_channel
from datmo_cli.tracking.accuracy import ideal_features


@dataclass
class RunFeatures:
    lines: np.ndarray
    circles: np.ndarray
    blobs: np.ndarray
    line_offsets: np.ndarray
    circle_offsets: np.ndarray
    blob_offsets: np.ndarray


def flat(parts):
    return np.concatenate(parts), np.concatenate([[0], np.cumsum([len(p) for p in parts])])


@pytest.fixture
def stand_in_perception(tmp_path, monkeypatch):
    """A simulated log and a perception module whose features are the ground truth's ideal features."""
    src = tmp_path / "hall.mcap"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "hall", "--duration", "12", "-o", str(src)])
    assert result.exit_code == 0, result.output
    truth = decode_channel(types.GROUND_TRUTH, mcapio.read_messages(src, mcapio.TOPIC_GROUND_TRUTH)[1])
    scans = ideal_features(truth.offsets["objects"], truth.items["objects"], np.random.default_rng(3))

    def derive_features(run, *, odometry=None, params=None):
        payloads = [cdr.encode(types.FEATURES, {"stamp_ns": int(s), "frame_id": run.geometry.frame_id,
                                                "lines": f.lines, "circles": f.circles, "blobs": f.blobs})
                    for s, f in zip(run.stamps, scans, strict=True)]
        lines, lo = flat([f.lines for f in scans])
        circles, co = flat([f.circles for f in scans])
        blobs, bo = flat([f.blobs for f in scans])
        return ({mcapio.TOPIC_FEATURES: (types.FEATURES, run.stamps, payloads)},
                RunFeatures(lines, circles, blobs, lo, co, bo))

    module = pytypes.ModuleType(pipeline.PERCEPTION)
    module.__spec__ = importlib.machinery.ModuleSpec(pipeline.PERCEPTION, None)
    module.derive_features = derive_features
    monkeypatch.setitem(sys.modules, pipeline.PERCEPTION, module)
    return src, derive_features


def test_tracks_of_the_one_pass_equal_datmo_track_on_the_features_file(tmp_path, stand_in_perception):
    src, derive_features = stand_in_perception
    log = mcapio.read_log(src, topics=None)
    channels, _ = derive_features(mcapio.run_from_log(log))
    feat = tmp_path / "features.mcap"
    with mcapio.LogWriter(feat) as w:
        w.copy_from(log)
        for topic, (msgtype, stamps, payloads) in channels.items():
            w.write_many(topic, msgtype, stamps, payloads)
    staged = tmp_path / "tracked.mcap"
    result = CliRunner().invoke(cli, ["track", str(feat), "-o", str(staged)])
    assert result.exit_code == 0, result.output

    scans = pipeline.process_file(src, tmp_path / "one-pass.mcap")
    a = mcapio.read_log(staged, topics=None).messages
    b = mcapio.read_log(tmp_path / "one-pass.mcap", topics=None).messages
    assert scans == 60
    assert sorted(a) == sorted(b)
    assert mcapio.TOPIC_TRACKS in b and mcapio.TOPIC_MARKERS_TRACKS in b
    for topic in a:
        assert a[topic] == b[topic], topic
    meta = mcapio.summary(tmp_path / "one-pass.mcap").metadata
    assert meta["datmo"]["command"] == "run" and "track" in meta["datmo.params"]


def test_cli_run_in_parallel_then_evaluate(tmp_path, stand_in_perception):
    src, _ = stand_in_perception
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
    ev = CliRunner().invoke(cli, ["evaluate", str(out / "hall.mcap"), "--min-mota", "0.5"])
    assert ev.exit_code == 0, ev.output
