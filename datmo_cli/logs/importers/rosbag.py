"""ROS 1 bags and ROS 2 bag folders (via rosbags' AnyReader) into a ScanRun (single MCAP files: mcap_file.py).

Scans come from one sensor_msgs/LaserScan topic (the only one, or `topic`); ranges are kept as the
driver wrote them (metres, sensor frame `header.frame_id`; inf/NaN as REP 117), intensities when every
message has one per beam. Stamps are header stamps (ns); a zero header stamp falls back to the bag's
log (receive) time. Poses come from one nav_msgs/Odometry topic (the only one, or `odom_topic`):
x, y in metres and yaw from the quaternion, in the message's frame. Frame names lose ROS 1's leading slash
(`/laser` -> `laser`; transforms.ros2_frame) in scans, poses and transforms alike. A source with poses is first
surveyed for its fixed transforms (`survey_tf`), so the import knows up front where the laser sits on the base.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...base.errors import GeometryError, InputError
from ..scan import Odometry, ScanGeometry, ScanRun
from ..transforms import ros2_frame
from .ros_messages import (
    LASERSCAN_TYPES,
    ODOMETRY_TYPES,
    check_bag_scan,
    choose_topic,
    header_stamp,
    scan_geometry,
    scan_stamp,
    survey_tf,
    tf_payload,
    tf_topics,
    tf_transforms,
    yaw_of,
)

_MEMBER_MAGIC = {".mcap": (b"\x89MCAP0\r\n", b"\x89MCAP0\r\n"), ".db3": (b"SQLite format 3\x00", b"")}


def bag_error(path: str | Path, exc: BaseException) -> InputError:
    """The error for a bag rosbags cannot read: for a ROS 2 bag folder it names the member at fault, the
    first whose start or end is not what its storage writes (MCAP's magic, SQLite's header), else the only
    member; members are looked at only if regular files (a FIFO or device is never opened here)."""
    import os

    path = Path(path)
    what = f"({type(exc).__name__}: {exc})"
    if not path.is_dir():
        return InputError(f"{path}: cannot read bag {what}")
    try:
        members = sorted(p for p in path.iterdir() if p.suffix in _MEMBER_MAGIC and p.is_file())
    except OSError:
        members = []
    for member in members:
        head, tail = _MEMBER_MAGIC[member.suffix]
        try:
            with open(member, "rb") as f:
                start = f.read(len(head))
                f.seek(max(os.fstat(f.fileno()).st_size - len(tail), 0))
                end = f.read(len(tail)) if tail else b""
        except OSError as err:
            return InputError(f"{path}: cannot read bag member {member.name} ({err.strerror or err})")
        if start != head or end != tail:
            kind = "MCAP" if member.suffix == ".mcap" else "SQLite"
            cut = " (cut short?)" if start == head else ""
            return InputError(f"{path}: bag member {member.name} is not a whole {kind} file{cut} {what}")
    if len(members) == 1:
        return InputError(f"{path}: cannot read bag member {members[0].name} {what}")
    return InputError(f"{path}: cannot read bag {what}")


def open_bag(path: str | Path):
    """An opened rosbags AnyReader on a ROS 1 bag or ROS 2 bag folder, and its topics with their types and
    message counts; InputError naming the file when it cannot be read. The caller closes the reader."""
    from rosbags.highlevel import AnyReader

    from .bag_chunks import bound_bag_chunks, check_bag_folder

    bound_bag_chunks()
    if Path(path).is_dir():
        check_bag_folder(Path(path))
    try:
        reader = AnyReader([Path(path)])
        reader.open()
    except Exception as exc:  # rosbags raises several unrelated types for corrupt bags
        raise bag_error(path, exc) from None
    topics: dict[str, tuple[str, int]] = {}
    for c in reader.connections:
        m, n = topics.get(c.topic, (c.msgtype, 0))
        topics[c.topic] = (m, n + c.msgcount)
    return reader, topics


def stream_bag(
    path: str | Path,
    *,
    topic: str | None = None,
    odom_topic: str | None = None,
    max_scans: int | None = None,
    progress=None,
    block_scans: int = 1024,
):
    """ImportStream of a ROS 1 bag or ROS 2 bag folder.

    A first pass over the scans settles what concerns the whole run (their geometry, which must not
    change; whether intensities are kept; the last scan stamp, after which one more pose is read); the
    blocks then come from one pass over scans and poses in the bag's time order. Memory holds a block of
    scans, and rosbags' reader holds the bag's index (about 200 bytes a message, as the bag stores it).
    Each pose keeps its own message's frame ids (the whole-run import gave all poses the last ones; the
    same for a bag whose frames do not change)."""
    from .stream import ImportStream

    path = Path(path)
    label = str(path)
    reader, topics = open_bag(path)
    closed = False

    def close() -> None:
        nonlocal closed
        if not closed:
            closed = True
            reader.close()

    try:
        scan_topic = choose_topic(label, topics, topic, LASERSCAN_TYPES, "sensor_msgs/LaserScan", "--topic")
        o_topic = choose_topic(
            label, topics, odom_topic, ODOMETRY_TYPES, "nav_msgs/Odometry", "--odom-topic", required=False
        )
        one_connection(label, reader, scan_topic)
        if o_topic is not None:
            one_connection(label, reader, o_topic)  # two odometry streams would interleave too
        total = topics[scan_topic][1]
        scans = _survey(reader, label, scan_topic, total, max_scans, progress)
    except (InputError, GeometryError):
        close()
        raise
    except Exception as exc:  # corrupt chunks, unknown message definitions
        close()
        raise bag_error(path, exc) from None
    warns = []
    if odom_topic is None and o_topic is None and sum(m in ODOMETRY_TYPES for m, _ in topics.values()) > 1:
        warns.append(f"{label}: several nav_msgs/Odometry topics; none written (choose one with --odom-topic)")

    tfs = tf_topics(topics)
    moved: list[tuple[str, int, bytes]] = []
    survey = None
    if o_topic is not None and tfs:
        conns = [c for c in reader.connections if c.topic in tfs]
        try:
            survey = survey_tf(
                (c.topic, tf_transforms(reader.deserialize(raw, c.msgtype)))
                for c, _, raw in reader.messages(connections=conns)
            )
        except Exception as exc:  # corrupt chunks, unknown message definitions
            close()
            raise bag_error(path, exc) from None

    def pieces() -> Iterator[tuple[ScanRun | None, Odometry | None]]:
        try:
            yield from _bag_blocks(reader, scan_topic, o_topic, scans, block_scans, progress, total, tfs, moved)
        except (InputError, GeometryError):
            raise
        except Exception as exc:  # corrupt chunks, unknown message definitions
            raise bag_error(path, exc) from None
        finally:
            close()

    return ImportStream(
        pieces(),
        warnings=warns,
        topic=scan_topic,
        odom_topic=o_topic,
        facts={"topics": {t: m for t, (m, _) in topics.items()}},
        geometry=scans.geometry,
        sort_odometry=True,
        closer=close,
        transforms=moved,
        tf_topics=tfs,
        tf_survey=survey,
    )


def one_connection(label: str, reader, topic: str) -> None:
    """InputError when two of the bag's connections (two publishers, as ROS 1 records them) hold messages on
    `topic` (the scan or the odometry topic): two streams, which a read by topic would interleave."""
    on = [c for c in reader.connections if c.topic == topic and c.msgcount]
    if len(on) > 1:
        who = ", ".join(f"{getattr(c.ext, 'callerid', None) or c.msgtype}: {c.msgcount} messages" for c in on)
        raise InputError(
            f"{label}: {topic} is on {len(on)} connections ({who}); their messages would interleave "
            "into one stream: keep one connection, or give each its own topic"
        )


@dataclass
class _Survey:
    """What a first pass over a bag's scans found: geometry, count, intensity lengths, last stamp."""

    geometry: ScanGeometry
    count: int
    intensities: str  # "all" (one per beam in every scan), "none", or "fill" (NaN where missing)
    last: int  # the largest scan stamp, ns


