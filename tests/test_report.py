"""`datmo report`: the summary of a hand-made processed log with known answers, its formats, plot and errors."""

from __future__ import annotations

import csv
import io
import json

import pytest
from click.testing import CliRunner
from synthetic_logs import write

from datmo_cli import report
from datmo_cli.cli import cli
from datmo_cli.passes.pipeline import read_run_data

pytestmark = pytest.mark.cli


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("report") / "run.mcap"
    write(path)
    return path


@pytest.fixture(scope="module")
def summary(log):
    return report.summarise(read_run_data(log))


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_run_facts(summary):
    r = summary.run
    assert (r["scans"], r["beams"], r["dropped_scans"]) == (50, 361, 0)
    assert r["duration_s"] == pytest.approx(9.8)
    assert r["rate_hz"] == pytest.approx(5.0)
    assert r["version"] and r["command"] == "datmo track in.mcap -o x"
    assert r["parameters"] == {"gate_m": 1.5, "c0": 0.05}


def test_dropped_scans_counted_from_gaps(tmp_path):
    path = tmp_path / "gaps.mcap"
    write(path, drop_scans=(10, 11, 30))
    assert report.summarise(read_run_data(path)).run["dropped_scans"] == 3


def test_features_and_landmarks(summary):
    f = summary.features
    assert f["lines"] == {"total": 100, "per_scan": 2.0, "max_per_scan": 2}
    assert f["circles"]["total"] == 49 and f["circles"]["max_per_scan"] == 2
    assert f["blobs"]["per_scan"] == 1.0
    column, corner = summary.landmarks  # the database after the last scan
    assert (column["type"], column["x_m"], column["y_m"], column["size_m"]) == ("column", 6.0, -2.0, 0.15)
    assert (column["first_seen_s"], column["last_seen_s"], column["scans"]) == (2.0, 9.8, 40)
    assert (corner["type"], corner["first_seen_s"]) == ("corner", 4.0)


def test_track_rows(summary):
    rows = {r["id"]: r for r in summary.tracks}
    assert set(rows) == {1, 2, 3, 4, 5, 6, 7}
    assert not rows[6]["confirmed"] and all(rows[i]["confirmed"] for i in (1, 2, 3, 4, 5, 7))
    one = rows[1]
    assert (one["class"], one["mobility"], one["scans"]) == ("person", "dynamic", 50)
    assert one["lifetime_s"] == pytest.approx(9.8)
    assert one["distance_m"] == pytest.approx(0.6 * 0.2 * 47, abs=1e-3)  # its 48 confirmed states

    assert one["mean_speed_mps"] == pytest.approx(0.6, abs=1e-3) and one["max_speed_mps"] == pytest.approx(0.6)
    two = rows[2]
    assert (two["occlusions"], two["occluded_scans"], two["last_s"]) == (1, 5, 4.8)
    assert two["distance_m"] == pytest.approx(0.5 * 0.2 * 19, abs=1e-3)  # not along its coasting states
    assert rows[5]["mobility"] == "static" and rows[5]["distance_m"] == 0
    assert summary.frame == "sensor"


def test_class_rows_count_confirmed_tracks(summary):
    got = {(r["class"], r["mobility"]): r for r in summary.classes}
    assert list(got) == [
        ("person", "dynamic"),
        ("circle object", "dynamic"),
        ("rectangular object", "dynamic"),
        ("rectangular object", "static"),
    ]
    people = got[("person", "dynamic")]
    assert (people["tracks"], people["occlusions"]) == (3, 1)
    assert people["max_lifetime_s"] == pytest.approx(9.8)
    assert people["distance_m"] == pytest.approx(5.64 + 1.9 + 2.4, abs=1e-2)


def test_sort_and_top(summary):
    assert [r["id"] for r in report.sort_tracks(summary.confirmed(), "distance")][:3] == [1, 7, 2]
    assert [r["id"] for r in report.sort_tracks(summary.confirmed(), "first")] == [1, 2, 5, 3, 7, 4]
    assert [r["id"] for r in summary.to_dict(top=2)["moving_tracks"]] == [1, 3]
    assert [r["id"] for r in summary.shown(None, "id", all_tracks=True)] == [1, 2, 3, 4, 5, 7]


def test_moving_tracks_in_full_static_pieces_summarised(summary):
    assert [r["id"] for r in summary.shown(None, "id")] == [1, 2, 3, 4, 7]  # 5 is a static rectangle
    five = next(r for r in summary.tracks if r["id"] == 5)
    (static,) = report.static_rows(summary.tracks)
    assert (static["class"], static["mobility"], static["tracks"]) == ("rectangular object", "static", 1)
    assert (static["centroid_x_m"], static["centroid_y_m"]) == (five["x_m"], five["y_m"])
    assert static["x_min_m"] == static["x_max_m"] == five["x_m"]
    row = summary.file_row()
    assert (row["tracks"], row["moving"], row["static_pieces"]) == (6, 5, 1)


def test_cli_rich(log):
    result = invoke("report", log)
    assert result.exit_code == 0, result.output
    for text in (
        "1 file",
        "run.mcap: run",
        "5.00 Hz",
        "dropped scans",
        "features (50 scans)",
        "landmarks (2",
        "column",
        "people and dynamic tracks (5 of 5, by lifetime; 6 confirmed, 1 never confirmed",
        "person",
        "circle object",
        "static pieces by class (1 tracks",
    ):
        assert text in result.output, text


