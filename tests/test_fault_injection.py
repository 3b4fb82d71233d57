"""Fault injection: write failures at seeded points of every writing command, and signals at seeded
moments of real `datmo features`, `track` and `run` processes on a long log.

Promises: a one-line error (the last line of stderr), a non-zero exit (128 + the signal for a signal), no
traceback, no temporary file, no partial output, the input unchanged. Cases are counted with
fuzzing.tally ("write failures", "signals").
"""

from __future__ import annotations

import errno
import hashlib
import json
import random
import re
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from fuzzing import tally

from datmo_cli.base import outputs
from datmo_cli.cli import cli
from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanRun

pytestmark = pytest.mark.cli

ROOT = Path(__file__).resolve().parent.parent
HALL = ROOT / "sample_logs" / "hall.mcap"


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def temps(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".*.tmp")]


def _cut(run: ScanRun, n: int) -> ScanRun:
    intensities = None if run.intensities is None else run.intensities[:n]
    return ScanRun(run.stamps[:n], run.ranges[:n], run.geometry, intensities)


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict[str, Path]:
    """A 40-scan log, the same with tracks (for report --plot), and a long log: hall tiled 4 times."""
    folder = tmp_path_factory.mktemp("fault-inputs")
    run = mcapio.read_run(HALL)
    small = folder / "small.mcap"
    with mcapio.LogWriter(small) as w:
        w.write_scans(_cut(run, 40))
    tracked = folder / "tracked.mcap"
    assert CliRunner().invoke(cli, ["track", str(small), "-o", str(tracked)]).exit_code == 0
    period = int(np.median(np.diff(run.stamps)))
    span = int(run.stamps[-1] - run.stamps[0]) + period
    k = 4
    long = folder / "long.mcap"
    with mcapio.LogWriter(long) as w:
        w.write_scans(
            ScanRun(
                np.concatenate([run.stamps + i * span for i in range(k)]),
                np.concatenate([run.ranges] * k),
                run.geometry,
                None if run.intensities is None else np.concatenate([run.intensities] * k),
            )
        )
    return {"small": small, "tracked": tracked, "long": long}


class FullDisk:
    """A temporary file that takes `room` bytes, then raises ENOSPC (as a full disk does)."""

    def __init__(self, file, room: int) -> None:
        self._file = file
        self.room = room

    def write(self, data) -> int:
        n = len(memoryview(data).cast("B"))
        if n > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= n
        return self._file.write(data)

    def __getattr__(self, name: str):
        return getattr(self._file, name)


COMMANDS = {
    "segment": lambda L, o: ["segment", L["small"], "-o", o],
    "features": lambda L, o: ["features", L["small"], "-o", o],
    "track": lambda L, o: ["track", L["small"], "-o", o],
    "import": lambda L, o: ["import", L["small"], "-o", o],
    "simulate": lambda L, o: ["simulate", "--scene", "hall", "--duration", "4", "-o", o],
    "report-plot": lambda L, o: ["report", L["tracked"], "--format", "json", "--plot", o.with_suffix(".png")],
    "run": lambda L, o: ["run", L["small"], "-o", o.parent / "batch", "--no-report", "--jobs", "1"],
    "export": lambda L, o: ["export", L["tracked"], "--features", "-o", o.with_suffix(".csv")],
}
ROOM = [0, 64, 700, 5_000, 40_000, 150_000]  # bytes the disk takes before it is full


@pytest.mark.parametrize("name", list(COMMANDS))
def test_write_failures_at_seeded_points_of_every_writing_command(logs, tmp_path, monkeypatch, name):
    rng = random.Random(f"write failures {name}")
    before = {k: digest(p) for k, p in logs.items()}
    rooms = ROOM + [rng.randrange(1, 200_000) for _ in range(2)]
    real = outputs._file_for
    for i, room in enumerate(rooms):
        folder = tmp_path / f"case{i}"
        folder.mkdir()
        out = folder / "out.mcap"
        monkeypatch.setattr(outputs, "_file_for", lambda fd, mode, room=room: FullDisk(real(fd, mode), room))
        res = CliRunner().invoke(cli, [str(a) for a in COMMANDS[name](logs, out)])
        monkeypatch.setattr(outputs, "_file_for", real)
        made = [p for p in folder.rglob("*") if p.is_file() and p.name != "manifest.jsonl"]
        last = res.stderr.strip().splitlines()[-1] if res.stderr.strip() else ""
        if res.exit_code == 0:  # the whole output fitted in `room`: it must then be complete
            ok = bool(made) and not temps(folder)
        else:
            ok = (
                last.startswith("datmo: error: ")
                and "no space left on the device" in last
                and "Traceback" not in res.output
                and not made
                and not temps(folder)
                and not outputs.live()
            )
        ok = ok and {k: digest(p) for k, p in logs.items()} == before
        tally("write failures", failed=not ok)
        assert ok, (name, room, res.exit_code, res.output[-2000:], made, temps(folder))


