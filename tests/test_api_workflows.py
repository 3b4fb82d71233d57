"""The commands' work called from Python (docs/python.md): api.run_batch is `datmo run` (resumed by the
manifest, a failing input in .failed, the report's summaries), api.report is `datmo report`, api.evaluate is
`datmo evaluate`, api.record and api.Recording are `datmo record` (against the emulator), api.tune is the
command's own call; and the CLI prints what these return."""

from __future__ import annotations

import json
import shutil
import threading
from pathlib import Path

import pytest
from click.testing import CliRunner

from datmo_cli import api, report
from datmo_cli.base.errors import DatmoError, InputError, OutputExistsError
from datmo_cli.cli import cli
from datmo_cli.lms2xx.emulator import Emulator
from datmo_cli.logs import mcapio
from datmo_cli.passes.simulated import SceneSource

pytestmark = [pytest.mark.cli, pytest.mark.timeout(300)]

SAMPLES = Path(__file__).resolve().parent.parent / "sample_logs"


@pytest.fixture(scope="module")
def batch(tmp_path_factory) -> tuple[Path, api.BatchResult, list[dict]]:
    """api.run_batch of hall and a broken log into a folder: (the folder, the result, the lines on_record saw)."""
    d = tmp_path_factory.mktemp("batch")
    broken = d / "broken.mcap"
    broken.write_bytes(b"not a log")
    seen: list[dict] = []
    result = api.run_batch([SAMPLES / "hall.mcap", broken], d / "out", jobs=1, on_record=seen.append)
    return d, result, seen


def test_run_batch_runs_reports_and_keeps_a_failure(batch):
    d, result, seen = batch
    by_name = {Path(r["input"]).name: r for r in result.records}
    assert by_name["hall.mcap"]["status"] == "done" and by_name["broken.mcap"]["status"] == "failed"
    assert "broken.mcap" in by_name["broken.mcap"]["error"]
    assert [r["input"] for r in result.failed] == [by_name["broken.mcap"]["input"]]
    assert [r["input"] for r in result.ok] == [by_name["hall.mcap"]["input"]]
    assert sorted(r["input"] for r in seen) == sorted(r["input"] for r in result.records)
    assert (d / "out" / "hall.mcap").exists() and (d / "out" / "manifest.jsonl").exists()
    assert result.summaries is not None and len(result.summaries) == 1
    assert result.summaries[0].run["scans"] == by_name["hall.mcap"]["scans"]
    assert result.where and result.seconds > 0


def test_run_batch_resumes_by_the_manifest(batch):
    d, first, _ = batch
    again = api.run_batch([SAMPLES / "hall.mcap"], d / "out", jobs=1)
    assert [r["status"] for r in again.records] == ["skipped"]
    assert again.summaries is not None
    # the skipped output's report is read from it: the same as the one gathered while writing it
    assert report.render(again.summaries, "json", top=None, sort="lifetime") == report.render(
        first.summaries, "json", top=None, sort="lifetime"
    )
    forced = api.run_batch([SAMPLES / "hall.mcap"], d / "out", jobs=1, force=True, report=False)
    assert [r["status"] for r in forced.records] == ["done"] and forced.summaries is None


def test_run_batch_refuses_options_that_do_not_go_together(tmp_path):
    with pytest.raises(DatmoError, match="--jobs is for local runs"):
        api.run_batch([SAMPLES / "hall.mcap"], tmp_path / "out", jobs=1, scheduler="local:1")
    with pytest.raises(DatmoError, match="--plot needs a local output folder"):
        api.run_batch([SAMPLES / "hall.mcap"], "memory://out", plot=True)
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_run_plot_of_a_batch_with_skipped_and_new_inputs(tmp_path):
    """A rerun with --plot that skips one input and runs another draws the new one's plot (each output's plot
    was paired by position, so the skipped output took the new one's plot and the next one failed)."""
    out = tmp_path / "out"
    first = CliRunner().invoke(cli, ["run", str(SAMPLES / "static.mcap"), "-o", str(out), "--plot", "--no-report"])
    assert first.exit_code == 0, first.output
    (out / "static.png").unlink()
    args = ["run", str(SAMPLES / "static.mcap"), str(SAMPLES / "hall.mcap"), "-o", str(out), "--plot", "--jobs", "1"]
    again = CliRunner().invoke(cli, [*args, "--format", "json"])
    assert again.exit_code == 0, again.output
    assert (out / "hall.png").exists() and not (out / "static.png").exists()
    assert sorted(Path(f["run"]["file"]).name for f in json.loads(again.stdout)["files"]) == [
        "hall.mcap",
        "static.mcap",
    ]


