"""`datmo node`: datmo live on a ROS 2 robot, over DDS (dds.py), with no ROS installation.

It subscribes to the robot's sensor_msgs/LaserScan (and, when given, nav_msgs/Odometry) and publishes what
`datmo run` writes to a log, as the scans arrive: /datmo/segments, /datmo/features, /datmo/landmarks,
/datmo/tracks and the markers, each stamped with its scan's stamp, byte for byte the CDR datmo writes to MCAP
(with --markers and --covariance: the node always publishes the markers and the tracks' covariance).
The processing is the live pipeline of `play` and `record --live` (live.LiveFeed and its Stages, the stages of
`datmo run`), on a thread of its own: the DDS side only takes samples, decodes them and queues the scans. A
burst the stages cannot keep up with drops the oldest waiting scans (counted); a scan of a new geometry, or one
stamped before the last, starts the tracking over; the robot's own /tf is left alone (none is published).

With odometry, tracks carry world positions: each scan is placed at the pose interpolated at its stamp (the
latest pose held when the odometry lags); scans that arrive before the first pose are skipped (counted).

In the ROS 2 graph (ros_graph.py) the node is `/datmo` (name and namespace given): announced on
ros_discovery_info with its endpoints, logging to /rosout, serving its parameters (node_params.py); a parameter
set live takes effect from the next scans processed (RetunedFeed).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from ..live import LiveFeed, Message, PoseBuffer
from ..logs import types
from ..logs.scan import decode_scan
from . import dds, ros_graph
from .node_params import Parameters

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig

SCAN_DEPTH = 256  # scans DDS keeps for the node between two takes (history depth of the subscription)
BACKLOG = 64  # scans waiting for the stages; beyond, the oldest is dropped
WAIT_S = 0.2  # longest wait for data, s (Ctrl-C is seen between waits)


def published_topics() -> dict[str, str]:
    """{ROS 2 topic: type} of what the node publishes: the stages' channels (not /tf, not /odom)."""
    from ..passes.pipeline import derived_topics

    return derived_topics(segments=True, features=True, tracks=True, markers=True)


class DdsSink:
    """What LiveFeed publishes to, for the node: each message on its ROS 2 topic through a CdrWriter made up
    front; messages of other topics are not sent."""

    def __init__(self, participant: dds.Participant, topics: dict[str, str]) -> None:
        self.writers = {topic: participant.writer(topic, msgtype) for topic, msgtype in topics.items()}
        self.sent = 0

    def time(self, stamp: int) -> None:
        pass

    def publish(self, message: Message) -> None:
        writer = self.writers.get(message.topic)
        if writer is not None:
            writer.write(message.payload)
            self.sent += 1


class RetunedFeed(LiveFeed):
    """A LiveFeed whose tracking parameters may change while it runs: `retune(config)` gives the new
    configuration, which the running tracker takes before the next scans it processes (only the parameters
    node_params.LIVE names may differ) and new stages (after a restart) start with."""

    def __init__(self, *args, **kwargs) -> None:
        self._pending: DatmoConfig | None = None
        self._lock = threading.Lock()
        super().__init__(*args, **kwargs)

    def retune(self, config: DatmoConfig) -> None:
        with self._lock:
            self.config = self._pending = config

    def _publish(self, stages, scans) -> None:
        if stages is not None:
            with self._lock:
                config, self._pending = self._pending, None
            if config is not None:
                retune_stages(stages, config)
        super()._publish(stages, scans)


def retune_stages(stages, config: DatmoConfig) -> None:
    """Give running live.Stages the tracking parameters of `config`: the tracker reads them as one vector
    (TrackingParams.kernel_vector) on each scan."""
    run_stages = stages.stages
    run_stages.config = config
    stream = run_stages.tracking
    stream.params = stream.tracker.params = config.track
    stream.tracker._prm = config.track.kernel_vector(stream.tracker.leg_threshold)


@dataclass
class Counts:
    """What the node has seen: scans taken from DDS, scans that did not decode (the first reason), scans
    skipped while no odometry had arrived, odometry messages taken and those that did not decode."""

    scans: int = 0
    bad_scans: int = 0
    bad_scan_reason: str = ""
    before_odometry: int = 0
    poses: int = 0
    bad_poses: int = 0
    notes: list[str] = field(default_factory=list)


