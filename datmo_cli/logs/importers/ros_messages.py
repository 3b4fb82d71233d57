"""ROS messages as the bag and MCAP importers meet them: the LaserScan, Odometry and TFMessage type names, the
choice of a topic, transforms (frame names without ROS 1's leading slash; transforms.ros2_frame), and a
deserialised LaserScan's geometry, stamp (ns) and sanity checks."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, overload

from datmo_cli.base import libm

from ...base.errors import InputError
from ..scan import ScanGeometry, geometry_problem, stamp_problem
from ..transforms import ros2_frame

LASERSCAN_TYPES = ("sensor_msgs/msg/LaserScan", "sensor_msgs/LaserScan")
ODOMETRY_TYPES = ("nav_msgs/msg/Odometry", "nav_msgs/Odometry")
# ROS 2's tf2 message, and ROS 1's (tf's tfMessage before tf2; tf2_msgs/TFMessage after): the same fields
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf2_msgs/TFMessage", "tf/msg/tfMessage", "tf/tfMessage")
TF_TOPICS = ("/tf", "/tf_static")


def tf_topics(topics: dict[str, tuple[str, int]]) -> tuple[str, ...]:
    """The /tf and /tf_static topics among `topics` ({topic: (msgtype, count)}) that hold transforms."""
    return tuple(t for t in TF_TOPICS if t in topics and topics[t][0] in TF_TYPES and topics[t][1])


def tf_transforms(msg) -> list:
    """The transforms.Transform list of a deserialised TFMessage (ROS 2, or ROS 1's tf/tfMessage), frame names
    without a leading slash."""
    from ..transforms import Transform, ros2_frame

    out = []
    for t in msg.transforms:
        s, p, q = t.header.stamp, t.transform.translation, t.transform.rotation
        out.append(
            Transform(
                int(s.sec) * 1_000_000_000 + int(s.nanosec),
                ros2_frame(t.header.frame_id),
                ros2_frame(t.child_frame_id),
                float(p.x),
                float(p.y),
                float(p.z),
                float(q.x),
                float(q.y),
                float(q.z),
                float(q.w),
            )
        )
    return out


def tf_payload(msg) -> bytes:
    """A deserialised TFMessage (ROS 2, or ROS 1's tf/tfMessage) as a CDR tf2_msgs/msg/TFMessage payload, frame
    names without a leading slash."""
    from ..transforms import encode_tf

    return encode_tf(tf_transforms(msg))


@dataclass
class TfSurvey:
    """A source's fixed transforms, read before its blocks: everything on /tf_static, and the /tf transforms
    that never change (transforms.ConstantTransforms), frame names without a leading slash."""

    statics: list = field(default_factory=list)
    constant: list = field(default_factory=list)


def survey_tf(messages) -> TfSurvey:
    """The TfSurvey of `messages`: (topic, list of transforms.Transform) of the source's /tf and /tf_static."""
    from ..transforms import ConstantTransforms

    statics, moving = [], ConstantTransforms()
    for topic, found in messages:
        if topic == "/tf_static":
            statics += found
        else:
            moving.add(found)
    return TfSurvey(statics, moving.constant())


@overload
def choose_topic(
    label: str,
    topics: dict[str, tuple[str, int]],
    wanted: str | None,
    types: tuple[str, ...],
    what: str,
    option: str,
    required: Literal[True] = True,
) -> str: ...


@overload
def choose_topic(
    label: str,
    topics: dict[str, tuple[str, int]],
    wanted: str | None,
    types: tuple[str, ...],
    what: str,
    option: str,
    required: bool,
) -> str | None: ...


def choose_topic(
    label: str,
    topics: dict[str, tuple[str, int]],
    wanted: str | None,
    types: tuple[str, ...],
    what: str,
    option: str,
    required: bool = True,
) -> str | None:
    """The topic to read among `topics` ({topic: (msgtype, count)}) of one of `types`.

    `wanted` must be such a topic; otherwise the only one is taken. Several and none chosen raises
    InputError listing them (as does none at all when `required`).
    """
    fit = {t: c for t, (m, c) in topics.items() if m in types}
    listing = ", ".join(f"{t} ({c} messages)" for t, c in sorted(fit.items()))
    if wanted is not None:
        if wanted in fit:
            return wanted
        if wanted in topics:
            raise InputError(f"{label}: {wanted} holds {topics[wanted][0]}, not {what}")
        have = f"its {what} topics: {listing}" if fit else f"it has no {what} topic"
        raise InputError(f"{label}: no topic {wanted}; {have}")
    if not fit:
        if not required:
            return None
        others = ", ".join(f"{t} ({m})" for t, (m, _) in sorted(topics.items())) or "no topics"
        raise InputError(f"{label}: no {what} topic (it has {others})")
    if len(fit) > 1:
        if not required:
            return None
        raise InputError(f"{label}: several {what} topics, choose one with {option}: {listing}")
    return next(iter(fit))


def yaw_of(qx, qy, qz, qw):
    """Yaw (radians) of a quaternion."""
    return libm.arctan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))


