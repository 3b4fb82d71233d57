"""Transforms for /tf and /tf_static: tf2_msgs/msg/TFMessage CDR payloads, planar poses and laser mounts.

The frames of a datmo log: /odom poses are `odom -> base` (the Odometry message's frame_id -> child_frame_id),
one /tf transform per pose; the scan is in its own frame (`laser`), tied to the base by one /tf_static
transform `base -> laser` (the laser pose, identity unless `--laser-pose` gave one). A log whose odometry is the
scanner's own (child frame = the scan's frame: CARMEN's laser poses, poses from scan matching) needs no static
transform. Track markers and landmarks are in the odometry frame when there is odometry, so Foxglove resolves
`odom -> base -> laser` to draw them over the scan.

Frame names are ROS 2's: no leading slash (ROS 1 tools wrote `/base_link`; tf2 refuses such names), see
`ros2_frame`. A mount may also come as a transform that a ROS 1 log repeats on /tf (as static_transform_publisher
and robot_state_publisher did) instead of /tf_static: `ConstantTransforms` finds the /tf transforms that never
change and `chain` the transforms that join two frames.

Everything is planar: poses are (x, y, yaw) in metres and radians, z = 0, rotation about z only. Payloads
are encoded with struct (the layout rosbags' serialiser gives, byte for byte; tests check it), so writing a
transform per pose needs no type store.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, replace

import numpy as np

from datmo_cli.base import libm

from .scan import Odometry

TF_MESSAGE = "tf2_msgs/msg/TFMessage"
BASE_FRAME = "base_link"
LASER_POSE_RECORD = "datmo.laser_pose"  # metadata record of the laser pose given on the command line
# The ros2msg schema of TFMessage with its dependencies, as rosbags' type store generates it (a test checks).
SCHEMA = "\n".join(
    [
        "geometry_msgs/TransformStamped[] transforms",
        "=" * 80,
        "MSG: geometry_msgs/TransformStamped",
        "std_msgs/Header header",
        "string child_frame_id",
        "geometry_msgs/Transform transform",
        "=" * 80,
        "MSG: std_msgs/Header",
        "builtin_interfaces/Time stamp",
        "string frame_id",
        "=" * 80,
        "MSG: builtin_interfaces/Time",
        "int32 sec",
        "uint32 nanosec",
        "=" * 80,
        "MSG: geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation",
        "geometry_msgs/Quaternion rotation",
        "=" * 80,
        "MSG: geometry_msgs/Vector3",
        "float64 x",
        "float64 y",
        "float64 z",
        "=" * 80,
        "MSG: geometry_msgs/Quaternion",
        "float64 x",
        "float64 y",
        "float64 z",
        "float64 w",
        "",
    ]
)

_CDR_HEADER = b"\x00\x01\x00\x00"  # CDR, little endian
_U32, _STAMP, _POSE = struct.Struct("<I"), struct.Struct("<iI"), struct.Struct("<7d")


@dataclass(frozen=True)
class Transform:
    """One geometry_msgs/TransformStamped: `child` in `parent` at `stamp_ns`; translation in metres, rotation
    as a unit quaternion."""

    stamp_ns: int
    parent: str
    child: str
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    qx: float = 0.0
    qy: float = 0.0
    qz: float = 0.0
    qw: float = 1.0

    @classmethod
    def planar(cls, stamp_ns: int, parent: str, child: str, x: float, y: float, yaw: float) -> Transform:
        """A transform in the plane: (x, y) metres, yaw radians about z."""
        return cls(
            int(stamp_ns), parent, child, float(x), float(y), 0.0, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)
        )

    @property
    def yaw(self) -> float:
        """Rotation about z, radians (the planar part of the quaternion)."""
        return math.atan2(2 * (self.qw * self.qz + self.qx * self.qy), 1 - 2 * (self.qy * self.qy + self.qz * self.qz))


@dataclass(frozen=True)
class LaserPose:
    """Where the scanner sits on the robot: its frame's origin in the base frame (metres) and its yaw (radians)."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    @property
    def identity(self) -> bool:
        return self.x == 0.0 and self.y == 0.0 and self.yaw == 0.0

    def record(self, base: str, laser: str) -> dict[str, str]:
        """The metadata record LASER_POSE_RECORD: the pose and the frames it joins."""
        return {
            "parent": base,
            "child": laser,
            "x_m": repr(self.x),
            "y_m": repr(self.y),
            "yaw_deg": repr(math.degrees(self.yaw)),
        }


# ------------------------------------------------------------------------------------------- CDR payloads


def _pad(buf: bytearray, n: int) -> None:
    buf += b"\x00" * ((-(len(buf) - 4)) % n)  # alignment counts from after the 4-byte encapsulation header


