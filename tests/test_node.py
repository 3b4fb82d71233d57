"""`datmo node`: a ROS 2 node over DDS, checked with a publisher and a subscriber written
here on cyclonedds alone, with their own IDL types (the ROS 2 definitions of LaserScan, Odometry and
datmo_msgs/Tracks as rmw_cyclonedds names them), not datmo's code. They run on a domain of this test run's own,
over the loopback interface only. Also: the DDS types and topic names, and the live feed's drop-oldest and new-geometry
rules (in process).

No `from __future__ import annotations` here: cyclonedds reads the IDL classes' annotations as types."""

import math
import os
import random
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli import live
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio, types
from datmo_cli.logs.scan import Odometry, ScanGeometry, ScanRun

pytestmark = pytest.mark.cli

cyclonedds = pytest.importorskip("cyclonedds", reason="the node extra (cyclonedds) is not installed")

from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import array, float32, float64, int32, sequence, uint8, uint32  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.qos import Policy, Qos  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
HALL = ROOT / "sample_logs" / "hall.mcap"
N_SCANS = 100
POSE = (1.5, -0.5, 0.3)  # where the (still) robot stands in odom: x m, y m, yaw rad

# The ROS 2 messages as IDL, written here from their .msg definitions (ROS 2 Humble; datmo_msgs/msg/*.msg)


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class LaserScan(IdlStruct, typename="sensor_msgs::msg::dds_::LaserScan_"):
    header: Header
    angle_min: float32
    angle_max: float32
    angle_increment: float32
    time_increment: float32
    scan_time: float32
    range_min: float32
    range_max: float32
    ranges: sequence[float32]
    intensities: sequence[float32]


@dataclass
class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
    position: Point
    orientation: Quaternion


@dataclass
class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
    pose: Pose
    covariance: array[float64, 36]


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Twist(IdlStruct, typename="geometry_msgs::msg::dds_::Twist_"):
    linear: Vector3
    angular: Vector3


@dataclass
class TwistWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::TwistWithCovariance_"):
    twist: Twist
    covariance: array[float64, 36]


@dataclass
class OdometryMsg(IdlStruct, typename="nav_msgs::msg::dds_::Odometry_"):
    header: Header
    child_frame_id: str
    pose: PoseWithCovariance
    twist: TwistWithCovariance


@dataclass
class Track(IdlStruct, typename="datmo_msgs::msg::dds_::Track_"):
    id: uint32
    age: uint32
    hits: uint32
    misses: uint32
    x: float32
    y: float32
    vx: float32
    vy: float32
    world_x: float32
    world_y: float32
    world_vx: float32
    world_vy: float32
    covariance: array[float32, 16]
    size: float32
    classification: uint8
    mobility: uint8
    status: uint8
    occluded: uint8


@dataclass
class Tracks(IdlStruct, typename="datmo_msgs::msg::dds_::Tracks_"):
    header: Header
    tracks: sequence[Track]

    @classmethod
    def deserialize(cls, data, has_header=True, use_version_2=None):
        """Decoded as cyclonedds decodes it, with the sample's bytes as they came (`cdr`)."""
        msg = super().deserialize(data, has_header=has_header, use_version_2=use_version_2)
        msg.cdr = bytes(data)
        return msg


