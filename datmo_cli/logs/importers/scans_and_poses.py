"""Scans and geometry_msgs/PoseArray messages of a ROS 1 bag, a ROS 2 bag folder or an MCAP file, each with
its log time: what training the leg detector reads of a labelled recording (leg_tracker's positive bags: the
legs seen in each scan as a PoseArray in the laser frame, without a header stamp, so matched to scans by log
time) or of an empty one (scans alone). The scans of several topics are read in one pass; each topic's keep
one geometry. Bad input raises InputError (GeometryError when a topic's geometry changes). Times in ns,
positions in metres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...base.errors import DatmoError, GeometryError, InputError
from ..scan import ScanGeometry, ScanRun

POSE_ARRAY_TYPES = ("geometry_msgs/msg/PoseArray", "geometry_msgs/PoseArray")


@dataclass
class ScansAndPoses:
    """What a file holds on the topics read: the file's topics ({topic: (message type, messages)}), the scans of
    each topic read with their log times ({topic: (ScanRun, (N,) int64 ns)}; a stamp of 0 takes the log time)
    and the PoseArray messages ((M,) int64 log times in ns, M arrays of K x 2 positions in metres; None when not
    read)."""

    topics: dict[str, tuple[str, int]]
    runs: dict[str, tuple[ScanRun, np.ndarray]] = field(default_factory=dict)
    poses: tuple[np.ndarray, list[np.ndarray]] | None = None


def _poses_xy(msg) -> np.ndarray:
    return np.array([[p.position.x, p.position.y] for p in msg.poses], np.float64).reshape(-1, 2)


def _run_of(
    label: str, topic: str, stamps: list[int], ranges: list[np.ndarray], geoms: list[ScanGeometry], log_times: list[int]
) -> tuple[ScanRun, np.ndarray]:
    if not ranges:
        raise InputError(f"{label}: {topic} has no messages")
    g0 = geoms[0]
    for i, g in enumerate(geoms):
        if not g.same_beams(g0):
            raise GeometryError(f"{label}: {topic} geometry changes at scan {i}: {g0.describe()} -> {g.describe()}")
    return ScanRun(np.array(stamps, np.int64), np.stack(ranges), g0), np.array(log_times, np.int64)


def _read_bag(path: Path, scan_topics: Callable[[dict], list[str]], pose_topic: str | None) -> ScansAndPoses:
    """Scans and poses of a ROS 1 bag or ROS 2 bag folder (rosbags' AnyReader)."""
    from .rosbag import bag_error, open_bag, scan_geometry, scan_stamp

    label = str(path)
    reader, topics = open_bag(path)
    try:
        out = ScansAndPoses(topics)
        wanted = scan_topics(topics)
        want_poses = pose_topic is not None and topics.get(pose_topic, ("", 0))[0] in POSE_ARRAY_TYPES
        conns = [c for c in reader.connections if c.topic in wanted or (want_poses and c.topic == pose_topic)]
        scans: dict[str, tuple[list, list, list, list]] = {t: ([], [], [], []) for t in wanted}
        pose_t, pose_xy = [], []
        for conn, log_time, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic in scans:
                s = scans[conn.topic]
                s[0].append(scan_stamp(msg, log_time))
                s[1].append(np.asarray(msg.ranges, np.float32))
                s[2].append(scan_geometry(msg))
                s[3].append(log_time)
            else:
                pose_t.append(log_time)
                pose_xy.append(_poses_xy(msg))
    except (InputError, DatmoError):
        raise
    except Exception as exc:  # corrupt chunks, unknown message definitions
        raise bag_error(path, exc) from None
    finally:
        reader.close()
    out.runs = {t: _run_of(label, t, *s) for t, s in scans.items()}
    if want_poses:
        out.poses = (np.array(pose_t, np.int64), pose_xy)
    return out


def _read_mcap(path: Path, scan_topics: Callable[[dict], list[str]], pose_topic: str | None) -> ScansAndPoses:
    """Scans and poses of a single MCAP file (CDR, ROS 2 types)."""
    from .. import mcapio, types

    head = mcapio.summary(path)
    topics = {c.topic: (c.msgtype, c.count) for c in head.channels.values()}
    out = ScansAndPoses(topics)
    wanted = scan_topics(topics)
    want_poses = pose_topic is not None and topics.get(pose_topic, ("", 0))[0] in POSE_ARRAY_TYPES
    log = mcapio.read_log(path, topics=wanted + ([pose_topic] if want_poses and pose_topic is not None else []))
    for t in wanted:
        run = mcapio.run_from_log(log, t)
        log_times = np.array(log.messages[t][0], np.int64)
        zero = run.stamps == 0
        run.stamps[zero] = log_times[zero]
        out.runs[t] = (run, log_times)
    if want_poses:
        assert pose_topic is not None  # want_poses says so
        store = types.typestore()
        times, payloads = log.messages.get(pose_topic, ([], []))
        try:
            xy = [_poses_xy(store.deserialize_cdr(p, "geometry_msgs/msg/PoseArray")) for p in payloads]
        except Exception as exc:  # a payload the ROS 2 type store cannot decode
            raise InputError(f"{path}: bad geometry_msgs/PoseArray message on {pose_topic}: {exc}") from None
        out.poses = (np.array(times, np.int64), xy)
    return out


def read_scans_and_poses(
    path: str | Path, scan_topics: Callable[[dict], list[str]], pose_topic: str | None
) -> ScansAndPoses:
    """The scans on the topics `scan_topics(topics)` picks ({topic: (message type, messages)} of the file) and,
    when `pose_topic` holds geometry_msgs/PoseArray, its messages, of a ROS 1 bag, a ROS 2 bag folder or an MCAP
    file. InputError for another kind of log, a topic without messages or a file that cannot be read."""
    from . import detect_kind

    path = Path(path)
    kind = detect_kind(path)
    if kind in ("ros1", "ros2"):
        return _read_bag(path, scan_topics, pose_topic)
    if kind == "mcap":
        return _read_mcap(path, scan_topics, pose_topic)
    raise InputError(f"{path}: a {kind} log has no leg labels; give a ROS 1/ROS 2 bag or an MCAP file")
