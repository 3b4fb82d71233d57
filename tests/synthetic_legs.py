"""Small synthetic leg data for the leg-training tests: scans of legs, a column and a wall ray-cast in numpy,
written as ROS 1 bags or MCAP files with a /leg_cluster_positions PoseArray per scan (as leg_tracker's bags).

Sensor frame: x forward, y left, metres; 361 beams over -90..+90 degrees.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.typesys import Stores, get_typestore

STORE1 = get_typestore(Stores.ROS1_NOETIC)
STORE2 = get_typestore(Stores.ROS2_HUMBLE)
SCAN = "sensor_msgs/msg/LaserScan"
POSES = "geometry_msgs/msg/PoseArray"
ANGLE_MIN, ANGLE_INC, BEAMS = -np.pi / 2, np.pi / 360, 361
LEG_RADIUS = 0.06


def cast(circles: np.ndarray, wall_x: float = 4.5, range_max: float = 8.0) -> np.ndarray:
    """Ranges (BEAMS,) float32 of circles (K x 3: x, y, radius) in front of a wall at x = wall_x; inf where
    nothing is hit within range_max."""
    a = ANGLE_MIN + ANGLE_INC * np.arange(BEAMS)
    u = np.stack([np.cos(a), np.sin(a)], axis=1)
    with np.errstate(divide="ignore"):
        r = np.where(u[:, 0] > 1e-6, wall_x / u[:, 0], np.inf)
    for cx, cy, rad in np.asarray(circles, np.float64).reshape(-1, 3):
        d = u @ np.array([cx, cy])
        h2 = d * d - (cx * cx + cy * cy - rad * rad)
        t = np.where((h2 >= 0) & (d > 0), d - np.sqrt(np.maximum(h2, 0.0)), np.inf)
        r = np.minimum(r, t)
    return np.where(r < range_max, r, np.inf).astype(np.float32)


def scene(n_scans: int, seed: int = 0, people: bool = True) -> tuple[np.ndarray, list[np.ndarray]]:
    """Ranges (n x BEAMS) of a person walking (two legs) past a column, and each scan's leg centres (K x 2)."""
    rng = np.random.default_rng(seed)
    ranges, legs = [], []
    y0 = rng.uniform(-0.5, 0.5)
    for k in range(n_scans):
        x = 1.0 + 2.5 * k / max(n_scans - 1, 1)
        swing = 0.15 * np.sin(k * 0.9)
        lk = np.array([[x + swing, y0 + 0.12], [x - swing, y0 - 0.12]]) if people else np.zeros((0, 2))
        col = [[2.0, -1.6, 0.3], [2.5 + 0.2 * rng.standard_normal(), 1.7, 0.25]]
        circles = np.concatenate([np.c_[lk, np.full(len(lk), LEG_RADIUS)], col]) if people else np.array(col)
        r = cast(circles) + rng.normal(0, 0.005, BEAMS).astype(np.float32)
        ranges.append(r)
        legs.append(lk)
    return np.stack(ranges), legs


def _scan_msg(store, t_ns: int, ranges: np.ndarray):
    T = store.types
    stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
    header = (
        T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="laser")
        if store is STORE1
        else T["std_msgs/msg/Header"](stamp=stamp, frame_id="laser")
    )
    return T[SCAN](
        header=header,
        angle_min=ANGLE_MIN,
        angle_max=ANGLE_MIN + ANGLE_INC * (BEAMS - 1),
        angle_increment=ANGLE_INC,
        time_increment=0.0,
        scan_time=0.1,
        range_min=0.02,
        range_max=8.0,
        ranges=np.asarray(ranges, np.float32),
        intensities=np.zeros(0, np.float32),
    )


def _poses_msg(store, xy: np.ndarray):
    T = store.types
    header = (
        T["std_msgs/msg/Header"](seq=0, stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="laser")
        if store is STORE1
        else T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id="laser")
    )
    q = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    poses = [
        T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0), orientation=q)
        for x, y in xy
    ]
    return T[POSES](header=header, poses=poses)


def _messages(ranges: np.ndarray, legs: list[np.ndarray] | None, scan_topic: str, labels_topic: str):
    out = []
    for k, r in enumerate(ranges):
        t = 1_000_000_000 + k * 100_000_000
        out.append((scan_topic, SCAN, t, lambda s, t=t, r=r: _scan_msg(s, t, r)))
        if legs is not None:
            out.append((labels_topic, POSES, t + 3_000_000, lambda s, xy=legs[k]: _poses_msg(s, xy)))
    return out


def write_bag(
    path: Path,
    ranges: np.ndarray,
    legs: list[np.ndarray] | None = None,
    *,
    scan_topic: str = "/scan",
    labels_topic: str = "/leg_cluster_positions",
    extra_scan_topics: tuple[str, ...] = (),
) -> Path:
    """A ROS 1 bag of the scans (and labels, 3 ms after each scan, when given); extra scan topics repeat them."""
    from rosbags.rosbag1 import Writer

    msgs = _messages(ranges, legs, scan_topic, labels_topic)
    for extra in extra_scan_topics:
        msgs += _messages(ranges, None, extra, labels_topic)
    msgs.sort(key=lambda m: m[2])
    with Writer(path) as w:
        conns = {}
        for topic, msgtype, t, make in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=STORE1)
            w.write(conns[topic], t, STORE1.serialize_ros1(make(STORE1), msgtype))
    return path


def write_mcap(
    folder: Path,
    ranges: np.ndarray,
    legs: list[np.ndarray] | None = None,
    *,
    scan_topic: str = "/scan",
    labels_topic: str = "/leg_cluster_positions",
) -> Path:
    """A single MCAP file (ROS 2 CDR) of the scans and labels, written by rosbags' ROS 2 writer in `folder`."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conns = {}
        for topic, msgtype, t, make in _messages(ranges, legs, scan_topic, labels_topic):
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=STORE2)
            w.write(conns[topic], t, STORE2.serialize_cdr(make(STORE2), msgtype))
    return next(Path(folder).glob("*.mcap"))
