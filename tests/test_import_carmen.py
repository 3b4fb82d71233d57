"""CARMEN / g2o text parsing on tiny hand-made logs: angles, no-return, stamps, poses, malformed lines."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from datmo_cli.base.errors import GeometryError, InputError
from datmo_cli.logs.importers import detect_kind, import_log
from datmo_cli.logs.importers.carmen_conventions import flaser_angles, no_return_limit, stamps_ns
from datmo_cli.logs.importers.carmen_parse import parse_lines

pytestmark = pytest.mark.unit


def flaser(ranges, t: float, pose=(1.0, 2.0, 0.5), name: str = "FLASER") -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    x, y, th = pose
    return f"{name} {len(ranges)} {r} {x} {y} {th} {x} {y} {th} {t:.6f} host {t:.6f}"


def robotlaser(ranges, t: float, start=-1.570796, fov=3.141593, res=0.017453, max_range=50.0, rem=()) -> str:
    r = " ".join(f"{v:g}" for v in ranges)
    rm = " ".join(f"{v:g}" for v in rem)
    rem_part = f"{len(rem)} {rm}".strip()
    return (
        f"ROBOTLASER1 0 {start} {fov} {res} {max_range} 0.1 0 {len(ranges)} {r} {rem_part} "
        f"3 4 0.25 3 4 0.25 0 0 0 0 0 {t:.6f} host {t:.6f}"
    )


def write(tmp_path, name: str, lines: list[str], gz: bool = False):
    path = tmp_path / name
    text = "\n".join(lines) + "\n"
    if gz:
        with gzip.open(path, "wt") as f:
            f.write(text)
    else:
        path.write_text(text)
    return path


@pytest.mark.parametrize(("n", "first", "last"), [(180, -90, 89), (181, -90, 90), (360, -90, 89.5), (361, -90, 90)])
def test_flaser_angle_convention(n, first, last):
    a0, inc = flaser_angles(n)
    angles = np.degrees(a0 + inc * np.arange(n))
    assert angles[0] == pytest.approx(first)
    assert angles[-1] == pytest.approx(last)


def test_no_return_limit_follows_the_codes():
    assert no_return_limit(np.array([1.0, 81.91])) == pytest.approx(81.83)
    assert no_return_limit(np.array([1.0, 51.15])) == 50.0
    assert no_return_limit(np.array([1.0, 50.0])) == 50.0
    assert no_return_limit(np.array([1.0, 32.767])) == pytest.approx(32.767)
    assert no_return_limit(np.array([1.0, 7.0])) == pytest.approx(81.83)
    assert no_return_limit(np.array([1.0, 7.0]), stated_max=8.0) == 8.0


def test_stamps_kept_repaired_or_synthesised():
    ns, note = stamps_ns(np.array([1.5, 2.0, 2.5]))
    assert note is None and ns.tolist() == [1_500_000_000, 2_000_000_000, 2_500_000_000]
    t = np.arange(100, dtype=float)
    t[50] = 48.5  # one step backwards
    ns, note = stamps_ns(t)
    assert "1 stamps go backwards" in note and np.all(np.diff(ns) > 0)
    assert ns[50] == ns[49] + 1_000_000 and ns[51] == 51_000_000_000
    ns, note = stamps_ns(np.full(10, 1.13486e9))
    assert "synthesised" in note and np.all(np.diff(ns) == 1_000_000_000) and ns[0] == 1_134_860_000_000_000_000
    ns, note = stamps_ns(np.array([-0.4, -0.9, 4.29e9]))
    assert ns[0] == 0 and "synthesised" in note


def test_flaser_log_to_run_and_odometry(tmp_path):
    lines = ["# a comment", "PARAM robot_front_laser_max 50 nohost 0", "ODOM 0 0 0 0 0 0 0.5 host 0.5"]
    lines += [flaser([1.0, 2.0, 81.91, 3.0] + [4.0] * 357, 10.0 + i, pose=(i, 2 * i, 0.1 * i)) for i in range(5)]
    lines += ["NEFF 1 2 3"]
    res = import_log(write(tmp_path, "a.log", lines))
    run = res.run
    assert res.kind == "carmen" and res.topic == "FLASER" and res.warnings == []
    assert run.ranges.shape == (5, 361) and run.ranges.dtype == np.float32
    assert run.stamps.tolist() == [10_000_000_000 + i * 1_000_000_000 for i in range(5)]
    assert np.isinf(run.ranges[:, 2]).all() and run.ranges[0, 1] == 2.0
    g = run.geometry
    assert g.range_max == pytest.approx(81.83) and g.angle_min == pytest.approx(-np.pi / 2)
    assert np.degrees(g.angle_increment) == pytest.approx(0.5)
    odom = res.odometry
    assert odom.stamps.tolist() == run.stamps.tolist()
    assert odom.x.tolist() == [0, 1, 2, 3, 4] and odom.y[2] == 4 and odom.theta[3] == pytest.approx(0.3)


def test_gzipped_equals_plain(tmp_path):
    lines = [flaser([1.0] * 180, 1.0 + i) for i in range(3)]
    plain = import_log(write(tmp_path, "p.log", lines))
    packed = import_log(write(tmp_path, "p.log.gz", lines, gz=True))
    assert np.array_equal(plain.run.ranges, packed.run.ranges)
    assert plain.run.stamps.tolist() == packed.run.stamps.tolist()
    assert np.degrees(packed.run.geometry.angle_max) == pytest.approx(89.0)


def test_malformed_lines_are_skipped_and_counted(tmp_path):
    good = [flaser([1.0] * 181, 1.0 + i) for i in range(4)]
    lines = [
        good[0],
        "FLASER 181 1 2 3",
        good[1],
        "FLASER 181 " + "x " * 192,
        "garbage here",
        good[2],
        "ODOM 1 2",
        good[3],
    ]
    res = import_log(write(tmp_path, "m.log", lines))
    assert len(res.run) == 4
    assert res.warnings[0].endswith("skipped 4 malformed lines (first at line 2, 4, 5)")
    assert str(tmp_path / "m.log") in res.warnings[0]


def test_robotlaser_geometry_poses_and_remissions(tmp_path):
    lines = (
        ["VERTEX_SE2 0 1 2 3"]
        + [robotlaser([1.0, 60.0, 2.0], 5.0 + i, start=-0.5, res=0.5, max_range=50.0, rem=(7, 8, 9)) for i in range(3)]
        + ["EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1"]
    )
    path = write(tmp_path, "k.g2o", lines)
    assert detect_kind(path) == "g2o"
    res = import_log(path)
    g = res.run.geometry
    assert (g.angle_min, g.angle_increment, g.n_beams, g.range_max) == (-0.5, 0.5, 3, 50.0)
    assert np.isinf(res.run.ranges[:, 1]).all()
    assert res.run.intensities.tolist() == [[7, 8, 9]] * 3
    assert res.odometry.x.tolist() == [3, 3, 3] and res.odometry.theta[0] == 0.25


def test_rawlaser_takes_poses_from_odom_lines(tmp_path):
    raw = "RAWLASER1 0 -1.5708 3.14159 0.0174533 81.9 0.01 0 3 1 2 3 0 {t} host {t}"
    lines = ["ODOM 0 0 0 0 0 0 0.5 h 0.5", raw.format(t=1.0), "ODOM 1 0 0 0 0 0 1.5 h 1.5", raw.format(t=2.0)]
    res = import_log(write(tmp_path, "raw.log", lines))
    assert res.topic == "RAWLASER1" and len(res.run) == 2 and res.run.geometry.range_max == pytest.approx(81.9)
    assert res.odometry.x.tolist() == [0, 1] and res.odom_topic == "ODOM"


def test_several_laser_streams_need_topic(tmp_path):
    lines = [flaser([1.0] * 180, 1.0), flaser([2.0] * 180, 1.5, name="RLASER"), flaser([1.0] * 180, 2.0)]
    path = write(tmp_path, "two.log", lines)
    with pytest.raises(
        InputError,
        match=r"several laser streams, choose one with --topic: FLASER \(2 scans\), "
        r"RLASER \(1 scans\)",
    ):
        import_log(path)
    assert len(import_log(path, "RLASER").run) == 1
    with pytest.raises(InputError, match="no ROBOTLASER1 scans; it has FLASER"):
        import_log(path, "ROBOTLASER1")


def test_geometry_change_is_refused_with_scan_index(tmp_path):
    lines = [flaser([1.0] * 180, 1.0), flaser([1.0] * 180, 2.0), flaser([1.0] * 181, 3.0)]
    with pytest.raises(
        GeometryError,
        match=r"x.log: FLASER geometry changes at scan 2 \(line 3\): "
        r"180 beams -> 181 beams",
    ):
        import_log(write(tmp_path, "x.log", lines))


def test_max_scans_stops_early(tmp_path):
    lines = [flaser([1.0] * 180, 1.0 + i) for i in range(10)] + ["this line is never read"]
    res = import_log(write(tmp_path, "long.log", lines), "FLASER", max_scans=3)
    assert len(res.run) == 3 and len(res.odometry) == 3 and res.warnings == []
    parsed = parse_lines(lines, topic="FLASER", max_scans=3)
    assert parsed.malformed == 0


def test_truncated_gzip_keeps_what_was_read(tmp_path):
    lines = [flaser([1.0 + i % 7] * 361, 1.0 + i) for i in range(400)]
    path = write(tmp_path, "cut.log.gz", lines, gz=True)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    res = import_log(path)
    assert 0 < len(res.run) < 400
    assert any("truncated" in w for w in res.warnings)


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (b"", "empty file"),
        (b"\x00\x01\x02garbage\xff" * 100, "unknown kind of file"),
        (b"hello world\nthis is not a log\n", "unknown kind of file"),
        (b"# only comments\nPARAM a 1 nohost 0\n", "no laser scans"),
        (
            b"FLASER 3 1 2\nFLASER x\n",
            "no laser scans (no valid FLASER, RLASER, RAWLASER1-4 or ROBOTLASER1-2 lines; skipped 2 malformed lines)",
        ),
    ],
)
def test_bad_inputs_raise_one_line_errors(tmp_path, content, problem):
    path = tmp_path / "bad.log"
    path.write_bytes(content)
    with pytest.raises(InputError) as err:
        import_log(path)
    msg = str(err.value)
    assert str(path) in msg and problem in msg and "\n" not in msg


def test_empty_gzip_is_empty(tmp_path):
    path = tmp_path / "e.log.gz"
    with gzip.open(path, "wb"):
        pass
    with pytest.raises(InputError, match="empty file"):
        import_log(path)