def _stamp(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def _ns(header: Header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def _scan_msg(stamp: int, ranges: np.ndarray, g: ScanGeometry) -> LaserScan:
    return LaserScan(
        Header(_stamp(stamp), g.frame_id),
        g.angle_min,
        g.angle_max,
        g.angle_increment,
        g.time_increment,
        g.scan_time,
        g.range_min,
        g.range_max,
        ranges.tolist(),
        [],
    )


def _odom_msg(stamp: int) -> OdometryMsg:
    x, y, yaw = POSE
    pose = Pose(Point(x, y, 0.0), Quaternion(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))
    zero = Vector3(0.0, 0.0, 0.0)
    return OdometryMsg(
        Header(_stamp(stamp), "odom"),
        "base_link",
        PoseWithCovariance(pose, [0.0] * 36),
        TwistWithCovariance(Twist(zero, zero), [0.0] * 36),
    )


# ------------------------------------------------------------------------ a domain of this run's own, loopback


def _free_domain() -> int:
    """A ROS 2 domain id whose DDS discovery ports on this machine are free (7410 + 250 d, ...)."""
    rng = random.Random(os.getpid() ^ time.time_ns())
    for _ in range(200):
        d = rng.randint(1, 232)
        try:
            for port in range(7410 + 250 * d, 7430 + 250 * d):
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
                    s.bind(("127.0.0.1", port))
        except OSError:
            continue
        return d
    raise RuntimeError("no free DDS domain")


LOOPBACK = (
    "<CycloneDDS><Domain id='any'><General><Interfaces><NetworkInterface address='127.0.0.1'/>"
    "</Interfaces><AllowMulticast>false</AllowMulticast></General><Discovery>"
    "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>"
    "<Peers><Peer address='127.0.0.1'/></Peers></Discovery></Domain></CycloneDDS>"
)


def _wait_for(condition, what: str, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.02)


# ------------------------------------------------------------------------------------- the node, end to end


def _expected(tmp_path: Path, run: ScanRun, odom_stamps: np.ndarray) -> dict[int, bytes]:
    """{stamp: the /datmo/tracks payload} that `datmo track --covariance` writes for `run` without hindsight
    (datmo.toml with lag 0) with the robot at POSE (the node publishes the covariance; a file stores it when
    asked)."""
    n = len(odom_stamps)
    # the node is causal whatever the lag: datmo track gives its tracks without hindsight
    causal = tmp_path / "causal.toml"
    causal.write_text((tmp_path / "datmo.toml").read_text() + "hindsight_lag = 0.0\n")
    odom = Odometry(odom_stamps, np.full(n, POSE[0]), np.full(n, POSE[1]), np.full(n, POSE[2]))
    with mcapio.LogWriter(tmp_path / "in.mcap", provenance=mcapio.Provenance("test", {})) as w:
        w.write_scans(run)
        w.write_odometry(odom)
    result = CliRunner().invoke(
        cli,
        [
            "track",
            str(tmp_path / "in.mcap"),
            "-o",
            str(tmp_path / "out.mcap"),
            "--config",
            str(causal),
            "--covariance",
            "-q",
        ],
    )
    assert result.exit_code == 0, result.output
    stamps, payloads = mcapio.read_messages(tmp_path / "out.mcap", mcapio.TOPIC_TRACKS)
    return dict(zip(stamps.tolist(), payloads, strict=True))


@pytest.mark.slow
def test_an_independent_ros2_peer_gets_tracks_from_datmo_node(tmp_path, monkeypatch):
    domain = _free_domain()
    monkeypatch.setenv("ROS_DOMAIN_ID", str(domain))
    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    run = mcapio.read_run(HALL).slice(0, N_SCANS)
    odom_stamps = np.concatenate([[run.stamps[0] - 10_000_000], run.stamps])
    (tmp_path / "datmo.toml").write_text("[track]\nconfirm_hits = 2\ngate = 11.0\n")  # the node reads it too
    expected = _expected(tmp_path, run, odom_stamps)
    # then 10 scans of another geometry (every other beam), later
    g181 = ScanGeometry(
        angle_min=run.geometry.angle_min,
        angle_increment=2 * run.geometry.angle_increment,
        n_beams=181,
        range_min=run.geometry.range_min,
        range_max=run.geometry.range_max,
        frame_id=run.geometry.frame_id,
    )
    later = run.stamps[-1] + 200_000_000 * np.arange(1, 11)

    node = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from datmo_cli.cli import main; main()",
            "node",
            "--odom-topic",
            "/odom",
            "--config",
            str(tmp_path / "datmo.toml"),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ | {"PYTHONUNBUFFERED": "1"},
    )
    try:
        ready = node.stdout.readline()
        assert ready.startswith(f"datmo node: ROS 2 domain {domain}: /scan and /odom in, "), (ready, node.stderr.read())
        assert "/datmo/tracks" in ready and "/datmo/features" in ready and "/datmo/markers/tracks" in ready

        dp = DomainParticipant(domain)
        reliable = Qos(
            Policy.Reliability.Reliable(duration(milliseconds=100)),
            Policy.Durability.Volatile,
            Policy.History.KeepLast(10),
        )
        scans = DataWriter(dp, Topic(dp, "rt/scan", LaserScan), reliable)
        odom = DataWriter(dp, Topic(dp, "rt/odom", OdometryMsg), reliable)
        tracks = DataReader(
            dp,
            Topic(dp, "rt/datmo/tracks", Tracks),
            Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(500)),
        )
        got: list[Tracks] = []
        done = threading.Event()

        def take() -> None:
            while not done.is_set():
                got.extend(tracks.take(100))
                time.sleep(0.01)

        taker = threading.Thread(target=take, daemon=True)
        taker.start()
        _wait_for(
            lambda: (
                scans.get_matched_subscriptions()
                and odom.get_matched_subscriptions()
                and tracks.get_matched_publications()
            ),
            "the node's endpoints to match",
        )
        odom.write(_odom_msg(int(odom_stamps[0])))
        time.sleep(0.3)  # a pose before the first scan (the node takes poses before scans anyway)
        for i in range(N_SCANS):
            odom.write(_odom_msg(int(run.stamps[i])))
            scans.write(_scan_msg(int(run.stamps[i]), run.ranges[i], run.geometry))
            time.sleep(0.02)  # 50 Hz
        for stamp in later.tolist():
            scans.write(_scan_msg(stamp, run.ranges[N_SCANS - 1][::2], g181))
            time.sleep(0.02)
        try:
            _wait_for(lambda: len(got) >= N_SCANS + 10, "the tracks of every scan", timeout=30)
        except AssertionError:
            pass  # the checks below say what is missing
        done.set()
        taker.join()
        node.send_signal(signal.SIGINT)
        _, err = node.communicate(timeout=60)
    finally:
        if node.poll() is None:
            node.kill()

    assert node.returncode == 130, err
    lines = err.strip().splitlines()
    summary = re.fullmatch(
        r"datmo node: stopped \(Ctrl-C\); 110 scans received, (\d+) processed, (\d+) dropped "
        r"\(the stages were behind\), 1 restarts",
        lines[-1],
    )
    assert summary, err
    processed, dropped = int(summary.group(1)), int(summary.group(2))
    assert processed + dropped == 110 and processed == len(got)  # a Tracks for each scan processed
    assert any(
        re.search(r"the scans' geometry changed \(361 beams .*now 181 .*: tracking starts over$", line)
        for line in lines
    ), err

    stamps = [_ns(m.header) for m in got]
    hall = [m for m in got if _ns(m.header) in expected]
    assert len(hall) >= 90 and stamps == sorted(stamps)
    # up to the first scan the node had to drop (none, unless the machine is very busy) the tracks are byte for
    # byte what datmo track wrote for the same scans (in a sample padded to a multiple of 4 bytes)
    first_gap = next((i for i, m in enumerate(hall) if _ns(m.header) != run.stamps[i]), len(hall))
    assert first_gap >= 50
    for m in hall[:first_gap]:
        wire = m.cdr[: len(expected[_ns(m.header)])]
        assert wire == expected[_ns(m.header)] and not any(m.cdr[len(wire) :])
    for m in hall:
        assert m.header.frame_id == "laser"
        assert all(math.isfinite(t.world_x) and math.isfinite(t.world_y) for t in m.tracks)  # with odometry
    assert sum(len(m.tracks) for m in hall) > 0
    after = [s for s in stamps if s not in expected]
    assert len(after) >= 8 and set(after) <= set(later.tolist())


