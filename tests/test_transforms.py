"""/tf and /tf_static: checked with an independent reader (mcap's reader and mcap_ros2's
decoder, not datmo's code) and a tiny tf buffer: the chain from every marker's frame (and the landmarks') to the
scan's frame resolves at every marker stamp, on a moving robot (the patrol sample log through datmo run), a CARMEN
import with odometry, a still scanner, and a ROS 1 bag import that holds /tf and /tf_static."""

from __future__ import annotations

import bisect
import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import SAMPLE_LOGS, shared_path
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from datmo_cli.cli import cli
from datmo_cli.logs import transforms
from datmo_cli.logs.scan import Odometry

pytestmark = pytest.mark.cli

MARKER_TOPICS = ("/datmo/markers/tracks", "/datmo/markers/features", "/datmo/landmarks")  # runs with --markers
DELETEALL = 3
TOLERANCE_NS = 50_000_000  # a dynamic transform is taken up to 50 ms beyond the first or last one


def datmo(*args: str) -> str:
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.output


# ------------------------------------------------------------------------------------- an independent tf buffer


def _yaw(q) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def _compose(a, b):
    c, s = math.cos(a[2]), math.sin(a[2])
    return a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]


def _inverse(a):
    c, s = math.cos(a[2]), math.sin(a[2])
    return -(c * a[0] + s * a[1]), -(-s * a[0] + c * a[1]), -a[2]


class TfBuffer:
    """Static transforms hold at all times; a dynamic one is interpolated between the two around a stamp (or
    the nearest within TOLERANCE_NS before the first or after the last)."""

    def __init__(self) -> None:
        self.static: dict[str, tuple[str, tuple]] = {}
        self.dynamic: dict[str, list[tuple[int, str, tuple]]] = defaultdict(list)

    def add(self, msg, static: bool) -> None:
        for t in msg.transforms:
            tr, stamp = t.transform, t.header.stamp.sec * 1_000_000_000 + t.header.stamp.nanosec
            pose = (tr.translation.x, tr.translation.y, _yaw(tr.rotation))
            if static:
                self.static[t.child_frame_id] = (t.header.frame_id, pose)
            else:
                bisect.insort(self.dynamic[t.child_frame_id], (stamp, t.header.frame_id, pose))

    def edge(self, child: str, stamp: int) -> tuple[str, tuple] | None:
        if child in self.static:
            return self.static[child]
        seq = self.dynamic.get(child)
        if not seq:
            return None
        i = bisect.bisect_left(seq, (stamp,))
        if i < len(seq) and seq[i][0] == stamp:
            return seq[i][1], seq[i][2]
        if i == 0 or i == len(seq):
            near = seq[0] if i == 0 else seq[-1]
            return (near[1], near[2]) if abs(near[0] - stamp) <= TOLERANCE_NS else None
        (t0, parent, a), (t1, _, b) = seq[i - 1], seq[i]
        w = (stamp - t0) / (t1 - t0)
        dyaw = math.atan2(math.sin(b[2] - a[2]), math.cos(b[2] - a[2]))
        return parent, (a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * dyaw)

    def to_root(self, frame: str, stamp: int) -> tuple[str, tuple]:
        pose, seen = (0.0, 0.0, 0.0), set()
        while (e := self.edge(frame, stamp)) is not None and frame not in seen:
            seen.add(frame)
            frame, pose = e[0], _compose(e[1], pose)
        return frame, pose

    def lookup(self, target: str, source: str, stamp: int) -> tuple | None:
        """The pose of frame `source` in frame `target` at `stamp`, or None when no chain joins them."""
        root_t, t = self.to_root(target, stamp)
        root_s, s = self.to_root(source, stamp)
        return _compose(_inverse(t), s) if root_t == root_s else None


def read_output(path: Path):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    tf, scan_frames, frames, counts = TfBuffer(), set(), [], defaultdict(int)
    with open(path, "rb") as f:
        for _, channel, _message, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            counts[channel.topic] += 1
            if channel.topic in ("/tf", "/tf_static"):
                tf.add(msg, static=channel.topic == "/tf_static")
            elif channel.topic == "/scan":
                scan_frames.add(msg.header.frame_id)
            elif channel.topic in MARKER_TOPICS:
                heads = (
                    [m.header for m in msg.markers if m.action != DELETEALL]
                    if hasattr(msg, "markers")
                    else [msg.header]
                )
                frames += [(channel.topic, h.frame_id, h.stamp.sec * 1_000_000_000 + h.stamp.nanosec) for h in heads]
    return tf, scan_frames, frames, counts


