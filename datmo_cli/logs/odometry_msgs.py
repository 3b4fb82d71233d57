"""nav_msgs/msg/Odometry messages to and from datmo's planar Odometry (x, y in metres, yaw in radians, z = 0)."""

from __future__ import annotations

import numpy as np

from datmo_cli.base import libm

from . import types
from .scan import Odometry


def encode_odometry(odom: Odometry) -> list[bytes]:
    """CDR payloads of nav_msgs/msg/Odometry, one per pose (planar: z = 0, yaw = theta)."""
    store = types.typestore()
    T = store.types
    out = []
    cov = np.zeros(36)
    for t, x, y, th in zip(odom.stamps, odom.x, odom.y, odom.theta, strict=True):
        stamp = T["builtin_interfaces/msg/Time"](sec=int(t // 1_000_000_000), nanosec=int(t % 1_000_000_000))
        header = T["std_msgs/msg/Header"](stamp=stamp, frame_id=odom.frame_id)
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=float(libm.sin(th / 2)), w=float(libm.cos(th / 2))
            ),
        )
        zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        msg = T[types.ODOMETRY](
            header=header,
            child_frame_id=odom.child_frame_id,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov
            ),
        )
        out.append(bytes(store.serialize_cdr(msg, types.ODOMETRY)))
    return out


def decode_odometry(stamps: np.ndarray, payloads: list[bytes]) -> Odometry:
    """The poses of nav_msgs/msg/Odometry CDR payloads stamped `stamps` (ns): x, y of the position, yaw from the
    quaternion; frame ids of the last message ("odom", "base_link" when empty)."""
    store = types.typestore()
    xs, ys, ths = np.empty(len(payloads)), np.empty(len(payloads)), np.empty(len(payloads))
    frame = child = ""
    for i, p in enumerate(payloads):
        msg = store.deserialize_cdr(p, types.ODOMETRY)
        pose = msg.pose.pose
        q = pose.orientation
        xs[i], ys[i] = pose.position.x, pose.position.y
        ths[i] = libm.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        frame, child = msg.header.frame_id, msg.child_frame_id
    return Odometry(stamps, xs, ys, ths, frame or "odom", child or "base_link")
