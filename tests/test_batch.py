"""Batches of `datmo run` without a cluster: input discovery, the manifest (torn lines, one line per input),
resume, --force, leftovers of an interrupted batch, Ctrl-C, fsspec URLs, `datmo report DIR`. The one-pass
processing is the stand-in of test_run_jobs (a synthetic processed log); tests/test_cluster.py runs the
real pipeline on a Dask cluster."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
import synthetic_logs
from click.testing import CliRunner

from datmo_cli import batch
from datmo_cli.base.errors import InputError
from datmo_cli.cli import cli
from datmo_cli.passes import pipeline, warm

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
    if "stop" in src.name:
        raise KeyboardInterrupt
    if "boxed" in src.name:  # how CPython reports a Ctrl-C whose handler ran while a numba call returned
        raise SystemError(
            "CPUDispatcher(<function track_block>) returned a result with an exception set"
        ) from KeyboardInterrupt()
    if Path(out).exists():
        if not force:
            raise InputError(f"{out}: exists; use --force to overwrite it")
        Path(out).unlink()
    if progress:
        progress(50, 100)
    synthetic_logs.write(out)
    if report is not None:
        synthetic_logs.fill_report(report, out)
    CALLS.append(src.name)
    return 50


CALLS: list[str] = []


@pytest.fixture
def logs(tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline, "process_file", fake_process)
    monkeypatch.setattr(warm, "warm_up", lambda *_a, **_k: None)  # the stand-in needs no kernels
    CALLS.clear()
    d = tmp_path / "logs"
    (d / "site" / "day2").mkdir(parents=True)
    for name in ("a.mcap", "b.mcap", "site/c.mcap", "site/day2/d.mcap", "site/notes.txt", ".hidden.mcap"):
        (d / name).write_bytes(name.encode())
    return d


def run(*args):
    return CliRunner().invoke(cli, ["run", *map(str, args), "--no-report"])


def manifest(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]


def test_discover_files_folders_globs(logs, tmp_path):
    out = str(tmp_path / "out")
    pairs = batch.discover([str(logs)], out)
    assert [Path(s).relative_to(logs).as_posix() for s, _ in pairs] == [
        "a.mcap",
        "b.mcap",
        "site/c.mcap",
        "site/day2/d.mcap",
    ]
    assert [Path(o).relative_to(out).as_posix() for _, o in pairs] == [
        "a.mcap",
        "b.mcap",
        "site/c.mcap",
        "site/day2/d.mcap",
    ]
    globbed = batch.discover([f"{logs}/**/*.mcap", str(logs / "a.mcap")], out)  # repeats are dropped
    assert [Path(o).name for _, o in globbed] == ["a.mcap", "b.mcap", "c.mcap", "d.mcap"]
    assert all(os.path.isabs(s) for s, _ in globbed)
    with pytest.raises(InputError, match=r"nothing\*\.mcap: no \.mcap log matches"):
        batch.discover([f"{logs}/nothing*.mcap"], out)
    (logs / "site" / "a.mcap").write_bytes(b"another a")
    with pytest.raises(InputError, match="same output name as"):
        batch.discover([str(logs / "a.mcap"), str(logs / "site" / "a.mcap")], out)


def test_a_folder_without_logs_and_the_output_folder_left_out(tmp_path, logs):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(InputError, match=f"{empty}: no .mcap logs in this folder"):
        batch.discover([str(empty)], str(tmp_path / "out"))
    inside = logs / "out"  # outputs written inside the searched folder are not inputs next time
    inside.mkdir()
    (inside / "a.mcap").write_bytes(b"x")
    assert not any("/out/" in s for s, _ in batch.discover([str(logs)], str(inside)))


def test_manifest_tolerates_a_torn_last_line_and_compacts(tmp_path):
    m = batch.Manifest(str(tmp_path))
    m.append({"input": "a", "status": "failed"})
    m.append({"input": "a", "status": "done"})
    with open(tmp_path / "manifest.jsonl", "a") as f:
        f.write('{"input": "b", "status": "do')  # a crash mid-write
    assert m.latest() == {"a": {"input": "a", "status": "done"}}
    m.compact()
    assert (tmp_path / "manifest.jsonl").read_text() == '{"input": "a", "status": "done"}\n'


DEFAULT_PARAMS_HASH = "c92fb8f724b5b478"  # the defaults' hash since circle_check_extent and _radius left [features]


def test_params_hash_follows_the_parameters():
    from datmo_cli.passes.config import DatmoConfig

    default = batch.params_hash()
    assert default == DEFAULT_PARAMS_HASH  # the manifests written before keep skipping default runs
    assert batch.params_hash(DatmoConfig(), batch.RunOptions(bag_dir=True)) == default  # same outputs
    assert batch.params_hash(DatmoConfig().replace(track={"gate": 10.0})) != default
    assert batch.params_hash(None, batch.RunOptions(markers=False, covariance=False)) == default  # lean outputs
    assert batch.params_hash(None, batch.RunOptions(markers=True)) != default
    assert batch.params_hash(None, batch.RunOptions(covariance=True)) != default
    assert batch.params_hash(None, batch.RunOptions(topic="/front")) != default


def test_a_task_pickles_with_its_configuration():
    import pickle

    from datmo_cli.passes.config import DatmoConfig

    cfg = DatmoConfig().replace(track={"gate": 10.0})
    task = batch.Task(0, "a.mcap", "out/a.mcap", False, cfg, batch.RunOptions(markers=True), "h", None)
    back = pickle.loads(pickle.dumps(task))
    assert back == task and back.config.track.gate == 10.0 and back.options.markers


def test_manifest_lines_then_resume_does_only_what_is_missing(logs, tmp_path):
    out = tmp_path / "out"
    first = run(logs / "a.mcap", logs / "bad.mcap", logs / "b.mcap", "-o", out, "--jobs", "1")
    assert first.exit_code == 1, first.output
    lines = manifest(out)
    assert [(Path(r["input"]).name, r["status"]) for r in lines] == [
        ("a.mcap", "done"),
        ("bad.mcap", "failed"),
        ("b.mcap", "done"),
    ]
    a = lines[0]
    assert a["input_sha256"] == batch.input_sha256(str(logs / "a.mcap")) and a["scans"] == 50
    assert a["output"] == str(out / "a.mcap") and a["datmo_version"] and len(a["params_hash"]) == 16
    assert a["tracks"] == {
        "confirmed": 6,
        "person": 3,
        "circle_object": 1,
        "rectangular_object": 2,
        "unknown": 0,
        "dynamic": 5,
    }
    assert lines[1]["error"] == f"{logs / 'bad.mcap'}: no such file"
    (logs / "bad.mcap").write_bytes(b"now it exists")
    CALLS.clear()
    again = run(logs / "a.mcap", logs / "bad.mcap", logs / "b.mcap", "-o", out, "--jobs", "1")
    assert again.exit_code == 1 and CALLS == []  # bad.mcap redone, and fails again
    assert "2 skipped" in again.stderr and "not an MCAP file" in again.stderr
    assert [r["status"] for r in batch.Manifest(str(out)).latest().values()] == ["skipped", "failed", "skipped"]
    assert len(manifest(out)) == 6  # the earlier lines compacted to one per input, then this batch's
    os.utime(logs / "a.mcap", ns=(1, 1))  # touched, same bytes: still skipped
    (logs / "b.mcap").write_bytes(b"changed")  # changed: redone
    third = run(logs / "a.mcap", logs / "b.mcap", "-o", out, "--jobs", "1")
    assert third.exit_code == 0 and CALLS == ["b.mcap"], third.output
    CALLS.clear()
    forced = run(logs / "a.mcap", logs / "b.mcap", "-o", out, "--jobs", "2", "--force")
    assert forced.exit_code == 0 and "2 done, 0 skipped" in forced.stderr


def test_other_parameters_redo_the_inputs(logs, tmp_path):
    out = tmp_path / "out"
    assert run(logs / "a.mcap", "-o", out, "--jobs", "1").exit_code == 0
    CALLS.clear()
    other = run(logs / "a.mcap", "-o", out, "--jobs", "1", "--ego-motion", "off")
    assert other.exit_code == 0 and CALLS == ["a.mcap"], other.output  # its own output: overwritten


def test_an_output_that_is_not_the_batchs_is_never_overwritten(logs, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "a.mcap").write_bytes(b"someone else's file")
    r = run(logs / "a.mcap", "-o", out, "--jobs", "1")
    assert r.exit_code == 1 and f"{out / 'a.mcap'}: exists; use --force" in r.stderr
    assert (out / "a.mcap").read_bytes() == b"someone else's file"


def test_the_leftover_of_an_interrupted_batch_is_redone(tmp_path, sample_logs):
    """An output a worker finished after the batch stopped listening is not in the manifest; its provenance
    says it is datmo run's output of this input, so the next run redoes it without --force."""
    src = tmp_path / "hall.mcap"
    src.write_bytes((sample_logs / "hall.mcap").read_bytes())
    out = tmp_path / "out"
    out.mkdir()
    from datmo_cli.logs import mcapio

    with mcapio.LogWriter(out / "hall.mcap", provenance=mcapio.Provenance("run", {}, [str(src)])) as w:
        w.copy_from(src)
    assert batch.plan._leftover(str(out / "hall.mcap"), str(src))
    plan = batch.prepare([str(src)], str(out))
    assert plan.tasks[0].force and not plan.skipped
    assert not batch.plan._leftover(str(out / "hall.mcap"), str(sample_logs / "hall.mcap"))


