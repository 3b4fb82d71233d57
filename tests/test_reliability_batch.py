"""Reliability of `datmo run`'s batches and `datmo report DIR`: nothing written through a
symbolic link, only outputs under DIR, each once, the datmo version part of what resume matches, no plot
written over another, a literal path with glob characters is that file, one batch at a time in a folder,
--scheduler local:N bounded by the cores, --jobs workers that end with their parent, manifest fields of the
wrong type are input errors, --jobs saying the processes it started. The one-pass processing is test_batch's
stand-in (a synthetic processed log); test_cluster_security.py holds the Dask cluster's TLS."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import synthetic_logs
from click.testing import CliRunner
from fuzzing import tally
from test_batch import CALLS, fake_process

from datmo_cli import batch
from datmo_cli.base.errors import DatmoError, InputError, OutputError
from datmo_cli.cli import cli
from datmo_cli.passes import pipeline, warm
from datmo_cli.report.plot_files import plot_paths

pytestmark = [pytest.mark.cli, pytest.mark.timeout(300)]


@pytest.fixture
def logs(tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline, "process_file", fake_process)
    monkeypatch.setattr(warm, "warm_up", lambda *_a, **_k: None)
    CALLS.clear()
    d = tmp_path / "logs"
    (d / "site").mkdir(parents=True)
    for name in ("a.mcap", "b.mcap", "site/c.mcap"):
        (d / name).write_bytes(name.encode())
    return d


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def run(*args):
    return invoke("run", *args, "--no-report", "--jobs", "1")


def one_line(result, *needles: str, code: int = 1) -> str:
    assert result.exit_code == code, (result.exit_code, result.output)
    assert "Traceback" not in result.output and "internal error" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("datmo: error: ")]
    assert len(errors) == 1, result.output
    for needle in needles:
        assert needle in errors[0], errors[0]
    return errors[0]


def lines(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "manifest.jsonl").read_text().splitlines()]


# ------------------------------------------------------------------------- 14: special files on resume


def test_an_input_done_before_and_now_a_fifo_is_not_hashed_on_resume(logs, tmp_path):
    out = tmp_path / "out"
    assert run(logs / "a.mcap", "-o", out).exit_code == 0
    (logs / "a.mcap").unlink()
    os.mkfifo(logs / "a.mcap")  # hashing it to compare with the manifest would wait forever
    r = run(logs / "a.mcap", "-o", out)
    one_line(r, f"{logs / 'a.mcap'}: is a FIFO (named pipe), not a regular file")
    assert batch.Manifest(str(out)).latest()[str(logs / "a.mcap")]["status"] == "failed"


# ------------------------------------------------------------------------------ 1: no write through links


def test_a_manifest_that_is_a_symlink_is_neither_written_nor_read_through(logs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    rc = tmp_path / "bashrc"
    rc.write_text("# a shell's rc file\n")
    (out / "manifest.jsonl").symlink_to(rc)
    one_line(run(logs / "a.mcap", "-o", out), f"{out / 'manifest.jsonl'}: is a symbolic link")
    assert rc.read_text() == "# a shell's rc file\n" and CALLS == []
    one_line(invoke("report", out), "manifest.jsonl: is a symbolic link")
    (out / "manifest.jsonl").unlink()
    m = batch.Manifest(str(out))
    m.append({"input": "x", "status": "failed"})
    os.replace(out / "manifest.jsonl", tmp_path / "moved")
    (out / "manifest.jsonl").symlink_to(rc)  # put there while a batch runs: its next line is refused
    with pytest.raises(OutputError, match="is a symbolic link"):
        m.append({"input": "y", "status": "failed"})
    assert rc.read_text() == "# a shell's rc file\n"


def test_an_output_folder_reached_through_a_symlink_fails_its_input_and_writes_nothing_there(logs, tmp_path):
    out, elsewhere = tmp_path / "out", tmp_path / "elsewhere"
    out.mkdir()
    elsewhere.mkdir()
    (out / "site").symlink_to(elsewhere)
    r = invoke("run", logs, "-o", out, "--no-report", "--jobs", "1")
    assert r.exit_code == 1, r.output
    by_name = {Path(x["input"]).name: x for x in lines(out)}
    assert by_name["a.mcap"]["status"] == by_name["b.mcap"]["status"] == "done"
    assert by_name["c.mcap"]["status"] == "failed"
    assert (
        by_name["c.mcap"]["error"] == f"{logs / 'site' / 'c.mcap'}: {out / 'site'}: is a symbolic link; datmo "
        "run writes its outputs only inside the output folder, never through a link"
    )
    assert list(elsewhere.iterdir()) == []


def test_a_lock_file_that_is_a_symlink_is_refused(logs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    target = tmp_path / "target"
    target.write_text("keep")
    (out / batch.LOCK).symlink_to(target)
    one_line(run(logs / "a.mcap", "-o", out), f"{out / batch.LOCK}: is a symbolic link")
    assert target.read_text() == "keep"


# ------------------------------------------------------------------------- 5: only outputs under DIR, once


def test_report_of_a_folder_reads_only_its_own_outputs_each_once(logs, tmp_path):
    out = tmp_path / "out"
    assert run(logs / "a.mcap", logs / "b.mcap", "-o", out).exit_code == 0
    outside = tmp_path / "outside.mcap"
    synthetic_logs.write(outside)
    a = lines(out)[0]
    extra = [
        {**a, "input": "/elsewhere/x.mcap", "output": str(outside)},
        {**a, "input": "/elsewhere/y.mcap", "output": str(out / ".." / "outside.mcap")},
    ]
    extra += [{**a, "input": f"/copies/{i}.mcap"} for i in range(2000)]  # 2,000 lines naming one output
    with open(out / "manifest.jsonl", "a") as f:
        f.writelines(json.dumps(x) + "\n" for x in extra)
    r = invoke("report", out, "--format", "json")
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert sorted(Path(f["file"]).name for f in doc["files"]) == ["a.mcap", "b.mcap"]
    s = doc["batches"][0]["summary"]
    assert (s["inputs"], s["done"], s["scans"]) == (2, 2, 100)
    assert "2002 manifest lines left out" in r.stderr


# ------------------------------------------------------------------------ 6: the version is part of a match


def test_a_line_of_another_datmo_version_is_redone(logs, tmp_path, monkeypatch):
    out = tmp_path / "out"
    assert run(logs / "a.mcap", "-o", out).exit_code == 0
    CALLS.clear()
    assert "1 skipped" in run(logs / "a.mcap", "-o", out).stderr and CALLS == []
    for module in (batch.plan, batch.task):  # an upgrade: the version prepare matches and record writes
        monkeypatch.setattr(module, "__version__", "99.0.0")
    again = run(logs / "a.mcap", "-o", out)
    assert again.exit_code == 0 and CALLS == ["a.mcap"], again.output  # its own output: overwritten
    assert batch.Manifest(str(out)).latest()[str(logs / "a.mcap")]["datmo_version"] == "99.0.0"


# --------------------------------------------------------------------------- 7: no plot over another


def test_plots_of_files_of_one_name_get_distinct_names(tmp_path):
    a, b = tmp_path / "A" / "x.mcap", tmp_path / "B" / "x.mcap"
    assert plot_paths(tmp_path / "q.png", [a, b]) == [tmp_path / "q-A-x.png", tmp_path / "q-B-x.png"]
    c = tmp_path / "A" / "y.mcap"
    assert plot_paths(tmp_path / "q.png", [a, c]) == [tmp_path / "q-x.png", tmp_path / "q-y.png"]
    deep = [tmp_path / "r1" / "A" / "x.mcap", tmp_path / "r2" / "A" / "x.mcap", tmp_path / "B" / "x.mcap"]
    names = [p.name for p in plot_paths(tmp_path / "q.png", deep)]
    assert names == ["q-r1-A-x.png", "q-r2-A-x.png", "q-B-x.png"]
    with pytest.raises(InputError, match="given twice"):
        plot_paths(tmp_path / "q.png", [a, tmp_path / "A" / ".." / "A" / "x.mcap"])


def test_report_plots_two_files_of_one_name_into_two_plots(tmp_path):
    for d in ("A", "B"):
        (tmp_path / d).mkdir()
        synthetic_logs.write(tmp_path / d / "x.mcap")
    r = invoke(
        "report",
        tmp_path / "A" / "x.mcap",
        tmp_path / "B" / "x.mcap",
        "--plot",
        tmp_path / "q.png",
        "--plot-kind",
        "counts",
        "--force",
        "--format",
        "json",
    )
    assert r.exit_code == 0, r.output
    assert sorted(p.name for p in tmp_path.glob("q*.png")) == ["q-A-x.png", "q-B-x.png"]


# ----------------------------------------------------------------------- 9: a literal path is that file


def test_a_path_with_glob_characters_that_exists_is_that_file(logs, tmp_path):
    (logs / "[a]b.mcap").write_bytes(b"the literal one")
    (logs / "ab.mcap").write_bytes(b"what the pattern [a]b matches")
    out = str(tmp_path / "out")
    assert batch.discover([str(logs / "[a]b.mcap")], out) == [(str(logs / "[a]b.mcap"), str(Path(out) / "[a]b.mcap"))]
    assert [Path(s).name for s, _ in batch.discover([str(logs / "[a]?.mcap")], out)] == ["ab.mcap"]  # a pattern
    r = run(logs / "[a]b.mcap", "-o", out)
    assert r.exit_code == 0 and CALLS == ["[a]b.mcap"], r.output


# ------------------------------------------------------------------------ 11: one batch in a folder at once


def test_a_second_run_on_a_locked_folder_is_refused_naming_the_first(logs, tmp_path):
    out = tmp_path / "out"
    assert run(logs / "a.mcap", "-o", out).exit_code == 0
    before = (out / "manifest.jsonl").read_text()
    CALLS.clear()
    with batch.folder_lock(str(out)):  # as a first `datmo run` holds it while it runs
        line = one_line(
            run(logs / "a.mcap", logs / "b.mcap", "-o", out),
            f"{out}: another datmo run is writing into this folder (pid {os.getpid()} on ",
        )
        assert "wait for it to finish or stop it, or give another -o folder" in line
    assert CALLS == [] and (out / "manifest.jsonl").read_text() == before
    r = run(logs / "a.mcap", logs / "b.mcap", "-o", out)  # released: the next run goes ahead
    assert r.exit_code == 0 and CALLS == ["b.mcap"], r.output
    assert not (out / batch.LOCK).exists()


def test_the_lock_is_taken_again_when_its_file_was_replaced_meanwhile(tmp_path, monkeypatch):
    """A run that opened the lock file just before its holder removed it (finishing) must not hold the old,
    removed file while a third run locks the new one."""
    out = tmp_path / "out"
    out.mkdir()
    import fcntl

    calls = []
    real = fcntl.flock

    def flock(fd, op):
        calls.append(op)
        if len(calls) == 1:  # the holder finishes between this run's open and its lock
            os.unlink(out / batch.LOCK)
            (out / batch.LOCK).write_text("")
        return real(fd, op)

    monkeypatch.setattr(fcntl, "flock", flock)
    with batch.folder_lock(str(out)):
        held = os.stat(out / batch.LOCK)
        with pytest.raises(DatmoError, match="another datmo run"), batch.folder_lock(str(out)):
            pass
    assert len(calls) == 3 and held.st_size > 0


# ------------------------------------------------------------------------ 17: bounded workers, no orphans


def test_local_n_is_bounded_by_the_cores():
    from datmo_cli.batch import cluster

    assert cluster.parse_local("local") == cluster.cores()
    assert cluster.parse_local(f"local:{cluster.cores()}") == cluster.cores()
    with pytest.raises(DatmoError, match=rf"local:100000: at most local:{cluster.cores()} here"):
        cluster.parse_local("local:100000")
    one_line(invoke("run", "x.mcap", "-o", "out", "--scheduler", "local:100000"), "at most local:")


def test_jobs_says_the_processes_it_started(logs, tmp_path):
    r = invoke("run", logs / "a.mcap", logs / "b.mcap", "-o", tmp_path / "out", "--jobs", "1000", "--no-report")
    assert r.exit_code == 0, r.output
    assert "on 2 local processes" in r.stderr and "1000" not in r.stderr
    one = invoke("run", logs / "site" / "c.mcap", "-o", tmp_path / "out", "--jobs", "1000", "--no-report")
    assert one.exit_code == 0 and "on 1 local process " in one.stderr, one.output


WORKERS_SCRIPT = """
import os, sys, time
sys.path[:0] = [{root!r}, {tests!r}]
from datmo_cli import batch
from datmo_cli.passes import pipeline, warm

