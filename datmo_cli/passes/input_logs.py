"""The log a stage reads for an input: a datmo MCAP as it is, or a bag (ROS 1 file, ROS 2 folder or its .db3),
a CARMEN log or a chosen topic converted as by `datmo import` into a temporary MCAP for the length of a block."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from ..base.errors import InputError


@contextmanager
def scan_log(
    src: Path,
    output: Path,
    topic: str | None = None,
    odom_topic: str | None = None,
    *,
    force: bool = False,
    dest: Path | None = None,
    tell: Callable[[str], None] | None = None,
) -> Iterator[Path]:
    """The datmo log to read for `src`: `src` itself when it is an MCAP file and no topic is chosen; otherwise
    (a ROS 1 or ROS 2 bag, a CARMEN log, or a topic chosen) `src` converted as by `datmo import` into a
    temporary MCAP beside `output`, said on stderr and removed when the block ends (or on any way out).
    Before converting, `output` is checked (check_output with `force`): a refused output costs no conversion.
    `dest`: the temporary MCAP's path (default: a hidden name beside `output`); `tell`: what gets the lines
    said (the conversion, warnings), e.g. a batch task's record (default: stderr, the conversion unless --quiet)."""
    from ..base import outputs
    from ..base.progress import say, stderr_line
    from ..base.text import printable
    from ..logs.importers import detect_kind, open_import, write_import

    src = _bag_folder(Path(src))
    if not needs_conversion(src, topic, odom_topic):
        yield src  # an MCAP (or not a log at all: the reader says what is wrong with it)
        return
    detect_kind(src)  # a missing file, a folder without metadata.yaml: one line
    outputs.check_output(output, force=force, inputs=[src])
    tmp = dest if dest is not None else outputs.temp_path(Path(output))
    outputs.track(tmp)
    try:
        folder = outputs.folder_of(Path(output))
        stream = open_import(src, topic, odom_topic=odom_topic, spool_dir=folder)
        try:
            stats = write_import(stream, tmp, force=True)
        finally:
            for w in stream.warnings:
                (tell or stderr_line)(f"datmo: warning: {printable(w)}")
        odom = f" and {stats.poses} poses from {stream.odom_topic}" if stats.poses else ""
        kind = {"ros1": "ROS 1 bag", "ros2": "ROS 2 bag"}.get(stream.kind, stream.kind)
        (tell or say)(
            f"datmo: converted {src} ({kind}: {stats.scans} scans from {stream.topic}{odom}) to a temporary MCAP"
        )
        yield tmp
    finally:
        outputs.discard(tmp)


def needs_conversion(src: Path, topic: str | None = None, odom_topic: str | None = None) -> bool:
    """Whether `src` is read through the importers: a bag (ROS 1 file, ROS 2 folder or its .db3) or a topic
    chosen; a datmo MCAP is read as it is."""
    src = Path(src)
    return topic is not None or odom_topic is not None or src.is_dir() or src.suffix == ".db3" or _is_ros1_bag(src)


def _bag_folder(src: Path) -> Path:
    """A ROS 2 bag's .db3 (or .mcap) file as its folder when the folder holds the bag's metadata.yaml."""
    if src.suffix == ".db3":
        if not (src.parent / "metadata.yaml").is_file():
            raise InputError(f"{src}: a ROS 2 .db3 is read with its bag folder, and {src.parent} has no metadata.yaml")
        return src.parent
    return src


def _is_ros1_bag(src: Path) -> bool:
    from ..base.input_files import is_regular, open_regular
    from ..logs.importers import _ROSBAG1_MAGIC

    if not is_regular(src):
        return False  # a FIFO or a device is never opened here (its reader refuses it in one line)
    try:
        with open_regular(src) as f:
            return f.read(len(_ROSBAG1_MAGIC)) == _ROSBAG1_MAGIC
    except (OSError, InputError):
        return False