def assert_chains_resolve(path: Path) -> tuple[TfBuffer, str, set[str]]:
    """Every marker's frame resolves to the scan's frame at its stamp; returns (buffer, scan frame, marker frames)."""
    tf, scan_frames, frames, counts = read_output(path)
    assert len(scan_frames) == 1 and frames, (scan_frames, counts)
    laser = scan_frames.pop()
    for topic, frame, stamp in frames:
        assert tf.lookup(laser, frame, stamp) is not None, f"{path.name}: {topic} in {frame!r} at {stamp}"
    return tf, laser, {f for _, f, _ in frames}


# ------------------------------------------------------------------------------------------------ payloads


def test_tf_payloads_are_the_bytes_of_rosbags_serialiser_and_decode_back():
    store = get_typestore(Stores.ROS2_HUMBLE)
    T = store.types
    assert transforms.SCHEMA == store.generate_msgdef(transforms.TF_MESSAGE, ros_version=2)[0]
    for transforms_ in (
        [],
        [transforms.Transform.planar(1_700_000_000_123_456_789, "odom", "base_link", 1.5, -2.25, 0.7)],
        [
            transforms.Transform(5, "a", "bb", 1, 2, 3, 0.5, 0.5, 0.5, 0.5),
            transforms.Transform.planar(10**9, "base_link", "laser_front", 0.2, 0.0, math.pi),
        ],
    ):
        msg = T[transforms.TF_MESSAGE](
            transforms=[
                T["geometry_msgs/msg/TransformStamped"](
                    header=T["std_msgs/msg/Header"](
                        stamp=T["builtin_interfaces/msg/Time"](sec=t.stamp_ns // 10**9, nanosec=t.stamp_ns % 10**9),
                        frame_id=t.parent,
                    ),
                    child_frame_id=t.child,
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=T["geometry_msgs/msg/Vector3"](x=t.x, y=t.y, z=t.z),
                        rotation=T["geometry_msgs/msg/Quaternion"](x=t.qx, y=t.qy, z=t.qz, w=t.qw),
                    ),
                )
                for t in transforms_
            ]
        )
        payload = transforms.encode_tf(transforms_)
        assert payload == bytes(store.serialize_cdr(msg, transforms.TF_MESSAGE))
        assert transforms.decode_tf(payload) == transforms_
    with pytest.raises(ValueError):
        transforms.decode_tf(payload[:-9])


def test_odometry_poses_decode_as_rosbags_reads_them():
    from datmo_cli.logs import mcapio

    odom = Odometry(
        np.array([10, 2_000_000_001]),
        np.array([1.0, -2.5]),
        np.array([3.0, 4.0]),
        np.array([0.3, -2.0]),
        "odom",
        "base_footprint",
    )
    back = transforms.decode_odometry(mcapio.encode_odometry(odom))
    assert back.stamps.tolist() == odom.stamps.tolist() and back.child_frame_id == "base_footprint"
    assert np.allclose([back.x, back.y, back.theta], [odom.x, odom.y, odom.theta], atol=1e-12)


def test_a_laser_pose_moves_the_base_and_the_chain_gives_the_scanner_back():
    sensor = Odometry(
        np.arange(3), np.array([1.0, 2.0, -3.0]), np.array([0.5, 0.0, 7.0]), np.array([0.0, 1.0, -3.0]), "odom", "laser"
    )
    mount = transforms.LaserPose(0.3, -0.1, math.radians(90))
    base = transforms.base_odometry(sensor, mount)
    assert base.child_frame_id == "base_link" and not np.allclose(base.x, sensor.x)
    statics = [transforms.Transform.planar(0, "base_link", "laser", mount.x, mount.y, mount.yaw)]
    back = transforms.sensor_odometry(base, statics, "laser")
    assert back.child_frame_id == "laser"
    assert np.allclose([back.x, back.y], [sensor.x, sensor.y], atol=1e-12)
    assert np.allclose(np.cos(back.theta - sensor.theta), 1.0)
    identity = [transforms.Transform.planar(0, "base_link", "laser", 0, 0, 0)]
    assert transforms.sensor_odometry(base, identity, "laser") is base  # bit for bit: no arithmetic
    assert transforms.sensor_odometry(base, [], "laser") is base


