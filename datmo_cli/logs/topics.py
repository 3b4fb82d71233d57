"""The topics datmo's logs use, the QoS rosbag2 records for them, and which command makes each derived one."""

from __future__ import annotations

TOPIC_SCAN = "/scan"
TOPIC_ODOM = "/odom"
TOPIC_SEGMENTS = "/datmo/segments"
TOPIC_FEATURES = "/datmo/features"
TOPIC_LANDMARKS = "/datmo/landmarks"
TOPIC_TRACKS = "/datmo/tracks"
TOPIC_GROUND_TRUTH = "/datmo/ground_truth"
TOPIC_MARKERS_FEATURES = "/datmo/markers/features"
TOPIC_MARKERS_TRACKS = "/datmo/markers/tracks"
TOPIC_TELEGRAM = "/lms2xx/telegram"
TOPIC_TF = "/tf"
TOPIC_TF_STATIC = "/tf_static"


def _qos_yaml(durability: int) -> str:
    """An offered QoS profile as rosbag2 records it in a channel's metadata (rmw's enums: history 3 and depth 0
    are what an offer reports; reliability 1 reliable; durability 1 transient-local, 2 volatile)."""
    return (
        f"- history: 3\n  depth: 0\n  reliability: 1\n  durability: {durability}\n"
        "  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n"
        "  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n"
        "  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n"
        "  avoid_ros_namespace_conventions: false\n"
    )


# Reliable and volatile, as rosbag2 records a topic of an ordinary publisher (a driver's /scan, /tf): `ros2 bag
# play` offers each topic with the recorded reliability and durability, which subscribers with the default QoS
# (RViz, tf2's /tf listener) accept, and a late subscriber is not sent old messages.
QOS_YAML = _qos_yaml(durability=2)
# Reliable and transient-local, for a latched topic (/tf_static): tf2's listener asks for transient-local, which
# a volatile offer cannot serve, and a late subscriber still gets the last message.
QOS_YAML_LATCHED = _qos_yaml(durability=1)

# Which command makes each derived channel: named in errors about missing channels.
PRODUCER = {
    TOPIC_SCAN: "datmo import, datmo simulate or datmo record",
    TOPIC_SEGMENTS: "datmo segment",
    TOPIC_FEATURES: "datmo features",
    TOPIC_LANDMARKS: "datmo features",
    TOPIC_TRACKS: "datmo track (or datmo run)",
    TOPIC_GROUND_TRUTH: "datmo simulate",
}
