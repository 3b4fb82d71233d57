"""Temporary files that are only our own, and inputs never outputs: a batch removes exactly the temporary
files its tasks made (recorded by name as they are made, never found by a pattern: a user's
`.ab.mcap.notes.tmp` and another process's temporary file survive, and an output folder named `o[1]` leaves
`o1/` alone); `datmo config -o` refuses the config it reads, as every command refuses its input, even with
--force."""

from __future__ import annotations

import os

import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli

pytestmark = pytest.mark.cli


def test_config_refuses_to_write_over_the_config_it_reads_even_with_force(tmp_path):
    p = tmp_path / "p.toml"
    p.write_text("[track]\nconfirm_hits = 4\n")
    before = p.read_bytes()
    result = CliRunner().invoke(cli, ["config", "--config", str(p), "-o", str(p), "--force"])
    assert result.exit_code == 1, result.output
    assert f"{p}: the output would overwrite the input" in result.output
    assert "Traceback" not in result.output
    assert p.read_bytes() == before
    ok = CliRunner().invoke(cli, ["config", "--config", str(p), "-o", str(tmp_path / "q.toml")])
    assert ok.exit_code == 0 and "confirm_hits = 4" in (tmp_path / "q.toml").read_text()


def dies_mid_write(src, out, **kwargs):
    """The one-pass processing of a worker that dies while writing `dies.mcap`'s output: its temporary file
    stays on disk and its process's registry of temporary files is gone with it."""
    from pathlib import Path

    from test_batch import fake_process

    from datmo_cli.base import outputs
    from datmo_cli.base.errors import InputError

    if Path(src).name != "dies.mcap":
        return fake_process(src, out, **kwargs)
    tmp, f = outputs.open_temp(Path(out))
    f.write(b"half an output")
    f.close()
    outputs._LIVE.pop(os.fspath(tmp))  # as a SIGKILL leaves it: on disk, in no live registry
    raise InputError(f"{src}: the worker died")


@pytest.fixture
def batch_of_one_death(tmp_path, monkeypatch):
    from test_batch import CALLS

    from datmo_cli.passes import pipeline, warm

    monkeypatch.setattr(pipeline, "process_file", dies_mid_write)
    monkeypatch.setattr(warm, "warm_up", lambda *_a, **_k: None)
    CALLS.clear()
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("ab.mcap", "dies.mcap"):
        (logs / name).write_bytes(name.encode())
    return logs


@pytest.mark.parametrize(("folder", "jobs"), [("out", "1"), ("o[1]", "1"), ("o[1]", "2")])
def test_a_batch_removes_exactly_the_temporary_files_its_tasks_made(batch_of_one_death, tmp_path, folder, jobs):
    out = tmp_path / folder
    out.mkdir()
    sibling = tmp_path / "o1"  # what `o[1]` matches as a glob
    sibling.mkdir(exist_ok=True)
    theirs = [
        out / ".ab.mcap.notes.tmp",  # a user's file
        out / ".ab.mcap.99999.1.tmp",  # another process's live temporary file
        out / ".dies.mcap.99999.1.tmp",
        sibling / ".ab.mcap.99999.1.tmp",
        sibling / ".dies.mcap.notes.tmp",
    ]
    for path in theirs:
        path.write_bytes(b"not datmo's to remove")
    result = CliRunner().invoke(cli, ["run", str(batch_of_one_death), "-o", str(out), "--no-report", "--jobs", jobs])
    assert result.exit_code == 1, result.output  # one input failed
    assert (out / "ab.mcap").is_file()
    for path in theirs:
        assert path.read_bytes() == b"not datmo's to remove", path
    left = sorted(p.name for p in out.iterdir() if p.name.startswith(".") and p not in theirs)
    assert left == [], left  # the dead worker's temporary file removed, by its name
