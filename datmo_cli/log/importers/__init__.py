"""Importers: real logs from other tools into a ScanRun (and Odometry) that `datmo import` writes.

Supported kinds (see `detect_kind`):

- ``carmen``: CARMEN text logs (FLASER, RLASER, RAWLASER1-4, ROBOTLASER1-2; plain or gzipped),
- ``g2o``: g2o files carrying CARMEN ROBOTLASER1 lines (e.g. MIT Killian Court), read like CARMEN,
- ``ros1``: ROS 1 bags, ``ros2``: ROS 2 bag folders (sqlite3 or mcap storage), both via rosbags,
- ``mcap``: a single MCAP file with CDR sensor_msgs/msg/LaserScan (ROS 2 style, datmo's own included).

Every importer returns an ImportResult; bad input raises datmo_cli.errors.InputError with a one-line
message naming the file and the problem.
"""

from __future__ import annotations

import gzip
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ...errors import InputError
from ..scan import Odometry, ScanRun

#: progress(done, total): bytes of a text log, or messages of a bag, read so far (total 0 when unknown).
Progress = Callable[[int, int], None]

KINDS = ("carmen", "g2o", "ros1", "ros2", "mcap")
_ROSBAG1_MAGIC = b"#ROSBAG V2.0"
_MCAP_MAGIC = b"\x89MCAP"
_GZIP_MAGIC = b"\x1f\x8b"


@dataclass
class ImportResult:
    """What an importer made of a source log.

    run: the scans (ranges in metres, sensor frame; +inf = no return); odometry: poses of the sensor
    in the world/odom frame at the scan stamps (or from the source's odometry topic), or None;
    warnings: one-line notes for the user (skipped lines, synthesised stamps, ...); kind: one of KINDS;
    topic: the source's name of the scan stream (a ROS topic, or a CARMEN message name such as FLASER);
    odom_topic: the source of the poses, or None; facts: small JSON-ready details (counts, conventions).
    """

    run: ScanRun
    odometry: Odometry | None
    warnings: list[str] = field(default_factory=list)
    kind: str = ""
    topic: str = ""
    odom_topic: str | None = None
    source: Path | None = None
    facts: dict = field(default_factory=dict)


def _check_path(path: Path) -> None:
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        if (path / "metadata.yaml").exists():
            return
        raise InputError(f"{path}: is a directory, not a log (a ROS 2 bag folder holds metadata.yaml)")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")


def _head(path: Path, size: int = 65536) -> bytes:
    """The first `size` bytes of the file's content (decompressed when gzipped)."""
    with open(path, "rb") as f:
        raw = f.read(size)
    if raw.startswith(_GZIP_MAGIC):
        try:
            return zlib.decompressobj(16 + zlib.MAX_WBITS).decompress(raw, size)
        except zlib.error as exc:
            raise InputError(f"{path}: corrupt gzip data ({exc})") from None
    return raw


def detect_kind(path: str | Path) -> str:
    """The kind of log at `path` (one of KINDS), judged by content, not by name.

    Raises InputError for a missing file, an empty file, a directory that is not a ROS 2 bag, and
    content of no known kind.
    """
    from .carmen import sniff_text

    path = Path(path)
    _check_path(path)
    if path.is_dir():
        return "ros2"
    head = _head(path)
    if not head:
        raise InputError(f"{path}: empty file (nothing after decompression)")
    if head.startswith(_ROSBAG1_MAGIC):
        return "ros1"
    if head.startswith(_MCAP_MAGIC):
        return "mcap"
    kind = sniff_text(head)
    if kind is None:
        raise InputError(f"{path}: unknown kind of file (not a CARMEN or g2o text log, ROS bag or MCAP)")
    return kind


def import_log(path: str | Path, topic: str | None = None, *, odom_topic: str | None = None,
               max_scans: int | None = None, progress: Progress | None = None) -> ImportResult:
    """Read the log at `path` into arrays.

    topic: which scan stream to take when there are several (a ROS topic, or for CARMEN a message name
    such as FLASER or ROBOTLASER1); odom_topic: the nav_msgs/Odometry topic of a bag (default: the only
    one, if any); max_scans: keep only the first N scans (and the poses up to the last one kept).
    """
    path = Path(path)
    kind = detect_kind(path)
    if max_scans is not None and max_scans < 1:
        raise InputError(f"{path}: --max-scans must be at least 1")
    try:
        if kind in ("carmen", "g2o"):
            from .carmen import read_carmen

            result = read_carmen(path, topic=topic, max_scans=max_scans, progress=progress)
        elif kind == "mcap":
            from .rosbag import read_mcap

            result = read_mcap(path, topic=topic, odom_topic=odom_topic, max_scans=max_scans)
        else:
            from .rosbag import read_bag

            result = read_bag(path, topic=topic, odom_topic=odom_topic, max_scans=max_scans, progress=progress)
    except (EOFError, gzip.BadGzipFile, zlib.error) as exc:
        raise InputError(f"{path}: corrupt or truncated compressed data ({exc})") from None
    result.kind = kind
    result.source = path
    return result


__all__ = ["KINDS", "ImportResult", "detect_kind", "import_log"]
