"""`datmo node`: a live ROS 2 node over DDS (Cyclone DDS, no ROS installation): LaserScans in, tracks out: the
options, one call of datmo_cli.api.node (workflows.ros_node) and what it prints."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from ..base.bounds import OPTIONS
from .options import config_options, quiet_option
from .types import option

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


@click.command(name="node")
@click.option(
    "--scan-topic",
    default="/scan",
    show_default=True,
    metavar="TOPIC",
    help="The sensor_msgs/LaserScan topic to subscribe to.",
)
@click.option(
    "--odom-topic",
    default=None,
    metavar="TOPIC",
    help="A nav_msgs/Odometry topic: tracks then also carry world (odom) positions. [default: none]",
)
@option(
    "--domain-id",
    bound=OPTIONS["domain_id"],
    default=None,
    metavar="ID",
    help="The ROS 2 domain. [default: ROS_DOMAIN_ID, else 0]",
)
@click.option("--name", default="datmo", show_default=True, metavar="NAME", help="The node's name in the ROS 2 graph.")
@click.option("--namespace", default="/", show_default=True, metavar="NS", help="The node's namespace.")
@click.option(
    "--ros-distro",
    default=None,
    metavar="DISTRO",
    help="The ROS 2 distribution whose graph messages to speak: humble, iron, jazzy, kilted or rolling "
    "(Humble's GIDs are 24 bytes, later ones 16). [default: ROS_DISTRO, else humble]",
)
@config_options("TOML file with [features] and [track] tables.")
@quiet_option
def command(
    scan_topic: str,
    odom_topic: str | None,
    domain_id: int | None,
    name: str,
    namespace: str,
    ros_distro: str | None,
    cfg: DatmoConfig,
) -> None:
    """Run datmo live on a ROS 2 robot: subscribe to its LaserScans (and odometry) over DDS and publish
    /datmo/tracks (datmo_msgs/Tracks), /datmo/features, /datmo/landmarks, /datmo/segments and the markers
    (/datmo/markers/features, /datmo/markers/tracks), each stamped with its scan's stamp.

    It speaks ROS 2's wire conventions through Eclipse Cyclone DDS (as rmw_cyclonedds_cpp does), so no ROS
    installation is needed; run the robot's nodes with RMW_IMPLEMENTATION=rmw_cyclonedds_cpp and the same
    ROS_DOMAIN_ID. Scans are processed as datmo run would, on a thread of their own; when they come faster than
    they are processed, the oldest waiting are dropped (counted). A scan of another geometry starts the tracking
    over. Ctrl-C stops (exit 130) and prints what was received and processed. Needs the node extra:
    pip install 'datmo-cli[node]'.

    It announces itself in the ROS 2 graph as the node /datmo (--name, --namespace) with its topics, logs to
    /rosout, and serves its parameters, the config keys (ros2 param list /datmo): those the running tracker
    reads on each scan (the tracking thresholds) can be set live (ros2 param set /datmo track.gate 9.0), the
    others are refused with the reason (docs/ros2.md says what was checked without ROS 2).

    Example: datmo node --domain-id 7 --scan-topic /front/scan --odom-topic /odom
    """
    from .. import api
    from ..base import outputs
    from ..base.progress import say

    options = {"domain_id": domain_id, "name": name, "namespace": namespace, "ros_distro": ros_distro}
    node = api.node(scan_topic, odom_topic, config=cfg, on_warning=lambda line: click.echo(line, err=True), **options)
    try:
        click.echo(node.started)
        say("  Ctrl-C to stop")
        node.spin()
    except (KeyboardInterrupt, outputs.Terminated) as exc:
        code = 130 if isinstance(exc, KeyboardInterrupt) else exc.exit_code
        say(node.close("Ctrl-C" if code == 130 else str(exc)))
        raise click.exceptions.Exit(code) from None
