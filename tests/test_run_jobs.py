"""`datmo run`'s batch machinery: one output per input, parallel jobs, a failing input does not lose the
others' results. The one-pass processing itself is replaced by a stand-in that writes the synthetic
processed log (tests/test_run.py checks the real one against the stages)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import synthetic_logs
from click.testing import CliRunner

from datmo_cli import batch
from datmo_cli.base.errors import InputError
from datmo_cli.cli import cli
from datmo_cli.passes import pipeline

pytestmark = pytest.mark.cli


def fake_process(
    src,
    out,
    *,
    force=False,
    config=None,
    markers=False,
    covariance=False,
    bag_dir=False,
    command_line=None,
    progress=None,
    input_name=None,
    report=None,
):
    src = Path(src)
    if "bad" in src.name:
        raise InputError(f"{src}: not an MCAP file (bad magic bytes)")
    if "crash" in src.name:
        raise ZeroDivisionError("division by zero")
    if Path(out).exists():
        if not force:
            raise InputError(f"{out}: exists; use --force to overwrite it")
        Path(out).unlink()
    for done in (10, 50):
        if progress:
            progress(done, 50)
    synthetic_logs.write(out)
    if report is not None:
        synthetic_logs.fill_report(report, out)
    return 50


@pytest.fixture
def inputs(tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline, "process_file", fake_process)
    names = ["a.mcap", "bad.mcap", "b.mcap", "crash.mcap"]
    for n in names:
        (tmp_path / n).write_bytes(b"x")
    return [tmp_path / n for n in names]


@pytest.mark.parametrize("jobs", [1, 2])
def test_failures_are_reported_and_the_others_finish(tmp_path, inputs, jobs):
    out = tmp_path / "out"
    seen = []
    prepared = batch.prepare(list(map(str, inputs)), str(out))
    results = batch.run_many(prepared, batch.LocalExecutor(jobs), on_scans=lambda i, d, t: seen.append((i, d, t)))
    assert [r["input"] for r in results] == list(map(str, inputs))
    assert [r["status"] for r in results] == ["done", "failed", "done", "failed"]
    assert "bad magic bytes" in results[1]["error"]
    assert results[3]["error"] == f"{inputs[3]}: failed: ZeroDivisionError: division by zero"
    assert (out / "a.mcap").exists() and (out / "b.mcap").exists()
    assert results[0]["scans"] == 50
    assert (0, 50, 50) in seen and (2, 50, 50) in seen


def test_cli_keeps_good_outputs_and_exits_1(tmp_path, inputs):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["run", *map(str, inputs), "-o", str(out), "--jobs", "2", "--format", "json"])
    assert result.exit_code == 1
    assert f"datmo: error: {inputs[1]}: not an MCAP file" in result.stderr
    assert result.stderr.rstrip().endswith("datmo: error: 2 of 4 inputs failed; the other outputs are complete")
    report = json.loads(result.stdout)
    assert [f["file"] for f in report["files"]] == [str(out / "a.mcap"), str(out / "b.mcap")]


def test_cli_single_input_prints_its_report_and_plot(tmp_path, inputs):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, ["run", str(inputs[0]), "-o", str(out), "--plot"])
    assert result.exit_code == 0, result.output
    assert "people and dynamic tracks" in result.stdout
    assert (out / "a.png").stat().st_size > 10_000
    again = CliRunner().invoke(cli, ["run", str(inputs[0]), "-o", str(out), "--plot"])
    assert again.exit_code == 0 and "0 done, 1 skipped" in again.stderr  # the manifest says it is done
    (out / "manifest.jsonl").unlink()
    again = CliRunner().invoke(cli, ["run", str(inputs[0]), "-o", str(out), "--plot"])
    assert again.exit_code == 1 and "a.png: exists; use --force" in again.stderr
    forced = CliRunner().invoke(cli, ["run", str(inputs[0]), "-o", str(out), "--plot", "--force", "--no-report"])
    assert forced.exit_code == 0 and forced.stdout == ""


def test_cli_output_dir_must_be_a_folder(tmp_path, inputs):
    f = tmp_path / "file"
    f.write_text("x")
    result = CliRunner().invoke(cli, ["run", str(inputs[0]), "-o", str(f)])
    assert result.exit_code != 0 and "file" in result.output


class _Stubborn:
    """A batch task that ignores SIGTERM and never ends (index 1), or ends at once (index 0)."""

    def __init__(self, index: int, flag: Path) -> None:
        self.index, self.flag = index, flag

    def run(self, **_kwargs) -> dict:
        import signal
        import time

        if self.index == 0:  # ends once the other one ignores SIGTERM
            while not self.flag.exists():
                time.sleep(0.01)
            return {"input": "quick", "status": "done"}
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        self.flag.touch()
        while True:
            time.sleep(0.05)


def test_a_stopped_batch_kills_a_worker_that_does_not_end(monkeypatch, tmp_path):
    """Ctrl-C during a --jobs batch: a worker that does not end on SIGTERM (its exit blocked on a lock, or a
    handler that ignores it) is killed after STOP_GRACE; the batch does not hang (pytest-timeout would say so)."""
    from datmo_cli.batch import executors
    from datmo_cli.passes import warm

    monkeypatch.setattr(executors, "STOP_GRACE", 0.5)
    monkeypatch.setattr(warm, "warm_up", lambda *_a, **_k: None)

    def on_record(line: dict) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        executors.LocalExecutor(jobs=2).run([_Stubborn(0, tmp_path / "f"), _Stubborn(1, tmp_path / "f")], on_record)