def stuck(src, out, **kw):
    open(os.path.join({pids!r}, str(os.getpid())), "w").close()
    time.sleep(600)

pipeline.process_file = stuck
warm.warm_up = lambda *_a, **_k: None
plan = batch.prepare([{a!r}, {b!r}], {out!r})
batch.run_many(plan, batch.LocalExecutor(2))
"""


def _session(sid: int) -> list[int]:
    """The live processes (zombies have exited) of session `sid`."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[0] != "Z" and int(fields[3]) == sid:
                found.append(int(entry))
    return found


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_jobs_workers_end_when_the_batch_process_is_killed(logs, tmp_path):
    """The batch's process runs in a session of its own: once it is killed (SIGKILL, so nothing of it runs),
    no process of that session may live on (its workers, or any helper process it started)."""
    pids = tmp_path / "pids"
    pids.mkdir()
    here = Path(__file__).resolve().parent
    script = WORKERS_SCRIPT.format(
        root=str(here.parent),
        tests=str(here),
        pids=str(pids),
        a=str(logs / "a.mcap"),
        b=str(logs / "b.mcap"),
        out=str(tmp_path / "out"),
    )
    parent = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True
    )
    try:
        deadline = time.monotonic() + 120
        while len(list(pids.iterdir())) < 2 and time.monotonic() < deadline and parent.poll() is None:
            time.sleep(0.05)
        assert len(list(pids.iterdir())) == 2, parent.stderr.read().decode() if parent.poll() is not None else ""
        assert len(_session(parent.pid)) >= 3
        parent.kill()
        parent.wait()
        deadline = time.monotonic() + 60
        while _session(parent.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _session(parent.pid) == []
    finally:
        try:
            os.killpg(parent.pid, signal.SIGKILL)  # the group this test started, should anything be left
        except ProcessLookupError:
            pass
        parent.wait()


# ---------------------------------------------------------------------- 18: manifest fields of wrong types

WRONG = {
    "input": [5, None, ["a.mcap"], {"a": 1}],
    "status": [1, None, "finished", ["done"]],
    "output": [7, ["x.mcap"], {"path": "x"}],
    "input_sha256": [12, ["ab"]],
    "input_size": ["100", -1, 1.5, True],
    "input_mtime_ns": ["1", 1.5],
    "error": [3, ["boom"]],
    "scans": ["50", -3, 2.5, None, False],
    "seconds": ["1.0", -1.0, None, float("inf"), float("nan")],
    "scans_per_s": ["fast", [1]],
    "tracks": ["many", [1, 2], {"person": "3"}, {"person": -1}, {"person": 1.5}],
    "datmo_version": [1.0, ["0.1.0"]],
    "params_hash": [123, {"h": 1}],
    "finished": [20261201, ["today"]],
    "worker": [1, ["vm"]],
    "notes": ["a note", [1, 2], None],
}
CASES = [(key, value) for key, values in WRONG.items() for value in values]


@pytest.fixture
def batch_dir(logs, tmp_path):
    out = tmp_path / "out"
    assert run(logs / "a.mcap", logs / "b.mcap", "-o", out).exit_code == 0
    return out


@pytest.mark.parametrize("key, value", CASES, ids=[f"{k}={json.dumps(v)}" for k, v in CASES])
def test_a_manifest_field_of_the_wrong_type_is_one_input_error(logs, batch_dir, key, value):
    good, second = lines(batch_dir)
    second[key] = value
    (batch_dir / "manifest.jsonl").write_text(json.dumps(good) + "\n" + json.dumps(second) + "\n")
    ok = False
    try:
        resume = ["run", logs / "a.mcap", logs / "b.mcap", "-o", batch_dir, "--no-report", "--jobs", "1"]
        for args in (["report", batch_dir, "--format", "json"], resume):
            line = one_line(invoke(*args), f"{batch_dir / 'manifest.jsonl'}: line 2: {key} must be ")
            assert "correct or delete the line" in line
        ok = True
    finally:
        tally("manifest fields of the wrong type", failed=not ok)


def test_a_manifest_line_too_long_is_passed_over_and_a_manifest_too_large_is_refused(tmp_path, monkeypatch):
    from datmo_cli.base import input_files

    monkeypatch.setattr(input_files, "MAX_MANIFEST_LINE_BYTES", 100)
    (tmp_path / "manifest.jsonl").write_bytes(b"\0" * 1000 + b"\n" + b'{"input": "a", "status": "done"}\n')
    assert batch.Manifest(str(tmp_path)).read() == [{"input": "a", "status": "done"}]
    monkeypatch.setattr(input_files, "MAX_MANIFEST_BYTES", 500)
    with pytest.raises(InputError, match=r"manifest.jsonl: 1,034 bytes; a manifest is at most 500 bytes"):
        batch.Manifest(str(tmp_path)).read()
