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
    """The `ros2msg` schema text of a type with its dependencies, as ROS 2 writes it in MCAP: from
    msg/schemas.json for the types datmo writes (no type store to build: a tenth of a second at start-up;
    tests check the table against the type store), else from the type store."""
    text = _schema_table().get(msgtype)
    if text is None:
        text, _ = typestore().generate_msgdef(msgtype, ros_version=2)
    return text


SCHEMA_TABLE = "schemas.json"  # in datmo_cli/msg; python -m datmo_cli.logs.types rewrites it
WRITTEN_TYPES = (LASERSCAN, ODOMETRY, MARKER_ARRAY, SEGMENTS, FEATURES, LANDMARKS, TRACKS, GROUND_TRUTH)


@cache
def _schema_table() -> dict[str, str]:
    import json

    entry = resources.files("datmo_cli.msg").joinpath(SCHEMA_TABLE)
    return json.loads(entry.read_text(encoding="utf-8")) if entry.is_file() else {}


def schema_table() -> dict[str, str]:
    """{type: schema text} of WRITTEN_TYPES from the type store (what msg/schemas.json must hold)."""
    return {t: typestore().generate_msgdef(t, ros_version=2)[0] for t in WRITTEN_TYPES}


# Field definitions as rosbags' type store gives them ((node, spec) per field; node 1 base type, 2 named
# type, 3 fixed array, 4 sequence), read from the .msg files without building the store (cdr needs them).
BASE, NAME, ARRAY, SEQUENCE = 1, 2, 3, 4
_BUILTIN_FIELDS = {"builtin_interfaces/msg/Time": [("sec", (BASE, ("int32", 0))), ("nanosec", (BASE, ("uint32", 0)))]}
_BASE_TYPES = {
    "bool",
    "byte",
    "char",
    "int8",
    "uint8",
    "int16",
    "uint16",
    "int32",
    "uint32",
    "int64",
    "uint64",
    "float32",
    "float64",
    "string",
}


@cache
def fields(msgtype: str) -> tuple:
    """The fields of `msgtype`, [(name, (node, spec))] as in rosbags' `typestore().fielddefs[msgtype][1]`:
    parsed from datmo's .msg files for datmo_msgs (and known for builtin_interfaces/Time), else the store's."""
    if msgtype in _BUILTIN_FIELDS:
        return tuple(_BUILTIN_FIELDS[msgtype])
    text = _msg_texts().get(msgtype)
    if text is None:
        return tuple(typestore().fielddefs[msgtype][1])
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        kind, name = line.split()[:2]
        if "=" in name or "=" in kind:
            continue  # a constant
        out.append((name, _field_type(kind, msgtype)))
    return tuple(out)


_msg_texts = cache(datmo_msg_files)


@cache
def constants(msgtype: str) -> dict[str, int]:
    """The integer constants of datmo_msgs type `msgtype` ({name: value}, in file order), as rosbags' type
    store gives them (class attributes of `typestore().types[msgtype]`): parsed from its .msg file without
    building the store (vocabulary needs them at start-up; tests check them against the store)."""
    out = {}
    for line in _msg_texts()[msgtype].splitlines():
        line = line.split("#", 1)[0].strip()
        if "=" in line:
            kind, assignment = line.split(None, 1)
            name, value = (s.strip() for s in assignment.split("=", 1))
            out[name] = int(value, 0)
    return out


def _field_type(kind: str, owner: str) -> tuple:
    if kind.endswith("]"):
        inner, count = kind[:-1].split("[")
        return (
            (SEQUENCE, (_field_type(inner, owner), 0))
            if not count
            else (ARRAY, (_field_type(inner, owner), int(count)))
        )
    if kind in _BASE_TYPES:
        return BASE, (kind, 0)
    if kind == "Header":
        return NAME, "std_msgs/msg/Header"
    pkg, _, name = kind.rpartition("/")
    pkg = pkg or owner.split("/")[0]
    return NAME, f"{pkg}/msg/{name}"


if __name__ == "__main__":  # rewrite msg/schemas.json from the type store
    import json
    from pathlib import Path

    path = Path(__file__).parent.parent / "msg" / SCHEMA_TABLE
    path.write_text(json.dumps(schema_table(), indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(f"{path}: {len(WRITTEN_TYPES)} schemas")