# ---------------------------------------------------------------------------------------- record, disk full

KEPT = re.compile(r"keeps the (\d+) scans? that reached the disk")


def _record_case(emu, folder: Path, room: int) -> tuple[bool, str]:
    """`datmo record` from `emu` into a disk with `room` bytes: (promise kept, what happened)."""
    out = folder / "run.mcap"
    before = len(emu.sent)
    res = CliRunner().invoke(
        cli, ["record", "--port", emu.device_path, "-o", str(out), "--baud", "500000", "--scans", str(RECORD_SCANS)]
    )
    sent = [s for s in emu.sent[before:] if s.good]
    err = res.stderr.strip()
    last = err.splitlines()[-1] if err else ""
    clean = "Traceback" not in res.output and not temps(folder) and not outputs.live()
    if res.exit_code == 0:  # everything fitted: the whole recording, finished
        run = mcapio.read_run(out)
        return clean and len(run) == RECORD_SCANS and _exact(run, sent), "complete"
    ok = clean and last.startswith("datmo: error: ") and "no space left on the device" in last
    kept = KEPT.search(last)
    if kept is None:  # full before the first flush (or before recording began): no output at all
        return ok and not out.exists(), "nothing kept"
    n = int(kept.group(1))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = mcapio.read_log(out, topics=[mcapio.TOPIC_SCAN])
    run = mcapio.run_from_log(log)
    warned = any(issubclass(w.category, mcapio.TruncatedLogWarning) for w in caught)
    info = CliRunner().invoke(cli, ["info", str(out), "--json"])
    counted = json.loads(info.stdout)
    ok = ok and n > 0 and len(run) == n and _exact(run, sent) and log.truncated and warned and counted["truncated"]
    return ok, f"kept {n} scans"


def _exact(run: ScanRun, sent) -> bool:
    expected = np.stack([s.ranges() for s in sent[: len(run)]])
    return np.array_equal(run.ranges.view(np.uint32), np.ascontiguousarray(expected, np.float32).view(np.uint32))


RECORD_SCANS = 20
# bytes the disk takes: full at once, full before the first scan is flushed, after a few flushes, never
RECORD_ROOM = [0, 2_000, 12_000, 10**8]


def test_write_failures_at_seeded_points_of_record(tmp_path, monkeypatch):
    """A full disk while recording keeps every scan flushed before it: the file cut after its last complete
    chunk and renamed into place, one line saying so, exit 1, no temporary file."""
    from datmo_cli.lms2xx import recorder
    from datmo_cli.lms2xx.emulator import Emulator
    from datmo_cli.lms2xx.scan_sources import ArraySource

    rng = random.Random("write failures record")
    rooms = RECORD_ROOM + [rng.randrange(1_000, 20_000) for _ in range(2)]
    monkeypatch.setattr(recorder, "FLUSH_EVERY_S", 0.05)  # many flushes in a short recording
    values = (np.arange(361, dtype=np.uint16)[None] * 7 + np.arange(16, dtype=np.uint16)[:, None] * 13) % 8000
    real = outputs._file_for
    outcomes = []
    with Emulator(ArraySource(values), seed=1) as emu:
        for i, room in enumerate(rooms):
            folder = tmp_path / f"case{i}"
            folder.mkdir()
            monkeypatch.setattr(outputs, "_file_for", lambda fd, mode, room=room: FullDisk(real(fd, mode), room))
            try:
                ok, what = _record_case(emu, folder, room)
            finally:
                monkeypatch.setattr(outputs, "_file_for", real)
            ok = ok and (room < 12_000 or what != "nothing kept")  # room for a first flush: scans kept
            tally("write failures", failed=not ok)
            outcomes.append((room, what))
            assert ok, (room, what, list(folder.iterdir()))
    assert {what for _, what in outcomes} >= {"complete", "nothing kept"}
    assert any(what.startswith("kept ") for _, what in outcomes), outcomes


