"""The simulated sample logs: small, and exactly what sample_logs/make_simulated.sh makes today."""

from __future__ import annotations

import shlex

import pytest
from click.testing import CliRunner
from conftest import SAMPLE_LOGS

from datmo_cli.cli import cli

pytestmark = pytest.mark.cli

SCRIPT = SAMPLE_LOGS / "make_simulated.sh"


def commands() -> list[list[str]]:
    lines = [ln.strip() for ln in SCRIPT.read_text().splitlines() if ln.strip().startswith("datmo simulate")]
    return [shlex.split(ln)[1:] for ln in lines]


def test_the_script_makes_the_four_required_logs():
    outputs = {args[args.index("-o") + 1] for args in commands()}
    assert {
        "sample_logs/hall.mcap",
        "sample_logs/corridor.mcap",
        "sample_logs/crowd6.mcap",
        "sample_logs/static.mcap",
    } <= outputs


@pytest.mark.parametrize("args", commands(), ids=lambda a: a[a.index("-o") + 1])
def test_sample_log_is_small_and_regenerates_bit_for_bit(args, tmp_path, monkeypatch):
    out = args[args.index("-o") + 1]
    committed = SAMPLE_LOGS.parent / out
    if not committed.exists():
        pytest.skip(f"{out} is absent: run `make sample-logs`")
    assert committed.stat().st_size < 3_000_000
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sample_logs").mkdir()
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert (tmp_path / out).read_bytes() == committed.read_bytes(), f"{out} is stale: run `make sample-logs`"
