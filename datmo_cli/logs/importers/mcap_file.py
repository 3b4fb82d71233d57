"""Single MCAP files holding CDR sensor_msgs/msg/LaserScan (ROS 2 style; read with log.mcap_reader) into a
ScanRun, poses and transforms, block by block; the conventions are those of the bag importer (rosbag.py)."""

from __future__ import annotations

import struct
import warnings as _warnings
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from ...base.errors import GeometryError, InputError
from ..scan import GeometryChangeError, Odometry, ScanGeometry, ScanRun
from ..transforms import ros2_frame, ros2_frames
from .ros_messages import LASERSCAN_TYPES, ODOMETRY_TYPES, choose_topic, survey_tf, tf_topics


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
    from ..odometry_msgs import decode_odometry
    from .stream import ImportStream

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
        if o_topic is not None and (two := mcapio.several_channels(head, o_topic)):
            raise InputError(two)  # two odometry streams would interleave, as two scan streams would
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
            try:  # poses not finite or too far are dropped, and counted, by ImportStream.blocks
                odom = decode_odometry(np.asarray(o_stamps, np.int64), o_payloads)
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
    assert last is not None  # count > 0
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
