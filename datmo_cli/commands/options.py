"""Click options shared by several commands: --quiet, --config/--no-config, refusing `-o -` for logs."""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import click

from ..progress import quiet_option

__all__ = ["config_options", "input_options", "needs_conversion", "no_stdout", "quiet_option", "scan_log"]

STDOUT = "-"


def no_stdout(what: str = "an MCAP log", give: str = "a file name") -> Callable:
    """An option callback refusing `-` (stdout) for an output that cannot go to a stream."""
    def callback(ctx: click.Context, param: click.Parameter, value):
        if value is not None and str(value) == STDOUT:
            from ..errors import OutputError

            raise OutputError(f"{param.opts[-1]} -: cannot write {what} to stdout; give {give}")
        return value
    return callback


def config_options(help: str) -> Callable:
    """`--config FILE` (help: `help`) and `--no-config`; the command receives `config`, the file to use:
    --config, else ./datmo.toml when present (said on stderr), else None (config.effective_path)."""
    def decorate(f: Callable) -> Callable:
        @functools.wraps(f)
        def wrapper(*args, config: Path | None = None, no_config: bool = False, **kwargs):
            from ..config import effective_path

            return f(*args, config=effective_path(config, no_config), **kwargs)

        wrapper = click.option("--no-config", is_flag=True,
                               help="Ignore ./datmo.toml: defaults and options only.")(wrapper)
        return click.option("--config", type=click.Path(dir_okay=False, path_type=Path), default=None,
                            help=f"{help} [default: ./datmo.toml when present]")(wrapper)
    return decorate


def input_options(f: Callable) -> Callable:
    """`--topic` and `--odom-topic`, for inputs that are bags (see scan_log)."""
    f = click.option("--odom-topic", default=None,
                     help="With a bag: its nav_msgs/Odometry topic [default: the only one, if any].")(f)
    return click.option("--topic", default=None,
                        help="With a bag (ROS 1 .bag, ROS 2 folder or .db3) or a foreign MCAP: the LaserScan topic to "
                             "take when there are several (the input is converted as by datmo import).")(f)


@contextmanager
def scan_log(src: Path, output: Path, topic: str | None = None, odom_topic: str | None = None, *,
             force: bool = False, dest: Path | None = None,
             tell: Callable[[str], None] | None = None) -> Iterator[Path]:
    """The datmo log to read for `src`: `src` itself when it is an MCAP file and no topic is chosen; otherwise
    (a ROS 1 or ROS 2 bag, a CARMEN log, or a topic chosen) `src` converted as by `datmo import` into a
    temporary MCAP beside `output`, said on stderr and removed when the block ends (or on any way out).
    Before converting, `output` is checked (check_output with `force`): a refused output costs no conversion.
    `dest`: the temporary MCAP's path (default: a hidden name beside `output`); `tell`: what gets the lines
    said (the conversion, warnings), e.g. a batch task's record (default: stderr, the conversion unless --quiet)."""
    from .. import outputs
    from ..log.importers import detect_kind, open_import, write_import
    from ..progress import say

    src = _bag_folder(Path(src))
    if not needs_conversion(src, topic, odom_topic):
        yield src   # an MCAP (or not a log at all: the reader says what is wrong with it)
        return
    detect_kind(src)   # a missing file, a folder without metadata.yaml: one line
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
                (tell or functools.partial(click.echo, err=True))(f"datmo: warning: {w}")
        odom = f" and {stats.poses} poses from {stream.odom_topic}" if stats.poses else ""
        kind = {"ros1": "ROS 1 bag", "ros2": "ROS 2 bag"}.get(stream.kind, stream.kind)
        (tell or say)(f"datmo: converted {src} ({kind}: {stats.scans} scans from {stream.topic}{odom}) to a "
                      "temporary MCAP")
        yield tmp
    finally:
        outputs.discard(tmp)


def needs_conversion(src: Path, topic: str | None = None, odom_topic: str | None = None) -> bool:
    """Whether `src` is read through the importers: a bag (ROS 1 file, ROS 2 folder or its .db3) or a topic
    chosen; a datmo MCAP is read as it is."""
    src = Path(src)
    return (topic is not None or odom_topic is not None or src.is_dir() or src.suffix == ".db3"
            or _is_ros1_bag(src))


def _bag_folder(src: Path) -> Path:
    """A ROS 2 bag's .db3 (or .mcap) file as its folder when the folder holds the bag's metadata.yaml."""
    if src.suffix == ".db3":
        if not (src.parent / "metadata.yaml").is_file():
            from ..errors import InputError

            raise InputError(f"{src}: a ROS 2 .db3 is read with its bag folder, and {src.parent} has no "
                             "metadata.yaml")
        return src.parent
    return src


def _is_ros1_bag(src: Path) -> bool:
    from ..log.importers import _ROSBAG1_MAGIC

    try:
        with open(src, "rb") as f:
            return f.read(len(_ROSBAG1_MAGIC)) == _ROSBAG1_MAGIC
    except OSError:
        return False
