"""`datmo import` through the CLI: outputs, --force, --max-scans, warnings, and clean errors on bad input."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from click.testing import CliRunner
from test_import_carmen import flaser, write
from test_import_rosbag import messages, write_ros1

from datmo_cli.cli import cli
from datmo_cli.logs import mcapio

pytestmark = pytest.mark.cli


def run_cli(*args):
    result = CliRunner().invoke(cli, ["import", *map(str, args)])
    assert result.exception is None or isinstance(result.exception, SystemExit), result.exception
    assert "Traceback" not in result.output
    return result


def sha(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def carmen_log(tmp_path):
    lines = [flaser([1.0, 2.0] * 90, 100.0 + i, pose=(i, 0, 0)) for i in range(6)]
    return write(tmp_path, "in.log.gz", lines[:3] + ["FLASER 3 1 2", "@@@"] + lines[3:], gz=True)


def test_import_writes_scans_odometry_and_provenance(tmp_path, carmen_log):
    out = tmp_path / "out.mcap"
    before = sha(carmen_log)
    result = run_cli(carmen_log, "-o", out)
    assert result.exit_code == 0, result.output
    assert f"datmo: warning: {carmen_log}: skipped 2 malformed lines (first at line 4, 5)" in result.output
    assert f"{out}: 6 scans of 180 beams from -90.00° by 1.000°" in result.output
    run = mcapio.read_run(out)
    assert run.ranges.shape == (6, 180) and run.stamps[0] == 100_000_000_000
    odom = mcapio.read_odometry(out)
    # the laser's own poses with no mount known: the base is put on the laser (the same poses), with a warning
    assert odom.x.tolist() == [0, 1, 2, 3, 4, 5] and (odom.frame_id, odom.child_frame_id) == ("odom", "base_link")
    assert f"datmo: warning: {carmen_log}: no laser mount (base_link -> laser) in the log" in result.output
    meta = mcapio.summary(out).metadata
    assert meta["datmo"]["command"] == "import"
    assert meta["datmo.inputs"][str(carmen_log)] == before
    assert json.loads(meta["datmo.import"]["malformed_lines"]) == 2
    assert sha(carmen_log) == before  # the input is only read
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left


def test_existing_output_needs_force(tmp_path, carmen_log):
    out = tmp_path / "out.mcap"
    out.write_bytes(b"keep me")
    result = run_cli(carmen_log, "-o", out)
    assert result.exit_code == 1
    assert result.output.strip().splitlines()[-1] == f"datmo: error: {out}: exists; use --force to overwrite it"
    assert out.read_bytes() == b"keep me"
    assert run_cli(carmen_log, "-o", out, "--force").exit_code == 0
    assert len(mcapio.read_run(out)) == 6


def test_max_scans(tmp_path, carmen_log):
    out = tmp_path / "few.mcap"
    assert run_cli(carmen_log, "-o", out, "--max-scans", "2").exit_code == 0
    assert len(mcapio.read_run(out)) == 2 and len(mcapio.read_odometry(out)) == 2


def test_failure_leaves_no_output(tmp_path):
    src = write(tmp_path, "geo.log", [flaser([1.0] * 180, 1.0), flaser([1.0] * 181, 2.0)])
    out = tmp_path / "out.mcap"
    result = run_cli(src, "-o", out)
    assert result.exit_code == 1
    assert "geometry changes at scan 1 (line 2)" in result.output
    assert list(tmp_path.iterdir()) == [src]


def test_bag_topic_choice_through_the_cli(tmp_path):
    bag = write_ros1(tmp_path / "b.bag", messages())
    out = tmp_path / "b.mcap"
    result = run_cli(bag, "-o", out)
    assert result.exit_code == 1
    assert result.output == (
        f"datmo: error: {bag}: several sensor_msgs/LaserScan topics, choose one with "
        "--topic: /front (5 messages), /rear (5 messages)\n"
    )
    assert not out.exists()
    result = run_cli(bag, "-o", out, "--topic", "/rear", "--odom-topic", "/odom")
    assert result.exit_code == 0, result.output
    run = mcapio.read_run(out)
    assert run.geometry.frame_id == "rear" and run.ranges.shape == (5, 4)
    assert np.allclose(mcapio.read_odometry(out).x, [0, 0.5, 1, 1.5, 2])


@pytest.mark.parametrize(
    ("make", "problem"),
    [
        (lambda d: d / "missing.log", "no such file"),
        (lambda d: d, "is a directory, not a log"),
        (lambda d: (d / "empty.log").write_bytes(b"") and None or d / "empty.log", "empty file"),
        (
            lambda d: (d / "junk.bin").write_bytes(bytes(range(256)) * 40) and None or d / "junk.bin",
            "unknown kind of file",
        ),
        (lambda d: write_ros1(d / "odom.bag", messages(), topics={"/odom"}), "no sensor_msgs/LaserScan topic"),
    ],
)
def test_bad_inputs_give_one_line_errors(tmp_path, make, problem):
    src_dir = tmp_path / "src"
    src_dir.mkdir()
    src = make(src_dir)
    out = tmp_path / "out.mcap"
    result = run_cli(src, "-o", out)
    assert result.exit_code == 1
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"datmo: error: {src}: ") and problem in lines[0]
    assert not out.exists()


def test_help_ends_with_the_example():
    result = CliRunner().invoke(cli, ["import", "--help"])
    assert result.exit_code == 0
    description = result.output.split("Options:")[0].rstrip()
    assert description.endswith("Example: datmo import ../shared/data/carmen/csail-corrected.log.gz -o csail.mcap")
