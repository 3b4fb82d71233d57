"""`datmo import`: a real log (CARMEN, g2o, ROS 1/2 bag, MCAP) converted to a datmo scan log."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path

import click

from ..base.bounds import OPTIONS
from .options import force_option, output_option, quiet_option
from .types import laser_pose_option, option


@click.command(name="import")
@click.argument("src", type=click.Path(path_type=Path))
@output_option("The log to write (MCAP with /scan and, when the source has poses, /odom).")
@force_option()
@click.option(
    "--topic",
    default=None,
    help="The scan stream to take when there are several: a LaserScan topic of a bag or MCAP, "
    "or a CARMEN message name (FLASER, RLASER, RAWLASER1-4, ROBOTLASER1).",
)
@click.option(
    "--odom-topic", default=None, help="The nav_msgs/Odometry topic of a bag or MCAP [default: the only one, if any]."
)
@option(
    "--max-scans",
    bound=OPTIONS["scans"],
    default=None,
    help="Keep only the first N scans (and the poses up to the last of them).",
)
@laser_pose_option()
@quiet_option
def command(
    src: Path,
    output: Path,
    force: bool,
    topic: str | None,
    odom_topic: str | None,
    max_scans: int | None,
    laser_pose: tuple | None,
) -> None:
    """Convert a CARMEN log, g2o file, ROS 1/2 bag or MCAP file to a datmo scan log.

    SRC is a CARMEN text log (FLASER, RLASER, RAWLASER1-4, ROBOTLASER1; plain or gzipped), a g2o file with
    ROBOTLASER1 lines, a ROS 1 .bag, a ROS 2 bag folder or an MCAP file with sensor_msgs/LaserScan. The
    kind is found from the content. Scans go to /scan (ranges in metres; "no return" readings as +inf)
    and poses, when the source has them, to /odom with /tf (one transform a pose) and /tf_static (the
    poses' child frame -> the scan's frame); a bag's own /tf and /tf_static are kept. With --laser-pose, poses
    of the scanner itself (CARMEN's) become the base's (base_link). Malformed CARMEN lines are skipped with a
    warning.
    The output is written beside OUTPUT under a temporary name and renamed when complete; SRC is only read.

    \b
    Example: datmo import ../shared/data/carmen/csail-corrected.log.gz -o csail.mcap
    """
    from ..base.outputs import check_output
    from ..base.progress import say
    from ..base.text import printable
    from ..cli import invocation
    from ..logs import mcapio
    from ..logs.importers import open_import, write_import

    check_output(output, force=force, inputs=[src])  # before reading a big input
    with _progress(src) as progress:
        stream = open_import(
            src,
            topic,
            odom_topic=odom_topic,
            max_scans=max_scans,
            progress=progress,
            spool_dir=output.parent if output.parent.is_dir() else None,
        )
        params: dict[str, object] = {
            "topic": stream.topic,
            "odom_topic": stream.odom_topic,
            "max_scans": max_scans,
            "kind": stream.kind,
        }
        mount = None
        if laser_pose is not None:
            from ..logs.transforms import LaserPose

            mount = LaserPose(*laser_pose)
            params["laser_pose"] = {"x_m": mount.x, "y_m": mount.y, "yaw_deg": math.degrees(mount.yaw)}
        provenance = mcapio.Provenance("import", params, [src] if src.is_file() else [], invocation("import"))
        try:
            stats = write_import(stream, output, force=force, provenance=provenance, laser_pose=mount)
        finally:
            for w in stream.warnings:
                click.echo(f"datmo: warning: {printable(w)}", err=True)
    odom = f", {stats.poses} poses on /odom" if stats.poses else ""
    geometry = stats.geometry.describe() if stats.geometry is not None else "no geometry"
    say(f"{output}: {stats.scans} scans of {geometry} from {stream.kind} {stream.topic}{odom}")


@contextlib.contextmanager
def _progress(src: Path):
    """A progress callback (done, total) drawing a bar on stderr for inputs over 20 MB, else None. The
    total is the bytes of a text log or the messages of a bag, as the importer counts them."""
    from ..logs.importers import detect_kind

    size = src.stat().st_size if src.is_file() else 0
    if size < 20_000_000:
        yield None
        return
    from ..base.progress import bar

    unit = "messages" if detect_kind(src) in ("ros1", "ros2", "mcap") else "bytes"
    with bar(f"reading {src.name}", None, unit=unit) as progress:
        yield lambda done, total: progress.update(done, total or None)
