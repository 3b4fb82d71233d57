"""The numpy CDR codecs against rosbags' serializer: same bytes, lossless round trips."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from datmo_cli.logs import cdr, types
from datmo_cli.logs.scan import GeometryChangeError, ScanGeometry, ScanRun, decode_scan, decode_scans, encode_scans

pytestmark = pytest.mark.unit

STORE = types.typestore()
SPECIALS = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-30, 3.4e38], np.float32)


def rosbags_scan(stamp: int, ranges: np.ndarray, inten: np.ndarray, g: ScanGeometry):
    T = STORE.types
    return T[types.LASERSCAN](
        header=T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id=g.frame_id
        ),
        angle_min=g.angle_min,
        angle_max=g.angle_max,
        angle_increment=g.angle_increment,
        time_increment=g.time_increment,
        scan_time=g.scan_time,
        range_min=g.range_min,
        range_max=g.range_max,
        ranges=ranges,
        intensities=inten,
    )


@settings(max_examples=60, deadline=None)
@given(
    n_scans=st.integers(1, 4),
    n_beams=st.integers(1, 400),
    frame_len=st.integers(0, 70),
    with_intensities=st.booleans(),
    seed=st.integers(0, 2**31),
)
def test_laserscan_bytes_equal_rosbags(n_scans, n_beams, frame_len, with_intensities, seed):
    rng = np.random.default_rng(seed)
    step = float(rng.uniform(1e-4, min(0.05, 6.28 / max(n_beams - 1, 1))))  # the beams span at most a turn
    g = ScanGeometry(
        float(rng.uniform(-3, 0)),
        step,
        n_beams,
        float(rng.uniform(0, 1)),
        float(rng.uniform(1, 100)),
        float(rng.uniform(0, 1e-3)),
        float(rng.uniform(0, 0.5)),
        "f" * frame_len,
    )
    ranges = rng.uniform(0, 80, (n_scans, n_beams)).astype(np.float32)
    ranges[rng.random(ranges.shape) < 0.2] = rng.choice(SPECIALS, size=1)[0]
    inten = rng.uniform(0, 1e4, (n_scans, n_beams if with_intensities else 0)).astype(np.float32)
    stamps = rng.integers(0, 2**31 - 1, n_scans, dtype=np.int64) * 10**9 + rng.integers(0, 10**9, n_scans)
    run = ScanRun(stamps, ranges, g, inten)
    payloads = encode_scans(run)
    for i, p in enumerate(payloads):
        expected = bytes(STORE.serialize_cdr(rosbags_scan(int(stamps[i]), ranges[i], inten[i], g), types.LASERSCAN))
        assert p == expected
        msg = STORE.deserialize_cdr(p, types.LASERSCAN)
        np.testing.assert_array_equal(msg.ranges, ranges[i])
    back = decode_scans(payloads)
    np.testing.assert_array_equal(back.stamps, stamps)
    np.testing.assert_array_equal(back.ranges, ranges)
    np.testing.assert_array_equal(back.intensities, inten)
    assert back.geometry.same_beams(g)
    assert back.geometry.frame_id == g.frame_id


def test_decode_handles_mixed_lengths_and_missing_intensities():
    g = ScanGeometry(-1.0, 0.01, 10, 0.0, 8.0)
    a = encode_scans(ScanRun([1], np.ones((1, 10)), g, np.ones((1, 10))))[0]
    b = encode_scans(ScanRun([2], np.full((1, 10), 2.0), g))[0]
    run = decode_scans([a, b])
    assert run.intensities.shape == (2, 10)
    assert np.isnan(run.intensities[1]).all() and (run.intensities[0] == 1).all()


def test_geometry_change_is_refused_with_index():
    g1 = ScanGeometry(-1.0, 0.01, 10, 0.0, 8.0)
    g2 = ScanGeometry(-1.0, 0.02, 10, 0.0, 8.0)
    p1 = encode_scans(ScanRun([1, 2], np.ones((2, 10)), g1))
    p2 = encode_scans(ScanRun([3], np.ones((1, 10)), g2))
    with pytest.raises(GeometryChangeError, match="at scan 2"):
        decode_scans(p1 + p2)
    g3 = ScanGeometry(-1.0, 0.01, 11, 0.0, 8.0)
    p3 = encode_scans(ScanRun([3], np.ones((1, 11)), g3))
    with pytest.raises(GeometryChangeError, match="at scan 2: 10 beams .* -> 11 beams"):
        decode_scans(p1 + p3)


def test_decode_scan_rejects_bad_length():
    g = ScanGeometry(-1.0, 0.01, 10, 0.0, 8.0)
    p = encode_scans(ScanRun([1], np.ones((1, 10)), g))[0]
    with pytest.raises(ValueError):
        decode_scan(p[:-3])


def _random_struct(msgtype: str, n: int, rng) -> np.ndarray:
    dt = cdr.element_dtype(msgtype)
    raw = rng.integers(0, 256, n * dt.itemsize, dtype=np.uint8).tobytes()
    arr = np.frombuffer(raw, dt).copy()
    for name in dt.names:  # keep floats finite so == comparisons hold
        if dt[name].kind == "f" or (dt[name].subdtype and dt[name].subdtype[0].kind == "f"):
            arr[name] = rng.uniform(-100, 100, arr[name].shape)
        elif dt[name].names:  # builtin_interfaces/Time: nanosec < 1e9
            arr[name]["sec"] = rng.integers(0, 2**31 - 1, n)
            arr[name]["nanosec"] = rng.integers(0, 10**9, n)
    return arr


def _fill(msgtype: str, rng, n: int) -> dict:
    values = {
        "stamp_ns": int(rng.integers(0, 2**31 - 1)) * 10**9 + int(rng.integers(0, 10**9)),
        "frame_id": "laser_frame"[: int(rng.integers(0, 12))],
    }
    for f in cdr._plan(msgtype):
        if f.kind == "structseq":
            _, fields = STORE.fielddefs[msgtype]
            inner = dict(fields)[f.name][1][0][1]
            values[f.name] = _random_struct(inner, n, rng)
        elif f.kind == "seq":
            values[f.name] = rng.integers(0, 1000, n).astype(f.dtype)
        elif f.kind == "scalar":
            values[f.name] = float(rng.uniform(-1e3, 1e3)) if f.dtype.kind == "f" else int(rng.integers(0, 100))
    return values


@pytest.mark.parametrize("msgtype", [types.SEGMENTS, types.FEATURES, types.LANDMARKS, types.TRACKS, types.GROUND_TRUTH])
@pytest.mark.parametrize("n", [0, 1, 7])
def test_datmo_msgs_round_trip_and_match_rosbags(msgtype, n):
    rng = np.random.default_rng(n)
    values = _fill(msgtype, rng, n)
    data = cdr.encode(msgtype, values)
    msg = STORE.deserialize_cdr(data, msgtype)  # rosbags reads our bytes ...
    assert bytes(STORE.serialize_cdr(msg, msgtype)) == data  # ... and writes the same bytes
    assert msg.header.frame_id == values["frame_id"]
    back = cdr.decode(msgtype, data)
    assert back["stamp_ns"] == values["stamp_ns"]
    for key, value in values.items():
        if isinstance(value, np.ndarray):
            assert back[key].dtype == value.dtype
            np.testing.assert_array_equal(back[key], value)
        elif key not in ("stamp_ns", "frame_id"):
            assert back[key] == pytest.approx(value)


@settings(max_examples=40, deadline=None)
@given(
    msgtype=st.sampled_from([types.SEGMENTS, types.FEATURES, types.LANDMARKS, types.TRACKS]),
    counts=st.lists(st.integers(0, 6), min_size=0, max_size=12),
    frame_len=st.integers(0, 9),
    first=st.integers(0, 3),
    seed=st.integers(0, 2**31),
)
def test_encode_block_gives_encode_s_bytes(msgtype, counts, frame_len, first, seed):
    """One message per stamp from flat arrays and offsets (which need not start at 0): each message's bytes
    are encode's of its slices, whatever the lengths of the frame and of each sequence do to the padding."""
    rng = np.random.default_rng(seed)
    n = len(counts)
    stamps = rng.integers(-(2**31), 2**31 - 1, n) * 10**9 + rng.integers(0, 10**9, n)
    frame = "laser_frame"[:frame_len]
    sequences = {}
    for f in cdr._plan(msgtype)[1:]:
        own = np.roll(counts, int(rng.integers(0, 3))) if n else counts  # each field its own lengths
        offsets = first + np.concatenate([[0], np.cumsum(own)]).astype(np.int64)
        total = int(offsets[-1]) + int(rng.integers(0, 3))  # values past the last message are not written
        raw = rng.integers(0, 256, total * f.dtype.itemsize, dtype=np.uint8).tobytes()
        sequences[f.name] = (np.frombuffer(raw, f.dtype), offsets)
    expected = [
        cdr.encode(
            msgtype,
            {"stamp_ns": int(stamps[k]), "frame_id": frame}
            | {name: values[offsets[k] : offsets[k + 1]] for name, (values, offsets) in sequences.items()},
        )
        for k in range(n)
    ]
    assert cdr.encode_block(msgtype, stamps, frame, sequences) == expected