# ------------------------------------------------------------------------------------------- whole outputs


def test_patrol_run_chains_resolve_and_match_the_ground_truth(tmp_path):
    from datmo_cli.logs import cdr, mcapio, types

    datmo("run", SAMPLE_LOGS / "patrol.mcap", "-o", tmp_path / "out", "--markers")
    out = tmp_path / "out" / "patrol.mcap"
    tf, laser, frames = assert_chains_resolve(out)
    assert frames == {"odom", "laser"}  # tracks and landmarks in odom, the features' markers in the scan's frame
    stamps, payloads = mcapio.read_messages(out, mcapio.TOPIC_GROUND_TRUTH)
    for stamp, payload in list(zip(stamps.tolist(), payloads, strict=True))[::37]:
        truth = cdr.decode(types.GROUND_TRUTH, payload)
        pose = tf.lookup("odom", laser, stamp)  # the world frame of the scene is odom
        assert pose[:2] == pytest.approx((truth["sensor_x"], truth["sensor_y"]), abs=1e-9)
        assert math.cos(pose[2] - truth["sensor_theta"]) == pytest.approx(1.0)


def test_carmen_import_with_odometry_then_run(tmp_path):
    src = shared_path("carmen", "csail-corrected.log.gz")
    out = datmo("import", src, "--max-scans", "120", "-o", tmp_path / "csail.mcap")
    tf, _, _, counts = read_output(tmp_path / "csail.mcap")
    # CARMEN's poses are the laser's, and no mount is known: the base is put on the laser, said in a warning
    assert counts["/tf"] == counts["/odom"] == 120 and counts["/tf_static"] == 1
    assert tf.static["laser"] == ("base_link", (0.0, 0.0, 0.0))
    assert "no laser mount (base_link -> laser)" in out and "--laser-pose X,Y,YAW" in out
    datmo("run", tmp_path / "csail.mcap", "-o", tmp_path / "out", "--markers")
    _, laser, frames = assert_chains_resolve(tmp_path / "out" / "csail.mcap")
    assert "map" in frames and laser == "laser"  # SLAM-corrected poses: map -> base_link -> laser

    datmo("import", src, "--max-scans", "120", "-o", tmp_path / "mounted.mcap", "--laser-pose", "0.25,0,0")
    tf, laser, _, counts = read_output(tmp_path / "mounted.mcap")
    assert counts["/tf_static"] == 1 and tf.static["laser"][0] == "base_link"
    assert tf.static["laser"][1] == pytest.approx((0.25, 0.0, 0.0))


def test_still_scanner_markers_are_in_the_scan_frame(tmp_path):
    datmo("run", SAMPLE_LOGS / "static.mcap", "-o", tmp_path / "out", "--markers")
    _, laser, frames = assert_chains_resolve(tmp_path / "out" / "static.mcap")
    assert frames == {laser}
    _, _, _, counts = read_output(tmp_path / "out" / "static.mcap")
    assert "/tf" not in counts and "/tf_static" not in counts  # nothing to join: no transform written

    datmo(
        "simulate",
        "--scene",
        "static",
        "--duration",
        "4",
        "-o",
        tmp_path / "mounted.mcap",
        "--laser-pose=-0.1,0.05,180",
    )
    tf, _, _, counts = read_output(tmp_path / "mounted.mcap")
    assert counts["/tf_static"] == 1 and "/tf" not in counts
    assert tf.static["laser"] == ("base_link", pytest.approx((-0.1, 0.05, math.pi)))


