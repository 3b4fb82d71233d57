"""ROS 1 bags, ROS 2 bag folders (via rosbags' AnyReader) and single MCAP files (via mcapio) into a ScanRun.

Scans come from one sensor_msgs/LaserScan topic (the only one, or `topic`); ranges are kept as the
driver wrote them (metres, sensor frame `header.frame_id`; inf/NaN as REP 117), intensities when every
message has one per beam. Stamps are header stamps (ns); a zero header stamp falls back to the bag's
log (receive) time. Poses come from one nav_msgs/Odometry topic (the only one, or `odom_topic`):
x, y in metres and yaw from the quaternion, in the message's frame.
"""

from __future__ import annotations

import warnings as _warnings
from pathlib import Path

import numpy as np

from ...errors import GeometryError, InputError
from ..scan import GeometryChangeError, Odometry, ScanGeometry, ScanRun

LASERSCAN_TYPES = ("sensor_msgs/msg/LaserScan", "sensor_msgs/LaserScan")
ODOMETRY_TYPES = ("nav_msgs/msg/Odometry", "nav_msgs/Odometry")


def choose_topic(label: str, topics: dict[str, tuple[str, int]], wanted: str | None, types: tuple[str, ...],
                 what: str, option: str, required: bool = True) -> str | None:
    """The topic to read among `topics` ({topic: (msgtype, count)}) of one of `types`.

    `wanted` must be such a topic; otherwise the only one is taken. Several and none chosen raises
    InputError listing them (as does none at all when `required`).
    """
    fit = {t: c for t, (m, c) in topics.items() if m in types}
    listing = ", ".join(f"{t} ({c} messages)" for t, c in sorted(fit.items()))
    if wanted is not None:
        if wanted in fit:
            return wanted
        if wanted in topics:
            raise InputError(f"{label}: {wanted} holds {topics[wanted][0]}, not {what}")
        have = f"its {what} topics: {listing}" if fit else f"it has no {what} topic"
        raise InputError(f"{label}: no topic {wanted}; {have}")
    if not fit:
        if not required:
            return None
        others = ", ".join(f"{t} ({m})" for t, (m, _) in sorted(topics.items())) or "no topics"
        raise InputError(f"{label}: no {what} topic (it has {others})")
    if len(fit) > 1:
        if not required:
            return None
        raise InputError(f"{label}: several {what} topics, choose one with {option}: {listing}")
    return next(iter(fit))


def _yaw(qx, qy, qz, qw):  # noqa: ANN001, ANN202
    return np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))


def _stamp(header, log_time: int) -> int:  # noqa: ANN001
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns else int(log_time)


def scan_geometry(msg) -> ScanGeometry:  # noqa: ANN001 - a deserialised LaserScan
    """The ScanGeometry of a deserialised sensor_msgs/LaserScan."""
    return ScanGeometry(angle_min=float(msg.angle_min), angle_increment=float(msg.angle_increment),
                        n_beams=len(msg.ranges), range_min=float(msg.range_min), range_max=float(msg.range_max),
                        time_increment=float(msg.time_increment), scan_time=float(msg.scan_time),
                        frame_id=msg.header.frame_id)


def scan_stamp(msg, log_time: int) -> int:  # noqa: ANN001 - a deserialised message with a header
    """The header stamp of a message (ns), or its log time when the stamp is zero."""
    return _stamp(msg.header, log_time)


def open_bag(path: str | Path):  # noqa: ANN201 - (rosbags AnyReader, {topic: (msgtype, count)})
    """An opened rosbags AnyReader on a ROS 1 bag or ROS 2 bag folder, and its topics with their types and
    message counts; InputError naming the file when it cannot be read. The caller closes the reader."""
    from rosbags.highlevel import AnyReader

    try:
        reader = AnyReader([Path(path)])
        reader.open()
    except Exception as exc:  # rosbags raises several unrelated types for corrupt bags
        raise InputError(f"{path}: cannot read bag ({type(exc).__name__}: {exc})") from None
    topics: dict[str, tuple[str, int]] = {}
    for c in reader.connections:
        m, n = topics.get(c.topic, (c.msgtype, 0))
        topics[c.topic] = (m, n + c.msgcount)
    return reader, topics


def read_bag(path: str | Path, *, topic: str | None = None, odom_topic: str | None = None,
             max_scans: int | None = None, progress=None):  # noqa: ANN001, ANN201
    """ImportResult of a ROS 1 bag or ROS 2 bag folder."""
    from . import ImportResult

    path = Path(path)
    label = str(path)
    reader, topics = open_bag(path)
    try:
        scan_topic = choose_topic(label, topics, topic, LASERSCAN_TYPES, "sensor_msgs/LaserScan", "--topic")
        o_topic = choose_topic(label, topics, odom_topic, ODOMETRY_TYPES, "nav_msgs/Odometry", "--odom-topic",
                               required=False)
        run = _scans(reader, label, scan_topic, topics[scan_topic][1], max_scans, progress)
        odom = _odometry(reader, o_topic, run) if o_topic else None
    except (InputError, GeometryError):
        raise
    except Exception as exc:  # corrupt chunks, unknown message definitions
        raise InputError(f"{label}: cannot read bag ({type(exc).__name__}: {exc})") from None
    finally:
        reader.close()
    warns = []
    if odom_topic is None and o_topic is None and sum(m in ODOMETRY_TYPES for m, _ in topics.values()) > 1:
        warns.append(f"{label}: several nav_msgs/Odometry topics; none written (choose one with --odom-topic)")
    return ImportResult(run=run, odometry=odom, warnings=warns, topic=scan_topic, odom_topic=o_topic,
                        facts={"topics": {t: m for t, (m, _) in topics.items()}})