def test_encode_block_refuses_what_it_cannot_encode():
    with pytest.raises(TypeError, match="header followed by sequences"):
        cdr.encode_block(types.GROUND_TRUTH, [0], "laser", {})
    offsets = np.zeros(3, np.int64)
    with pytest.raises(ValueError, match="3 offsets for 1 messages"):
        cdr.encode_block(types.TRACKS, [0], "laser", {"tracks": (np.zeros(0, cdr.element_dtype(types.TRACK)), offsets)})
    with pytest.raises(OverflowError):
        cdr.encode_block(types.TRACKS, [2**31 * 10**9], "laser", {})


def test_fields_method_md_needs_are_defined():
    line = cdr.element_dtype(types.LINE).names
    for name in ("x_ini", "y_ini", "x_end", "y_end", "rho", "theta", "length", "r_acc"):
        assert name in line
    track = cdr.element_dtype(types.TRACK).names
    for name in ("id", "classification", "mobility", "x", "y", "vx", "vy", "covariance", "occluded"):
        assert name in track
    gt = cdr.element_dtype(types.GROUND_TRUTH_OBJECT).names
    for name in ("id", "classification", "x", "world_x", "visible", "n_beams", "left_leg_x"):
        assert name in gt


def test_layout_check_rejects_non_c_layouts():
    from rosbags.typesys import get_types_from_msg

    STORE.register(get_types_from_msg("uint32 a\nfloat64 b\nuint32 c\n", "datmo_test/msg/Bad"))
    with pytest.raises(TypeError, match="not a C layout"):
        cdr.element_dtype("datmo_test/msg/Bad")


def test_msg_files_ship_in_the_package():
    files = types.datmo_msg_files()
    assert {
        "datmo_msgs/msg/Segments",
        "datmo_msgs/msg/Features",
        "datmo_msgs/msg/Tracks",
        "datmo_msgs/msg/Landmarks",
        "datmo_msgs/msg/GroundTruth",
    } <= set(files)
    assert "MSG: datmo_msgs/Line" in types.schema_text(types.FEATURES)