def test_report_of_files_and_a_batch_folder(batch):
    d, result, _ = batch
    folder = api.report([d / "out"])
    assert folder.files == [d / "out" / "hall.mcap"]
    assert [b[0] for b in folder.batches] == [d / "out"] and len(folder.batches[0][1]) == 2
    assert report.render(folder.summaries, "csv", top=None, sort="lifetime") == report.render(
        result.summaries, "csv", top=None, sort="lifetime"
    )
    cli_json = CliRunner().invoke(cli, ["report", str(d / "out" / "hall.mcap"), "--format", "json"])
    assert cli_json.exit_code == 0
    assert cli_json.stdout.strip() == report.render(
        api.report([d / "out" / "hall.mcap"]).summaries, "json", top=None, sort="lifetime"
    )


def test_evaluate_gives_the_commands_scores(batch):
    d, _, _ = batch
    out = d / "out" / "hall.mcap"
    scores = api.evaluate(out)
    cli_json = CliRunner().invoke(cli, ["evaluate", str(out), "--format", "json"])
    assert cli_json.exit_code == 0, cli_json.output
    assert json.loads(cli_json.stdout)["scores"] == json.loads(json.dumps(scores["scores"]))
    assert 0.0 < scores["scores"]["all"]["mota"] <= 1.0
    looser = api.evaluate(str(out), match_radius=1.0)
    assert looser["match_radius_m"] == pytest.approx(1.0)


def test_record_against_the_emulator(tmp_path):
    out = tmp_path / "run.mcap"
    with Emulator(SceneSource("hall", seed=3, duration=10)) as emu:
        result = api.record(emu.device_path, out, baud=500000, max_scans=6, laser_pose=(0.1, 0.0, 0.0))
    assert result.scans == 6 and result.reason == "scans" and result.disconnect is None
    run = mcapio.read_run(out)
    assert len(run.stamps) == 6 and run.geometry.n_beams == 361
    metadata = mcapio.read_log(out).metadata
    params = {k: json.loads(v) for k, v in metadata["datmo.params"].items()}
    assert params["baud"] == 500000 and params["scans"] == 6 and params["angle"] == 180
    assert params["laser_pose"]["x_m"] == pytest.approx(0.1)
    assert metadata["datmo"]["command"] == "record" and "datmo_cli.api.record(" in metadata["datmo"]["command_line"]


def test_a_recording_stops_when_asked_and_refuses_what_the_command_refuses(tmp_path):
    out = tmp_path / "run.mcap"
    stop = threading.Event()
    with Emulator(SceneSource("hall", seed=3, duration=10)) as emu:
        counts: list[int] = []

        def progress(scans: int, seconds: float, stats) -> None:
            counts.append(scans)
            if scans >= 3:
                stop.set()  # as a signal handler does: the recording ends at the next scan

        with api.Recording(emu.device_path, out, baud=500000) as recording:
            result = recording.run(stop=stop, progress=progress)
        assert result.reason == "interrupted" and result.scans >= 3 and counts[0] == 0
        with pytest.raises(OutputExistsError, match="exists"):  # before the device is touched
            api.record(emu.device_path, out, max_scans=1)
        with pytest.raises(InputError, match="0.25"):
            api.Recording(emu.device_path, tmp_path / "other.mcap", angle=180, resolution=0.25)
    assert len(mcapio.read_run(out).stamps) == result.scans


def test_the_other_commands_calls_are_theirs_not_copies():
    from datmo_cli.passes import stage_files, warm
    from datmo_cli.tune import run_tune

    assert api.tune is run_tune
    assert (api.segment, api.extract_features, api.track) == (
        stage_files.segment_file,
        stage_files.features_file,
        stage_files.track_file,
    )
    assert api.warm_up is warm.warm_up
    assert set(api.__all__) >= {"run_batch", "report", "evaluate", "record", "Recording", "tune", "track"}
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        api.nothing  # noqa: B018


def test_the_api_takes_folders_as_paths_or_text(batch, tmp_path):
    d, _, _ = batch
    copy = tmp_path / "copy"
    shutil.copytree(d / "out", copy)
    assert api.report([str(copy / "hall.mcap")]).files == [copy / "hall.mcap"]
