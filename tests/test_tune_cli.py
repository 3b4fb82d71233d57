"""`datmo tune` on the command line: a bad space, objective or log is one line naming the key or the file, with
nothing written; a finished tune run again prints its result without running an evaluation (slow)."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from datmo_cli.cli import cli

pytestmark = pytest.mark.cli

ROOT = Path(__file__).resolve().parent.parent
HALL = str(ROOT / "sample_logs" / "hall.mcap")
GOOD = "[track]\nperson_maintain = [0.05, 0.3]\n"


@pytest.mark.parametrize(
    ("space", "logs", "extra", "said"),
    [
        ("[track]\nperson_maintian = [0.05, 0.3]\n", [HALL], [], "space.toml: track.person_maintian: unknown"),
        ("[track]\ngate = [1.0, 1e9]\n", [HALL], [], "space.toml: track.gate: must be at most"),
        ("[features]\nleg_model = []\n", [HALL], [], "space.toml: features.leg_model: an empty list of choices"),
        (GOOD, [str(ROOT / "sample_logs" / "csail-excerpt.mcap")], [], "csail-excerpt.mcap: no ground truth"),
        (GOOD, [HALL], ["--objective", "motaa"], "--objective motaa: not a figure"),
        (GOOD, [HALL], ["--max", "false_people_s"], "--max false_people_s: expected NAME=VALUE"),
        (GOOD, [HALL, HALL], ["--cv"], "a second log named hall.mcap"),
    ],
)
def test_a_bad_tune_is_one_line_and_writes_nothing(tmp_path, space, logs, extra, said):
    (tmp_path / "space.toml").write_text(space)
    out = tmp_path / "out"
    r = CliRunner().invoke(cli, ["tune", *logs, "--space", str(tmp_path / "space.toml"), "-o", str(out), *extra])
    assert r.exit_code != 0
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("datmo: error: ") and said in lines[0], r.output
    assert not out.exists()


@pytest.mark.slow
def test_a_finished_tune_prints_its_result_again_without_running(tmp_path):
    (tmp_path / "space.toml").write_text(GOOD)
    args = ["tune", HALL, "--space", str(tmp_path / "space.toml"), "-o", str(tmp_path / "out"), "--trials", "2"]
    first = CliRunner().invoke(cli, [*args, "-j", "1"])
    assert first.exit_code == 0, first.output
    again = CliRunner().invoke(cli, [*args, "-j", "1", "--plot"])
    assert again.exit_code == 0, again.output
    best = [line for line in first.output.splitlines() if line.startswith("best: trial")]
    assert best and best[0] in again.output
    assert "0 evaluations run, 2 reused" in again.output
    assert (tmp_path / "out" / "best.toml").is_file() and (tmp_path / "out" / "trials.parquet").is_file()
    assert (tmp_path / "out" / "tune.png").read_bytes().startswith(b"\x89PNG")
    other = CliRunner().invoke(cli, [*args[:-1], "3"])  # another tune in the same folder
    assert other.exit_code != 0 and "holds another tune" in other.output and "--force" in other.output


def test_a_folder_of_datmo_run_is_refused(tmp_path):
    (tmp_path / "space.toml").write_text(GOOD)
    out = tmp_path / "out"
    out.mkdir()
    (out / "manifest.jsonl").write_text("")
    r = CliRunner().invoke(cli, ["tune", HALL, "--space", str(tmp_path / "space.toml"), "-o", str(out), "--force"])
    assert r.exit_code != 0 and "holds a datmo run batch" in r.output and len(r.output.strip().splitlines()) == 1
    assert sorted(p.name for p in out.iterdir()) == ["manifest.jsonl"]


@pytest.mark.slow
def test_ctrl_c_stops_a_tune_that_the_same_command_then_continues(tmp_path):
    import json
    import os
    import signal
    import subprocess
    import sys
    import time

    (tmp_path / "space.toml").write_text(GOOD)
    out = tmp_path / "out"
    args = [sys.executable, "-m", "datmo_cli", "tune", HALL, "--space", str(tmp_path / "space.toml"), "-o", str(out)]
    args += ["--trials", "4", "-j", "1"]  # in this process: a --jobs pool's Ctrl-C is batch/'s (tests/test_batch.py)
    # Ctrl-C as in a terminal, even where this test runs with SIGINT ignored (a background job of a script):
    # Python then installs no KeyboardInterrupt handler in the child
    proc = subprocess.Popen(
        args,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    manifest = out / "manifest.jsonl"
    deadline = time.monotonic() + 300
    while not (manifest.exists() and manifest.read_text().count("\n") >= 2) and time.monotonic() < deadline:
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    try:
        output, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, output
    assert output.strip().splitlines()[-1].startswith("datmo: error: interrupted: "), output
    lines = [json.loads(line) for line in manifest.read_text().splitlines()]
    kept = {r["input"] for r in lines if r["status"] == "done"}
    import re

    left = [p.name for p in (out / ".work").iterdir()]  # the prefix of the hall only: no evaluation's output
    assert all(re.fullmatch(r"hall-[0-9a-f]{12}-\d+\.mcap", name) for name in left), left
    again = subprocess.run(args, capture_output=True, text=True, timeout=600, env=os.environ)
    assert again.returncode == 0, again.stderr
    assert f"{len(kept)} reused" in again.stderr, (lines, again.stderr)