# ---------------------------------------------------------------------------------------- train-legs, disk full


@pytest.mark.slow
def test_write_failures_at_seeded_points_of_train_legs(tmp_path, monkeypatch):
    """`datmo train-legs` with the disk full while its model is written: one line, no model, no temporary
    file. The training itself runs once (it takes seconds); each case reuses its result, so what is tried at
    every point is the command's reading of its inputs and its write."""
    pytest.importorskip("sklearn")
    from datmo_cli.perception import training
    from datmo_cli.perception.leg_model import LegModel
    from tests.synthetic_legs import scene, write_bag

    positive = write_bag(tmp_path / "p0.bag", *scene(20, seed=0))
    before = digest(positive)
    trained = []
    real_train = training.train_leg_model

    def train_once(*args, **kwargs):
        if not trained:
            trained.append(real_train(*args, **kwargs))
        return trained[0]

    monkeypatch.setattr(training, "train_leg_model", train_once)
    rng = random.Random("write failures train-legs")
    real = outputs._file_for
    for i, room in enumerate([10**9, *ROOM, rng.randrange(1, 200_000)]):
        folder = tmp_path / f"case{i}"
        folder.mkdir()
        out = folder / "legs.npz"
        monkeypatch.setattr(outputs, "_file_for", lambda fd, mode, room=room: FullDisk(real(fd, mode), room))
        res = CliRunner().invoke(cli, ["train-legs", "--positive", str(positive), "-o", str(out)])
        monkeypatch.setattr(outputs, "_file_for", real)
        made = [p for p in folder.rglob("*") if p.is_file()]
        last = res.stderr.strip().splitlines()[-1] if res.stderr.strip() else ""
        if res.exit_code == 0:  # the model fitted in `room`: it must then be whole
            ok = made == [out] and LegModel.load(out).n_trees > 0
        else:
            ok = (
                res.exit_code != 0
                and last.startswith("datmo: error: ")
                and "no space left on the device" in last
                and "Traceback" not in res.output
                and not made
                and not outputs.live()
            )
        ok = ok and not temps(folder) and digest(positive) == before and (room != 0 or res.exit_code != 0)
        tally("write failures", failed=not ok)
        assert ok, (room, res.exit_code, res.output[-2000:], made)


# ------------------------------------------------------------------------------------------------- signals


def _wait_for_temp(folder: Path, proc: subprocess.Popen, timeout: float = 60.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and proc.poll() is None:
        if temps(folder):
            return True
        time.sleep(0.01)
    return False


SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGHUP]


@pytest.mark.slow
@pytest.mark.parametrize("command", ["features", "track", "run"])
def test_signals_at_seeded_moments_leave_no_partial_output(logs, tmp_path, command):
    rng = random.Random(f"signals {command}")
    long = logs["long"]
    before = digest(long)
    for sig in SIGNALS:
        folder = tmp_path / signal.Signals(sig).name
        folder.mkdir()
        out = folder / "out.mcap"
        args = (
            ["run", str(long), "-o", str(folder), "--no-report", "--jobs", "1"]
            if command == "run"
            else [command, str(long), "-o", str(out)]
        )
        proc = subprocess.Popen(
            [sys.executable, "-m", "datmo_cli", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        try:
            writing = _wait_for_temp(folder, proc)
            time.sleep(rng.uniform(0.0, 1.5))
            if proc.poll() is None:
                proc.send_signal(sig)
            _, err = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
        result = folder / long.name if command == "run" else out
        if proc.returncode == 0:  # finished before the signal: the output is then whole
            ok = len(mcapio.read_run(result)) == 1200
        elif proc.returncode == -sig:
            # the signal came after the work was done and datmo's handlers were gone, as the interpreter exited:
            # killed by it (a shell shows 128 + the signal too), with the output already whole
            ok = "Traceback" not in err and len(mcapio.read_run(result)) == 1200
        else:
            last = err.strip().splitlines()[-1] if err.strip() else ""
            ok = (
                proc.returncode == 128 + sig
                and last.startswith("datmo: error: ")
                and "Traceback" not in err
                and (not result.exists() or len(mcapio.read_run(result)) == 1200)
            )  # nothing, or the whole
        ok = ok and writing and not temps(folder) and digest(long) == before
        tally("signals", failed=not ok)
        assert ok, (command, signal.Signals(sig).name, proc.returncode, err[-2000:])
