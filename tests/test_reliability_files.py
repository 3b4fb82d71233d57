"""Files the user names for reading : a FIFO, /dev/zero or another device given
as a log, a bag, --config, --gt, a leg model, a scene or a batch's manifest is refused in one line naming the
path and what it is (never "empty file" or "no such file"), without hanging or reading until memory runs out;
text inputs read whole are refused past their kind's size; an unreadable input is one line and exit 1, not
Click's usage error. Every reader calls the one check, datmo_cli/base/input_files.py. Counted with fuzzing.tally
("special files as inputs", "unreadable inputs")."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import synthetic_logs
from click.testing import CliRunner
from fuzzing import tally

from datmo_cli.base import input_files
from datmo_cli.base.errors import InputError
from datmo_cli.cli import cli

pytestmark = [
    pytest.mark.cli,
    pytest.mark.timeout(120),
]  # a reader that blocks on a FIFO fails here instead of hanging the suite


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line(result, *needles: str) -> str:
    assert result.exit_code == 1, (result.exit_code, result.output)
    assert "Traceback" not in result.output and "Usage:" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("datmo: error: ")]
    assert errors, result.output
    for needle in needles:
        assert needle in errors[0], errors[0]
    return errors[0]


@pytest.fixture(scope="module")
def files(tmp_path_factory, sample_logs):
    """A FIFO, a processed log (tracks, ground truth) and a plain sample log."""
    d = tmp_path_factory.mktemp("special")
    os.mkfifo(d / "pipe")
    synthetic_logs.write(d / "tracked.mcap")
    return {
        "fifo": d / "pipe",
        "zero": Path("/dev/zero"),
        "tracked": d / "tracked.mcap",
        "log": sample_logs / "static.mcap",
        "dir": d,
    }


# every reader of a user-named file: the arguments with X where the special file goes
READERS = {
    "info": ["info", "X"],
    "segment": ["segment", "X", "-o", "{out}/s.mcap"],
    "features": ["features", "X", "-o", "{out}/f.mcap"],
    "track": ["track", "X", "-o", "{out}/t.mcap"],
    "import": ["import", "X", "-o", "{out}/i.mcap"],
    "export": ["export", "X", "-o", "{out}/e.csv"],
    "report": ["report", "X"],
    "evaluate": ["evaluate", "X"],
    "evaluate --gt": ["evaluate", "{tracked}", "--gt", "X"],
    "--config": ["config", "--config", "X"],
    "run --config": ["run", "{log}", "-o", "{out}/run-config", "--config", "X"],
    "run": ["run", "X", "-o", "{out}/run", "--no-report"],
    "train-legs": ["train-legs", "--positive", "X", "--negative", "{log}", "-o", "{out}/m.npz"],
    "emulate --log": ["emulate", "--log", "X"],
    "--leg-model": ["features", "{log}", "-o", "{out}/f.mcap", "--leg-model", "X"],
    "simulate --scene": ["simulate", "--scene", "X", "-o", "{out}/sim.mcap"],
}


@pytest.mark.parametrize("kind", ["fifo", "zero"])
@pytest.mark.parametrize("reader", list(READERS))
def test_a_fifo_or_device_is_refused_by_every_reader_in_one_line(files, tmp_path, reader, kind):
    special = files[kind]
    args = [
        str(special) if a == "X" else a.format(out=tmp_path, tracked=files["tracked"], log=files["log"])
        for a in READERS[reader]
    ]
    result = invoke(*args)
    ok = False
    try:
        what = "a FIFO (named pipe)" if kind == "fifo" else "a character device"
        line = one_line(result, str(special), f"is {what}, not a regular file")
        assert "empty file" not in line and "no such file" not in line
        ok = True
    finally:
        tally("special files as inputs", failed=not ok)


def test_a_manifest_that_is_a_fifo_or_a_device_is_refused(files, tmp_path):
    for kind in ("fifo", "zero"):
        out = tmp_path / kind
        out.mkdir()
        (out / "manifest.jsonl").symlink_to(files[kind]) if kind == "zero" else os.mkfifo(out / "manifest.jsonl")
        for args in (["report", out], ["run", files["log"], "-o", out, "--no-report"]):
            ok = False
            try:
                one_line(invoke(*args), "manifest.jsonl")
                ok = True
            finally:
                tally("special files as inputs", failed=not ok)


def test_text_inputs_are_refused_past_their_size_before_being_read(tmp_path, monkeypatch):
    big = tmp_path / "big.toml"
    with open(big, "wb") as f:
        f.truncate(input_files.MAX_CONFIG_BYTES + 1)  # sparse: nothing is written, nothing should be read
    line = one_line(
        invoke("config", "--config", big),
        f"{big}: {input_files.MAX_CONFIG_BYTES + 1:,} bytes",
        f"a configuration file is at most {input_files.MAX_CONFIG_BYTES:,} bytes",
    )
    assert "TOML" not in line
    gt = tmp_path / "gt.csv"
    gt.write_text("stamp_ns,id,x,y\n" + "1,1,0.0,0.0\n" * 100)
    monkeypatch.setattr(input_files, "MAX_GROUND_TRUTH_BYTES", 1000)
    from datmo_cli.evaluate import read_ground_truth_csv

    with pytest.raises(InputError, match=r"gt\.csv: 1,216 bytes; a ground-truth CSV file is at most 1,000 bytes"):
        read_ground_truth_csv(gt)


def test_a_special_file_swapped_in_after_the_check_is_refused_when_opened(tmp_path, monkeypatch):
    """open_regular checks what it opened: a FIFO put in place between the check and the open is not read
    (and the open itself does not wait for a writer)."""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    monkeypatch.setattr(input_files, "check", lambda path, **kw: os.stat(tmp_path))  # the check saw a file
    with pytest.raises(InputError, match="is a FIFO"):
        input_files.open_regular(fifo)


def test_the_check_names_what_is_wrong(tmp_path):
    (tmp_path / "dangling").symlink_to(tmp_path / "gone")
    with pytest.raises(InputError, match=r"dangling: a symbolic link to .*gone, which does not exist"):
        input_files.check(tmp_path / "dangling")
    with pytest.raises(InputError, match=r"missing: no such file$"):
        input_files.check(tmp_path / "missing")
    with pytest.raises(InputError, match="is a directory"):
        input_files.check(tmp_path)
    assert input_files.check(tmp_path, folder_ok=True)


# inputs of each kind of command, and what they are given as (an argument or an option)
UNREADABLE = {
    "info": ["info", "X"],
    "segment": ["segment", "X", "-o", "{out}/s.mcap"],
    "track": ["track", "X", "-o", "{out}/t.mcap"],
    "report": ["report", "X"],
    "export": ["export", "X", "-o", "{out}/e.csv"],
    "evaluate": ["evaluate", "X"],
    "import": ["import", "X", "-o", "{out}/i.mcap"],
    "--config": ["config", "--config", "X"],
    "emulate --log": ["emulate", "--log", "X"],
}


@pytest.mark.parametrize("reader", list(UNREADABLE))
def test_an_unreadable_input_is_one_line_and_exit_1_not_a_usage_error(files, tmp_path, monkeypatch, reader):
    """As root every file is readable, so the permission is taken away by os.access, which both Click's
    Path(readable=True) and datmo's check ask."""
    locked = tmp_path / "locked.mcap"
    locked.write_bytes(files["log"].read_bytes())
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda p, mode, **kw: False if os.fspath(p) == str(locked) else real_access(p, mode, **kw)
    )
    args = [str(locked) if a == "X" else a.format(out=tmp_path) for a in UNREADABLE[reader]]
    ok = False
    try:
        one_line(invoke(*args), f"{locked}: permission denied")
        ok = True
    finally:
        tally("unreadable inputs", failed=not ok)
