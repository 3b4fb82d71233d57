"""`datmo track` end to end on a small log that already has /datmo/features, and its errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from test_tracking_people import legs_as_circles, walker_legs

from benchmarks.synthetic_features import features_from_lists
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import Odometry, ScanGeometry, ScanRun
from datmo_cli.passes.config import DatmoConfig
from datmo_cli.perception.params import FeatureParams

pytestmark = pytest.mark.cli

GEOM = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, 0.0, 0.2, "laser")
N = 30
STAMPS = 1_700_000_000_000_000_000 + np.arange(N, dtype=np.int64) * 200_000_000


def make_log(path, odometry: bool = False) -> None:
    run = ScanRun(STAMPS, np.full((N, 361), 7.5, np.float32), GEOM)
    scans = [
        {"circles": legs_as_circles(walker_legs(0.2 * k, (1, -3), (0.3, 1.0))) + [(5.0, 2.0, 0.25)]} for k in range(N)
    ]
    feats = features_from_lists(scans)
    payloads = [
        cdr.encode(
            types.FEATURES,
            {"stamp_ns": int(s), "frame_id": "laser", "lines": f.lines, "circles": f.circles, "blobs": f.blobs},
        )
        for s, f in zip(STAMPS, feats, strict=True)
    ]
    with mcapio.LogWriter(path) as w:
        w.write_scans(run)
        w.write_many(mcapio.TOPIC_FEATURES, types.FEATURES, STAMPS, payloads)
        if odometry:
            w.write_odometry(Odometry(STAMPS, np.full(N, 2.0), np.zeros(N), np.zeros(N)))


def _tracks(path) -> list[dict]:
    _, payloads = mcapio.read_messages(path, mcapio.TOPIC_TRACKS)
    return [cdr.decode(types.TRACKS, p) for p in payloads]


@pytest.mark.parametrize("odometry", [False, True])
def test_track_writes_tracks_and_markers_every_scan(tmp_path, odometry):
    src, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    make_log(src, odometry)
    result = CliRunner().invoke(cli, ["track", str(src), "-o", str(out), "--markers"])
    assert result.exit_code == 0, result.output
    log = mcapio.read_log(out, topics=None)
    assert log.has(mcapio.TOPIC_SCAN) and log.has(mcapio.TOPIC_FEATURES)
    msgs = _tracks(out)
    assert len(msgs) == N
    assert [m["stamp_ns"] for m in msgs] == STAMPS.tolist() and msgs[0]["frame_id"] == "laser"
    last = msgs[-1]["tracks"]
    confirmed = last[last["status"] != 0]
    assert sorted(confirmed["classification"].tolist()) == [1, 2]
    column = confirmed[confirmed["classification"] == 2][0]
    assert np.allclose([column["x"], column["y"]], [5.0, 2.0], atol=0.05)
    if odometry:
        assert np.allclose([column["world_x"], column["world_y"]], [7.0, 2.0], atol=0.05)
    else:
        assert np.isnan(column["world_x"])
    _, markers = mcapio.read_messages(out, mcapio.TOPIC_MARKERS_TRACKS)
    assert len(markers) == N
    types.typestore().deserialize_cdr(markers[-1], types.MARKER_ARRAY)
    assert log.metadata["datmo"]["command"] == "track"


def test_track_options_and_config(tmp_path):
    src, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    make_log(src)
    cfg = tmp_path / "c.toml"
    cfg.write_text("[track]\nconfirm_hits = 4\nconfirm_window = 4\n")
    result = CliRunner().invoke(
        cli, ["track", str(src), "-o", str(out), "--config", str(cfg), "--gate", "9.2", "--d-max", "2.0"]
    )
    assert result.exit_code == 0, result.output
    msgs = _tracks(out)
    assert all((m["tracks"]["status"] == 0).all() for m in msgs[:3])  # 4 hits needed
    params = mcapio.summary(out).metadata["datmo.params"]
    assert json.loads(params["track"])["confirm_hits"] == 4
    assert json.loads(params["track"])["gate"] == 9.2 and json.loads(params["track"])["d_max"] == 2.0
    assert "features" not in params  # the log had /datmo/features: no feature extraction ran


def test_track_errors(tmp_path):
    runner = CliRunner()
    src, out = tmp_path / "in.mcap", tmp_path / "out.mcap"
    r = runner.invoke(cli, ["track", str(tmp_path / "missing.mcap"), "-o", str(out)])
    assert r.exit_code == 1 and "missing.mcap: no such file" in r.output
    make_log(src)
    out.write_bytes(b"x")
    r = runner.invoke(cli, ["track", str(src), "-o", str(out)])
    assert r.exit_code == 1 and "exists; use --force" in r.output
    bad = tmp_path / "bad.toml"
    bad.write_text("[track]\nwhat = 1\n")
    r = runner.invoke(cli, ["track", str(src), "-o", str(out), "--force", "--config", str(bad)])
    assert r.exit_code == 1 and "track.what: unknown parameter" in r.output
    assert "Traceback" not in r.output


def test_help_ends_in_an_example():
    r = CliRunner().invoke(cli, ["track", "--help"])
    assert r.exit_code == 0
    assert "Example: datmo track" in r.output


def _raycast_circles(ranges: np.ndarray, circles: list[tuple[float, float, float]]) -> np.ndarray:
    """The ranges of GEOM's beams with circles (x, y, radius, m) in front of a background at `ranges`."""
    a = GEOM.angle_min + GEOM.angle_increment * np.arange(GEOM.n_beams)
    ux, uy = np.cos(a), np.sin(a)
    out = ranges.astype(np.float64)
    for cx, cy, r in circles:
        along = ux * cx + uy * cy
        across2 = cx * cx + cy * cy - along * along
        hit = (across2 < r * r) & (along > 0)
        out = np.where(hit, np.minimum(out, along - np.sqrt(np.maximum(r * r - across2, 0.0))), out)
    return out.astype(np.float32)


