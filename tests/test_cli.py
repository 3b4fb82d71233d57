"""The command group: help for every command, clean errors, `datmo info`."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.cli import COMMANDS, cli
from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanGeometry, ScanRun

pytestmark = pytest.mark.cli


@pytest.fixture
def log(tmp_path):
    g = ScanGeometry(-np.pi / 2, np.pi / 360, 361, 0.0, 8.0, 0.0, 0.2, "laser")
    run = ScanRun(np.arange(25, dtype=np.int64) * 200_000_000, np.full((25, 361), 3.0), g)
    path = tmp_path / "log.mcap"
    with mcapio.LogWriter(path, provenance=mcapio.Provenance("simulate", {"seed": 1})) as w:
        w.write_scans(run)
    return path


def test_every_available_command_has_help_ending_in_an_example():
    runner = CliRunner()
    names = cli.list_commands(None)
    assert "info" in names
    for name in names:
        result = runner.invoke(cli, [name, "--help"])
        assert result.exit_code == 0, (name, result.output)
        assert "Example: datmo " + name in result.output, name
    top = runner.invoke(cli, ["--help"])
    for name in names:
        assert name in top.output


def test_command_table_points_at_modules():
    assert set(COMMANDS) >= {
        "import",
        "info",
        "simulate",
        "record",
        "emulate",
        "segment",
        "features",
        "track",
        "run",
        "report",
        "evaluate",
    }


def test_info_tables(log):
    result = CliRunner().invoke(cli, ["info", str(log)])
    assert result.exit_code == 0, result.output
    for text in ("/scan", "sensor_msgs/msg/LaserScan", "361", "5.00 Hz", "180.00°", "0.500°", "simulate"):
        assert text in result.output


def test_info_json(log):
    result = CliRunner().invoke(cli, ["info", str(log), "--json"])
    info = json.loads(result.output)
    assert info["scan"]["scans"] == 25
    assert info["scan"]["beams"] == 361
    assert info["scan"]["rate_hz"] == pytest.approx(5.0)
    assert info["scan"]["fov_deg"] == pytest.approx(180.0)
    assert info["metadata"]["datmo.params"] == {"seed": "1"}
    assert info["duration_s"] == pytest.approx(4.8)


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: None, "no such file"),
        (lambda p: p.write_bytes(b""), "empty file"),
        (lambda p: p.write_text("# CARMEN\n"), "not an MCAP file"),
    ],
)
def test_info_bad_input_one_line_no_traceback(tmp_path, make, message):
    path = tmp_path / "x.mcap"
    make(path)
    result = CliRunner().invoke(cli, ["info", str(path)])
    assert result.exit_code == 1
    assert result.output.strip().count("\n") == 0
    assert result.output.startswith("datmo: error: ") and message in result.output and str(path) in result.output
    assert "Traceback" not in result.output


def test_info_truncated_warns(tmp_path, log):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(log.read_bytes()[:-200])
    result = CliRunner().invoke(cli, ["info", str(cut)])
    assert result.exit_code == 0
    assert "datmo: warning:" in result.output and "truncated" in result.output
