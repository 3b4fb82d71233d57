"""simulate_scene and `datmo simulate`: determinism, ground truth consistency, visible flags, moving sensor."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.base.errors import ConfigError
from datmo_cli.cli import cli
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.vocabulary import CLASS_COLUMN, CLASS_PERSON, CLASS_WALL_CORNER
from datmo_cli.sim.scene import parse_scene
from datmo_cli.sim.simulate import START_NS, simulate_scene

pytestmark = pytest.mark.cli

OCCLUSION = """
[[column]]
center = [2.0, 0.0]
radius = 0.3
[[person]]
name = "behind"
path = [[5.0, -3.0], [5.0, 3.0]]
speed = 1.0
"""

MOVING = """
[sensor]
path = [[0.0, 0.0], [3.0, 0.0], [3.0, 3.0]]
speed = 0.5
[[column]]
center = [5.0, 1.0]
radius = 0.2
[[wall]]
points = [[-1.0, -1.0], [8.0, -1.0], [8.0, 6.0]]
"""


def test_same_seed_same_run_and_another_seed_differs():
    a = simulate_scene("crowd", seed=5, duration=10)
    b = simulate_scene("crowd", seed=5, duration=10)
    c = simulate_scene("crowd", seed=6, duration=10)
    assert np.array_equal(a.codes, b.codes) and a.truth.tobytes() == b.truth.tobytes()
    assert not np.array_equal(a.codes, c.codes)


def test_crowd_people_keep_their_paths_with_more_people_and_a_longer_run_of_the_same_minute():
    short = simulate_scene("crowd", seed=2, duration=5, noise_sigma=0.0)
    long = simulate_scene("crowd", seed=2, duration=50, noise_sigma=0.0, people=8)
    n = len(short.run)
    s = short.truth.reshape(n, -1)
    lg = long.truth.reshape(len(long.run), -1)[:n]
    assert (lg["classification"][0] == CLASS_PERSON).sum() == 8
    np.testing.assert_array_equal(s["world_x"][:, :6], lg["world_x"][:, :6])


def test_stamps_rate_and_geometry():
    r = simulate_scene("static", duration=2.0, rate=10.0, fov_deg=100, resolution_deg=0.25)
    assert len(r.run) == 20 and r.run.stamps[0] == START_NS
    assert np.all(np.diff(r.run.stamps) == 100_000_000)
    g = r.run.geometry
    assert g.n_beams == 401 and np.degrees(g.angle_min) == pytest.approx(-50.0)
    assert np.array_equal(r.truth_offsets, np.arange(21) * len(r.objects))


def test_sensor_frame_agrees_with_world_frame_and_scan():
    r = simulate_scene("static", duration=1.0, noise_sigma=0.0)
    gt = r.truth_at(0)
    col = gt[gt["classification"] == CLASS_COLUMN][0]
    np.testing.assert_allclose([col["x"], col["y"]], [col["world_x"], col["world_y"]], atol=1e-6)
    # the beam towards the column's centre measures centre distance minus radius
    bearing = np.arctan2(col["y"], col["x"])
    i = int(np.argmin(np.abs(r.run.geometry.angles() - bearing)))
    expect = np.hypot(col["x"], col["y"]) - col["length"] / 2
    assert r.run.ranges[0, i] == pytest.approx(expect, abs=0.01)
    assert not gt["moving"].any() and np.all(gt["vx"] == 0)


def test_visible_flags_follow_occlusion():
    r = simulate_scene(parse_scene(OCCLUSION, "occ.toml"), duration=6.0, rate=10.0, noise_sigma=0.0)
    gt = r.truth.reshape(len(r.run), -1)
    person = int(np.flatnonzero(gt["classification"][0] == CLASS_PERSON)[0])
    y = gt["world_y"][:, person]
    vis = gt["visible"][:, person].astype(bool)
    # the column (r 0.3 at 2 m) hides y in about +-0.75 m at 5 m, minus the legs' own extent
    assert not vis[np.abs(y) < 0.4].any()
    assert vis[np.abs(y) > 1.3].all()
    assert np.all(gt["n_beams"][vis, person] > 0) and np.all(gt["n_beams"][~vis, person] == 0)
    # the legs in the ground truth sit where the scan sees them
    k = int(np.flatnonzero(np.abs(y + 2.0) < 0.06)[0])
    pts = r.run.ranges[k, :, None] * np.stack([np.cos(r.run.geometry.angles()), np.sin(r.run.geometry.angles())], 1)
    for side in ("left", "right"):
        leg = np.array([gt[f"{side}_leg_x"][k, person], gt[f"{side}_leg_y"][k, person]])
        d = np.hypot(*(pts - leg).T)
        assert np.nanmin(d) < 0.105


def test_moving_sensor_writes_odometry_and_relative_velocities():
    r = simulate_scene(parse_scene(MOVING, "moving.toml"), duration=10.0, noise_sigma=0.0)
    assert r.odometry is not None and len(r.odometry) == len(r.run)
    np.testing.assert_allclose(r.odometry.x[:5], [0.0, 0.1, 0.2, 0.3, 0.4])
    gt = r.truth.reshape(len(r.run), -1)
    col = int(np.flatnonzero(gt["classification"][0] == CLASS_COLUMN)[0])
    np.testing.assert_allclose(gt["vx"][1:5, col], -0.5, atol=1e-6)  # a static column seen from a moving robot
    np.testing.assert_allclose(gt["world_vx"][:, col], 0.0)
    # sensor-frame positions follow the pose
    k = 40
    x, y, th = r.sensor_poses[k]
    dx, dy = gt["world_x"][k, col] - x, gt["world_y"][k, col] - y
    assert gt["x"][k, col] == pytest.approx(np.cos(th) * dx + np.sin(th) * dy, abs=1e-5)
    assert gt["y"][k, col] == pytest.approx(-np.sin(th) * dx + np.cos(th) * dy, abs=1e-5)
    assert (gt["classification"][0] == CLASS_WALL_CORNER).sum() == 1


def test_moving_sensor_turns_on_the_spot_and_velocities_are_derivatives():
    rate = 75.0
    r = simulate_scene(parse_scene(MOVING, "moving.toml"), duration=9.0, rate=rate, resolution_deg=1.0, noise_sigma=0.0)
    th = np.unwrap(r.sensor_poses[:, 2])
    assert np.abs(np.diff(th)).max() <= np.pi / 2 / rate + 1e-9  # 90°/s, no jumps
    assert th[-1] == pytest.approx(np.pi / 2)
    turning = np.flatnonzero(np.abs(np.diff(th)) > 1e-9)
    assert len(turning) == pytest.approx(rate, abs=2)  # a 90° turn takes 1 s
    assert np.ptp(r.sensor_poses[turning, :2], axis=0).max() < 1e-9  # on the spot
    gt = r.truth.reshape(len(r.run), -1)
    col = int(np.flatnonzero(gt["classification"][0] == CLASS_COLUMN)[0])
    for axis in ("x", "y"):
        numeric = np.gradient(gt[axis][:, col].astype(float), 1 / rate)
        inner = turning[2:-2]
        np.testing.assert_allclose(gt["v" + axis][inner, col], numeric[inner], atol=2e-3)


def test_bad_parameters_raise_config_errors():
    for kwargs in (dict(rate=40.0), dict(duration=-1.0), dict(people=3), dict(range_mode_m=80)):
        with pytest.raises(ConfigError):
            simulate_scene("hall", **kwargs)


def test_cli_writes_a_log_with_scans_and_ground_truth(tmp_path):
    out = tmp_path / "hall.mcap"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "hall", "--duration", "4", "--seed", "3", "-o", str(out)])
    assert result.exit_code == 0, result.output
    run = mcapio.read_run(out)
    assert len(run) == 20 and run.geometry.n_beams == 361
    stamps, payloads = mcapio.read_messages(out, mcapio.TOPIC_GROUND_TRUTH)
    assert np.array_equal(stamps, run.stamps)
    msg = cdr.decode(types.GROUND_TRUTH, payloads[3])
    assert msg["stamp_ns"] == run.stamps[3] and msg["frame_id"] == "laser"
    direct = simulate_scene("hall", duration=4, seed=3)
    assert msg["objects"].tobytes() == direct.truth_at(3).tobytes()
    np.testing.assert_array_equal(run.ranges, direct.run.ranges)
    assert mcapio.read_odometry(out) is None


def test_cli_is_bit_for_bit_deterministic_and_writes_odometry(tmp_path):
    args = ["simulate", "--scene", "patrol", "--duration", "3", "--range", "80", "--resolution", "1", "-o"]
    for name in ("a.mcap", "b.mcap"):
        assert CliRunner().invoke(cli, args + [str(tmp_path / name)]).exit_code == 0
    # the output name is part of the recorded command line: compare with it blanked out
    a = (tmp_path / "a.mcap").read_bytes().replace(b"a.mcap", b"x.mcap")
    assert a == (tmp_path / "b.mcap").read_bytes().replace(b"b.mcap", b"x.mcap")
    odom = mcapio.read_odometry(tmp_path / "a.mcap")
    assert odom is not None and len(odom) == 15
    run = mcapio.read_run(tmp_path / "a.mcap")
    finite = run.ranges[np.isfinite(run.ranges)]
    assert np.allclose(np.round(finite * 100), finite * 100, atol=1e-3)  # cm units in the 80 m mode


def test_cli_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[[column]]\ncenter = [1, 2]\n")
    runner = CliRunner()
    cases = [
        (["--scene", str(bad)], "bad.toml: [[column]] 1: missing key 'radius'"),
        (["--scene", "nowhere"], "unknown scene 'nowhere'"),
        (["--rate", "50"], "at most 37.5 Hz"),
        (["--angle", "180", "--resolution", "0.25"], "not available at 180°"),
        (["--people", "4"], "[crowd]"),
    ]
    for extra, text in cases:
        result = runner.invoke(cli, ["simulate", "-o", str(tmp_path / "x.mcap"), *extra])
        assert result.exit_code == 1, (extra, result.output)
        assert text in result.output and "Traceback" not in result.output
        assert not (tmp_path / "x.mcap").exists()
    (tmp_path / "x.mcap").write_bytes(b"")
    result = runner.invoke(cli, ["simulate", "--duration", "1", "-o", str(tmp_path / "x.mcap")])
    assert result.exit_code == 1 and "--force" in result.output


def test_cli_lists_scenes():
    result = CliRunner().invoke(cli, ["simulate", "--list-scenes"])
    assert result.exit_code == 0 and "hall" in result.output and "crowd" in result.output


def test_streaming_chunks_equal_the_collected_run():
    from datmo_cli.sim.simulate import Simulation

    whole = simulate_scene("hall", seed=4, duration=8.0)
    sim = Simulation("hall", seed=4, duration=8.0)
    parts = list(sim.chunks(size=7))
    assert [p.start for p in parts[:3]] == [0, 7, 14]
    assert np.array_equal(np.concatenate([p.codes for p in parts]), whole.codes)
    assert np.concatenate([p.truth for p in parts]).tobytes() == whole.truth.tobytes()
    with pytest.raises(RuntimeError):
        next(sim.chunks())


def test_the_world_does_not_depend_on_the_scan_rate():
    slow = simulate_scene("hall", duration=4.0, rate=5.0).truth.reshape(20, -1)
    fast = simulate_scene("hall", duration=4.0, rate=10.0).truth.reshape(40, -1)
    for field in ("world_x", "world_y", "left_leg_x", "right_leg_y"):
        np.testing.assert_allclose(slow[field][:3], fast[field][:6:2], atol=1e-6)