def test_cli_json(log):
    result = invoke("report", log, "--format", "json", "--sort", "id")
    assert result.exit_code == 0, result.output
    (data,) = json.loads(result.output)["files"]
    assert data["run"]["scans"] == 50 and data["scans"] == 50
    assert data["tracks"] == 6 and data["tentative_only"] == 1
    assert [t["id"] for t in data["moving_tracks"]] == [1, 2, 3, 4, 7]
    assert data["features"]["lines"]["total"] == 100
    assert len(data["landmark_list"]) == 2


def test_cli_csv_tracks_is_the_track_table(log):
    result = invoke("report", log, "--format", "csv", "--tracks", "--top", "3", "--sort", "lifetime", "--all")
    rows = list(csv.DictReader(io.StringIO(result.output)))
    assert [int(r["id"]) for r in rows] == [1, 5, 3] and {r["file"] for r in rows} == {str(log)}
    assert float(rows[0]["distance_m"]) == pytest.approx(5.64, abs=1e-3)


def test_cli_markdown(log):
    result = invoke("report", log, "--format", "markdown")
    assert result.exit_code == 0
    assert "### run.mcap: run" in result.output and "| id | class | mobility |" in result.output
    assert "|---:|---|---|" in result.output


def test_several_files_give_a_row_each_and_a_total(tmp_path, log):
    other = tmp_path / "other.mcap"
    write(other, drop_scans=tuple(range(25, 50)))
    result = invoke("report", log, other, "--format", "csv")
    rows = list(csv.DictReader(io.StringIO(result.output)))
    assert [r["file"] for r in rows] == [str(log), str(other), "total"]
    assert int(rows[2]["scans"]) == 75
    assert int(rows[2]["tracks"]) == int(rows[0]["tracks"]) + int(rows[1]["tracks"])
    rich = invoke("report", log, other)
    assert "total" in rich.output and "2 files" in rich.output
    data = json.loads(invoke("report", log, other, "--format", "json").output)
    assert data["total"]["scans"] == 75 and len(data["files"]) == 2


def test_plot_is_written(tmp_path, log):
    out = tmp_path / "run.png"
    result = invoke("report", log, "--plot", out, "--format", "json")
    assert result.exit_code == 0, result.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000
    again = invoke("report", log, "--plot", out)
    assert again.exit_code == 1 and "use --force" in again.output
    assert invoke("report", log, "--plot", out, "--force").exit_code == 0
    svg = tmp_path / "run.svg"
    assert invoke("report", log, "--plot", svg, "--format", "json").exit_code == 0
    assert b"<svg" in svg.read_bytes()[:2000]


def test_plot_rejects_unknown_format(tmp_path, log):
    result = invoke("report", log, "--plot", tmp_path / "run.gif")
    assert result.exit_code == 1 and "plot format must be one of .png, .svg, .pdf" in result.output


@pytest.mark.parametrize(
    "channels, missing, command", [({"with_tracks": False}, "/datmo/tracks", "run datmo track (or datmo run) first")]
)
def test_missing_channel_names_the_command(tmp_path, channels, missing, command):
    path = tmp_path / "partial.mcap"
    write(path, **channels)
    result = invoke("report", path)
    assert result.exit_code == 1
    assert result.output == f"datmo: error: {path}: no messages on {missing}; {command}\n"


def test_report_without_features_still_summarises_tracks(tmp_path):
    path = tmp_path / "nofeatures.mcap"
    write(path, with_features=False)
    (data,) = json.loads(invoke("report", path, "--format", "json").output)["files"]
    assert data["features"] is None and data["landmark_list"] is None and data["tracks"] == 6


def test_bad_input_is_one_clean_line(tmp_path):
    result = invoke("report", tmp_path / "nope.mcap")
    assert result.exit_code == 1 and result.output.startswith("datmo: error: ") and "no such file" in result.output


def test_several_files_give_one_plot_each(tmp_path, log):
    other = tmp_path / "other.mcap"
    write(other)
    result = invoke("report", log, other, "--plot", tmp_path / "fig.svg", "--format", "json")
    assert result.exit_code == 0, result.output
    assert (tmp_path / f"fig-{log.stem}.svg").stat().st_size > 0 and (tmp_path / "fig-other.svg").stat().st_size > 0


def test_run_table_shows_the_leg_model_by_name_and_keeps_long_values_whole():
    from datmo_cli.report import PARAM_WIDTH, param_text

    model = {"model": "default", "sha256": "4c0e3a7d6b376a30f0b3", "threshold": 0.8007, "trained": {"x": [1] * 500}}
    assert param_text("leg_model", model) == "default (sha256 4c0e3a7d6b37, threshold 0.80)"
    long = param_text("other", {"values": list(range(200))})
    assert len(long) > PARAM_WIDTH and long == json.dumps({"values": list(range(200))})  # a terminal cuts it
    assert param_text("c0", 0.08) == "0.08" and param_text("leg_model", "paper") == "paper"