# ----------------------------------------------------------------------------------- in process: the parts


def test_dds_types_and_names_follow_rmw_cyclonedds():
    from datmo_cli.ros2 import dds

    assert dds.dds_type_name(types.TRACKS) == "datmo_msgs::msg::dds_::Tracks_"
    for msgtype, ours in [(types.LASERSCAN, LaserScan), (types.ODOMETRY, OdometryMsg), (types.TRACKS, Tracks)]:
        theirs = dds.idl_class(msgtype)
        assert theirs.__idl_typename__ == ours.__idl_typename__
        a, b = theirs.__idl__.get_type_info(), ours.__idl__.get_type_info()  # XTypes: the same type, by hash
        assert a.minimal.typeid_with_size.type_id == b.minimal.typeid_with_size.type_id, msgtype
        assert a.complete.typeid_with_size.type_id == b.complete.typeid_with_size.type_id, msgtype
    assert dds.dds_topic(dds.ros_topic("scan")) == "rt/scan" and dds.ros_topic("/a/b_2") == "/a/b_2"
    for bad in ("", "/", "a//b", "/2d", "a b", "/scan/"):
        with pytest.raises(dds.ConfigError, match="not a ROS 2 topic name"):
            dds.ros_topic(bad, "--scan-topic")


def test_dds_types_encode_as_datmo_writes_to_mcap(tmp_path):
    """Every channel the node publishes, decoded with the IDL class it is published as and encoded again by
    cyclonedds, is the payload datmo wrote: the classes lay the bytes out as datmo's codecs do."""
    from datmo_cli.ros2 import dds
    from datmo_cli.ros2.node import published_topics

    run = mcapio.read_run(HALL).slice(0, 8)
    derived = live.Stages(None, run.geometry, has_tf=True).messages(run)
    topics = published_topics()
    assert {m.topic for m in derived} == set(topics)
    for m in derived:
        cls = dds.idl_class(topics[m.topic])
        assert cls.deserialize(m.payload).serialize() == m.payload, m.topic
    scan = mcapio.encode_scans(run.slice(0, 1))[0]
    assert dds.idl_class(types.LASERSCAN).deserialize(scan).serialize() == scan
    assert LaserScan.deserialize(scan).serialize() == scan  # the test's own type agrees


