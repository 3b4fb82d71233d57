"""The Dask side of `datmo run` and security: `--scheduler local[:N]` starts a
cluster that speaks TLS with a temporary certificate, so nobody without it (another user of the machine) can
connect and run code as the user running datmo; `--scheduler tls://...` uses the certificate of the Dask
configuration, and says in one line (exit 1, not 70) when there is none."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner
from test_batch import CALLS, fake_process

from datmo_cli.cli import cli
from datmo_cli.passes import pipeline, warm

distributed = pytest.importorskip("distributed")
pytest.importorskip("cryptography")
pytestmark = [pytest.mark.cli, pytest.mark.timeout(300)]


def _refused(address: str, **kw) -> bool:
    try:
        client = distributed.Client(address, timeout="5s", **kw)
    except (OSError, TimeoutError, TypeError, ValueError):
        return True
    client.close()
    return False


_LOCAL_TLS_CHECK = """
import sys
from pathlib import Path

import distributed
from distributed.security import Security

from datmo_cli import batch
from datmo_cli.batch.cluster import DaskExecutor


def refused(address, **kw):
    try:
        client = distributed.Client(address, timeout="5s", **kw)
    except (OSError, TimeoutError, TypeError, ValueError):
        return True
    client.close()
    return False


tmp, src = Path(sys.argv[1]), sys.argv[2]
import os
os.environ.pop("NUMBA_NUM_THREADS", None)
executor = DaskExecutor("local:1")
try:
    assert "NUMBA_NUM_THREADS" not in os.environ, "the workers' numba setting leaked into this process"
    address = executor.client.scheduler.address
    workers = list(executor.client.scheduler_info()["workers"])
    assert address.startswith("tls://127.0.0.1:") and workers and all(w.startswith("tls://") for w in workers)
    assert refused(address.replace("tls://", "tcp://"))                  # no TLS: no entry
    other = Security.temporary()
    stranger = Security(tls_ca_file=executor.cluster.security.tls_ca_file, tls_client_cert=other.tls_client_cert,
                        tls_client_key=other.tls_client_key, require_encryption=True)
    assert refused(address, security=stranger)    # trusts the scheduler, but holds another certificate
    assert not refused(address, security=executor.cluster.security)     # the run's own certificate: in
    plan = batch.prepare([src], str(tmp / "out"))
    records = batch.run_many(plan, executor)                               # and it runs the batch
    assert [r["status"] for r in records] == ["done"] and records[0]["scans"] == 300
finally:
    executor.close()
print("ok")
"""


@pytest.mark.slow
def test_a_runs_own_local_cluster_speaks_tls_and_refuses_strangers(tmp_path, sample_logs):
    """In a process of its own: a local cluster sets NUMBA_NUM_THREADS=1 in its process's environment while it
    spawns the workers, and this test process's numba thread pool must not start under it (as test_cluster.py)."""
    import subprocess
    import sys

    src = tmp_path / "static.mcap"
    src.write_bytes((sample_logs / "static.mcap").read_bytes())
    result = subprocess.run(
        [sys.executable, "-c", _LOCAL_TLS_CHECK, str(tmp_path), str(src)], capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0 and result.stdout.strip().endswith("ok"), result.stderr[-2000:]


_NO_HTTP_CHECK = """
import socket
import urllib.request

from datmo_cli.batch.cluster import DaskExecutor


def answers(port):
    try:
        socket.create_connection(("127.0.0.1", port), timeout=5).close()
    except OSError:
        return False
    return True


executor = DaskExecutor("local:1")
try:
    ports = {"scheduler": executor.cluster.scheduler.http_server.port}
    for address, worker in executor.client.scheduler_info()["workers"].items():
        ports[address] = worker["services"]["dashboard"]
    assert len(ports) == 2 and all(isinstance(p, int) and p > 0 for p in ports.values()), ports
    for who, port in ports.items():
        assert not answers(port), f"{who}: an HTTP server on 127.0.0.1:{port}"
finally:
    executor.close()
print("ok")
"""


@pytest.mark.slow
def test_a_runs_own_local_cluster_serves_no_http(tmp_path):
    """No HTTP server on the local cluster's scheduler or workers: their endpoints (/info, /json, /metrics,
    /eventstream, call stacks, logs) would be open to every user of the machine, without authentication."""
    import subprocess
    import sys

    result = subprocess.run(
        [sys.executable, "-c", _NO_HTTP_CHECK], capture_output=True, text=True, timeout=600, cwd=tmp_path
    )
    assert result.returncode == 0 and result.stdout.strip().endswith("ok"), result.stderr[-2000:]
    assert "Traceback" not in result.stderr and "8787" not in result.stderr, result.stderr[-2000:]


@pytest.fixture
def tls_scheduler(tmp_path, monkeypatch):
    """A TLS scheduler with a worker thread in this process (so the stand-in processing reaches it), and its
    certificate as files, as a user keeps them for the Dask configuration."""
    from distributed.security import Security

    monkeypatch.setattr(pipeline, "process_file", fake_process)
    monkeypatch.setattr(warm, "warm_up", lambda *_a, **_k: None)
    CALLS.clear()
    sec = Security.temporary()
    pem = {"ca": sec.tls_ca_file, "cert": sec.tls_client_cert, "key": sec.tls_client_key}
    files = {}
    for name, text in pem.items():
        files[name] = tmp_path / f"{name}.pem"
        files[name].write_text(text)
    cluster = distributed.LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        protocol="tls://",
        host="127.0.0.1",
        security=sec,
        dashboard_address=None,
    )
    try:
        yield cluster.scheduler_address, files
    finally:
        cluster.close()


def test_a_tls_scheduler_with_the_certificate_of_the_dask_configuration(tls_scheduler, tmp_path):
    import dask

    address, files = tls_scheduler
    src = tmp_path / "a.mcap"
    src.write_bytes(b"a log")
    args = ["run", str(src), "-o", str(tmp_path / "out"), "--scheduler", address, "--no-report"]
    r = CliRunner().invoke(cli, args)
    assert r.exit_code == 1 and "Traceback" not in r.output, r.output
    assert (
        r.output.startswith(
            f"datmo: error: --scheduler {address}: a tls:// scheduler needs this client's "
            "certificate: set distributed.comm.tls.ca-file"
        )
        and len(r.output.splitlines()) == 1
    )
    with dask.config.set(
        {
            "distributed.comm.tls.ca-file": str(files["ca"]),
            "distributed.comm.tls.client.cert": str(files["cert"]),
            "distributed.comm.tls.client.key": str(files["key"]),
        }
    ):
        ok = CliRunner().invoke(cli, args)
    assert ok.exit_code == 0, ok.output
    assert CALLS == ["a.mcap"] and f"the Dask scheduler {address}" in ok.stderr
    line = json.loads((tmp_path / "out" / "manifest.jsonl").read_text())
    assert line["status"] == "done" and Path(line["output"]).exists()
