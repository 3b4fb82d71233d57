"""`datmo run` in one pass: the report it prints is gathered while each output is written (never by reading
the output back) and equals `datmo report` on the output; the ego-motion "auto" check reads the first block
of a log, not the whole log an extra time."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from run_cases import sample_logs

from datmo_cli import report as report_module
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanRun

pytestmark = pytest.mark.cli


def invoke(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, (args, result.output)
    return result


@pytest.fixture(scope="module")
def ran(tmp_path_factory):
    """Every sample log through one `datmo run --format json`: (output folder, the report it printed)."""
    out = tmp_path_factory.mktemp("run") / "out"
    result = invoke("run", *sample_logs(), "-o", out, "--jobs", "1", "--format", "json")
    return out, json.loads(result.stdout)


def test_run_report_equals_datmo_report_of_its_outputs(ran):
    out, printed = ran
    files = [out / p.name for p in sample_logs()]
    again = json.loads(invoke("report", *files, "--format", "json").stdout)
    assert printed == again
    assert [f["file"] for f in printed["files"]] == [str(f) for f in files]


@pytest.mark.parametrize("fmt", ["csv", "markdown"])
def test_other_formats_too(tmp_path, fmt):
    log = sample_logs()[0]
    printed = invoke("run", log, "-o", tmp_path, "--jobs", "1", "--format", fmt).stdout
    assert printed == invoke("report", tmp_path / log.name, "--format", fmt).stdout


def test_the_manifest_keeps_no_report(ran):
    out, printed = ran
    lines = [json.loads(line) for line in (out / "manifest.jsonl").read_text().splitlines()]
    assert lines and all("summary" not in line for line in lines)
    by_name = {f["file"]: f for f in printed["files"]}
    for line in lines:
        assert line["tracks"]["confirmed"] == by_name[line["output"]]["tracks"]


def test_run_never_reads_its_output_back(tmp_path, monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("the output was read back for the report")

    monkeypatch.setattr(report_module, "stream_run", refuse)
    monkeypatch.setattr(report_module, "summarise_file", refuse)
    result = invoke("run", sample_logs()[0], "-o", tmp_path, "--jobs", "1", "--format", "json")
    assert json.loads(result.stdout)["files"][0]["scans"] > 0


def test_skipped_inputs_are_reported_from_their_outputs(ran, tmp_path):
    log = sample_logs()[0]
    first = invoke("run", log, "-o", tmp_path, "--jobs", "1", "--format", "json").stdout
    again = invoke("run", log, "-o", tmp_path, "--jobs", "1", "--format", "json")
    assert "1 skipped" in again.stderr and again.stdout == first


def test_two_jobs_report_the_same(tmp_path):
    logs = sample_logs()[:2]
    printed = json.loads(invoke("run", *logs, "-o", tmp_path, "--jobs", "2", "--format", "json").stdout)
    assert printed == json.loads(invoke("report", *(tmp_path / p.name for p in logs), "--format", "json").stdout)


def test_ego_motion_auto_reads_only_the_first_block(tmp_path, monkeypatch):
    from datmo_cli.passes import streaming
    from datmo_cli.perception.egomotion import EGO_SAMPLE_SCANS

    hall = mcapio.read_run(sample_logs()[[p.stem for p in sample_logs()].index("hall")])
    n = 3 * EGO_SAMPLE_SCANS
    period = int(np.median(np.diff(hall.stamps)))
    reps = -(-n // len(hall))
    long = ScanRun(
        hall.stamps[0] + np.arange(n, dtype=np.int64) * period, np.tile(hall.ranges, (reps, 1))[:n], hall.geometry
    )
    path = tmp_path / "long.mcap"
    with mcapio.LogWriter(path) as w:
        w.write_scans(long)
    stream = streaming.LogStream(path)
    read = []
    walk = mcapio.iter_messages

    def counting(*args, **kwargs):
        for m in walk(*args, **kwargs):
            read.append(m[0])
            yield m

    monkeypatch.setattr(mcapio, "iter_messages", counting)
    odometry, estimated = streaming.stream_odometry(stream, "auto")
    assert odometry is None and not estimated  # the hall's scanner stands still
    assert read.count(mcapio.TOPIC_SCAN) <= EGO_SAMPLE_SCANS + 1  # the first block (and the scan after it)


def test_the_report_is_fed_from_the_stages_arrays_not_from_decoded_payloads(tmp_path, monkeypatch):
    """The run's report comes from the arrays the stages made (features, landmarks, tracks): no message is
    decoded for it, and it equals `datmo report` on the output."""
    from datmo_cli.logs import cdr

    def refuse(*args, **kwargs):
        raise AssertionError("a payload was decoded for the report")

    log = sample_logs()[0]
    with monkeypatch.context() as m:
        m.setattr(cdr, "decode", refuse)
        m.setattr(cdr, "decode_many", refuse)
        printed = invoke("run", log, "-o", tmp_path, "--jobs", "1", "--format", "json").stdout
    assert json.loads(printed)["files"][0]["landmarks"] is not None
    assert json.loads(printed) == json.loads(invoke("report", tmp_path / log.name, "--format", "json").stdout)
