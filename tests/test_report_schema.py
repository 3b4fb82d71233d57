"""`datmo report`'s shapes are pinned: the same CSV header and JSON keys for one file, several files, a batch
folder and datmo run's closing report; piped tables keep long names whole; the progress bar's total."""

from __future__ import annotations

import csv
import io
import json

import pytest
from click.testing import CliRunner
from synthetic_logs import write

from datmo_cli import report
from datmo_cli.cli import cli

pytestmark = pytest.mark.cli

FILE_HEADER = (
    "file,duration_s,scans,lines_per_scan,circles_per_scan,blobs_per_scan,landmarks,tracks,moving,"
    "static_pieces,person,circle_object,rectangular_object,unknown,dynamic,distance_m"
)
TRACK_HEADER = (
    "file,id,class,mobility,first_s,last_s,lifetime_s,distance_m,mean_speed_mps,max_speed_mps,"
    "occlusions,x_m,y_m,occluded_scans,scans"
)
TOP_KEYS = ["schema", "files", "total", "batches"]
FILE_KEYS = FILE_HEADER.split(",") + [
    "run",
    "features",
    "landmark_list",
    "frame",
    "tentative_only",
    "classes",
    "moving_tracks",
    "static_by_class",
]
STATIC_KEYS = [
    "class",
    "mobility",
    "tracks",
    "mean_lifetime_s",
    "centroid_x_m",
    "centroid_y_m",
    "x_min_m",
    "x_max_m",
    "y_min_m",
    "y_max_m",
]


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("schema")
    one, two = folder / "one.mcap", folder / "two.mcap"
    write(one)
    write(two, drop_scans=tuple(range(25, 50)))
    return one, two


def invoke(*args):
    result = CliRunner().invoke(cli, [str(a) for a in args])
    assert result.exit_code == 0, result.output
    return result.stdout


def test_csv_header_is_the_same_for_one_file_and_many(logs):
    one = invoke("report", logs[0], "--format", "csv").splitlines()
    many = invoke("report", *logs, "--format", "csv").splitlines()
    assert one[0] == many[0] == FILE_HEADER
    assert [r.split(",")[0] for r in one[1:]] == [str(logs[0]), "total"]
    assert [r.split(",")[0] for r in many[1:]] == [*map(str, logs), "total"]
    assert one[1].split(",")[1:] == one[2].split(",")[1:]  # the total of one file is that file


def test_csv_tracks_header_is_the_same_for_one_file_and_many(logs):
    one = invoke("report", logs[0], "--format", "csv", "--tracks").splitlines()
    many = invoke("report", *logs, "--format", "csv", "--tracks").splitlines()
    assert one[0] == many[0] == TRACK_HEADER
    rows = list(csv.DictReader(io.StringIO("\n".join(many))))
    assert {r["file"] for r in rows} == set(map(str, logs))
    # every confirmed track, static pieces too (--all changes the tables and the plot, not this table)
    assert len([r for r in rows if r["file"] == str(logs[0])]) == 6
    assert {r["mobility"] for r in rows if r["file"] == str(logs[0])} >= {"static", "dynamic"}
    every = invoke("report", logs[0], "--format", "csv", "--tracks", "--all").splitlines()
    assert every == one


@pytest.mark.parametrize("extra", [[], ["--tracks"]])
def test_json_keys_are_the_same_for_one_file_and_many(logs, extra):
    for files in ([logs[0]], list(logs)):
        doc = json.loads(invoke("report", *files, "--format", "json", *extra))
        assert list(doc) == TOP_KEYS + (["tracks"] if extra else [])
        assert doc["schema"] == report.SCHEMA == "datmo.report/1" and doc["batches"] == []
        assert [list(f) for f in doc["files"]] == [FILE_KEYS] * len(files)
        assert list(doc["total"]) == FILE_HEADER.split(",") and doc["total"]["file"] == "total"
        assert [list(s) for s in doc["files"][0]["static_by_class"]] == [STATIC_KEYS]
        assert list(doc["files"][0]["moving_tracks"][0]) == list(report.summarise_file(logs[0]).tracks[0])
        if extra:
            assert {tuple(t) for t in doc["tracks"]} == {tuple(TRACK_HEADER.split(","))}


