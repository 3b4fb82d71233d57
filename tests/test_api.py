"""The Python API (docs/python.md): `process` writes what `datmo run` writes, a Log's tables are
`datmo export`'s rows, and a LiveTracker fed the scans of a log one at a time gives the tracks `datmo run` gave
for them (with the log's poses, and for a still scanner without), with one-line refusals of bad scans."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli import api
from datmo_cli.base.errors import InputError, MissingChannelError
from datmo_cli.base.extras import MissingExtraError
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio

pytestmark = pytest.mark.cli

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"


@pytest.fixture(scope="module")
def made(tmp_path_factory) -> dict[str, Path]:
    """api.process of patrol (odometry), static and hall (a still scanner, none; people walking in the hall), and
    datmo run's output of patrol."""
    d = tmp_path_factory.mktemp("api")
    out = {
        name: api.process(SAMPLES / f"{name}.mcap", d / f"{name}.mcap").path for name in ("patrol", "static", "hall")
    }
    result = CliRunner().invoke(
        cli, ["run", str(SAMPLES / "patrol.mcap"), "-o", str(d / "cli"), "--no-report", "--jobs", "1"]
    )
    assert result.exit_code == 0, result.output
    return out | {"cli": d / "cli" / "patrol.mcap"}


def equal_tables(a: np.ndarray, b: np.ndarray) -> None:
    assert a.dtype == b.dtype and len(a) == len(b)
    for name in a.dtype.names:
        if a.dtype[name].kind == "f":
            np.testing.assert_array_equal(a[name], b[name], err_msg=name)  # NaN where NaN
        else:
            assert a[name].tolist() == b[name].tolist(), name


def test_process_writes_what_datmo_run_writes(made):
    for topic in (mcapio.TOPIC_TRACKS, mcapio.TOPIC_FEATURES, mcapio.TOPIC_LANDMARKS):
        ours, theirs = mcapio.read_messages(made["patrol"], topic), mcapio.read_messages(made["cli"], topic)
        assert ours[0].tolist() == theirs[0].tolist() and ours[1] == theirs[1], topic
    for path in (made["patrol"], made["cli"]):  # both lean: no markers unless asked
        assert mcapio.TOPIC_MARKERS_TRACKS not in mcapio.summary(path).topics()


def test_the_tables_are_the_exports_rows(made, tmp_path):
    import pyarrow.parquet as pq

    log = api.open_log(made["patrol"])
    out = tmp_path / "all.parquet"
    assert CliRunner().invoke(cli, ["export", str(made["patrol"]), "--features", "-o", str(out)]).exit_code == 0
    table = pq.read_table(out).to_pydict()
    rows = np.array(table["kind"]) == "track"
    tracks, features = log.tracks(), log.features()
    assert list(tracks.dtype.names) == list(api.TRACK_COLUMNS) and len(tracks) == rows.sum() > 1000
    assert list(features.dtype.names) == list(api.FEATURE_COLUMNS) and len(features) == (~rows).sum() > 1000
    for name in tracks.dtype.names:
        want = [v for v, r in zip(table[name], rows, strict=True) if r]
        got = tracks[name].tolist()
        assert [None if isinstance(v, float) and np.isnan(v) else v for v in got] == want, name
    for name in features.dtype.names:
        want = [v for v, r in zip(table[name], rows, strict=True) if not r]
        got = features[name].tolist()
        assert [None if isinstance(v, float) and np.isnan(v) else v for v in got] == want, name
    assert np.isnan(api.open_log(made["static"]).tracks()["world_x_m"]).all()  # no odometry: NaN


def test_dataframes_hold_the_tables(made):
    log = api.open_log(made["patrol"])
    df, tracks = log.tracks_dataframe(), log.tracks()
    assert list(df.columns) == list(api.TRACK_COLUMNS) and len(df) == len(tracks)
    assert str(df["id"].dtype) == "uint32" and str(df["world_x_m"].dtype) == "float32"
    assert df["class"].tolist() == tracks["class"].tolist()
    assert len(log.features_dataframe()) == len(log.features())


