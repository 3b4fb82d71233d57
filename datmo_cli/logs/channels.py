"""A log's channels as arrays: the messages of one topic, its scans as a ScanRun and its odometry, with the
errors that name the file, the topic and the command that makes a missing channel."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..base.errors import GeometryError, InputError, MissingChannelError
from . import types
from .mcap_reader import LogContents, read_log
from .odometry_msgs import decode_odometry
from .scan import GeometryChangeError, Odometry, ScanGeometry, ScanRun, decode_scans
from .topics import PRODUCER, TOPIC_ODOM, TOPIC_SCAN


def read_messages(path: str | Path, topic: str, *, required: bool = True) -> tuple[np.ndarray, list[bytes]]:
    """(log times in ns as int64, payloads) of one topic, in file order."""
    log = read_log(path, topics=[topic])
    return _messages_of(log, topic, required)


def _messages_of(log: LogContents, topic: str, required: bool = True) -> tuple[np.ndarray, list[bytes]]:
    stamps, payloads = log.messages.get(topic, ([], []))
    if required and not payloads:
        maker = PRODUCER.get(topic)
        hint = f"; run {maker} first" if maker else ""
        raise MissingChannelError(f"{log.path}: no messages on {topic}{hint}")
    return np.array(stamps, np.int64), payloads


@contextmanager
def decoding(path: str | Path, topic: str) -> Iterator[None]:
    """Decode errors of `topic`'s messages (cdr.DecodeError: a damaged payload in a sound chunk) as one InputError
    naming the file and the topic."""
    from .cdr import DecodeError

    try:
        yield
    except DecodeError as exc:
        raise InputError(f"{path}: bad message on {topic}: {exc}") from None


def several_channels(log: LogContents, topic: str) -> str | None:
    """What is wrong when two channels of the log hold messages on `topic` (two streams, which a read by topic
    would interleave), else None."""
    on = [c for c in sorted(log.channels.values(), key=lambda c: c.id) if c.topic == topic and c.count]
    if len(on) < 2:
        return None
    which = ", ".join(f"id {c.id}: {c.count} {c.msgtype}" for c in on)
    return (
        f"{log.path}: {topic} is on {len(on)} channels ({which}); their messages would interleave into one "
        "stream: keep one channel, or give each its own topic"
    )


def check_scan_channel(log: LogContents, topic: str = TOPIC_SCAN) -> int:
    """The number of scans on `topic` (read or not); raises when it holds none or not CDR LaserScans, or when
    two channels of the file hold messages on it (two scan streams, which a read by topic would interleave)."""
    problem = several_channels(log, topic)
    if problem:
        raise InputError(problem)
    ch = log.topics().get(topic)
    if ch is not None and ch.count and ch.msgtype not in (types.LASERSCAN, "sensor_msgs/LaserScan"):
        raise InputError(f"{log.path}: {topic} holds {ch.msgtype}, not sensor_msgs/msg/LaserScan")
    if ch is not None and ch.count and ch.message_encoding != "cdr":
        raise InputError(f"{log.path}: {topic} is {ch.message_encoding}-encoded; convert it with datmo import")
    if ch is None or not ch.count:
        hint = f"; run {PRODUCER[topic]} first" if topic in PRODUCER else ""
        raise MissingChannelError(f"{log.path}: no messages on {topic}{hint}")
    return ch.count


def decode_scan_block(
    path: Path, payloads: list[bytes], first: int = 0, geometry: ScanGeometry | None = None, topic: str = TOPIC_SCAN
) -> ScanRun:
    """The ScanRun of a block of LaserScan payloads, scans first.. of the log at `path`; refuses a geometry
    that changes within the block or from `geometry` (the blocks' before)."""
    try:
        run = decode_scans(payloads, first)
    except GeometryChangeError as exc:
        raise GeometryError(f"{path}: {exc}; split the log before processing it") from None
    except ValueError as exc:
        raise InputError(f"{path}: bad LaserScan message on {topic}: {exc}") from None
    if geometry is not None and not run.geometry.same_beams(geometry):
        raise GeometryError(
            f"{path}: scan geometry changes at scan {first}: {geometry.describe()} -> "
            f"{run.geometry.describe()}; split the log before processing it"
        )
    return run


def run_from_log(log: LogContents, topic: str = TOPIC_SCAN) -> ScanRun:
    """The ScanRun of `topic` in an already-read log (see read_run)."""
    ch = log.topics().get(topic)
    if ch is not None and ch.count:
        check_scan_channel(log, topic)
    _, payloads = _messages_of(log, topic)
    try:
        return decode_scans(payloads)
    except GeometryChangeError as exc:
        raise GeometryError(f"{log.path}: {exc}; split the log before processing it") from None
    except ValueError as exc:
        raise InputError(f"{log.path}: bad LaserScan message on {topic}: {exc}") from None


def read_run(path: str | Path, topic: str = TOPIC_SCAN) -> ScanRun:
    """All scans of `topic` as one ScanRun. Refuses a run whose geometry changes."""
    return run_from_log(read_log(path, topics=[topic]), topic)


def odometry_from_log(log: LogContents, topic: str = TOPIC_ODOM) -> Odometry | None:
    """Odometry poses of an already-read log, or None when it has none on `topic` (or no sane one). Poses that
    are not finite or lie beyond poses.MAX_POSE_M are dropped with a BadPoseWarning saying how many; two
    channels on `topic` are refused (InputError), as for scans."""
    import warnings

    from . import poses

    problem = several_channels(log, topic)
    if problem:
        raise InputError(problem)
    stamps, payloads = _messages_of(log, topic, required=False)
    if not payloads:
        return None
    odo, dropped, first = poses.keep_sane(decode_odometry(stamps, payloads))
    if dropped:
        warnings.warn(poses.note(log.path, dropped, len(payloads), first), poses.BadPoseWarning, stacklevel=2)
    return odo


def read_odometry(path: str | Path, topic: str = TOPIC_ODOM) -> Odometry | None:
    """The log's odometry (world-frame poses of the sensor's base), or None when it has none."""
    return odometry_from_log(read_log(path, topics=[topic]), topic)
