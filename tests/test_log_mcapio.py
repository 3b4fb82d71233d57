"""Writing and reading logs: round trips, Foxglove/ROS 2 conventions, provenance, and safety rules."""

from __future__ import annotations

import hashlib
import warnings

import numpy as np
import pytest
from mcap.reader import make_reader

from datmo_cli.base.errors import GeometryError, InputError, MissingChannelError, OutputExistsError
from datmo_cli.logs import cdr, mcapio, types
from datmo_cli.logs.scan import Odometry, ScanGeometry, ScanRun

pytestmark = pytest.mark.unit

GEOM = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, 0.0, 0.2, "laser")


def make_run(n: int = 50, seed: int = 0, geometry: ScanGeometry = GEOM) -> ScanRun:
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(0.1, 8, (n, geometry.n_beams)).astype(np.float32)
    ranges[:, ::17] = np.nan
    ranges[:, 5] = np.inf
    return ScanRun(1_600_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 200_000_000, ranges, geometry)


def write_log(path, run: ScanRun, **kw) -> None:
    with mcapio.LogWriter(path, provenance=mcapio.Provenance("test", {"c0": 0.05}, kw.pop("inputs", [])), **kw) as w:
        w.write_scans(run)


def test_round_trip_and_ros2_conventions(tmp_path):
    run = make_run()
    path = tmp_path / "a.mcap"
    write_log(path, run)
    back = mcapio.read_run(path)
    np.testing.assert_array_equal(back.ranges, run.ranges)
    np.testing.assert_array_equal(back.stamps, run.stamps)
    assert back.geometry.same_beams(run.geometry)
    with open(path, "rb") as f:  # what Foxglove and ros2 bag rely on, read with mcap's own reader
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        (channel,) = summary.channels.values()
        schema = summary.schemas[channel.schema_id]
        assert (channel.topic, channel.message_encoding) == ("/scan", "cdr")
        assert "offered_qos_profiles" in channel.metadata
        assert (schema.name, schema.encoding) == ("sensor_msgs/msg/LaserScan", "ros2msg")
        assert schema.data.decode().startswith("std_msgs/Header header")
        assert all(ci.compression == "zstd" for ci in summary.chunk_indexes)
        msgs = list(reader.iter_messages())
        assert len(msgs) == len(run)
        assert msgs[0][2].log_time == run.stamps[0]


def test_linear_reader_agrees_with_mcap_reader(tmp_path):
    path = tmp_path / "b.mcap"
    run = make_run(300)
    with mcapio.LogWriter(path, chunk_size=20_000) as w:
        w.write_scans(run)
        seg = cdr.encode(
            types.SEGMENTS,
            {"stamp_ns": int(run.stamps[3]), "start": np.array([1], np.uint32), "end": np.array([9], np.uint32)},
        )
        w.write(mcapio.TOPIC_SEGMENTS, types.SEGMENTS, int(run.stamps[3]), seg)
    log = mcapio.read_log(path, topics=None)
    assert log.chunks > 5
    with open(path, "rb") as f:
        expected = [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages()]
    got = sorted((t, s, p) for t, (ss, ps) in log.messages.items() for s, p in zip(ss, ps, strict=True))
    assert got == sorted(expected)
    # time order in the file: the segment message sits right after its scan
    topics_in_order = [t for t, _, _ in expected]
    assert topics_in_order[4] == mcapio.TOPIC_SEGMENTS


def test_provenance_metadata(tmp_path):
    src = tmp_path / "input.log"
    src.write_bytes(b"some input")
    path = tmp_path / "p.mcap"
    write_log(path, make_run(3), inputs=[src])
    meta = mcapio.summary(path).metadata
    assert meta["datmo"]["version"]
    assert meta["datmo"]["command"] == "test"
    assert meta["datmo"]["command_line"].startswith("datmo")
    assert meta["datmo.params"] == {"c0": "0.05"}
    assert meta["datmo.inputs"] == {str(src): hashlib.sha256(b"some input").hexdigest()}


def test_existing_output_needs_force_and_is_kept(tmp_path):
    path = tmp_path / "o.mcap"
    path.write_bytes(b"precious")
    with pytest.raises(OutputExistsError, match="--force"):
        mcapio.LogWriter(path)
    assert path.read_bytes() == b"precious"
    write_log(path, make_run(2), force=True)
    assert len(mcapio.read_run(path)) == 2


def test_failed_write_leaves_no_output_and_no_temp(tmp_path):
    path = tmp_path / "f.mcap"
    with pytest.raises(RuntimeError), mcapio.LogWriter(path) as w:
        w.write_scans(make_run(2))
        raise RuntimeError("interrupted")
    assert list(tmp_path.iterdir()) == []


def test_writes_go_to_a_temp_file_until_complete(tmp_path):
    path = tmp_path / "t.mcap"
    w = mcapio.LogWriter(path)
    w.write_scans(make_run(2))
    assert not path.exists() and w.tmp.exists() and w.tmp.parent == tmp_path
    w.close()
    assert path.exists() and not w.tmp.exists()