def test_a_laser_pose_on_a_moving_simulation_leaves_the_tracks_where_they_were(tmp_path):
    from datmo_cli.logs import cdr, mcapio, types

    for name, extra in (("plain", []), ("mounted", ["--laser-pose", "0.3,0.1,90"])):
        datmo("simulate", "--scene", "patrol", "--duration", "16", "-o", tmp_path / f"{name}.mcap", *extra)
    datmo("run", tmp_path / "plain.mcap", tmp_path / "mounted.mcap", "-o", tmp_path / "out", "--markers")
    tf, laser, _ = assert_chains_resolve(tmp_path / "out" / "mounted.mcap")
    assert tf.static[laser][0] == "base_link" and tf.static[laser][1] == pytest.approx((0.3, 0.1, math.pi / 2))
    plain = mcapio.read_odometry(tmp_path / "plain.mcap")
    mounted = mcapio.read_odometry(tmp_path / "mounted.mcap")
    assert not np.allclose(plain.x, mounted.x)  # /odom holds the base, not the scanner
    for a, b in zip(
        mcapio.read_messages(tmp_path / "out" / "plain.mcap", mcapio.TOPIC_TRACKS)[1],
        mcapio.read_messages(tmp_path / "out" / "mounted.mcap", mcapio.TOPIC_TRACKS)[1],
        strict=True,
    ):
        ta, tb = cdr.decode(types.TRACKS, a)["tracks"], cdr.decode(types.TRACKS, b)["tracks"]
        assert len(ta) == len(tb)
        assert np.allclose(ta["world_x"], tb["world_x"], atol=1e-4) and np.allclose(
            ta["world_y"], tb["world_y"], atol=1e-4
        )


# ------------------------------------------------------------------------------------------ a ROS 1 bag with tf

ROS1_TF = "tf2_msgs/msg/TFMessage"
MOUNT = (0.2, 0.05, 0.1)  # base_link -> laser, m, m, rad


def _ros1_bag(
    path: Path, n: int = 60, with_tf: bool = True, mount_on: str = "/tf_static", slash: str = "", wobble: float = 0.0
) -> Path:
    """A ROS 1 bag: /scan (a room, 10 Hz) from a robot turning on the spot, /odom and, `with_tf`, /tf (odom ->
    base_link at 20 Hz, stamped between the scans) and the mount base_link -> laser on `mount_on`: once on
    /tf_static, or with every odom -> base_link on /tf (its x `wobble` m more each time). Frame names start with
    `slash` ("/" as ROS 1 tools wrote them)."""
    from rosbags.rosbag1 import Writer

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", ROS1_TF))
    T = store.types

    def header(t: int, frame: str):
        return T["std_msgs/msg/Header"](
            seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9), frame_id=frame
        )

    def tfm(t: int, parent: str, child: str, x: float, y: float, yaw: float):
        parent, child = slash + parent, slash + child
        return T[ROS1_TF](
            transforms=[
                T["geometry_msgs/msg/TransformStamped"](
                    header=header(t, parent),
                    child_frame_id=child,
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=T["geometry_msgs/msg/Vector3"](x=x, y=y, z=0.0),
                        rotation=T["geometry_msgs/msg/Quaternion"](
                            x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
                        ),
                    ),
                )
            ]
        )

    angles = np.linspace(-math.pi / 2, math.pi / 2, 181)
    t0 = 1_600_000_000 * 10**9
    with Writer(path) as w:
        scan = w.add_connection("/scan", "sensor_msgs/msg/LaserScan", typestore=store)
        odom = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
        tf = w.add_connection("/tf", ROS1_TF, typestore=store)
        static = w.add_connection("/tf_static", ROS1_TF, typestore=store)
        if with_tf and mount_on == "/tf_static":
            w.write(static, t0, store.serialize_ros1(tfm(t0, "base_link", "laser", *MOUNT), ROS1_TF))
        for k in range(2 * n):
            t = t0 + k * 50_000_000
            yaw = 0.01 * k
            if with_tf:
                w.write(tf, t, store.serialize_ros1(tfm(t, "odom", "base_link", 0.0, 0.0, yaw), ROS1_TF))
            if with_tf and mount_on == "/tf":
                x, y, mount_yaw = MOUNT
                mount = tfm(t, "base_link", "laser", x + wobble * k, y, mount_yaw)
                w.write(tf, t, store.serialize_ros1(mount, ROS1_TF))
            if k % 2:
                continue
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)),
            )
            zero, cov = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0), np.zeros(36)
            msg = T["nav_msgs/msg/Odometry"](
                header=header(t, slash + "odom"),
                child_frame_id=slash + "base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov
                ),
            )
            w.write(odom, t, store.serialize_ros1(msg, "nav_msgs/msg/Odometry"))
            ts = t + 20_000_000  # scans between the transforms: the buffer interpolates
            ranges = (3.0 / np.maximum(np.abs(np.cos(angles + yaw + MOUNT[2])), 0.4)).astype(np.float32)
            w.write(
                scan,
                ts,
                store.serialize_ros1(
                    T["sensor_msgs/msg/LaserScan"](
                        header=header(ts, slash + "laser"),
                        angle_min=-math.pi / 2,
                        angle_max=math.pi / 2,
                        angle_increment=math.pi / 180,
                        time_increment=0.0,
                        scan_time=0.1,
                        range_min=0.05,
                        range_max=10.0,
                        ranges=ranges,
                        intensities=np.zeros(0, np.float32),
                    ),
                    "sensor_msgs/msg/LaserScan",
                ),
            )
    return path