def _survey(reader, label: str, topic: str, total: int, max_scans: int | None, progress) -> _Survey:
    conns = [c for c in reader.connections if c.topic == topic]
    g0, sizes, count, last = None, set(), 0, None
    for i, (conn, log_time, raw) in enumerate(reader.messages(connections=conns)):
        if max_scans is not None and i >= max_scans:
            break
        msg = reader.deserialize(raw, conn.msgtype)
        check_bag_scan(label, topic, i, msg)
        g = scan_geometry(msg)
        if g0 is None:
            g0 = g
        elif not g.same_beams(g0):
            raise GeometryError(
                f"{label}: {topic} geometry changes at scan {i}: {g0.describe()} -> "
                f"{g.describe()}; datmo does not split runs, cut the bag there first"
            )
        t = scan_stamp(msg, log_time)
        last = t if last is None else max(last, t)
        sizes.add(len(msg.intensities))
        count += 1
        if progress is not None and i % 500 == 0:
            progress(i, 2 * total)
    if g0 is None:
        raise InputError(f"{label}: {topic} has no messages")
    n = g0.n_beams
    mode = "all" if sizes == {n} else "none" if sizes <= {0} or 0 not in sizes and n not in sizes else "fill"
    assert last is not None  # set with g0
    return _Survey(g0, count, mode, last)