def _scans(reader, label: str, topic: str, total: int, max_scans: int | None, progress) -> ScanRun:  # noqa: ANN001
    conns = [c for c in reader.connections if c.topic == topic]
    stamps, ranges, intens = [], [], []
    g0 = None
    for i, (conn, log_time, raw) in enumerate(reader.messages(connections=conns)):
        if max_scans is not None and i >= max_scans:
            break
        msg = reader.deserialize(raw, conn.msgtype)
        r = np.asarray(msg.ranges, np.float32)
        g = scan_geometry(msg)
        if g0 is None:
            g0 = g
        elif not g.same_beams(g0):
            raise GeometryError(f"{label}: {topic} geometry changes at scan {i}: {g0.describe()} -> "
                                f"{g.describe()}; datmo does not split runs, cut the bag there first")
        stamps.append(_stamp(msg.header, log_time))
        ranges.append(r)
        intens.append(np.asarray(msg.intensities, np.float32))
        if progress is not None and i % 500 == 0:
            progress(i, total)
    if g0 is None:
        raise InputError(f"{label}: {topic} has no messages")
    return ScanRun(np.array(stamps, np.int64), np.stack(ranges), g0, _intensities(intens, g0.n_beams))


def _intensities(intens: list[np.ndarray], n: int) -> np.ndarray | None:
    sizes = {len(it) for it in intens}
    if sizes == {n}:
        return np.stack(intens)
    if sizes <= {0} or 0 not in sizes and n not in sizes:
        return None
    out = np.full((len(intens), n), np.nan, np.float32)  # some scans carry intensities: NaN where missing
    for i, it in enumerate(intens):
        if len(it) == n:
            out[i] = it
    return out


def _odometry(reader, topic: str, run: ScanRun) -> Odometry | None:  # noqa: ANN001
    conns = [c for c in reader.connections if c.topic == topic]
    rows, frame, child = [], "odom", "base_link"
    last = int(run.stamps.max()) if len(run) else 0
    for conn, log_time, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        t = _stamp(msg.header, log_time)
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        rows.append((t, p.x, p.y, _yaw(q.x, q.y, q.z, q.w)))
        frame, child = msg.header.frame_id or frame, msg.child_frame_id or child
        if t > last:
            break
    if not rows:
        return None
    a = np.array(rows, np.float64)
    order = np.argsort(a[:, 0], kind="stable")
    a = a[order]
    return Odometry(a[:, 0].astype(np.int64), a[:, 1], a[:, 2], a[:, 3], frame_id=frame, child_frame_id=child)


def read_mcap(path: str | Path, *, topic: str | None = None, odom_topic: str | None = None,
              max_scans: int | None = None):  # noqa: ANN201
    """ImportResult of a single MCAP file holding CDR sensor_msgs/msg/LaserScan (ROS 2 style)."""
    from .. import mcapio
    from . import ImportResult

    path = Path(path)
    label = str(path)
    warns: list[str] = []
    with _warnings.catch_warnings(record=True) as caught:
        _warnings.simplefilter("always")
        head = mcapio.summary(path)
        topics = {c.topic: (c.msgtype, c.count) for c in head.channels.values()}
        scan_topic = choose_topic(label, topics, topic, LASERSCAN_TYPES, "sensor_msgs/LaserScan", "--topic")
        o_topic = choose_topic(label, topics, odom_topic, ODOMETRY_TYPES, "nav_msgs/Odometry", "--odom-topic",
                               required=False)
        log = mcapio.read_log(path, topics=[scan_topic] + ([o_topic] if o_topic else []))
    warns += [f"{w.message}" for w in caught]
    log_times, _ = log.messages[scan_topic]
    try:
        run = mcapio.run_from_log(log, scan_topic)
    except GeometryChangeError as exc:
        raise GeometryError(f"{label}: {exc}") from None
    zero = run.stamps == 0
    if zero.any():
        run.stamps[zero] = np.asarray(log_times, np.int64)[zero]
    if max_scans is not None:
        run = run.slice(0, max_scans)
    odom = None
    if o_topic:
        try:
            odom = mcapio.odometry_from_log(log, o_topic)
        except Exception as exc:  # a message the ROS 2 type store cannot decode
            raise InputError(f"{label}: bad nav_msgs/Odometry message on {o_topic}: {exc}") from None
        if odom is not None and max_scans is not None and len(run):
            keep = odom.stamps <= run.stamps.max()
            keep[0] = True
            odom = Odometry(odom.stamps[keep], odom.x[keep], odom.y[keep], odom.theta[keep], odom.frame_id,
                            odom.child_frame_id)
    return ImportResult(run=run, odometry=odom, warnings=warns, topic=scan_topic, odom_topic=o_topic,
                        facts={"topics": {t: m for t, (m, _) in topics.items()}})