class _Stuck:
    """A sink whose first publish waits until `gate` is set (the stages are behind)."""

    def __init__(self) -> None:
        self.gate = threading.Event()
        self.messages: list[live.Message] = []
        self.stamps: list[int] = []

    def time(self, stamp: int) -> None:
        self.gate.wait(60)
        self.stamps.append(stamp)

    def publish(self, m: live.Message) -> None:
        self.messages.append(m)


class _NoStages:
    def __init__(self, *args, **kwargs) -> None:
        pass

    def messages(self, run: ScanRun) -> list[live.Message]:
        return []


def test_a_burst_drops_the_oldest_waiting_scans_and_counts_them(monkeypatch):
    monkeypatch.setattr(live.feed, "Stages", _NoStages)
    run = mcapio.read_run(HALL).slice(0, 12)
    sink = _Stuck()
    feed = live.LiveFeed(sink, backlog=3, drop_oldest=True, scans=False)
    feed.scan(int(run.stamps[0]), run.ranges[0], run.geometry)
    _wait_for(feed.queue.empty, "the feed to take the first scan")
    for i in range(1, len(run)):  # the feed is stuck on scan 0: three wait, the oldest give way
        feed.scan(int(run.stamps[i]), run.ranges[i], run.geometry)
    assert feed.queue.qsize() == 3 and feed.dropped == 8
    sink.gate.set()
    feed.close(timeout=60)
    assert feed.failure is None and feed.published == 4
    assert sink.stamps == run.stamps[[0, 9, 10, 11]].tolist()  # the latest kept
    assert sink.messages == []  # scans=False: /scan not echoed


def test_a_new_geometry_or_time_going_back_starts_the_stages_over():
    run = mcapio.read_run(HALL).slice(0, 12)
    g = run.geometry
    g181 = ScanGeometry(
        angle_min=g.angle_min,
        angle_increment=2 * g.angle_increment,
        n_beams=181,
        range_min=g.range_min,
        range_max=g.range_max,
        frame_id=g.frame_id,
    )
    published: list[live.Message] = []

    class Sink:
        def time(self, stamp: int) -> None:
            pass

        def publish(self, m: live.Message) -> None:
            published.append(m)

    why: list[str] = []
    feed = live.LiveFeed(Sink(), batch=32, scans=False, on_restart=why.append)
    s = run.stamps.tolist()
    for i in range(6):
        feed.scan(s[i], run.ranges[i], g)
    feed.scan(s[5], run.ranges[5], g)  # a repeat: skipped
    for i in range(3):
        feed.scan(s[i], run.ranges[i], g)  # back in time (a bag played again)
    for i in range(6, 9):
        feed.scan(s[i], run.ranges[i][::2], g181)  # another geometry: over again
    feed.close(timeout=120)
    assert feed.failure is None and (feed.published, feed.skipped, feed.restarts) == (12, 1, 2)
    assert why[0] == "the scans' time went back by 1.000 s"
    assert why[1] == (
        "the scans' geometry changed (361 beams from -90 deg in 'laser', now 181 from -90 deg in 'laser')"
    )
    tracks = [m for m in published if m.topic == mcapio.TOPIC_TRACKS]
    assert [m.stamp for m in tracks] == s[:6] + s[:3] + s[6:9]
    assert [m.payload for m in tracks[:3]] == [m.payload for m in tracks[6:9]]  # the same scans, fresh stages


def test_pose_buffer_reads_as_odometry():
    poses = live.PoseBuffer(keep=4)
    with pytest.raises(ValueError):
        poses.at(np.array([0]))
    for k in range(10):
        poses.add(1_000_000_000 * k, float(k), 2.0 * k, 0.1, "map", "base")
    poses.add(3_000_000_000, 0.0, 0.0, 0.0)  # stale: not kept
    assert poses.stale == 1 and (poses.frame_id, poses.child_frame_id) == ("map", "base")
    got = poses.at(np.array([7_500_000_000, 20_000_000_000]))
    assert np.allclose(got, [[7.5, 15.0, 0.1], [9.0, 18.0, 0.1]])
    assert len(poses) <= 8


