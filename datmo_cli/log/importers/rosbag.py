"""ROS 1 bags, ROS 2 bag folders (via rosbags' AnyReader) and single MCAP files (via mcapio) into a ScanRun.

Scans come from one sensor_msgs/LaserScan topic (the only one, or `topic`); ranges are kept as the
driver wrote them (metres, sensor frame `header.frame_id`; inf/NaN as REP 117), intensities when every
message has one per beam. Stamps are header stamps (ns); a zero header stamp falls back to the bag's
log (receive) time. Poses come from one nav_msgs/Odometry topic (the only one, or `odom_topic`):
x, y in metres and yaw from the quaternion, in the message's frame. Frame names lose ROS 1's leading slash
(`/laser` -> `laser`; transforms.ros2_frame) in scans, poses and transforms alike. A source with poses is first
surveyed for its fixed transforms (`survey_tf`), so the import knows up front where the laser sits on the base.
"""

from __future__ import annotations

import struct
import warnings as _warnings
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ...errors import GeometryError, InputError
from ..scan import GeometryChangeError, Odometry, ScanGeometry, ScanRun, geometry_problem, stamp_problem
from ..transforms import ros2_frame, ros2_frames

LASERSCAN_TYPES = ("sensor_msgs/msg/LaserScan", "sensor_msgs/LaserScan")
ODOMETRY_TYPES = ("nav_msgs/msg/Odometry", "nav_msgs/Odometry")
# ROS 2's tf2 message, and ROS 1's (tf's tfMessage before tf2; tf2_msgs/TFMessage after): the same fields
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf2_msgs/TFMessage", "tf/msg/tfMessage", "tf/tfMessage")
TF_TOPICS = ("/tf", "/tf_static")


def tf_topics(topics: dict[str, tuple[str, int]]) -> tuple[str, ...]:
    """The /tf and /tf_static topics among `topics` ({topic: (msgtype, count)}) that hold transforms."""
    return tuple(t for t in TF_TOPICS if t in topics and topics[t][0] in TF_TYPES and topics[t][1])


def tf_transforms(msg) -> list:
    """The transforms.Transform list of a deserialised TFMessage (ROS 2, or ROS 1's tf/tfMessage), frame names
    without a leading slash."""
    from ..transforms import Transform, ros2_frame

    out = []
    for t in msg.transforms:
        s, p, q = t.header.stamp, t.transform.translation, t.transform.rotation
        out.append(
            Transform(
                int(s.sec) * 1_000_000_000 + int(s.nanosec),
                ros2_frame(t.header.frame_id),
                ros2_frame(t.child_frame_id),
                float(p.x),
                float(p.y),
                float(p.z),
                float(q.x),
                float(q.y),
                float(q.z),
                float(q.w),
            )
        )
    return out


def tf_payload(msg) -> bytes:
    """A deserialised TFMessage (ROS 2, or ROS 1's tf/tfMessage) as a CDR tf2_msgs/msg/TFMessage payload, frame
    names without a leading slash."""
    from ..transforms import encode_tf

    return encode_tf(tf_transforms(msg))


@dataclass
class TfSurvey:
    """A source's fixed transforms, read before its blocks: everything on /tf_static, and the /tf transforms
    that never change (transforms.ConstantTransforms), frame names without a leading slash."""

    statics: list = field(default_factory=list)
    constant: list = field(default_factory=list)


def survey_tf(messages) -> TfSurvey:
    """The TfSurvey of `messages`: (topic, list of transforms.Transform) of the source's /tf and /tf_static."""
    from ..transforms import ConstantTransforms

    statics, moving = [], ConstantTransforms()
    for topic, found in messages:
        if topic == "/tf_static":
            statics += found
        else:
            moving.add(found)
    return TfSurvey(statics, moving.constant())


def choose_topic(
    label: str,
    topics: dict[str, tuple[str, int]],
    wanted: str | None,
    types: tuple[str, ...],
    what: str,
    option: str,
    required: bool = True,
) -> str | None:
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


def _yaw(qx, qy, qz, qw):
    return np.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))


def _stamp(header, log_time: int) -> int:
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns else int(log_time)


def scan_geometry(msg) -> ScanGeometry:
    """The ScanGeometry of a deserialised sensor_msgs/LaserScan."""
    return ScanGeometry(
        angle_min=float(msg.angle_min),
        angle_increment=float(msg.angle_increment),
        n_beams=len(msg.ranges),
        range_min=float(msg.range_min),
        range_max=float(msg.range_max),
        time_increment=float(msg.time_increment),
        scan_time=float(msg.scan_time),
        frame_id=ros2_frame(msg.header.frame_id),
    )