def test_ctrl_c_keeps_finished_outputs_and_a_consistent_manifest(logs, tmp_path):
    out = tmp_path / "out"
    (logs / "stop.mcap").write_bytes(b"x")
    names = [logs / "a.mcap", logs / "b.mcap", logs / "stop.mcap", logs / "site" / "c.mcap"]
    (out).mkdir()
    (out / ".stop.mcap.123.tmp").write_bytes(b"partial")  # another process's: not this batch's to remove
    r = run(*names, "-o", out, "--jobs", "1")
    assert r.exit_code == 130, r.output
    assert "interrupted: 2 of 4 inputs done" in r.stderr and "Traceback" not in r.output
    assert [Path(x["input"]).name for x in manifest(out)] == ["a.mcap", "b.mcap"]
    assert sorted(p.name for p in out.iterdir()) == [".stop.mcap.123.tmp", "a.mcap", "b.mcap", "manifest.jsonl"]
    (logs / "stop.mcap").rename(logs / "go.mcap")
    CALLS.clear()
    names[2] = logs / "go.mcap"
    again = run(*names, "-o", out, "--jobs", "1")
    assert again.exit_code == 0 and CALLS == ["go.mcap", "c.mcap"], again.output


def test_ctrl_c_inside_a_compiled_call_stops_the_batch_and_fails_no_log(logs, tmp_path):
    out = tmp_path / "out"
    (logs / "boxed.mcap").write_bytes(b"x")
    r = run(logs / "a.mcap", logs / "boxed.mcap", logs / "b.mcap", "-o", out, "--jobs", "1")
    assert r.exit_code == 130, r.output
    assert "interrupted: 1 of 3 inputs done" in r.stderr and "SystemError" not in r.output
    assert [(Path(x["input"]).name, x["status"]) for x in manifest(out)] == [("a.mcap", "done")]
    assert CALLS == ["a.mcap"]


