"""ROS 2 message types: the rosbags type store with datmo_msgs registered, and their schema text.

The `.msg` files in `datmo_cli/msg` are the single source of the datmo_msgs definitions.
"""

from __future__ import annotations

from functools import cache
from importlib import resources

LASERSCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
SEGMENTS = "datmo_msgs/msg/Segments"
FEATURES = "datmo_msgs/msg/Features"
LANDMARKS = "datmo_msgs/msg/Landmarks"
TRACKS = "datmo_msgs/msg/Tracks"
GROUND_TRUTH = "datmo_msgs/msg/GroundTruth"
LINE = "datmo_msgs/msg/Line"
CIRCLE = "datmo_msgs/msg/Circle"
BLOB = "datmo_msgs/msg/Blob"
LEG = "datmo_msgs/msg/Leg"
LANDMARK = "datmo_msgs/msg/Landmark"
TRACK = "datmo_msgs/msg/Track"
GROUND_TRUTH_OBJECT = "datmo_msgs/msg/GroundTruthObject"


def datmo_msg_files() -> dict[str, str]:
    """Map each datmo_msgs type name to its .msg text, read from the installed package."""
    out = {}
    for entry in resources.files("datmo_cli.msg").iterdir():
        if entry.name.endswith(".msg"):
            out[f"datmo_msgs/msg/{entry.name[:-4]}"] = entry.read_text(encoding="utf-8")
    return dict(sorted(out.items()))


@cache
def typestore():
    """The ROS 2 (Humble) type store with every datmo_msgs type registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    for name, text in datmo_msg_files().items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


@cache
def schema_text(msgtype: str) -> str:
    """The `ros2msg` schema text of a type with its dependencies, as ROS 2 writes it in MCAP."""
    text, _ = typestore().generate_msgdef(msgtype, ros_version=2)
    return text
