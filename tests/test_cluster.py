"""`datmo run --scheduler` on a real Dask cluster: a scheduler and two worker processes started here with
the `dask` command line (free ports, no dashboard, one thread each), stopped at the end. The sample logs
through the cluster give, message for message, the outputs of a local run; a corrupt input fails alone;
a worker killed mid-task has its task done elsewhere; a batch interrupted with Ctrl-C resumes with only
the missing inputs."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli
from datmo_cli.logs import mcapio

pytestmark = pytest.mark.cli

distributed = pytest.importorskip("distributed")

BIN = Path(sys.executable).parent


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Cluster:
    """A scheduler and named worker processes (each `dask worker --no-nanny`: killing it kills the worker)."""

    def __init__(self, logs: Path) -> None:
        self.port = free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.logs = logs
        self.procs: dict[str, subprocess.Popen] = {}
        dask = str(BIN / "dask") if (BIN / "dask").exists() else shutil.which("dask")
        self.dask = [dask] if dask else [sys.executable, "-m", "dask"]
        self._start("scheduler", "scheduler", "--host", "127.0.0.1", "--port", str(self.port), "--no-dashboard")
        self.client = None

    def _start(self, name: str, *args: str) -> None:
        log = open(self.logs / f"{name}.log", "w")
        self.procs[name] = subprocess.Popen(
            [*self.dask, *args], stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )

    def start_worker(self, name: str) -> None:
        self._start(
            name,
            "worker",
            self.address,
            "--nworkers",
            "1",
            "--nthreads",
            "1",
            "--no-nanny",
            "--no-dashboard",
            "--name",
            name,
            "--local-directory",
            str(self.logs / name),
        )

    def connect(self, workers: int) -> None:
        if self.client is None:
            self.client = distributed.Client(self.address, timeout="60s")
        self.client.wait_for_workers(workers, timeout=300)  # a worker loads (or compiles) the kernels first

    def address_of(self, name: str) -> str:
        return next(a for a, w in self.client.scheduler_info()["workers"].items() if w.get("name") == name)

    def stop(self) -> None:
        if self.client is not None:
            self.client.close()
        for p in self.procs.values():
            if p.poll() is None:
                p.terminate()
        for p in self.procs.values():
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    from datmo_cli.passes.warm import warm_up

    warm_up()  # the numba cache complete before the workers load it (a fresh clone compiles here, once)
    c = Cluster(tmp_path_factory.mktemp("dask"))
    try:
        for name in ("w0", "w1"):
            c.start_worker(name)
        c.connect(2)
        yield c
    finally:
        c.stop()


@pytest.fixture
def inputs(tmp_path, sample_logs):
    """The sample logs copied into a folder (a subfolder too)."""
    d = tmp_path / "in"
    (d / "more").mkdir(parents=True)
    for i, p in enumerate(sorted(sample_logs.glob("*.mcap"))):
        shutil.copy(p, d / ("more" if i % 2 else "") / p.name)
    return d


def datmo(*args, timeout=600, **kw):
    return subprocess.run([str(BIN / "datmo"), *map(str, args)], capture_output=True, text=True, timeout=timeout, **kw)


def lines(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "manifest.jsonl").read_text().splitlines()]


def same_messages(a: Path, b: Path) -> None:
    """Every channel of a and b: same topics, types, stamps and payloads; metadata equal but the command line."""
    la, lb = mcapio.read_log(a, topics=None), mcapio.read_log(b, topics=None)
    assert sorted((c.topic, c.msgtype) for c in la.channels.values()) == sorted(
        (c.topic, c.msgtype) for c in lb.channels.values()
    )
    assert sorted(la.messages) == sorted(lb.messages)
    for topic, (stamps, payloads) in la.messages.items():
        assert list(stamps) == list(lb.messages[topic][0]), (a, topic)
        assert payloads == lb.messages[topic][1], (a, topic)
    ma, mb = dict(la.metadata), dict(lb.metadata)
    assert ma["datmo"].pop("command_line") != mb["datmo"].pop("command_line")
    assert ma == mb


def test_cluster_outputs_equal_a_local_run(cluster, inputs, tmp_path):
    on_cluster, here = tmp_path / "cluster", tmp_path / "local"
    r = CliRunner().invoke(
        cli, ["run", str(inputs), "-o", str(on_cluster), "--scheduler", cluster.address, "--no-report"]
    )
    assert r.exit_code == 0, r.output
    assert "6 done, 0 skipped" in r.stderr and f"the Dask scheduler {cluster.address}" in r.stderr
    local = datmo("run", inputs, "-o", here, "--jobs", "2", "--no-report")  # a process of its own, as a user runs it
    assert local.returncode == 0, local.stderr[-3000:]
    outs = sorted(p.relative_to(on_cluster) for p in on_cluster.rglob("*.mcap"))
    assert len(outs) == 6 and any(len(p.parts) == 2 for p in outs)  # the subfolder is kept
    assert outs == sorted(p.relative_to(here) for p in here.rglob("*.mcap"))
    for rel in outs:
        same_messages(on_cluster / rel, here / rel)
    ledger = lines(on_cluster)
    assert {x["status"] for x in ledger} == {"done"} and len({x["worker"] for x in ledger}) == 2
    assert [x["tracks"] for x in sorted(ledger, key=lambda x: x["input"])] == [
        x["tracks"] for x in sorted(lines(here), key=lambda x: x["input"])
    ]


def test_a_corrupt_input_among_good_ones(cluster, sample_logs, tmp_path):
    good = [sample_logs / "csail-excerpt.mcap", sample_logs / "static.mcap"]
    bad = tmp_path / "corrupt.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + os.urandom(5000))
    out = tmp_path / "out"
    r = CliRunner().invoke(
        cli,
        ["run", str(good[0]), str(bad), str(good[1]), "-o", str(out), "--scheduler", cluster.address, "--no-report"],
    )
    assert r.exit_code == 1 and "Traceback" not in r.output
    assert r.stderr.rstrip().endswith("datmo: error: 1 of 3 inputs failed; the other outputs are complete")
    by_name = {Path(x["input"]).name: x for x in lines(out)}
    assert by_name["corrupt.mcap"]["status"] == "failed"
    assert by_name["corrupt.mcap"]["error"].startswith(f"{bad}: ") and "\n" not in by_name["corrupt.mcap"]["error"]
    assert by_name["csail-excerpt.mcap"]["status"] == by_name["static.mcap"]["status"] == "done"
    assert sorted(p.name for p in out.iterdir()) == ["csail-excerpt.mcap", "manifest.jsonl", "static.mcap"]


def test_resume_after_an_interrupted_batch_does_only_the_missing_inputs(cluster, inputs, tmp_path):
    for p in list(inputs.rglob("*.mcap")):  # 12 inputs: the batch is still running when it is stopped
        shutil.copy(p, p.with_name(f"copy-{p.name}"))
    out = tmp_path / "out"
    args = [str(BIN / "datmo"), "run", str(inputs), "-o", str(out), "--scheduler", cluster.address, "--no-report"]
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    manifest = out / "manifest.jsonl"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if manifest.exists() and manifest.read_text().count("\n") >= 2:
            break
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)  # Ctrl-C
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-3000:]
    assert "interrupted:" in err and "Traceback" not in err
    first = lines(out)  # every line whole
    assert first and all(x["status"] == "done" for x in first) and len(first) < 12
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]
    assert all(Path(x["output"]).exists() for x in first)
    again = datmo("run", inputs, "-o", out, "--scheduler", cluster.address, "--no-report")
    assert again.returncode == 0, again.stderr[-3000:]
    latest = {x["input"]: x for x in lines(out)}
    assert len(latest) == 12 and {x["status"] for x in latest.values()} <= {"done", "skipped"}
    assert {i for i, x in latest.items() if x["status"] == "skipped"} == {x["input"] for x in first}
    assert f"{12 - len(first)} done, {len(first)} skipped" in again.stderr


@pytest.mark.slow
def test_a_worker_killed_mid_task_has_its_task_done_elsewhere(cluster, inputs, tmp_path):
    cluster.start_worker("victim")
    cluster.connect(3)
    victim = cluster.address_of("victim")
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [str(BIN / "datmo"), "run", str(inputs), "-o", str(out), "--scheduler", cluster.address, "--no-report"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    killed = False
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None and not killed:
        if any(str(k).startswith("datmo-run-") for k in cluster.client.processing().get(victim, ())):
            time.sleep(0.3)  # well into the task
            cluster.procs["victim"].kill()
            killed = True
        time.sleep(0.02)
    _, err = proc.communicate(timeout=300)
    assert killed, "the victim worker never ran a task"
    assert proc.returncode == 0, err[-3000:]
    ledger = lines(out)
    assert len(ledger) == 6 and {x["status"] for x in ledger} == {"done"}
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]
