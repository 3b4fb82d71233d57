"""Track markers: CDR bytes identical to rosbags' serialisation of the same MarkerArray."""

from __future__ import annotations

import numpy as np
import pytest

from datmo_cli.logs import cdr, types
from datmo_cli.logs.markers import CUBE_LIST, DELETEALL, LINE_LIST, SPHERE_LIST, TEXT_VIEW_FACING
from datmo_cli.tracking.markers import tail_segments, track_markers

pytestmark = pytest.mark.unit


def _tracks() -> np.ndarray:
    tr = np.zeros(4, cdr.element_dtype(types.TRACK))
    tr["id"] = [4, 5, 9, 12]
    tr["x"], tr["y"] = [1, 2, 3, 4], [0, 1, -1, 2]
    tr["world_x"], tr["world_y"] = [11, 12, 13, 14], [5, 6, 7, 8]
    tr["vx"] = [0.5, 0, 0, 1]
    tr["classification"] = [1, 2, 3, 0]
    tr["status"] = [1, 2, 0, 1]
    tr["mobility"] = [0, 1, 1, 1]  # a still person, two movers (one tentative), a mover
    return tr


def test_bytes_equal_rosbags_and_content():
    ring = np.zeros((4, 4, 2))
    ring[0, :3] = [[0, 0], [0.5, 0], [1, 0]]
    ring[1, 0] = [2, 1]
    count = np.array([3, 1, 2, 0])
    for frame, world in [("laser", False), ("odom", True)]:
        data = track_markers(1_600_000_000_123_456_789, frame, _tracks(), ring, count, world=world)
        store = types.typestore()
        msg = store.deserialize_cdr(data, types.MARKER_ARRAY)
        assert bytes(store.serialize_cdr(msg, types.MARKER_ARRAY)) == data
        kinds = [(m.type, m.action) for m in msg.markers]
        assert kinds[0][1] == DELETEALL
        assert [k[0] for k in kinds[1:6]] == [SPHERE_LIST, SPHERE_LIST, CUBE_LIST, LINE_LIST, LINE_LIST]
        labels = [m.text for m in msg.markers if m.type == TEXT_VIEW_FACING]
        assert labels == ["4", "5", "12"]  # confirmed and coasting people and movers only
        assert all(m.header.frame_id == frame and m.header.stamp.nanosec == 123_456_789 for m in msg.markers)
        person = msg.markers[1].points
        assert len(person) == 1 and person[0].x == (11 if world else 1)
        assert len(msg.markers[4].points) == 6  # three velocity arrows
        assert len(msg.markers[5].points) == 4  # one tail of three points as two segments


def test_no_tracks():
    data = track_markers(5, "laser", np.zeros(0, cdr.element_dtype(types.TRACK)))
    msg = types.typestore().deserialize_cdr(data, types.MARKER_ARRAY)
    assert len(msg.markers) == 6


def test_tail_segments_follow_the_ring_buffer_oldest_first():
    T = 3
    ring = np.zeros((1, T, 2))
    for n in range(5):  # write positions 0..4 at x = n; the ring keeps the last three
        ring[0, n % T] = [n, 0]
    seg = tail_segments(ring, np.array([5]))
    assert seg[:, 0].tolist() == [2, 3, 3, 4]


def test_kernel_tails_equal_tail_segments():
    from datmo_cli.tracking import _marker_kernels

    rng = np.random.default_rng(0)
    ring, count = rng.normal(size=(5, 6, 2)), np.array([0, 1, 4, 6, 13])
    shown = np.ones(5, bool)
    z = np.zeros(5)
    tails = _marker_kernels.marker_points(
        z, z, z, z, np.zeros(5, np.int64), shown, 0.3, np.zeros((4, 4), np.float32), ring, count
    )[7]
    assert np.array_equal(tails, tail_segments(ring, count))


def test_static_clutter_is_a_dot_without_arrow_tail_or_label():
    tr = np.zeros(2, cdr.element_dtype(types.TRACK))
    tr["id"], tr["x"], tr["vx"] = [7, 8], [1.0, 2.0], [0.3, 0.3]
    tr["classification"], tr["status"], tr["mobility"] = [3, 3], [1, 1], [0, 1]  # static, dynamic
    ring = np.zeros((2, 4, 2))
    ring[:, :, 0] = np.arange(4)
    msg = types.typestore().deserialize_cdr(track_markers(5, "laser", tr, ring, np.array([4, 4])), types.MARKER_ARRAY)
    assert len(msg.markers[3].points) == 2  # both drawn
    assert len(msg.markers[4].points) == 2  # one arrow: the mover's
    assert len(msg.markers[5].points) == 6  # its tail of four points
    assert [m.text for m in msg.markers if m.type == TEXT_VIEW_FACING] == ["8"]
