"""ROS 1 bags, ROS 2 bags and bare MCAP files written with rosbags' writers: topics, stamps, odometry."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from datmo_cli.base.errors import GeometryError, InputError
from datmo_cli.logs.importers import detect_kind, import_log

pytestmark = pytest.mark.unit

STORE2 = get_typestore(Stores.ROS2_HUMBLE)
STORE1 = get_typestore(Stores.ROS1_NOETIC)
SCAN = "sensor_msgs/msg/LaserScan"
ODOM = "nav_msgs/msg/Odometry"


def _scan(store, t_ns: int, n: int, frame: str, value: float, intensities: bool = False, angle_min: float = -1.0):
    T = store.types
    stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
    header = (
        T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        if store is STORE1
        else T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)
    )
    return T[SCAN](
        header=header,
        angle_min=angle_min,
        angle_max=angle_min + 0.01 * (n - 1),
        angle_increment=0.01,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.05,
        range_max=10.0,
        ranges=np.full(n, value, np.float32),
        intensities=np.arange(n, dtype=np.float32) if intensities else np.zeros(0, np.float32),
    )


def _odom(store, t_ns: int, x: float, yaw: float):
    T = store.types
    stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
    header = (
        T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="odom")
        if store is STORE1
        else T["std_msgs/msg/Header"](stamp=stamp, frame_id="odom")
    )
    pose = T["geometry_msgs/msg/Pose"](
        position=T["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0),
        orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2)),
    )
    cov = np.zeros(36)
    zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    return T[ODOM](
        header=header,
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov
        ),
    )


def messages(n_scans: int = 5, zero_stamp_at: int | None = None, change_at: int | None = None):
    """(topic, msgtype, log_time_ns, make(store)) for two scan topics and one odometry topic."""
    out = []
    for i in range(n_scans):
        t = 1_000_000_000 + i * 100_000_000
        stamp = 0 if i == zero_stamp_at else t - 5_000_000
        a0 = -0.5 if i == change_at else -1.0
        out.append(("/front", SCAN, t, lambda s, st=stamp, i=i, a0=a0: _scan(s, st, 8, "front", 1.0 + i, True, a0)))
        out.append(("/rear", SCAN, t + 1, lambda s, t=t: _scan(s, t, 4, "rear", 2.0)))
        out.append(("/odom", ODOM, t, lambda s, t=t, i=i: _odom(s, t, 0.5 * i, 0.1 * i)))
    return out


def write_ros2(path, msgs, storage: str = "mcap", topics=None):
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {}
        for topic, msgtype, t, make in msgs:
            if topics is not None and topic not in topics:
                continue
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=STORE2)
            w.write(conns[topic], t, STORE2.serialize_cdr(make(STORE2), msgtype))
    return path


def write_ros1(path, msgs, topics=None):
    from rosbags.rosbag1 import Writer

    with Writer(path) as w:
        conns = {}
        for topic, msgtype, t, make in msgs:
            if topics is not None and topic not in topics:
                continue
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=STORE1)
            w.write(conns[topic], t, STORE1.serialize_ros1(make(STORE1), msgtype))
    return path


@pytest.fixture(params=["ros1", "ros2-mcap", "ros2-sqlite3", "mcap-file"])
def bag(request, tmp_path):
    """A bag of each kind with /front (8 beams, intensities), /rear (4 beams) and /odom."""
    kind = request.param
    msgs = messages(zero_stamp_at=2)
    if kind == "ros1":
        return kind, write_ros1(tmp_path / "b.bag", msgs)
    if kind == "ros2-sqlite3":
        return kind, write_ros2(tmp_path / "b2", msgs, "sqlite3")
    folder = write_ros2(tmp_path / "b2", msgs)
    if kind == "mcap-file":
        return kind, next(folder.glob("*.mcap"))
    return kind, folder


def test_several_scan_topics_are_listed(bag):
    _, path = bag
    with pytest.raises(InputError) as err:
        import_log(path)
    assert str(err.value) == (
        f"{path}: several sensor_msgs/LaserScan topics, choose one with --topic: "
        "/front (5 messages), /rear (5 messages)"
    )


def test_topic_picks_one_and_keeps_stamps_frames_intensities_odometry(bag):
    kind, path = bag
    assert detect_kind(path) == {"ros1": "ros1", "mcap-file": "mcap"}.get(kind, "ros2")
    res = import_log(path, "/front")
    run = res.run
    assert res.topic == "/front" and res.odom_topic == "/odom"
    assert run.ranges.shape == (5, 8) and run.ranges[:, 0].tolist() == [1, 2, 3, 4, 5]
    expected = [1_000_000_000 + i * 100_000_000 - 5_000_000 for i in range(5)]
    expected[2] = 1_200_000_000  # zero header stamp: the bag's log time
    assert run.stamps.tolist() == expected
    g = run.geometry
    assert g.frame_id == "front" and g.n_beams == 8 and g.angle_min == pytest.approx(-1.0)
    assert g.angle_increment == pytest.approx(0.01) and g.range_max == 10.0 and g.scan_time == pytest.approx(0.1)
    assert run.intensities.tolist() == [list(range(8))] * 5
    odom = res.odometry
    assert odom.x.tolist() == [0, 0.5, 1.0, 1.5, 2.0] and odom.theta[3] == pytest.approx(0.3)
    rear = import_log(path, "/rear").run
    assert rear.ranges.shape == (5, 4)
    assert rear.intensities.shape[1] == 0 and rear.geometry.frame_id == "rear"


def test_max_scans_cuts_scans_and_odometry(bag):
    _, path = bag
    res = import_log(path, "/front", max_scans=2)
    assert len(res.run) == 2
    assert res.odometry.stamps.max() <= 1_100_000_000 + 100_000_000


def test_unknown_topic_names_the_choices(bag):
    _, path = bag
    with pytest.raises(InputError, match=r"no topic /nope; its sensor_msgs/LaserScan topics: /front \(5 messages\)"):
        import_log(path, "/nope")
    with pytest.raises(InputError, match="/odom holds nav_msgs/.*Odometry, not sensor_msgs/LaserScan"):
        import_log(path, "/odom")


def test_bag_without_laserscan_is_refused(tmp_path):
    path = write_ros1(tmp_path / "o.bag", messages(), topics={"/odom"})
    with pytest.raises(InputError, match=r"o.bag: no sensor_msgs/LaserScan topic \(it has /odom "):
        import_log(path)
    folder = write_ros2(tmp_path / "o2", messages(), topics={"/odom"})
    with pytest.raises(InputError, match="no sensor_msgs/LaserScan topic"):
        import_log(next(folder.glob("*.mcap")))


def test_geometry_change_in_a_bag_names_the_scan(tmp_path):
    path = write_ros1(tmp_path / "g.bag", messages(change_at=3), topics={"/front"})
    with pytest.raises(GeometryError, match="/front geometry changes at scan 3"):
        import_log(path)


def test_corrupt_bag_is_an_input_error(tmp_path):
    path = write_ros1(tmp_path / "c.bag", messages(), topics={"/front"})
    data = path.read_bytes()
    path.write_bytes(data[:200])
    with pytest.raises(InputError, match="c.bag: "):
        import_log(path)