def _bag_blocks(
    reader,
    topic: str,
    o_topic: str | None,
    survey: _Survey,
    size: int,
    progress,
    total: int,
    tfs: tuple[str, ...] = (),
    moved: list | None = None,
) -> Iterator[tuple[ScanRun | None, Odometry | None]]:
    """Scans (and poses up to the first after the last scan) in the bag's order, `size` scans a block; the
    transforms on `tfs` read on the way appended to `moved` as (topic, log time, CDR TFMessage)."""
    conns = [c for c in reader.connections if c.topic in (topic, o_topic, *tfs)]
    g0, n = survey.geometry, survey.geometry.n_beams
    stamps: list[int] = []
    ranges: list[np.ndarray] = []
    intens: list[np.ndarray] = []
    rows: list[tuple] = []
    frames = ("odom", "base_link")
    odo_frames = frames
    scans = 0
    odom_done = o_topic is None

    def scan_block() -> ScanRun:
        inten = np.zeros((len(stamps), 0), np.float32)  # what ScanRun makes of None
        if survey.intensities == "all":
            inten = np.stack(intens)
        elif survey.intensities == "fill":
            inten = np.full((len(intens), n), np.nan, np.float32)
            for i, it in enumerate(intens):
                if len(it) == n:
                    inten[i] = it
        return ScanRun(np.array(stamps, np.int64), np.stack(ranges), g0, inten)

    def poses() -> Odometry | None:
        if not rows:
            return None
        a = np.array(rows, np.float64)
        return Odometry(
            a[:, 0].astype(np.int64), a[:, 1], a[:, 2], a[:, 3], frame_id=odo_frames[0], child_frame_id=odo_frames[1]
        )

    for conn, log_time, raw in reader.messages(connections=conns):
        if conn.topic in tfs:
            assert moved is not None  # given with tfs
            moved.append((conn.topic, int(log_time), tf_payload(reader.deserialize(raw, conn.msgtype))))
        elif conn.topic == topic:
            if scans >= survey.count:
                if odom_done:
                    break
                continue
            msg = reader.deserialize(raw, conn.msgtype)
            stamps.append(scan_stamp(msg, log_time))
            ranges.append(np.asarray(msg.ranges, np.float32))
            intens.append(np.asarray(msg.intensities, np.float32))
            scans += 1
            if progress is not None and scans % 500 == 0:
                progress(total + scans, 2 * total)
            if len(stamps) == size:
                yield scan_block(), poses()
                stamps, ranges, intens, rows = [], [], [], []
        elif not odom_done:
            msg = reader.deserialize(raw, conn.msgtype)
            t = header_stamp(msg.header, log_time)
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            now = (ros2_frame(msg.header.frame_id) or frames[0], ros2_frame(msg.child_frame_id) or frames[1])
            if now != frames and rows:
                yield None, poses()
                rows = []
            frames = odo_frames = now
            rows.append((t, p.x, p.y, yaw_of(q.x, q.y, q.z, q.w)))
            odom_done = t > survey.last
            if odom_done and scans >= survey.count:
                break
    if stamps:
        yield scan_block(), poses()
    elif rows:
        yield None, poses()