def test_raw_log_is_segmented_and_tracked(tmp_path):
    """Without /datmo/features, track runs segmentation and features itself and writes their channels too;
    its provenance records both parameter sets."""
    ranges = np.full((N, 361), 7.5, np.float32)
    for k in range(N):
        circles = legs_as_circles(walker_legs(0.2 * k, (1, -3), (0.3, 1.0))) + [(5.0, 2.0, 0.25)]
        ranges[k] = _raycast_circles(ranges[k], circles)
    src, out = tmp_path / "raw.mcap", tmp_path / "out.mcap"
    with mcapio.LogWriter(src) as w:
        w.write_scans(ScanRun(STAMPS, ranges, GEOM))
    r = CliRunner().invoke(cli, ["track", str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "segmented and extracted features first" in r.output
    log = mcapio.read_log(out, topics=None)
    assert log.has(mcapio.TOPIC_FEATURES) and log.has(mcapio.TOPIC_TRACKS)
    assert len(log.messages[mcapio.TOPIC_FEATURES][1]) == N
    msgs = _tracks(out)
    assert len(msgs) == N
    last = msgs[-1]["tracks"]
    confirmed = last[last["status"] != 0]
    column = confirmed[np.hypot(confirmed["x"] - 5.0, confirmed["y"] - 2.0) < 0.1]
    assert len(column) == 1 and column["classification"][0] == 2
    assert (confirmed["classification"] == 1).sum() == 1  # the walker
    params = log.metadata["datmo.params"]
    assert set(params) == {"track", "features", "leg_model", "config", "hindsight"}
    assert json.loads(params["hindsight"]) == {"used": True, "lag_s": 1.0}
    assert json.loads(params["config"]) == DatmoConfig(features=FeatureParams(leg_model="default")).to_dict()
    assert json.loads(params["track"])["confirm_hits"] == 3 and "min_points" in json.loads(params["features"])
    model = json.loads(params["leg_model"])  # the detector that found the legs, with its file's hash
    assert model["model"] == "default" and len(model["sha256"]) == 64 and 0 < model["threshold"] < 1


def test_config_tables_are_read_per_stage(tmp_path):
    """One datmo.toml serves every command: [track] for tracking, [features] ignored by it, and a file with
    no tables at all is read as the stage's own table."""
    from datmo_cli.base.errors import ConfigError
    from datmo_cli.passes.config import load
    from datmo_cli.tracking.params import TrackingParams

    both = tmp_path / "both.toml"
    both.write_text("[features]\nmin_points = 4\n\n[track]\ngate = 9.0\n")
    assert load(both).track.gate == 9.0 and load(both).features.min_points == 4
    only_features = tmp_path / "features.toml"
    only_features.write_text("[features]\nmin_points = 4\n")
    assert load(only_features).track == TrackingParams()
    flat = tmp_path / "flat.toml"
    flat.write_text("gate = 7.5\n")
    assert load(flat).track.gate == 7.5
    bad = tmp_path / "bad.toml"
    bad.write_text("[track]\ngaet = 7.5\n")
    with pytest.raises(ConfigError, match="gaet"):
        load(bad)