def _put_string(buf: bytearray, text: str) -> None:
    raw = text.encode() + b"\x00"
    _pad(buf, 4)
    buf += _U32.pack(len(raw)) + raw


def encode_tf(transforms: list[Transform]) -> bytes:
    """A tf2_msgs/msg/TFMessage payload (CDR) holding `transforms`."""
    buf = bytearray(_CDR_HEADER)
    buf += _U32.pack(len(transforms))
    for t in transforms:
        _pad(buf, 4)
        buf += _STAMP.pack(t.stamp_ns // 1_000_000_000, t.stamp_ns % 1_000_000_000)
        _put_string(buf, t.parent)
        _put_string(buf, t.child)
        _pad(buf, 8)
        buf += _POSE.pack(t.x, t.y, t.z, t.qx, t.qy, t.qz, t.qw)
    return bytes(buf)


def _get_string(data: bytes, pos: int) -> tuple[str, int]:
    pos += (-pos) % 4
    n = _U32.unpack_from(data, 4 + pos)[0]
    if n == 0 or 8 + pos + n > len(data):
        raise ValueError(f"a string of {n} bytes at byte {pos + 4} runs past the end of the {len(data)}-byte message")
    return data[8 + pos : 8 + pos + n - 1].decode("utf-8", "replace"), pos + 4 + n


def decode_tf(data: bytes) -> list[Transform]:
    """The transforms of a CDR tf2_msgs/msg/TFMessage payload; ValueError when it is not one."""
    data = bytes(data)
    if data[:2] != _CDR_HEADER[:2]:
        raise ValueError("not little-endian CDR data")
    try:
        count, pos, out = _U32.unpack_from(data, 4)[0], 4, []
        if count > len(data) // 64:  # a transform takes at least 64 bytes
            raise ValueError(f"{count} transforms cannot fit in {len(data)} bytes")
        for _ in range(count):
            pos += (-pos) % 4
            sec, nsec = _STAMP.unpack_from(data, 4 + pos)
            parent, pos = _get_string(data, pos + 8)
            child, pos = _get_string(data, pos)
            pos += (-pos) % 8
            out.append(Transform(sec * 1_000_000_000 + nsec, parent, child, *_POSE.unpack_from(data, 4 + pos)))
            pos += _POSE.size
    except struct.error:
        raise ValueError("a TFMessage runs past the end of its payload") from None
    return out


def decode_odometry(payloads: list[bytes]) -> Odometry:
    """The planar poses of CDR nav_msgs/msg/Odometry payloads (header stamps, x, y, yaw) with the frames of
    the last; ValueError for a payload that is not one."""
    n = len(payloads)
    stamps, xs, ys, ths = np.empty(n, np.int64), np.empty(n), np.empty(n), np.empty(n)
    frame, child = "odom", BASE_FRAME
    for i, p in enumerate(payloads):
        p = bytes(p)
        if p[:2] != _CDR_HEADER[:2]:
            raise ValueError("not little-endian CDR data")
        try:
            sec, nsec = _STAMP.unpack_from(p, 4)
            frame, pos = _get_string(p, 8)
            child, pos = _get_string(p, pos)
            pos += (-pos) % 8
            x, y, _, qx, qy, qz, qw = _POSE.unpack_from(p, 4 + pos)
        except struct.error:
            raise ValueError("an Odometry message runs past the end of its payload") from None
        stamps[i], xs[i], ys[i] = sec * 1_000_000_000 + nsec, x, y
        ths[i] = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    return Odometry(stamps, xs, ys, ths, frame, child)


def header_frame(payload: bytes) -> str:
    """The header frame_id of a CDR message whose first field is a std_msgs/Header (a LaserScan's)."""
    return _get_string(bytes(payload), 8)[0]


def odometry_tf(odom: Odometry) -> list[bytes]:
    """One TFMessage payload per pose: odom.frame_id -> odom.child_frame_id at the pose's stamp."""
    return [
        encode_tf([Transform.planar(t, odom.frame_id, odom.child_frame_id, x, y, th)])
        for t, x, y, th in zip(odom.stamps.tolist(), odom.x.tolist(), odom.y.tolist(), odom.theta.tolist(), strict=True)
    ]


def mount_tf(stamp_ns: int, base: str, laser: str, pose: LaserPose) -> bytes:
    """The /tf_static payload `base -> laser` of a laser pose."""
    return encode_tf([Transform.planar(stamp_ns, base, laser, pose.x, pose.y, pose.yaw)])


# ------------------------------------------------------------------------------------------- planar poses


def _compose(x, y, th, mx: float, my: float, mth: float):
    c, s = libm.cos(th), libm.sin(th)
    return x + c * mx - s * my, y + s * mx + c * my, libm.arctan2(libm.sin(th + mth), libm.cos(th + mth))


def base_odometry(sensor: Odometry, pose: LaserPose, base: str = BASE_FRAME) -> Odometry:
    """The base's poses under scanner poses `sensor` (e.g. CARMEN's laser poses) for a scanner at `pose` on
    the base: base = sensor ∘ pose⁻¹, child frame `base`."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    ix, iy = -(c * pose.x + s * pose.y), -(-s * pose.x + c * pose.y)
    x, y, th = _compose(sensor.x, sensor.y, sensor.theta, ix, iy, -pose.yaw)
    return Odometry(
        sensor.stamps, np.asarray(x, float), np.asarray(y, float), np.asarray(th, float), sensor.frame_id, base
    )


def chain(transforms: list[Transform], base: str, laser: str) -> list[Transform] | None:
    """The transforms that lead from frame `laser` up to frame `base` (laser's parent first; a later transform
    of the same child replaces an earlier one), [] when the frames are the same, None when they do not join."""
    parent = {t.child: t for t in transforms}
    out: list[Transform] = []
    frame, seen = laser, set()
    while frame != base:
        t = parent.get(frame)
        if t is None or frame in seen:
            return None
        seen.add(frame)
        out.append(t)
        frame = t.parent
    return out


def static_chain(statics: list[Transform], base: str, laser: str) -> LaserPose | None:
    """The pose of frame `laser` in frame `base` through the static transforms (last one wins for a child),
    or None when they do not join the two."""
    links = chain(statics, base, laser)
    if links is None:
        return None
    x = y = yaw = 0.0
    for t in links:
        c, s = math.cos(t.yaw), math.sin(t.yaw)
        x, y, yaw = t.x + c * x - s * y, t.y + s * x + c * y, t.yaw + yaw
    return LaserPose(x, y, math.atan2(math.sin(yaw), math.cos(yaw)))


def ros2_frame(name: str) -> str:
    """A frame name as ROS 2 writes it: without ROS 1's leading slash ("/base_link" -> "base_link")."""
    return name.lstrip("/") or name


def ros2_frames(transform: Transform) -> Transform:
    """`transform` with ros2_frame names."""
    return replace(transform, parent=ros2_frame(transform.parent), child=ros2_frame(transform.child))


def without_slashes(payload: bytes) -> bytes:
    """A TFMessage payload with ros2_frame names: `payload` itself when no name has a leading slash."""
    found = decode_tf(payload)
    if not any(t.parent.startswith("/") or t.child.startswith("/") for t in found):
        return payload
    return encode_tf([ros2_frames(t) for t in found])


class ConstantTransforms:
    """The /tf transforms of a log that never change: `add` every TFMessage's transforms in turn; `constant`
    gives, per (parent, child), the first transform of the pairs whose translation and rotation stayed within
    `tolerance` (metres, and quaternion components) of it in every message."""

    def __init__(self, tolerance: float = 1e-9) -> None:
        self.tolerance = tolerance
        self.first: dict[tuple[str, str], Transform] = {}
        self.varies: set[tuple[str, str]] = set()

    def add(self, transforms: list[Transform]) -> None:
        for t in transforms:
            key = (t.parent, t.child)
            f = self.first.get(key)
            if f is None:
                self.first[key] = t
            elif key not in self.varies:
                a = np.array([f.x, f.y, f.z, f.qx, f.qy, f.qz, f.qw])
                b = np.array([t.x, t.y, t.z, t.qx, t.qy, t.qz, t.qw])
                if not np.all(np.abs(a - b) <= self.tolerance):
                    self.varies.add(key)

    def constant(self) -> list[Transform]:
        return [t for key, t in self.first.items() if key not in self.varies]


def sensor_odometry(odom: Odometry | None, statics: list[Transform], laser: str) -> Odometry | None:
    """The scanner's poses under base poses `odom`: odom ∘ (the static chain from odom's child frame to the
    scanner's frame `laser`). `odom` itself when its child is the scanner's frame, no static transform joins
    them, or the chain is the identity (the poses then stay bit for bit)."""
    if odom is None or odom.child_frame_id == laser:
        return odom
    mount = static_chain(statics, odom.child_frame_id, laser)
    if mount is None or mount.identity:
        return odom
    x, y, th = _compose(odom.x, odom.y, odom.theta, mount.x, mount.y, mount.yaw)
    return Odometry(
        odom.stamps, np.asarray(x, float), np.asarray(y, float), np.asarray(th, float), odom.frame_id, laser
    )