def test_dataframes_without_pandas_name_the_extra(made, monkeypatch):
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(
        MissingExtraError,
        match=r"^DataFrames needs pandas, which is not installed: pip install "
        r"'datmo-cli\[pandas\]'$",
    ):
        api.open_log(made["patrol"]).tracks_dataframe()


def test_a_raw_log_has_no_tracks_yet_and_a_features_output_has_features_only(tmp_path):
    with pytest.raises(MissingChannelError, match="no messages on /datmo/tracks; run datmo track"):
        api.open_log(SAMPLES / "hall.mcap").tracks()
    out = tmp_path / "f.mcap"
    assert CliRunner().invoke(cli, ["features", str(SAMPLES / "static.mcap"), "-o", str(out)]).exit_code == 0
    log = api.open_log(out)
    assert len(log.features()) > 1000 and set(log.features()["kind"].tolist()) >= {"line", "circle"}
    with pytest.raises(MissingChannelError, match="no messages on /datmo/tracks"):
        log.tracks()


def test_process_takes_a_config(tmp_path):
    log = api.process(SAMPLES / "static.mcap", tmp_path / "s.mcap", config={"track": {"confirm_hits": 4}})
    track = json.loads(mcapio.summary(log.path).metadata["datmo.params"]["track"])
    assert track["confirm_hits"] == 4
    with pytest.raises(Exception, match="exists; use --force"):
        api.process(SAMPLES / "static.mcap", tmp_path / "s.mcap")


def live(log: api.Log, poses: bool) -> np.ndarray:
    """The tracks a LiveTracker gives for the scans of `log`, fed one at a time."""
    scans = log.read_scans()
    g = scans.geometry
    tracker = api.LiveTracker(
        g.angle_min, g.angle_increment, g.n_beams, g.range_min, g.range_max, frame_id=g.frame_id, name=log.name
    )
    given = log.poses() if poses else [None] * len(scans)
    return np.concatenate([tracker.update(r, s, p) for r, s, p in zip(scans.ranges, scans.stamps, given, strict=True)])


@pytest.mark.parametrize(("name", "poses"), [("patrol", True), ("static", False), ("hall", False)])
def test_a_live_tracker_gives_the_causal_tracks_of_datmo_run(tmp_path, name, poses):
    """Live, no hindsight: the tracks of datmo run with track.hindsight_lag = 0, whatever the config's lag."""
    causal = {"track": {"hindsight_lag": 0.0}}
    processed = api.process(SAMPLES / f"{name}.mcap", tmp_path / f"{name}.mcap", config=causal)
    assert (processed.poses() is not None) == poses
    tracks = processed.tracks()
    equal_tables(live(processed, poses), tracks)
    if name == "hall":
        assert len(set(tracks[tracks["class"] == "person"]["id"].tolist())) >= 2


def test_a_live_tracker_refuses_bad_scans():
    t = api.LiveTracker(-1.0, 0.01, 201, 0.0, 8.0, name="front")
    t.update(np.full(201, 3.0), 1_000)
    with pytest.raises(InputError, match=r"^front: a scan of \(200,\) ranges; this tracker's scans have 201 beams$"):
        t.update(np.full(200, 3.0), 2_000)
    with pytest.raises(InputError, match="^front: scan 1 stamped 1000 ns, not after the previous 1000$"):
        t.update(np.full(201, 3.0), 1_000)
    with pytest.raises(
        InputError, match="^front: scan 1 has a pose; the first had none: give a pose with every scan or with none$"
    ):
        t.update(np.full(201, 3.0), 2_000, pose=(0.0, 0.0, 0.0))
    assert t.update(np.full(201, 3.0), 2_000).dtype == api.dtype(api.TRACK_COLUMNS) and t.scans == 2
