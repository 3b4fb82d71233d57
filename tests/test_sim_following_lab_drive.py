"""The scenes of a moving robot among people: `following` (a robot trailing a person, no /odom) and `lab-drive` (a robot
with odometry, its Hokuyo-like laser mounted 0.85 m ahead and yawed 40°), the scene keys they brought (follow, gap,
odometry, laser_pose, [scanner], rate), and lab-drive as a ROS 1 bag that `datmo import` brings back to the same log and
`datmo run` to the same tracks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.base.errors import ConfigError
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio, transforms
from datmo_cli.logs.vocabulary import CLASS_PERSON
from datmo_cli.sim.scene import builtin_scenes, load_scene, parse_scene
from datmo_cli.sim.simulate import Simulation, simulate_scene

pytestmark = pytest.mark.cli


def invoke(*args) -> str:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


@pytest.fixture(scope="module")
def following():
    return simulate_scene("following", seed=1, noise_sigma=0.0)


@pytest.fixture(scope="module")
def lab():
    return simulate_scene("lab-drive", seed=1, duration=40.0, noise_sigma=0.0)


def test_both_are_listed_and_each_seed_gives_the_same_run():
    assert {"following", "lab-drive"} <= set(builtin_scenes())
    for name in ("following", "lab-drive"):
        a, b = (simulate_scene(name, seed=4, duration=3.0) for _ in range(2))
        c = simulate_scene(name, seed=5, duration=3.0)
        assert np.array_equal(a.codes, b.codes) and a.truth.tobytes() == b.truth.tobytes()
        assert not np.array_equal(a.codes, c.codes)


def test_following_trails_the_leader_and_stops_behind_them(following):
    sim = following
    assert sim.odometry is None and sim.objects[0].name == "leader" and sim.objects[0].id == 1
    assert sim.sensor.rate_hz == 10.0 and 90 <= len(sim.run) / 10 <= 120
    gt = sim.truth.reshape(len(sim.run), -1)
    leader = gt[:, 0]
    gap = np.hypot(leader["x"], leader["y"])
    assert gap.min() > 1.49 and gap.max() < 2.51  # 1.5-2.5 m all along
    assert np.all(np.abs(np.degrees(np.arctan2(leader["y"], leader["x"]))) < 1.0)  # it faces the leader
    stands = ~leader["moving"].astype(bool)
    robot_speed = np.hypot(*np.diff(sim.sensor_poses[:, :2], axis=0).T) * 10.0
    paused = np.flatnonzero(stands[1:] & stands[:-1])
    settled = paused[gap[paused + 1] < 1.53]
    assert len(settled) > 50 and robot_speed[settled].max() < 0.05  # it stops, the gap shrinks and holds
    walking = np.flatnonzero(~stands[1:])
    assert np.median(gap[walking + 1]) == pytest.approx(2.27, abs=0.05)
    assert leader["visible"].mean() > 0.95


def test_following_people_pass_the_robot_on_either_side(following):
    sim = following
    gt = sim.truth.reshape(len(sim.run), -1)
    passers = [k for k, o in enumerate(sim.objects) if o.classification == CLASS_PERSON and k > 0]
    assert len(passers) == 8
    sides = set()
    for k in passers:
        x, y = gt["x"][:, k], gt["y"][:, k]
        seen = gt["visible"][:, k].astype(bool)
        assert seen.sum() > 30 and (gt["vx"][seen, k] < 0).mean() > 0.9  # coming towards the robot
        beside = np.flatnonzero(seen & (np.abs(x) < 1.0))
        sides.add(int(np.sign(np.median(y[beside]))))
        assert np.hypot(x, y).min() > 0.7  # past it, not through it
    assert sides == {-1, 1}


def test_lab_drive_scanner_mount_and_odometry(lab):
    sim = lab
    g = sim.run.geometry
    assert g.n_beams == 768 and math.degrees(g.angle_min) == pytest.approx(-135.0)
    assert math.degrees(g.angle_increment) == pytest.approx(0.3515625) and (g.range_min, g.range_max) == (0.02, 10.0)
    assert sim.sensor.rate_hz == 10.0 and 60 <= load_scene("lab-drive").duration <= 90
    # /odom holds the base; the laser is the base composed with the mount, as the ground truth's sensor pose says
    mount = transforms.LaserPose(0.85, 0.0, math.radians(40.0))
    base = transforms.base_odometry(sim.odometry, mount)
    laser = transforms.sensor_odometry(
        base, [transforms.Transform.planar(0, "base_link", "laser", mount.x, mount.y, mount.yaw)], "laser"
    )
    assert np.allclose(laser.x, sim.sensor_poses[:, 0]) and np.allclose(laser.y, sim.sensor_poses[:, 1])
    speed = np.hypot(*np.diff(np.c_[base.x, base.y], axis=0).T) * 10.0
    assert 0.5 <= speed.max() <= 1.0 + 1e-9
    gt = sim.truth.reshape(len(sim.run), -1)
    people = [k for k, o in enumerate(sim.objects) if o.classification == CLASS_PERSON]
    names = [sim.objects[k].name for k in people]
    assert names == ["talker1", "talker2", "guard", "visitor", "waiter", "walker1", "walker2"]
    moving = gt["moving"][:, people].astype(bool)
    assert not moving[:, :3].any() and moving[:, 3:5].any(0).all() and (~moving[:, 3:5]).any(0).all()
    d = np.hypot(gt["x"][:, people], gt["y"][:, people])
    assert d.min() > 1.0 and np.median(d) < 6.0


def test_ground_truth_velocities_of_a_mounted_turning_scanner_are_the_derivatives(lab):
    """vx, vy in the laser's frame are d/dt of x, y (the mount's swing as the base turns included)."""
    gt = lab.truth.reshape(len(lab.run), -1)
    k = next(i for i, o in enumerate(lab.objects) if o.name == "column1")
    dx, dy = np.gradient(gt["x"][:, k].astype(float), 0.1), np.gradient(gt["y"][:, k].astype(float), 0.1)
    smooth = np.abs(np.gradient(np.gradient(gt["x"][:, k].astype(float)))) < 1e-3  # away from the starts and stops
    assert np.allclose(gt["vx"][smooth, k], dx[smooth], atol=0.02) and np.allclose(
        gt["vy"][smooth, k], dy[smooth], atol=0.02
    )
    assert np.abs(gt["vx"][:, k]).max() > 0.5


def test_the_lab_drive_bag_imports_to_the_same_log_and_runs_to_the_same_tracks(tmp_path):
    invoke("simulate", "--scene", "lab-drive", "--duration", "12", "-o", tmp_path / "lab.mcap")
    invoke("simulate", "--scene", "lab-drive", "--duration", "12", "-o", tmp_path / "robot.bag")
    out = invoke("import", tmp_path / "robot.bag", "-o", tmp_path / "imported.mcap")
    assert "warning" not in out
    a, b = (mcapio.read_log(tmp_path / n, topics=None) for n in ("lab.mcap", "imported.mcap"))
    assert mcapio.TOPIC_GROUND_TRUTH not in b.messages and mcapio.TOPIC_TF_STATIC in b.messages
    for topic in (mcapio.TOPIC_SCAN, mcapio.TOPIC_TF_STATIC):
        assert a.messages[topic][1] == b.messages[topic][1], topic  # byte for byte: frames, stamps, mount
    odom_a, odom_b = mcapio.odometry_from_log(a), mcapio.odometry_from_log(b)
    assert (odom_b.frame_id, odom_b.child_frame_id) == ("odom", "base_link")
    assert np.array_equal(odom_a.stamps, odom_b.stamps) and np.array_equal(odom_a.x, odom_b.x)
    assert np.allclose(odom_a.theta, odom_b.theta, rtol=0, atol=1e-15)  # the yaw through one more quaternion
    invoke("run", tmp_path / "lab.mcap", tmp_path / "robot.bag", "-o", tmp_path / "out", "--no-report")
    mcap, bag = (mcapio.read_messages(tmp_path / "out" / n, mcapio.TOPIC_TRACKS) for n in ("lab.mcap", "robot.mcap"))
    assert len(mcap[1]) == 120 and mcap[1] == bag[1]


@pytest.mark.parametrize(
    "text,message",
    [
        ("[sensor]\nfollow = 'ghost'\n", "no [[person]] is named 'ghost'"),
        ("[[person]]\nname = 'a'\nposition = [1, 1]\n[sensor]\nfollow = 'a'\n", "'a' stands still"),
        ("[[person]]\nname = 'a'\npath = [[0, 0], [5, 0]]\nspeed = 1.5\n[sensor]\nfollow = 'a'\n", "key 'speed'"),
        ("[[person]]\nname = 'a'\npath = [[0, 0], [5, 0]]\n[sensor]\nfollow = 'a'\ngap = [2.5, 1.5]\n", "key 'gap'"),
        ("[sensor]\npose = [0, 0, 0]\ngap = [1, 2]\n", "only applies with 'follow'"),
        ("[[person]]\nname = 'a'\npath = [[0, 0], [5, 0]]\n[sensor]\nfollow = 'a'\nloop = true\n", "key 'loop'"),
        ("[sensor]\nlaser_pose = [0.85, 0]\n", "key 'laser_pose'"),
        ("[sensor]\nodometry = 1\n", "key 'odometry'"),
        ("[scanner]\nbeams = 768\nfov_deg = 270\n", "missing key 'range'"),
        ("[scanner]\nbeams = 1\nfov_deg = 270\nrange = [0.02, 10]\n", "key 'beams'"),
        ("[scanner]\nbeams = 768\nfov_deg = 400\nrange = [0.02, 10]\n", "key 'fov_deg'"),
        ("[scanner]\nbeams = 768\nfov_deg = 270\nrange = [10, 1]\n", "key 'range'"),
        ("rate = 0\n", "top level, key 'rate'"),
    ],
)
def test_broken_new_keys_name_the_key(text, message):
    with pytest.raises(ConfigError) as err:
        parse_scene(text, "my.toml")
    assert str(err.value).startswith("my.toml: ") and message in str(err.value)


def test_a_scenes_own_scanner_or_mount_refuses_the_options_that_would_redo_it(tmp_path):
    for extra, word in ((["--angle", "100"], "--angle"), (["--laser-pose", "0,0,0"], "--laser-pose")):
        result = CliRunner().invoke(cli, ["simulate", "--scene", "lab-drive", "-o", str(tmp_path / "x.mcap"), *extra])
        assert result.exit_code == 2 and word in result.output and len(result.output.strip().splitlines()) == 1
    with pytest.raises(ConfigError, match="applies to the LMS200"):
        Simulation("lab-drive", resolution_deg=0.5)
    result = CliRunner().invoke(cli, ["emulate", "--scene", "lab-drive"])
    assert result.exit_code == 1 and "the emulator is an LMS200" in result.output
    assert Simulation("lab-drive", rate=20.0).sensor.rate_hz == 20.0 and Simulation("hall").sensor.rate_hz == 5.0


def test_a_bag_that_cannot_be_finished_leaves_nothing_behind(tmp_path, monkeypatch):
    from rosbags.rosbag1 import Writer

    real, calls = Writer.write, []

    def full_disk(self, *args):
        calls.append(1)
        if len(calls) > 50:
            raise OSError(28, "No space left on device")
        return real(self, *args)

    monkeypatch.setattr(Writer, "write", full_disk)
    out = tmp_path / "robot.bag"
    result = CliRunner().invoke(cli, ["simulate", "--scene", "lab-drive", "--duration", "3", "-o", str(out)])
    assert result.exit_code == 1
    assert result.output.strip().splitlines() == [f"datmo: error: {out}: no space left on the device (writing it)"]
    assert list(tmp_path.iterdir()) == []