def test_fsspec_urls_for_inputs_and_outputs(logs, tmp_path):
    fsspec = pytest.importorskip("fsspec")
    mem = fsspec.filesystem("memory")
    mem.pipe("/datmo-test/in/x.mcap", b"remote bytes")
    mem.pipe("/datmo-test/in/sub/y.mcap", b"more remote bytes")
    try:
        r = run("memory://datmo-test/in", f"file://{logs}/a.mcap", "-o", "memory://datmo-test/out", "--jobs", "1")
        assert r.exit_code == 0, r.output
        assert mem.exists("/datmo-test/out/x.mcap") and mem.exists("/datmo-test/out/sub/y.mcap")
        assert mem.exists("/datmo-test/out/a.mcap")
        assert not [p for p in mem.find("/datmo-test/out") if p.endswith(".tmp")]
        lines = [json.loads(x) for x in mem.cat("/datmo-test/out/manifest.jsonl").decode().splitlines()]
        assert {x["status"] for x in lines} == {"done"} and len(lines) == 3
        inputs = sorted(x["input"] for x in lines)
        assert inputs[0] == str(logs / "a.mcap")  # file:// is a local path
        assert [
            i.startswith("memory://") and i.endswith(n)
            for i, n in zip(inputs[1:], ("sub/y.mcap", "x.mcap"), strict=True)
        ] == [True, True]
        again = run("memory://datmo-test/in", "-o", "memory://datmo-test/out", "--jobs", "1")
        assert again.exit_code == 0 and "2 skipped" in again.stderr
    finally:
        mem.rm("/datmo-test", recursive=True)


def test_report_of_a_batch_folder(logs, tmp_path):
    out = tmp_path / "out"
    run(logs / "a.mcap", logs / "bad.mcap", logs / "b.mcap", "-o", out, "--jobs", "1")
    r = CliRunner().invoke(cli, ["report", str(out), "--format", "json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    s = doc["batches"][0]["summary"]
    assert (s["inputs"], s["done"], s["failed"], s["scans"]) == (3, 2, 1, 100)
    assert s["tracks"]["person"] == 6 and s["failures"][0]["input"] == str(logs / "bad.mcap")
    assert len(doc["files"]) == 2 and doc["total"]["scans"] == 100
    csv = CliRunner().invoke(cli, ["report", str(out), "--format", "csv"]).stdout.splitlines()
    assert csv[0].startswith("file,duration_s,scans") and len(csv) == 4 and csv[3].startswith("total,")
    rich = CliRunner().invoke(cli, ["report", str(out)])
    assert rich.exit_code == 0 and "Failed inputs" in rich.stdout
    missing = CliRunner().invoke(cli, ["report", str(logs)])
    assert (
        missing.exit_code == 1
        and missing.output.strip()
        == f"datmo: error: {logs}: no manifest.jsonl (a batch folder is the -o folder of datmo run)"
    )


def test_an_unreachable_scheduler_is_one_line(logs, tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    import socket

    from datmo_cli.batch import cluster

    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT", "1s")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    r = run(logs / "a.mcap", "-o", tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{port}")
    assert r.exit_code == 1 and "Traceback" not in r.output
    assert r.output.startswith(f"datmo: error: --scheduler tcp://127.0.0.1:{port}: cannot reach the Dask scheduler")
    bad = run(logs / "a.mcap", "-o", tmp_path / "out", "--scheduler", "local:0")
    assert bad.exit_code == 1 and "local or local:N with N >= 1" in bad.output