def test_json_file_entries_hold_the_csv_rows(logs):
    doc = json.loads(invoke("report", *logs, "--format", "json"))
    rows = list(csv.DictReader(io.StringIO(invoke("report", *logs, "--format", "csv"))))
    for entry, row in zip([*doc["files"], doc["total"]], rows, strict=True):
        assert {k: "" if entry[k] is None else str(entry[k]) for k in row} == row


def test_batch_folder_and_run_report_have_the_same_shapes(logs, tmp_path):
    out = tmp_path / "out"
    run = CliRunner().invoke(cli, ["run", str(logs[0]), "-o", str(out), "--jobs", "1", "--format", "csv"])
    assert run.exit_code == 0, run.output
    assert run.stdout.splitlines()[0] == FILE_HEADER
    run_json = json.loads(
        CliRunner().invoke(cli, ["run", str(logs[0]), "-o", str(out), "--jobs", "1", "--format", "json"]).stdout
    )
    assert list(run_json) == TOP_KEYS and list(run_json["files"][0]) == FILE_KEYS
    doc = json.loads(invoke("report", out, "--format", "json"))
    assert list(doc) == TOP_KEYS and [list(f) for f in doc["files"]] == [FILE_KEYS]
    (batch,) = doc["batches"]
    assert list(batch) == ["folder", "summary", "inputs"] and batch["summary"]["done"] == 1
    assert invoke("report", out, "--format", "csv").splitlines()[0] == FILE_HEADER
    assert invoke("report", out, logs[1], "--format", "csv", "--tracks").splitlines()[0] == TRACK_HEADER


def test_the_schema_is_documented_with_the_keys_in_use():
    for key in [*FILE_KEYS, *TOP_KEYS, "tracks"]:
        assert key in report.REPORT_SCHEMA, key
    assert FILE_HEADER in report.REPORT_SCHEMA and TRACK_HEADER in report.REPORT_SCHEMA


def test_empty_report_total_is_zeros():
    total = report.total_row([])
    assert list(total) == FILE_HEADER.split(",") and total["scans"] == 0 and total["lines_per_scan"] is None


def test_piped_tables_keep_long_names_whole(tmp_path):
    path = tmp_path / ("a_long_name_that_a_narrow_table_would_fold_" * 4 + ".mcap")
    write(path)
    out = invoke("report", path, "--format", "rich")
    assert any(str(path) in line for line in out.splitlines())
    assert all(len(line) < 1000 for line in out.splitlines())  # plain, unlimited: no padding to 10,000


def test_progress_counts_scans_to_the_total(logs, monkeypatch):
    from contextlib import contextmanager

    from datmo_cli.base import progress

    seen = {}

    class Recorder:
        def update(self, done, total=None):
            seen.setdefault("done", []).append(done)

    @contextmanager
    def bar(description, total, **kwargs):
        seen["total"] = total
        yield Recorder()

    monkeypatch.setattr(progress, "bar", bar)
    invoke("report", *logs, "--format", "csv")
    assert seen["total"] == 50 + 25
    assert seen["done"] == sorted(seen["done"]) and seen["done"][-1] == 75


def test_summarise_file_reports_scans_read(logs):
    calls = []
    report.summarise_file(logs[0], block=10, progress=calls.append)
    assert calls == sorted(calls) and calls[-1] == 50 and len(calls) > 2


def test_quiet_keeps_the_report_and_drops_the_plot_line(logs, tmp_path):
    plot = tmp_path / "one.png"
    result = CliRunner().invoke(cli, ["report", str(logs[0]), "--format", "csv", "--plot", str(plot), "-q"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines()[0] == FILE_HEADER and result.stderr == "" and plot.exists()
    loud = CliRunner().invoke(cli, ["report", str(logs[0]), "--format", "csv", "--plot", str(plot), "--force"])
    assert f"{plot}: plot written" in loud.stderr