def test_ros1_bag_import_keeps_tf_and_the_run_resolves_through_it(tmp_path):
    bag = _ros1_bag(tmp_path / "robot.bag")
    datmo("import", bag, "-o", tmp_path / "robot.mcap")
    tf, _, _, counts = read_output(tmp_path / "robot.mcap")
    assert counts["/tf"] == 120 and counts["/tf_static"] == 1 and counts["/odom"] == 60  # the bag's, none derived
    assert tf.static["laser"] == ("base_link", pytest.approx(MOUNT))
    datmo("run", tmp_path / "robot.mcap", "-o", tmp_path / "out", "--markers")
    out = tmp_path / "out" / "robot.mcap"
    tf, laser, frames = assert_chains_resolve(out)
    assert "odom" in frames and laser == "laser"
    _, _, _, counts = read_output(out)
    assert counts["/tf"] == 120 and counts["/tf_static"] == 1  # copied, not derived again
    t = 1_600_000_000 * 10**9 + 20 * 50_000_000 + 20_000_000
    expected = _compose((0.0, 0.0, 0.01 * 20.4), MOUNT)  # the odometry's yaw interpolated at the scan
    assert tf.lookup("odom", laser, t) == pytest.approx(expected, abs=1e-9)


def test_ros1_bag_without_tf_gets_tf_from_its_odometry(tmp_path):
    _ros1_bag(tmp_path / "odom.bag", n=20, with_tf=False)
    out = datmo("import", tmp_path / "odom.bag", "-o", tmp_path / "odom.mcap")
    tf, _, _, counts = read_output(tmp_path / "odom.mcap")
    assert counts["/tf"] == counts["/odom"] == 20 and counts["/tf_static"] == 1
    assert tf.static["laser"] == ("base_link", (0.0, 0.0, 0.0))  # the identity: no laser pose given
    warning = [line for line in out.splitlines() if "laser mount" in line]  # never silently
    assert warning == [
        f"datmo: warning: {tmp_path / 'odom.bag'}: no laser mount (base_link -> laser) in the log; "
        "wrote the identity: give the scanner's mounting with --laser-pose X,Y,YAW (metres, metres, "
        "degrees)"
    ]
    datmo("run", tmp_path / "odom.mcap", "-o", tmp_path / "out", "--markers")
    assert_chains_resolve(tmp_path / "out" / "odom.mcap")


def test_a_ros1_mount_only_on_tf_with_slashed_names_is_taken_to_tf_static(tmp_path):
    from datmo_cli.logs import mcapio

    _ros1_bag(tmp_path / "robot.bag", n=20, mount_on="/tf", slash="/")
    out = datmo("import", tmp_path / "robot.bag", "-o", tmp_path / "robot.mcap")
    assert "laser mount" not in out
    tf, scan_frames, _, counts = read_output(tmp_path / "robot.mcap")
    assert scan_frames == {"laser"} and counts["/tf_static"] == 1 and counts["/tf"] == 80  # the bag's /tf kept
    assert tf.static["laser"] == ("base_link", pytest.approx(MOUNT))  # constant on /tf
    assert set(tf.dynamic) == {"base_link", "laser"} and tf.dynamic["base_link"][0][1] == "odom"  # no "/"
    odom = mcapio.read_odometry(tmp_path / "robot.mcap")
    assert (odom.frame_id, odom.child_frame_id) == ("odom", "base_link")
    assert mcapio.summary(tmp_path / "robot.mcap").metadata["datmo.import"]["laser_pose"] == '"/tf (constant there)"'
    datmo("run", tmp_path / "robot.mcap", "-o", tmp_path / "out", "--markers")
    tf, laser, frames = assert_chains_resolve(tmp_path / "out" / "robot.mcap")
    assert "odom" in frames and laser == "laser"
    t = 1_600_000_000 * 10**9 + 20 * 50_000_000 + 20_000_000
    assert tf.lookup("odom", laser, t) == pytest.approx(_compose((0.0, 0.0, 0.01 * 20.4), MOUNT), abs=1e-9)