def header_stamp(header, log_time: int) -> int:
    """A std_msgs/Header's stamp (ns), or `log_time` when the stamp is zero."""
    ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
    return ns if ns else int(log_time)


def scan_geometry(msg) -> ScanGeometry:
    """The ScanGeometry of a deserialised sensor_msgs/LaserScan."""
    return ScanGeometry(
        angle_min=float(msg.angle_min),
        angle_increment=float(msg.angle_increment),
        n_beams=len(msg.ranges),
        range_min=float(msg.range_min),
        range_max=float(msg.range_max),
        time_increment=float(msg.time_increment),
        scan_time=float(msg.scan_time),
        frame_id=ros2_frame(msg.header.frame_id),
    )


def check_bag_scan(label: str, topic: str, i: int, msg) -> None:
    """InputError naming the file, the topic, scan `i` and the field when a LaserScan read from a bag cannot be
    what a scanner sent: bags have no checksums, so a damaged byte shows only where a message contradicts itself.
    Checked here: the header stamp is after 1970 with nanosec below 10^9; the angles and range limits are finite,
    0 <= range_min < range_max, the angle step is not zero, the beams span at most a turn and reach angle_max
    (within a beam); intensities are none or one a beam. (rosbags refuses a message longer or shorter than its
    fields.) A damaged reading itself is not seen: it is another range, or, outside the limits, not a return."""
    problem = _scan_problem(msg)
    if problem:
        raise InputError(f"{label}: damaged LaserScan on {topic}, scan {i}: {problem}")


def _scan_problem(msg) -> str | None:
    import math

    n, m = len(msg.ranges), len(msg.intensities)
    problem = stamp_problem(int(msg.header.stamp.sec), int(msg.header.stamp.nanosec))
    if problem:
        return problem
    a0, a1, step = float(msg.angle_min), float(msg.angle_max), float(msg.angle_increment)
    r0, r1 = float(msg.range_min), float(msg.range_max)
    for name, value in (
        ("angle_min", a0),
        ("angle_max", a1),
        ("angle_increment", step),
        ("range_min", r0),
        ("range_max", r1),
    ):
        if not math.isfinite(value):
            return f"{name} is {value}"
    problem = geometry_problem(a0, step, n, r0, r1)
    if problem:
        return problem
    if n and abs(a0 + (n - 1) * step - a1) > abs(step) * 1.01 + 1e-4:
        return (
            f"{n} beams from {math.degrees(a0):g}° by {math.degrees(step):g}° end at "
            f"{math.degrees(a0 + (n - 1) * step):g}°, not at angle_max {math.degrees(a1):g}°"
        )
    if m not in (0, n):
        return f"{m} intensities for {n} ranges"
    return None


def scan_stamp(msg, log_time: int) -> int:
    """The header stamp of a message (ns), or its log time when the stamp is zero."""
    return header_stamp(msg.header, log_time)
