"""`datmo import`: a real log (CARMEN, g2o, ROS 1/2 bag, MCAP) converted to a datmo scan log: the options, one call
of datmo_cli.api.import_log (workflows.importing) and the line it says."""

from __future__ import annotations

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
    from .. import api
    from ..base.progress import say
    from ..cli import invocation

    result = api.import_log(
        src,
        output,
        force=force,
        topic=topic,
        odom_topic=odom_topic,
        max_scans=max_scans,
        laser_pose=laser_pose,
        command_line=invocation("import"),
    )
    say(result.summary)