def test_output_may_not_overwrite_input(tmp_path):
    path = tmp_path / "same.mcap"
    write_log(path, make_run(2))
    before = path.read_bytes()
    with pytest.raises(InputError, match="overwrite the input"):
        mcapio.LogWriter(path, force=True, provenance=mcapio.Provenance("x", inputs=[path]))
    assert path.read_bytes() == before


def test_copy_from_is_byte_exact_and_keeps_input_metadata(tmp_path):
    src, dst = tmp_path / "src.mcap", tmp_path / "dst.mcap"
    write_log(src, make_run(20))
    before = src.read_bytes()
    with mcapio.LogWriter(dst, provenance=mcapio.Provenance("copy", inputs=[src])) as w:
        w.copy_from(src)
    assert src.read_bytes() == before  # the input is never modified
    a, b = mcapio.read_log(src, topics=None), mcapio.read_log(dst, topics=None)
    assert a.messages == b.messages
    assert b.metadata["input/datmo"]["command"] == "test"
    assert b.metadata["datmo"]["command"] == "copy"


def test_odometry_round_trip(tmp_path):
    path = tmp_path / "odom.mcap"
    odom = Odometry(
        np.arange(5, dtype=np.int64) * 10**8, np.linspace(0, 1, 5), np.zeros(5), np.array([0, 0.5, 3.0, -3.0, -0.1])
    )
    with mcapio.LogWriter(path) as w:
        w.write_scans(make_run(5))
        w.write_odometry(odom)
    back = mcapio.read_odometry(path)
    np.testing.assert_allclose(back.x, odom.x)
    np.testing.assert_allclose(back.theta, odom.theta, atol=1e-12)
    np.testing.assert_allclose(back.at(np.array([5 * 10**7]))[0], [0.125, 0, 0.25])
    assert mcapio.read_odometry(tmp_path / "odom.mcap", topic="/none") is None


def test_truncated_log_yields_complete_chunks_with_warning(tmp_path):
    path = tmp_path / "big.mcap"
    run = make_run(400)
    with mcapio.LogWriter(path, chunk_size=50_000) as w:
        w.write_scans(run)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        part = mcapio.read_run(cut)
    assert any("truncated" in str(w.message) for w in caught)
    assert 0 < len(part) < len(run)
    np.testing.assert_array_equal(part.ranges, run.ranges[: len(part)])


@pytest.mark.parametrize(
    "content, message",
    [(None, "no such file"), (b"", "empty file"), (b"hello, this is not mcap at all", "not an MCAP file")],
)
def test_bad_inputs_are_named(tmp_path, content, message):
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(InputError, match=message) as exc:
        mcapio.read_run(path)
    assert str(path) in str(exc.value)


def test_directory_is_refused(tmp_path):
    with pytest.raises(InputError, match="is a directory"):
        mcapio.read_run(tmp_path)


def test_log_without_scans_says_what_to_run(tmp_path):
    path = tmp_path / "noscan.mcap"
    with mcapio.LogWriter(path) as w:
        w.write(mcapio.TOPIC_SEGMENTS, types.SEGMENTS, 5, cdr.encode(types.SEGMENTS, {"stamp_ns": 5}))
    with pytest.raises(MissingChannelError, match="no messages on /scan; run datmo import"):
        mcapio.read_run(path)
    with pytest.raises(MissingChannelError, match="run datmo track"):
        mcapio.read_messages(path, mcapio.TOPIC_TRACKS)


def test_geometry_change_mid_run_is_refused(tmp_path):
    path = tmp_path / "geo.mcap"
    other = ScanGeometry(-np.pi / 2, np.pi / 180, 181, 0.0, 8.0, frame_id="laser")
    with mcapio.LogWriter(path) as w:
        w.write_scans(make_run(3))
        w.write_scans(ScanRun(make_run(2).stamps + 10**10, np.ones((2, 181)), other))
    with pytest.raises(GeometryError, match="geometry changes at scan 3: 361 beams .* -> 181 beams"):
        mcapio.read_run(path)


def test_rosbags_reads_datmo_logs_as_ros2_bags(tmp_path):
    """rosbags' ROS 2 reader (what ROS tooling does) opens a datmo log and decodes every channel."""
    from rosbags.highlevel import AnyReader

    path = tmp_path / "ros2.mcap"
    run = make_run(4)
    with mcapio.LogWriter(path) as w:
        w.write_scans(run)
        w.write_odometry(Odometry(run.stamps, np.ones(4), np.zeros(4), np.zeros(4)))
        w.write(
            mcapio.TOPIC_TRACKS,
            types.TRACKS,
            int(run.stamps[0]),
            cdr.encode(
                types.TRACKS,
                {
                    "stamp_ns": int(run.stamps[0]),
                    "frame_id": "laser",
                    "tracks": np.zeros(2, cdr.element_dtype(types.TRACK)),
                },
            ),
        )
    with AnyReader([path], default_typestore=types.typestore()) as reader:
        assert {c.msgtype for c in reader.connections} == {types.LASERSCAN, types.ODOMETRY, types.TRACKS}
        decoded = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
    assert len(decoded) == 9
    scans = [m for m in decoded if hasattr(m, "ranges")]
    np.testing.assert_array_equal(scans[2].ranges, run.ranges[2])
