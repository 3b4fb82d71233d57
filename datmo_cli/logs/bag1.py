"""Writing ROS 1 bags (rosbags' rosbag1 Writer, ROS 1 Noetic message definitions), as a ROS 1 robot records them.

For logs that must look like a ROS 1 robot's (`datmo simulate -o NAME.bag`): sensor_msgs/LaserScan, nav_msgs/Odometry
and tf2_msgs/TFMessage on /tf, frame names with ROS 1's leading slash (`/odom`, `/base_link`, `/laser`) and no
/tf_static (ROS 1 drivers and static_transform_publisher repeat fixed transforms on /tf). Poses are planar
(x, y in metres, yaw in radians, z = 0), quaternions made as encode_odometry makes them, so a pose read back
is the same number whichever format carried it. Messages are written in the order given; the bag's index sorts
them by time.

The bag goes to a temporary name beside the output and is renamed into place when complete (outputs.py); on any
error or signal it is removed and the output left as it was.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from datmo_cli.base import libm

from ..base import outputs
from .scan import Odometry, ScanRun
from .transforms import Transform

SCAN, ODOMETRY, TF = "sensor_msgs/msg/LaserScan", "nav_msgs/msg/Odometry", "tf2_msgs/msg/TFMessage"


def ros1_frame(frame: str) -> str:
    """A frame name as ROS 1 tools wrote it: with a leading slash."""
    return frame if frame.startswith("/") else "/" + frame


class Ros1BagWriter:
    """A ROS 1 bag being written: `scans`, `odometry` and `transforms` add messages; use as a context manager
    (the bag is renamed into place when the block ends without an error). Frame names are written as given:
    pass them through `ros1_frame` for a ROS 1 look."""

    def __init__(self, path: str | Path, *, force: bool = False, inputs=()) -> None:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.path = outputs.check_output(path, force=force, inputs=inputs)
        self.force = force
        self.store = get_typestore(Stores.ROS1_NOETIC)
        # rosbags' Noetic store lacks tf2_msgs; its one message, as tf2_msgs/msg/TFMessage.msg defines it
        self.store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", TF))
        self.tmp: Path | None = None
        self.writer: Any = None  # a rosbags Writer while open
        self.conns: dict[str, object] = {}
        self.seq = 0

    def __enter__(self) -> Ros1BagWriter:
        from rosbags.rosbag1 import Writer

        with outputs.critical():
            self.tmp = outputs.temp_path(self.path)
            outputs.track(self.tmp)
        try:
            self.writer = Writer(self.tmp)
            self.writer.open()
        except OSError as exc:
            outputs.discard(self.tmp)
            raise outputs.os_error(exc, self.path, "creating a file there") from None
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        assert self.tmp is not None  # made by __enter__
        if exc_type is not None:
            try:
                self.writer.close()
            except Exception:  # the error that ended the block is the one to report
                pass
            outputs.discard(self.tmp)
            return
        try:
            with outputs.writing(self.path):
                self.writer.close()
                with open(self.tmp, "rb+") as f:
                    os.fsync(f.fileno())
        except BaseException:
            outputs.discard(self.tmp)
            raise
        outputs.commit(self.tmp, self.path, self.force)

    def _write(self, topic: str, msgtype: str, stamp_ns: int, msg) -> None:
        if topic not in self.conns:
            self.conns[topic] = self.writer.add_connection(topic, msgtype, typestore=self.store)
        with outputs.writing(self.path):
            self.writer.write(self.conns[topic], int(stamp_ns), self.store.serialize_ros1(msg, msgtype))

    def _header(self, stamp_ns: int, frame: str):
        T = self.store.types
        self.seq += 1
        stamp = T["builtin_interfaces/msg/Time"](
            sec=int(stamp_ns // 1_000_000_000), nanosec=int(stamp_ns % 1_000_000_000)
        )
        return T["std_msgs/msg/Header"](seq=self.seq, stamp=stamp, frame_id=frame)

    def scans(self, run: ScanRun, topic: str = "/scan") -> None:
        """One sensor_msgs/LaserScan per scan, stamped (header and bag time) with the scan's stamp, in the
        geometry's frame."""
        T, g = self.store.types, run.geometry
        empty = np.zeros(0, np.float32)
        for k, stamp in enumerate(run.stamps.tolist()):
            inten = run.intensities[k] if run.intensities is not None and run.intensities.shape[1] else empty
            msg = T[SCAN](
                header=self._header(stamp, g.frame_id),
                angle_min=float(g.angle_min),
                angle_max=g.angle_max,
                angle_increment=float(g.angle_increment),
                time_increment=float(g.time_increment),
                scan_time=float(g.scan_time),
                range_min=float(g.range_min),
                range_max=float(g.range_max),
                ranges=np.ascontiguousarray(run.ranges[k], np.float32),
                intensities=np.ascontiguousarray(inten, np.float32),
            )
            self._write(topic, SCAN, stamp, msg)

    def odometry(self, odom: Odometry, topic: str = "/odom") -> None:
        """One nav_msgs/Odometry per pose (frame_id -> child_frame_id, zero twist and covariances)."""
        T = self.store.types
        cov = np.zeros(36)
        zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        for t, x, y, th in zip(odom.stamps, odom.x, odom.y, odom.theta, strict=True):
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=float(libm.sin(th / 2)), w=float(libm.cos(th / 2))
                ),
            )
            msg = T[ODOMETRY](
                header=self._header(int(t), odom.frame_id),
                child_frame_id=odom.child_frame_id,
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov
                ),
            )
            self._write(topic, ODOMETRY, int(t), msg)

    def transforms(self, stamp_ns: int, transforms: list[Transform], topic: str = "/tf") -> None:
        """One tf2_msgs/TFMessage holding `transforms`, written at `stamp_ns`."""
        T = self.store.types
        out = []
        for tr in transforms:
            out.append(
                T["geometry_msgs/msg/TransformStamped"](
                    header=self._header(tr.stamp_ns, tr.parent),
                    child_frame_id=tr.child,
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=T["geometry_msgs/msg/Vector3"](x=tr.x, y=tr.y, z=tr.z),
                        rotation=T["geometry_msgs/msg/Quaternion"](x=tr.qx, y=tr.qy, z=tr.qz, w=tr.qw),
                    ),
                )
            )
        self._write(topic, TF, stamp_ns, T[TF](transforms=out))