class Node:
    """The node on DDS domain `domain`: subscriptions to `scan_topic` (and `odom_topic`), publications of
    published_topics(), the stages of `config` fed by `spin()`. `say(line)` tells what happens (a geometry
    change, the first scan that does not decode). Raises ConfigError (bad topic names, a domain it cannot join)
    and MissingExtraError (no cyclonedds). In the ROS 2 graph it is node `name` in namespace `ns`, speaking
    `distro`'s rmw_dds_common (ros_graph)."""

    def __init__(
        self,
        domain: int,
        scan_topic: str = "/scan",
        odom_topic: str | None = None,
        config: DatmoConfig | None = None,
        say: Callable[[str], None] = lambda line: None,
        backlog: int = BACKLOG,
        name: str = "datmo",
        ns: str = "/",
        distro: str | None = None,
    ) -> None:
        dds.require_cyclonedds()
        self.scan_topic = dds.ros_topic(scan_topic, "--scan-topic")
        self.odom_topic = dds.ros_topic(odom_topic, "--odom-topic") if odom_topic else None
        name, ns, distro = ros_graph.node_name(name), ros_graph.namespace(ns), ros_graph.ros_distro(distro)
        self.counts = Counts()
        self.participant = dds.Participant(domain)
        self.topics = published_topics()
        self.sink = DdsSink(self.participant, self.topics)
        self.odometry = PoseBuffer() if self.odom_topic else None
        self.params = Parameters(config)
        self.graph = ros_graph.Graph(self.participant, self.params, name, ns, distro, self._retune)
        self.name = self.graph.fqn
        self.say = say
        self.feed = RetunedFeed(
            self.sink,
            config,
            backlog=backlog,
            odometry=self.odometry,
            drop_oldest=True,
            scans=False,
            on_restart=lambda why: say(f"datmo node: {why}: tracking starts over"),
        )
        from ..passes.warm import warm_up

        warm_up()  # the compiled stages load now, not while the first scans arrive
        self.scans = self.participant.reader(self.scan_topic, types.LASERSCAN, depth=SCAN_DEPTH)
        self.poses = self.participant.reader(self.odom_topic, types.ODOMETRY) if self.odom_topic else None
        inputs = [r for r in (self.scans, self.poses) if r is not None]
        self.graph.announce([r.reader for r in inputs], [w.writer for w in self.sink.writers.values()])
        self.waitset = self.participant.waitset(inputs + self.graph.readers())

    def _retune(self, config: DatmoConfig) -> None:
        self.feed.retune(config)

    def log(self, level: int, line: str) -> None:
        """`line` on /rosout at `level` (ros_graph.INFO, WARN, ERROR)."""
        self.graph.log(level, line)

    def spin(self, wait_s: float = WAIT_S) -> int:
        """Wait up to `wait_s` seconds for data, then take every pose and scan that arrived and queue the scans
        for the stages; returns the number of scans queued."""
        self.waitset.wait(int(wait_s * 1e9))
        self.graph.serve()
        if self.poses is not None:
            for payload in self.poses.take(SCAN_DEPTH):
                self._pose(payload)
        queued = 0
        while True:
            payloads = self.scans.take(SCAN_DEPTH)
            if not payloads:
                return queued
            for payload in payloads:
                queued += self._scan(payload)

    def _scan(self, payload: bytes) -> int:
        c = self.counts
        c.scans += 1
        try:
            stamp, ranges, _, geometry = decode_scan(payload)
        except ValueError as exc:
            c.bad_scans += 1
            if not c.bad_scan_reason:
                c.bad_scan_reason = str(exc)
                self.say(f"datmo node: a scan on {self.scan_topic} does not decode ({exc}); such scans are skipped")
            return 0
        if self.odometry is not None and not len(self.odometry):
            if not c.before_odometry:
                self.say(f"datmo node: no odometry on {self.odom_topic} yet; scans are skipped until it comes")
            c.before_odometry += 1
            return 0
        self.feed.scan(stamp, ranges, geometry)
        return 1

    def _pose(self, payload: bytes) -> None:
        c = self.counts
        try:
            msg = types.typestore().deserialize_cdr(payload, types.ODOMETRY)
            pose, stamp = msg.pose.pose, msg.header.stamp
            q = pose.orientation
            theta = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            values = (pose.position.x, pose.position.y, theta)
            if not all(math.isfinite(v) for v in values):
                raise ValueError("a pose that is not finite")
        except Exception as exc:  # rosbags raises several kinds for a payload that does not decode
            c.bad_poses += 1
            if c.bad_poses == 1:
                self.say(
                    f"datmo node: an odometry message on {self.odom_topic} does not decode ({exc}); "
                    "such messages are skipped"
                )
            return
        c.poses += 1
        assert self.odometry is not None  # odometry messages come only with an odometry topic
        self.odometry.add(stamp.sec * 1_000_000_000 + stamp.nanosec, *values, msg.header.frame_id, msg.child_frame_id)

    def summary(self) -> str:
        """One line: scans received, processed, dropped behind, and what else was skipped."""
        c, f = self.counts, self.feed
        parts = [
            f"{c.scans:,} scans received",
            f"{f.published:,} processed",
            f"{f.dropped:,} dropped (the stages were behind)",
        ]
        if f.restarts:
            parts.append(f"{f.restarts:,} restarts")
        if c.bad_scans:
            parts.append(f"{c.bad_scans:,} did not decode")
        if c.before_odometry:
            parts.append(f"{c.before_odometry:,} before any odometry")
        if f.skipped:
            parts.append(f"{f.skipped:,} repeated a stamp")
        if f.failure:
            parts.append(f"the stages failed: {f.failure}")
        return ", ".join(parts)

    def close(self, timeout: float = 5.0) -> None:
        """Finish the scans queued (waiting at most `timeout` seconds). The node leaves the domain when the
        process exits."""
        self.feed.close(timeout)