def test_a_mount_that_moves_on_tf_is_not_taken_for_one(tmp_path):
    _ros1_bag(tmp_path / "robot.bag", n=20, mount_on="/tf", wobble=0.01)
    out = datmo("import", tmp_path / "robot.bag", "-o", tmp_path / "robot.mcap")
    tf, _, _, _ = read_output(tmp_path / "robot.mcap")
    assert tf.static["laser"] == ("base_link", (0.0, 0.0, 0.0)) and "no laser mount (base_link -> laser)" in out


def test_constant_transforms_and_chains():
    T = transforms.Transform.planar
    seen = transforms.ConstantTransforms()
    seen.add([T(1, "odom", "base", 0.0, 0.0, 0.0), T(1, "base", "mast", 0.1, 0.0, 0.0)])
    seen.add([T(2, "odom", "base", 1.0, 0.0, 0.0), T(2, "base", "mast", 0.1, 0.0, 0.0), T(2, "mast", "laser", 0, 0, 1)])
    assert seen.constant() == [T(1, "base", "mast", 0.1, 0.0, 0.0), T(2, "mast", "laser", 0, 0, 1)]
    links = transforms.chain(seen.constant(), "base", "laser")
    assert [(t.parent, t.child) for t in links] == [("mast", "laser"), ("base", "mast")]
    assert transforms.chain(seen.constant(), "odom", "laser") is None and transforms.chain([], "a", "a") == []
    assert transforms.static_chain(links, "base", "laser") == transforms.LaserPose(0.1, 0.0, 1.0)
    assert [transforms.ros2_frame(f) for f in ("/base_link", "laser", "/", "//odom")] == [
        "base_link",
        "laser",
        "/",
        "odom",
    ]
    plain = transforms.encode_tf([T(3, "odom", "base_link", 1, 2, 3)])
    assert transforms.without_slashes(plain) is plain
    assert transforms.without_slashes(transforms.encode_tf([T(3, "/odom", "/base_link", 1, 2, 3)])) == plain


@pytest.mark.slow
def test_an_old_log_with_odometry_but_no_tf_gets_them_in_every_processed_output(tmp_path):
    from datmo_cli.logs import mcapio

    old = tmp_path / "old.mcap"
    log = mcapio.read_log(SAMPLE_LOGS / "patrol.mcap", topics=None)
    with mcapio.LogWriter(old) as w:
        w.copy_from(log, exclude=[mcapio.TOPIC_TF, mcapio.TOPIC_TF_STATIC])
    assert not mcapio.summary(old).has(mcapio.TOPIC_TF)
    datmo("features", old, "-o", tmp_path / "features.mcap")
    datmo("track", tmp_path / "features.mcap", "-o", tmp_path / "tracks.mcap")
    datmo("segment", old, "-o", tmp_path / "segments.mcap")
    for name in ("features", "tracks", "segments"):
        _, _, _, counts = read_output(tmp_path / f"{name}.mcap")
        assert counts["/tf"] == counts["/odom"] == 300 and counts["/tf_static"] == 1, name
    assert_chains_resolve(tmp_path / "tracks.mcap")


@pytest.mark.parametrize(
    "value, problem",
    [
        ("1,2", "expected X,Y,YAW"),
        ("a,0,0", "x is not a number"),
        ("0,nan,0", "y: nan is not a finite number"),
        ("0,0,400", "yaw: must be at most 360"),
        ("0,1e3,0", "at most 100"),
    ],
)
def test_a_bad_laser_pose_is_one_line_naming_the_option(tmp_path, value, problem):
    result = CliRunner().invoke(
        cli, ["simulate", "--scene", "static", "--duration", "1", "-o", tmp_path / "x.mcap", f"--laser-pose={value}"]
    )
    assert result.exit_code == 2 and problem in result.output and "--laser-pose" in result.output
    assert len(result.output.strip().splitlines()) == 1 and "Traceback" not in result.output
    assert not (tmp_path / "x.mcap").exists()