@pytest.mark.parametrize(
    "args, env, line",
    [
        (["--scan-topic", "front scan"], {}, "datmo: error: --scan-topic 'front scan': not a ROS 2 topic name"),
        (["--odom-topic", "/odom/"], {}, "datmo: error: --odom-topic '/odom/': not a ROS 2 topic name"),
        ([], {"ROS_DOMAIN_ID": "x"}, "datmo: error: ROS_DOMAIN_ID 'x': not an integer (0 to 232)"),
        ([], {"ROS_DOMAIN_ID": "300"}, "datmo: error: ROS_DOMAIN_ID 300: a ROS 2 domain id is 0 to 232"),
    ],
)
def test_bad_topics_and_domains_are_one_line(monkeypatch, args, env, line):
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    result = CliRunner().invoke(cli, ["node", "--no-config", *args])
    assert result.exit_code == 1 and result.output.splitlines()[0].startswith(line), result.output
    assert len(result.output.splitlines()) == 1


class _Broken:
    def __init__(self, *args, **kwargs) -> None:
        pass

    def messages(self, run: ScanRun) -> list[live.Message]:
        raise ValueError("a bug in the stages")


def test_a_feed_whose_stages_failed_closes_even_with_its_queue_full(monkeypatch):
    monkeypatch.setattr(live.feed, "Stages", _Broken)
    run = mcapio.read_run(HALL).slice(0, 1)
    feed = live.LiveFeed(object(), backlog=2)
    feed.scan(int(run.stamps[0]), run.ranges[0], run.geometry)
    _wait_for(lambda: feed.failure is not None, "the stages to fail")
    feed.scan(int(run.stamps[0]) + 1, run.ranges[0], run.geometry)  # ignored once failed
    while not feed.queue.full():
        feed.queue.put_nowait(("filler", None, None))
    feed.close(timeout=0.1)  # returns: nothing takes from the queue
    assert feed.failure == "ValueError: a bug in the stages"


def test_the_node_stops_when_its_stages_fail(monkeypatch):
    import datmo_cli.ros2.node

    logged: list[tuple[int, str]] = []

    class Failing:
        def __init__(self, domain, scan_topic, odom_topic, cfg, say, **graph) -> None:
            self.scan_topic, self.odom_topic, self.topics = scan_topic, odom_topic, {"/datmo/tracks": types.TRACKS}
            self.feed = type("Feed", (), {"failure": None})()
            self.spins = 0
            self.name = "/datmo"

        def log(self, level: int, line: str) -> None:
            logged.append((level, line))

        def spin(self) -> None:
            self.spins += 1
            if self.spins == 3:
                self.feed.failure = "ValueError: a bug"

    monkeypatch.setattr(datmo_cli.ros2.node, "Node", Failing)
    result = CliRunner().invoke(cli, ["node", "--no-config", "--domain-id", "3"])
    assert result.exit_code == 70, result.output
    assert result.output.splitlines()[0] == "datmo node: ROS 2 domain 3: /scan in, /datmo/tracks out"
    assert "the stages stopped: ValueError: a bug" in result.output.splitlines()[-1]
    assert logged[-1] == (40, "datmo node: the stages stopped: ValueError: a bug")  # /rosout: ERROR


def test_scans_and_poses_that_do_not_decode_are_counted_and_said_once(monkeypatch):
    from datmo_cli.logs.scan import encode_scan
    from datmo_cli.ros2.node import Node

    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)
    said: list[str] = []
    node = Node(_free_domain(), "/front/scan", "odom", say=said.append)
    assert (node.scan_topic, node.odom_topic) == ("/front/scan", "/odom")
    run = mcapio.read_run(HALL).slice(0, 3)
    good = [encode_scan(int(s), r, run.geometry) for s, r in zip(run.stamps, run.ranges, strict=True)]
    assert node._scan(good[0]) == 0 and node.counts.before_odometry == 1  # no pose yet: skipped
    for bad in (good[1][:40], good[1] + b"\x00" * 8):
        assert node._scan(bad) == 0
    node._pose(b"\x00\x01\x00\x00" + b"\x01" * 10)
    node._pose(_odom_msg(int(run.stamps[0])).serialize())
    assert node._scan(good[2]) == 1
    node.close(timeout=120)
    c = node.counts
    assert (c.scans, c.bad_scans, c.before_odometry, c.poses, c.bad_poses) == (4, 2, 1, 1, 1)
    assert node.feed.published == 1 and node.feed.failure is None
    assert [line.split(" (")[0] for line in said] == [
        "datmo node: no odometry on /odom yet; scans are skipped until it comes",
        "datmo node: a scan on /front/scan does not decode",
        "datmo node: an odometry message on /odom does not decode",
    ]
    assert node.summary() == (
        "4 scans received, 1 processed, 0 dropped (the stages were behind), 2 did not decode, 1 before any odometry"
    )
