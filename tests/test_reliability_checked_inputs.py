"""Inputs checked where they are read: a batch's manifest records each output's size and SHA-256 and resume
redoes an output that no longer matches; odometry poses must be finite and within MAX_POSE_M (the others
dropped, counted in a warning); two channels on the odometry topic are refused as two scan channels are;
a CARMEN log's bad timestamps are repaired alone, each named."""

from __future__ import annotations

import json
import os
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli

pytestmark = pytest.mark.cli


@pytest.fixture
def fake_batch(tmp_path, monkeypatch):
    from test_batch import CALLS, fake_process

    from datmo_cli.passes import pipeline, warm

    monkeypatch.setattr(pipeline, "process_file", fake_process)
    monkeypatch.setattr(warm, "warm_up", lambda *_a, **_k: None)
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


T0 = 1_600_000_000_000_000_000
BAD_POSES = {3: (float("nan"), 0.0, 0.0), 5: (0.0, float("inf"), 0.0), 7: (1e300, 0.0, 0.0), 8: (0.0, 0.0, np.nan)}


def odom_log(path, bad=BAD_POSES, n: int = 10, channels: int = 1) -> None:
    """An MCAP of `n` scans and /odom poses (x = 0.1 k) 0.2 s apart, except the poses `bad` (k: x, y, theta);
    with channels=2, /odom on two channels (the second 50 ms later)."""
    from mcap.writer import Writer

    from datmo_cli.logs import mcapio, types
    from datmo_cli.logs.scan import Odometry, ScanGeometry, ScanRun, encode_scans

    stamps = T0 + np.arange(n, dtype=np.int64) * 200_000_000
    g = ScanGeometry(-np.pi / 2, np.pi / 90, 91, 0.0, 8.0, 0.0, 0.2, "laser")
    run = ScanRun(stamps, np.full((n, 91), 3.0, np.float32), g)
    xyz = [bad.get(k, (0.1 * k, 0.0, 0.0)) for k in range(n)]
    odo = Odometry(stamps, *(np.array(c, np.float64) for c in zip(*xyz, strict=True)))
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(types.LASERSCAN, "ros2msg", types.schema_text(types.LASERSCAN).encode())
        oid = w.register_schema(types.ODOMETRY, "ros2msg", types.schema_text(types.ODOMETRY).encode())
        scan = w.register_channel(mcapio.TOPIC_SCAN, "cdr", sid, {})
        odoms = [w.register_channel(mcapio.TOPIC_ODOM, "cdr", oid, {"publisher": str(i)}) for i in range(channels)]
        payloads = mcapio.encode_odometry(odo)
        for k, (t, p) in enumerate(zip(stamps.tolist(), encode_scans(run), strict=True)):
            w.add_message(scan, t, p, t)
            for i, cid in enumerate(odoms):
                w.add_message(cid, t + i * 50_000_000, payloads[k], t)
        w.finish()


def test_odometry_poses_not_finite_or_beyond_the_bound_are_dropped_with_their_count(tmp_path):
    from datmo_cli.logs import mcapio, poses

    path = tmp_path / "odom.mcap"
    odom_log(path)
    with pytest.warns(
        poses.BadPoseWarning, match=r"dropped 4 of 10 odometry poses .* beyond 1,000,000 m \(the first: pose 3\)"
    ):
        odo = mcapio.odometry_from_log(mcapio.read_log(path, topics=None))
    assert len(odo) == 6 and np.isfinite(odo.x).all() and np.abs(odo.x).max() < 1
    result = CliRunner().invoke(cli, ["import", str(path), "-o", str(tmp_path / "out.mcap")])
    assert result.exit_code == 0, result.output
    assert "dropped 4 of 10 odometry poses" in result.stderr, result.stderr
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the output holds only sane poses: no warning when read
        assert len(mcapio.read_odometry(tmp_path / "out.mcap")) == 6


def test_carmen_poses_beyond_the_bound_are_dropped_with_their_count(tmp_path):
    from test_reliability_imports import flaser_log

    from datmo_cli.logs.importers import import_log

    path = tmp_path / "in.log"
    flaser_log(path, {4: "1e308 2 0.5", 9: "1 -1e300 0.5"})
    res = import_log(path)
    assert len(res.run) == 30 and len(res.odometry) == 28
    assert (
        f"{path}: dropped 2 of 30 odometry poses that are not finite or lie beyond 1,000,000 m (the first: pose 4)"
        in res.warnings
    )


def test_two_channels_on_the_odometry_topic_are_refused_as_for_scans(tmp_path):
    from datmo_cli.base.errors import InputError
    from datmo_cli.logs import mcapio

    path = tmp_path / "two.mcap"
    odom_log(path, bad={}, channels=2)
    with pytest.raises(InputError, match=r"/odom is on 2 channels \(id 2: 10 nav_msgs/msg/Odometry, id 3: 10"):
        mcapio.odometry_from_log(mcapio.read_log(path, topics=None))
    result = CliRunner().invoke(cli, ["import", str(path), "-o", str(tmp_path / "out.mcap")])
    assert result.exit_code == 1 and "/odom is on 2 channels" in result.stderr, result.output
    assert not (tmp_path / "out.mcap").exists()


def test_one_nan_carmen_timestamp_is_repaired_alone_and_named(tmp_path):
    from datmo_cli.logs.importers import import_log

    ranges = " ".join(["3.0"] * 181)
    lines = []
    for k in range(30):
        t = "nan" if k == 10 else f"{100 + 0.2 * k:.6f}"
        lines.append(f"FLASER 181 {ranges} 1 2 0.5 1 2 0.5 {t} host {t}")
    path = tmp_path / "in.log"
    path.write_text("\n".join(lines) + "\n")
    res = import_log(path)
    want = np.round((100 + 0.2 * np.arange(30)) * 1e9).astype(np.int64)
    want[10] = want[9] + 1_000_000  # the bad one alone: 1 ms after the one before
    np.testing.assert_array_equal(res.run.stamps, want)
    said = [w for w in res.warnings if "stamp" in w]
    assert (
        len(said) == 1 and "1 is not a number or out of range; each set 1 ms after the one before (scan 10)" in said[0]
    )
    assert "synthesised" not in said[0]


def test_carmen_poses_of_1e308_never_make_tracks_that_are_not_finite(tmp_path):
    from test_reliability_imports import flaser_log

    from datmo_cli.logs import mcapio, types
    from datmo_cli.report import decode_channel

    path = tmp_path / "in.log"
    flaser_log(path, {4: "1e308 2 0.5", 5: "1 1e308 0.5"})
    result = CliRunner().invoke(cli, ["import", str(path), "-o", str(tmp_path / "in.mcap")])
    assert result.exit_code == 0 and "dropped 2 of 30 odometry poses" in result.stderr, result.output
    result = CliRunner().invoke(cli, ["track", str(tmp_path / "in.mcap"), "-o", str(tmp_path / "tracks.mcap")])
    assert result.exit_code == 0, result.output
    _, payloads = mcapio.read_messages(tmp_path / "tracks.mcap", mcapio.TOPIC_TRACKS)
    states = decode_channel(types.TRACKS, payloads).items["tracks"]
    assert len(states) and all(np.isfinite(states[f]).all() for f in ("x", "y", "world_x", "world_y"))