def check_bag_scan(label: str, topic: str, i: int, msg) -> None:
    """InputError naming the file, the topic, scan `i` and the field when a LaserScan read from a bag cannot be
    what a scanner sent: bags have no checksums, so a damaged byte shows only where a message contradicts itself.
    Checked here: the header stamp is after 1970 with nanosec below 10^9; the angles and range limits are finite,
    0 <= range_min < range_max, the angle step is not zero, the beams span at most a turn and reach angle_max
    (within a beam); intensities are none or one a beam. (rosbags refuses a message longer or shorter than its
    fields.) A damaged reading itself is not seen: it is another range, or, outside the limits, not a return."""
    problem = _scan_problem(msg)
    if problem:
        raise InputError(f"{label}: damaged LaserScan on {topic}, scan {i}: {problem}")


def _scan_problem(msg) -> str | None:
    import math

    n, m = len(msg.ranges), len(msg.intensities)
    problem = stamp_problem(int(msg.header.stamp.sec), int(msg.header.stamp.nanosec))
    if problem:
        return problem
    a0, a1, step = float(msg.angle_min), float(msg.angle_max), float(msg.angle_increment)
    r0, r1 = float(msg.range_min), float(msg.range_max)
    for name, value in (
        ("angle_min", a0),
        ("angle_max", a1),
        ("angle_increment", step),
        ("range_min", r0),
        ("range_max", r1),
    ):
        if not math.isfinite(value):
            return f"{name} is {value}"
    problem = geometry_problem(a0, step, n, r0, r1)
    if problem:
        return problem
    if n and abs(a0 + (n - 1) * step - a1) > abs(step) * 1.01 + 1e-4:
        return (
            f"{n} beams from {math.degrees(a0):g}° by {math.degrees(step):g}° end at "
            f"{math.degrees(a0 + (n - 1) * step):g}°, not at angle_max {math.degrees(a1):g}°"
        )
    if m not in (0, n):
        return f"{m} intensities for {n} ranges"
    return None


def scan_stamp(msg, log_time: int) -> int:
    """The header stamp of a message (ns), or its log time when the stamp is zero."""
    return _stamp(msg.header, log_time)


def open_bag(path: str | Path):
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


