"""log.markers: MarkerArray bytes identical to rosbags' serialisation, its codes the type store's, and no CDR
written outside datmo_cli/logs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import datmo_cli
from datmo_cli.logs import markers, types

pytestmark = pytest.mark.unit

PACKAGE = Path(datmo_cli.__file__).parent


@pytest.mark.parametrize("frame_id", ["", "l", "laser", "base_laser_link"])  # every alignment of what follows
def test_the_writer_gives_rosbags_bytes(frame_id: str):
    rng = np.random.default_rng(1)
    w = markers.MarkerArrayWriter(6, markers.header(1_600_000_000_123_456_789, frame_id, "datmo/test"))
    w.marker(0, markers.ARROW, markers.DELETEALL)
    w.marker(
        1,
        markers.SPHERE_LIST,
        markers.ADD,
        scale=(0.5, 0.5, 0.5),
        points=rng.normal(size=(3, 3)),
        colors=rng.random((3, 4)).astype(np.float32),
    )
    w.marker(
        2,
        markers.LINE_LIST,
        markers.ADD,
        pose=(1.0, 2.0, 0.0),
        scale=(0.03, 0.0, 0.0),
        color=(1.0, 0.8, 0.0, 1.0),
        points=rng.normal(size=(4, 3)),
    )
    w.text(103, "3", 1.5, -2.0, z=0.5, height=0.3)
    w.marker(4, markers.CUBE_LIST, markers.ADD, text="odd")
    w.text(1012, "twelve", 0.25, 4.0, z=1.0, height=0.2)
    data = w.bytes()
    store = types.typestore()
    msg = store.deserialize_cdr(data, types.MARKER_ARRAY)
    assert bytes(store.serialize_cdr(msg, types.MARKER_ARRAY)) == data
    assert [m.id for m in msg.markers] == [0, 1, 2, 103, 4, 1012]
    assert all(m.header.frame_id == frame_id and m.ns == "datmo/test" for m in msg.markers)
    assert all(m.header.stamp.sec == 1_600_000_000 and m.header.stamp.nanosec == 123_456_789 for m in msg.markers)
    label = msg.markers[5]
    assert (label.type, label.text, label.scale.z) == (markers.TEXT_VIEW_FACING, "twelve", 0.2)
    assert (label.pose.position.x, label.pose.position.y, label.pose.position.z) == (0.25, 4.0, 1.0)


def test_the_codes_are_the_type_stores():
    marker = types.typestore().types["visualization_msgs/msg/Marker"]
    for name in (
        "ARROW",
        "CUBE",
        "SPHERE",
        "CYLINDER",
        "LINE_STRIP",
        "LINE_LIST",
        "CUBE_LIST",
        "SPHERE_LIST",
        "TEXT_VIEW_FACING",
        "ADD",
        "DELETEALL",
    ):
        assert getattr(markers, name) == getattr(marker, name), name


# The recorder writes its own CDR header until its loop moves into lms2xx/.
def test_no_cdr_is_written_outside_log():
    writers = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel.startswith("log/"):
            continue
        text = path.read_text(encoding="utf-8")
        if "CDR_HEADER" in text or r"b\"\x00\x01\x00\x00" in text or r"b'\x00\x01\x00\x00" in text:
            writers.append(rel)
    assert writers == []
