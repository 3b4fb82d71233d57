"""`datmo node`'s work as a call (datmo_cli.api.node, LiveNode): datmo live as a ROS 2 node over DDS
(ros2.node.Node: LaserScans in, /datmo/tracks and the other channels out, each stamped with its scan's stamp;
tracks in the scan's sensor frame, and in the odometry frame with an odometry topic). What a publisher's
messages make it say is escaped and rate-limited by kind, on `on_warning` and on /rosout. The command keeps what
it prints and how Ctrl-C ends it."""

from __future__ import annotations

import re
import threading
from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from . import Config


class LiveNode:
    """A running ROS 2 node: subscribed to `scan_topic` (and `odom_topic`) in `domain_id` (None:
    ROS_DOMAIN_ID, else 0), announced as `name` in `namespace`, speaking `ros_distro`'s graph messages (None:
    ROS_DISTRO, else humble), processing with `config` (as api.process takes it). `started` is the line that
    says what it does; `spin(stop)` serves until `stop` is set (RuntimeError if the stages stop on a bug);
    `close()` stops it and returns the line that says what it received and processed. `on_warning(line)`
    hears the publishers' trouble, rate-limited (None: stderr). Needs the node extra."""

    def __init__(
        self,
        scan_topic: str = "/scan",
        odom_topic: str | None = None,
        *,
        domain_id: int | None = None,
        name: str = "datmo",
        namespace: str = "/",
        ros_distro: str | None = None,
        config: Config = None,
        on_warning: Callable[[str], None] | None = None,
    ) -> None:
        from ..base.progress import Limited, stderr_line
        from ..ros2 import dds, ros_graph
        from ..ros2 import node as ros_node
        from . import as_config

        self.domain = dds.domain_id(domain_id)
        sink = on_warning or stderr_line
        nodes: list = []

        def warn(line: str) -> None:
            sink(line)
            for n in nodes:
                n.log(ros_graph.WARN, line)

        self._told = told = Limited("datmo node", sink=warn)
        self.node = ros_node.Node(
            self.domain,
            scan_topic,
            odom_topic,
            as_config(config),
            say=lambda line: told(line.removeprefix("datmo node: "), re.split(r"[\d(]", line)[0]),
            name=name,
            ns=namespace,
            distro=ros_distro,
        )
        nodes.append(self.node)
        node = self.node
        inputs = node.scan_topic + (f" and {node.odom_topic}" if node.odom_topic else "")
        self.started = f"datmo node: ROS 2 domain {self.domain}: {inputs} in, {', '.join(node.topics)} out"
        node.log(ros_graph.INFO, f"{self.started}; node {node.name}")

    def spin(self, stop: threading.Event | None = None) -> None:
        """Take the scans and poses as they come until `stop` is set (None: until interrupted); RuntimeError
        (said on /rosout) when the stages stopped on an error."""
        from ..ros2 import ros_graph

        node = self.node
        while node.feed.failure is None:
            if stop is not None and stop.is_set():
                return
            node.spin()
        node.log(ros_graph.ERROR, f"datmo node: the stages stopped: {node.feed.failure}")
        raise RuntimeError(f"the stages stopped: {node.feed.failure}")  # a bug: exit 70, one line

    def close(self, reason: str = "closed") -> str:
        """Stop the node; the line saying why (`reason`) and what it received and processed (also on /rosout)."""
        from ..ros2 import ros_graph

        self.node.close()
        self._told.close()
        stopped = f"datmo node: stopped ({reason}); {self.node.summary()}"
        self.node.log(ros_graph.INFO, stopped)
        return stopped

    def __enter__(self) -> LiveNode:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def node(scan_topic: str = "/scan", odom_topic: str | None = None, **options) -> LiveNode:
    """`datmo node`: a LiveNode on `scan_topic` (and `odom_topic`) with `options` (LiveNode's), started;
    `spin(stop)` serves it, `close()` stops it (`with api.node("/scan") as n: n.spin(stop)`)."""
    return LiveNode(scan_topic, odom_topic, **options)