def read_bag(
    path: str | Path,
    *,
    topic: str | None = None,
    odom_topic: str | None = None,
    max_scans: int | None = None,
    progress=None,
):
    """ImportResult of a ROS 1 bag or ROS 2 bag folder (the whole run)."""
    return stream_bag(path, topic=topic, odom_topic=odom_topic, max_scans=max_scans, progress=progress).collect()


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
    from . import ImportStream

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
        total = topics[scan_topic][1]
        scans = _survey(reader, label, scan_topic, total, max_scans, progress)
    except (InputError, GeometryError):
        close()
        raise
    except Exception as exc:  # corrupt chunks, unknown message definitions
        close()
        raise InputError(f"{label}: cannot read bag ({type(exc).__name__}: {exc})") from None
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
            raise InputError(f"{label}: cannot read bag ({type(exc).__name__}: {exc})") from None

    def pieces() -> Iterator[tuple[ScanRun | None, Odometry | None]]:
        try:
            yield from _bag_blocks(reader, scan_topic, o_topic, scans, block_scans, progress, total, tfs, moved)
        except (InputError, GeometryError):
            raise
        except Exception as exc:  # corrupt chunks, unknown message definitions
            raise InputError(f"{label}: cannot read bag ({type(exc).__name__}: {exc})") from None
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
    """InputError when two of the bag's connections (two publishers, as ROS 1 records them) hold messages on the
    scan topic: two scan streams, which a read by topic would interleave."""
    on = [c for c in reader.connections if c.topic == topic and c.msgcount]
    if len(on) > 1:
        who = ", ".join(f"{getattr(c.ext, 'callerid', None) or c.msgtype}: {c.msgcount} messages" for c in on)
        raise InputError(
            f"{label}: {topic} is on {len(on)} connections ({who}); their scans would interleave into "
            "one stream: keep one connection, or give each its own topic"
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
        t = _stamp(msg.header, log_time)
        last = t if last is None else max(last, t)
        sizes.add(len(msg.intensities))
        count += 1
        if progress is not None and i % 500 == 0:
            progress(i, 2 * total)
    if g0 is None:
        raise InputError(f"{label}: {topic} has no messages")
    n = g0.n_beams
    mode = "all" if sizes == {n} else "none" if sizes <= {0} or 0 not in sizes and n not in sizes else "fill"
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
    stamps, ranges, intens = [], [], []
    rows: list[tuple] = []
    frames = ("odom", "base_link")
    odo_frames = frames
    scans = 0
    odom_done = o_topic is None

    def scan_block() -> ScanRun:
        inten = None
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
            moved.append((conn.topic, int(log_time), tf_payload(reader.deserialize(raw, conn.msgtype))))
        elif conn.topic == topic:
            if scans >= survey.count:
                if odom_done:
                    break
                continue
            msg = reader.deserialize(raw, conn.msgtype)
            stamps.append(_stamp(msg.header, log_time))
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
            t = _stamp(msg.header, log_time)
            p, q = msg.pose.pose.position, msg.pose.pose.orientation
            now = (ros2_frame(msg.header.frame_id) or frames[0], ros2_frame(msg.child_frame_id) or frames[1])
            if now != frames and rows:
                yield None, poses()
                rows = []
            frames = odo_frames = now
            rows.append((t, p.x, p.y, _yaw(q.x, q.y, q.z, q.w)))
            odom_done = t > survey.last
            if odom_done and scans >= survey.count:
                break
    if stamps:
        yield scan_block(), poses()
    elif rows:
        yield None, poses()


def read_mcap(
    path: str | Path, *, topic: str | None = None, odom_topic: str | None = None, max_scans: int | None = None
):
    """ImportResult of a single MCAP file holding CDR sensor_msgs/msg/LaserScan (the whole run)."""
    return stream_mcap(path, topic=topic, odom_topic=odom_topic, max_scans=max_scans).collect()


def stream_mcap(
    path: str | Path,
    *,
    topic: str | None = None,
    odom_topic: str | None = None,
    max_scans: int | None = None,
    block_scans: int = 1024,
):
    """ImportStream of a single MCAP file holding CDR sensor_msgs/msg/LaserScan (ROS 2 style).

    A first pass over the scan payloads (header stamps and intensity counts only) settles the intensities
    and, with `max_scans`, the last stamp kept; the blocks come from a second pass in file order. With
    `max_scans`, the scans stop there (the whole-run import also checked the geometry of the scans after
    them) and the poses at the first one stamped after the last scan kept. Each block of poses keeps its
    own frame ids (the whole-run import gave all poses the last ones)."""
    from .. import mcapio
    from . import ImportStream

    path = Path(path)
    label = str(path)
    warns: list[str] = []
    with _warnings.catch_warnings(record=True) as caught:
        _warnings.simplefilter("always")
        head = mcapio.summary(path)
        topics = {c.topic: (c.msgtype, c.count) for c in head.channels.values()}
        scan_topic = choose_topic(label, topics, topic, LASERSCAN_TYPES, "sensor_msgs/LaserScan", "--topic")
        o_topic = choose_topic(
            label, topics, odom_topic, ODOMETRY_TYPES, "nav_msgs/Odometry", "--odom-topic", required=False
        )
        tfs = tuple(t for t in tf_topics(topics) if head.topics()[t].message_encoding == "cdr")
        if any(c.topic == scan_topic and c.count for c in head.channels.values()):
            mcapio.check_scan_channel(head, scan_topic)
        count, inten_mode, last, n_beams = _mcap_survey(path, label, scan_topic, max_scans)
        survey = None
        if o_topic is not None and tfs:
            survey = survey_tf(
                (t, [ros2_frames(x) for x in _decode_tf(payload)])
                for t, _, payload in mcapio.iter_messages(path, list(tfs), warn=False)
            )
    warns += [f"{w.message}" for w in caught]

    def pieces() -> Iterator[tuple[ScanRun | None, Odometry | None]]:
        payloads: list[bytes] = []
        log_times: list[int] = []
        o_stamps: list[int] = []
        o_payloads: list[bytes] = []
        first, g0, first_pose = 0, None, True
        scans_done, odom_done = False, o_topic is None

        def scan_block() -> ScanRun:
            nonlocal g0
            run = _decode_block(label, scan_topic, payloads, first, g0)
            g0 = g0 or replace(run.geometry, frame_id=ros2_frame(run.geometry.frame_id))
            zero = run.stamps == 0
            if zero.any():
                run.stamps[zero] = np.asarray(log_times, np.int64)[zero]
            inten = run.intensities
            if inten_mode == "fill" and inten.shape[1] == 0:
                inten = np.full((len(run), n_beams), np.nan, np.float32)
            return ScanRun(run.stamps, run.ranges, g0, inten)

        def poses() -> Odometry | None:
            nonlocal first_pose
            if not o_payloads:
                return None
            log = mcapio.LogContents(path=path, messages={o_topic: (o_stamps, o_payloads)})
            try:
                odom = mcapio.odometry_from_log(log, o_topic)
            except Exception as exc:  # a message the ROS 2 type store cannot decode
                raise InputError(f"{label}: bad nav_msgs/Odometry message on {o_topic}: {exc}") from None
            keep = odom.stamps <= last if max_scans is not None else np.ones(len(odom), bool)
            keep[0] |= first_pose
            first_pose = False
            return Odometry(
                odom.stamps[keep],
                odom.x[keep],
                odom.y[keep],
                odom.theta[keep],
                ros2_frame(odom.frame_id),
                ros2_frame(odom.child_frame_id),
            )

        for t, stamp, payload in mcapio.iter_messages(
            path, [scan_topic, *tfs] + ([o_topic] if o_topic else []), warn=False
        ):
            if t in tfs:
                moved.append((t, stamp, _without_slashes(payload)))
            elif t == scan_topic:
                if scans_done:
                    if odom_done:
                        break
                    continue
                payloads.append(payload)
                log_times.append(stamp)
                if first + len(payloads) == count:
                    scans_done = True
                if len(payloads) == block_scans or scans_done:
                    yield scan_block(), poses()
                    first += len(payloads)
                    payloads, log_times, o_stamps, o_payloads = [], [], [], []
            elif not odom_done:
                o_stamps.append(stamp)
                o_payloads.append(payload)
                if scans_done and max_scans is not None and stamp > last:  # the poses after: none kept
                    odom_done = True
                    break
        if payloads:
            yield scan_block(), poses()
        elif o_payloads:
            yield None, poses()

    moved: list[tuple[str, int, bytes]] = []
    return ImportStream(
        pieces(),
        warnings=warns,
        topic=scan_topic,
        odom_topic=o_topic,
        facts={"topics": {t: m for t, (m, _) in topics.items()}},
        transforms=moved,
        tf_topics=tfs,
        tf_survey=survey,
    )


def _decode_tf(payload: bytes) -> list:
    """The transforms of a TFMessage payload; none when it does not decode (it is copied as it is, as before)."""
    from ..transforms import decode_tf

    try:
        return decode_tf(payload)
    except ValueError:
        return []


def _without_slashes(payload: bytes) -> bytes:
    """transforms.without_slashes, or the payload as it is when it does not decode."""
    from ..transforms import without_slashes

    try:
        return without_slashes(payload)
    except ValueError:
        return payload


def _mcap_survey(path: Path, label: str, topic: str, max_scans: int | None) -> tuple[int, str, int, int]:
    """(scans to import, intensities mode as in decode_scans, their largest stamp, beams) of an MCAP's
    scan topic, from the payloads' headers."""
    from .. import mcapio
    from ..scan import decode_scan

    count, sizes, last, n_beams = 0, {}, None, 0
    for _, log_time, payload in mcapio.iter_messages(path, [topic], warn=False):
        if max_scans is not None and count >= max_scans:
            break
        if len(payload) not in sizes:
            try:
                _, ranges, inten, _ = decode_scan(payload)
            except ValueError as exc:
                raise InputError(f"{label}: bad LaserScan message on {topic}: {exc}") from None
            sizes[len(payload)] = len(inten)
            n_beams = n_beams or len(ranges)
        stamp = _cdr_stamp(payload) or log_time
        last = stamp if last is None else max(last, stamp)
        count += 1
    if not count:
        raise InputError(f"{label}: no messages on {topic}")
    counts = set(sizes.values())
    mode = "all" if counts == {n_beams} else "none" if counts == {0} else "fill"
    return count, mode, int(last), n_beams


def _cdr_stamp(payload: bytes) -> int:
    """The header stamp (ns) of a CDR message with a std_msgs/Header first."""
    sec, nanosec = struct.unpack_from("<iI", payload, 4)
    return sec * 1_000_000_000 + nanosec


def _decode_block(label: str, topic: str, payloads: list[bytes], first: int, g0: ScanGeometry | None) -> ScanRun:
    """The ScanRun of scans first.. of the log; the whole-run import's errors for a geometry that changes
    (scans numbered from the log's first) or a bad message."""
    from ..scan import decode_scan, decode_scans

    try:
        run = decode_scans(payloads)
        if g0 is None or run.geometry.same_beams(g0):
            return run
    except GeometryChangeError:
        pass
    except ValueError as exc:
        raise InputError(f"{label}: bad LaserScan message on {topic}: {exc}") from None
    g0 = g0 or decode_scan(payloads[0])[3]
    for i, p in enumerate(payloads):
        g = decode_scan(p)[3]
        if not g.same_beams(g0):
            raise GeometryError(
                f"{label}: scan geometry changes at scan {first + i}: {g0.describe()} -> "
                f"{g.describe()}; split the log before processing it"
            )
    raise AssertionError("decode_scans refused scans of one geometry")
