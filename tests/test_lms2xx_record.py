"""`datmo record` against the emulator over real pseudo-terminals: bit-exact scans, faults, signals, errors."""

from __future__ import annotations

import errno
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from datmo_cli.base import outputs
from datmo_cli.base.errors import OutputError
from datmo_cli.cli import cli
from datmo_cli.commands import record as record_cmd
from datmo_cli.lms2xx import protocol as P
from datmo_cli.lms2xx import recorder
from datmo_cli.lms2xx.driver import LMS2xx
from datmo_cli.lms2xx.emulator import Emulator
from datmo_cli.lms2xx.faults import Faults
from datmo_cli.lms2xx.recorder import record
from datmo_cli.lms2xx.scan_sources import ArraySource, LogSource
from datmo_cli.logs import mcapio
from datmo_cli.logs.scan import ScanGeometry, ScanRun
from datmo_cli.passes.simulated import SceneSource

pytestmark = [pytest.mark.cli, pytest.mark.timeout(60)]


def run_record(emu, path, *, baud=500000, scans=None, duration=None, stop=None, **kw):
    driver = LMS2xx(emu.device_path, baud=baud, **{k: v for k, v in kw.items() if k != "raw"})
    writer = mcapio.LogWriter(path, provenance=mcapio.Provenance("record", {"baud": baud}), streaming=True)
    result = record(driver, writer, max_scans=scans, duration=duration, raw=kw.get("raw", False), stop=stop)
    return result, driver


def settled(condition, seconds: float = 2.0) -> bool:
    """Whether `condition()` holds within `seconds`: the emulator applies a baud change only after its reply
    has left, in its own thread, so the host can see the reply first."""
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)
    return condition()


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, np.float32).view(np.uint32)


def assert_bit_exact(run: ScanRun, sent) -> None:
    expected = np.stack([s.ranges() for s in sent])
    assert run.ranges.shape == expected.shape
    assert np.array_equal(bits(run.ranges), bits(expected))


def scene() -> SceneSource:
    return SceneSource("hall", seed=3, duration=10)


@pytest.mark.parametrize("baud, n", [(500000, 30), (38400, 5)])
def test_record_is_bit_exact(tmp_path, baud, n):
    with Emulator(scene(), seed=1) as emu:
        result, driver = run_record(emu, tmp_path / "run.mcap", baud=baud, scans=n, raw=True)
        sent = emu.good_scans()
        assert settled(lambda: emu.baud == 9600)  # record switched back on exit
        assert emu.stats.variant_changes == 0 and emu.stats.config_writes == 0
    assert result.scans == n and result.reason == "scans"
    run = mcapio.read_run(tmp_path / "run.mcap")
    assert_bit_exact(run, sent[:n])
    assert np.all(np.diff(run.stamps) > 0)
    g = run.geometry
    assert (g.n_beams, g.range_max) == (361, 8.0)
    assert g.angle_min == pytest.approx(-np.pi / 2) and g.angle_increment == pytest.approx(np.radians(0.5))
    log = mcapio.read_log(tmp_path / "run.mcap", topics=[mcapio.TOPIC_TELEGRAM])
    assert log.metadata["lms2xx.status"]["recorded_baud"] == str(baud)
    assert log.metadata["lms2xx.status"]["angle_deg"] == "180"
    assert int(log.metadata["lms2xx.stats"]["crc_errors"]) == 0
    raws = log.messages[mcapio.TOPIC_TELEGRAM][1]
    b0 = [p[16:] for p in raws if p[16:][4] == P.REPLY_SCAN]
    assert b0[:n] == [s.telegram for s in sent[:n]]
    # the telegram rate, untimed (a loaded machine delays the emulator and the reads alike): the scans
    # the rate table lets through at this baud, each stamped (host time of its first byte) no earlier than the
    # one before it ended on the line
    numbers = [s.number for s in sent[:n]]
    assert all(k % (1 + P.LOST_PER_SENT[50][baud]) == 0 for k in numbers) and numbers == sorted(set(numbers))
    line_ns = [int(len(s.telegram) * 10e9 / baud) for s in sent[: n - 1]]
    assert np.all(np.diff(run.stamps) >= line_ns)


def test_record_at_9600_detects_the_scans_the_rate_table_drops(tmp_path):
    with Emulator(scene(), seed=1, indices=True) as emu:
        result, driver = run_record(emu, tmp_path / "run.mcap", baud=9600, scans=3, indices=True)
        sent = emu.good_scans()
    run = mcapio.read_run(tmp_path / "run.mcap")
    assert len(run) == 3
    assert_bit_exact(run, sent[:3])  # what does arrive is exact
    assert [s.number for s in sent[:3]] == [0, 30, 60]  # 29 lost per scan sent at 0.5°
    assert result.stats["dropped"] == 2 * 29
    assert np.diff(run.stamps) / 1e9 == pytest.approx([30 * 0.02664] * 2, rel=0.15)


def test_dropped_scans_by_timing_without_indices(tmp_path):
    with Emulator(scene(), seed=1) as emu:
        result, _ = run_record(emu, tmp_path / "run.mcap", baud=38400, scans=4)
    assert result.stats["dropped"] == pytest.approx(3 * 8, abs=3)


@pytest.mark.parametrize("kind", ["garbage", "crc", "truncate", "drop"])
def test_faults_give_the_right_counts_and_keep_every_good_scan(tmp_path, kind):
    faults = Faults(**{kind: 0.25}, disconnect=40)
    with Emulator(scene(), seed=7, faults=faults, indices=True) as emu:
        result, _ = run_record(emu, tmp_path / "run.mcap", baud=500000, indices=True)
        sent = list(emu.sent)
    assert result.reason == "disconnected" and len(sent) == 40
    good = [s for s in sent if s.good]
    bad = [s for s in sent if s.fault]
    assert len(bad) >= 3 or kind == "garbage"
    run = mcapio.read_run(tmp_path / "run.mcap")
    assert_bit_exact(run, good)  # every good scan, in order, nothing extra
    st = result.stats
    if kind == "garbage":
        bursts = [s.garbage for s in sent if s.garbage]
        assert len(bursts) >= 3
        assert (st["resyncs"], st["discarded_bytes"], st["crc_errors"]) == (len(bursts), sum(bursts), 0)
        assert st["dropped"] == 0
    else:
        # a truncated or shortened last telegram waits for bytes that never come: not counted
        counted = bad if sent[-1].fault in (None, "crc") else bad[:-1]
        assert st["crc_errors"] + st["length_errors"] == len(counted)
        numbers = [s.number for s in good]
        assert st["dropped"] == numbers[-1] - numbers[0] + 1 - len(good)


def test_nak_is_retried(tmp_path):
    with Emulator(scene(), faults=Faults(nak=2)) as emu:
        result, driver = run_record(emu, tmp_path / "run.mcap", baud=500000, scans=5)
        assert emu.stats.faults["nak"] == 2
    assert result.scans == 5 and driver.stats.naks >= 1


def test_variant_units_and_indices_written_only_when_different(tmp_path):
    with Emulator(scene(), seed=2) as emu:
        run_record(emu, tmp_path / "a.mcap", scans=5, angle=100, resolution=0.25, units="cm", indices=True)
        assert (emu.stats.variant_changes, emu.stats.config_writes) == (1, 1)
        assert (emu.angle, emu.res, emu.units) == (100, 25, "cm")
        before = len(emu.sent)
        run_record(emu, tmp_path / "b.mcap", scans=5, angle=100, resolution=0.25, units="cm", indices=True)
        assert (emu.stats.variant_changes, emu.stats.config_writes) == (1, 1)  # nothing written again
        sent = [s for s in emu.sent[before:] if s.good]
    run = mcapio.read_run(tmp_path / "b.mcap")
    g = run.geometry
    assert g.n_beams == 401 and g.angle_min == pytest.approx(np.radians(-50)) and g.range_max == 80.0
    assert g.angle_increment == pytest.approx(np.radians(0.25))
    assert sent[0].units == "cm" and len(sent[0].values) == 401
    assert_bit_exact(run, sent[:5])


def test_interlaced_partials_are_merged(tmp_path):
    values = np.arange(361, dtype=np.uint16)[None] * 3 + np.arange(4, dtype=np.uint16)[:, None]
    with Emulator(ArraySource(values)) as emu:
        result, _ = run_record(emu, tmp_path / "run.mcap", scans=6, interlaced=True)
        sent = emu.good_scans()
    assert sent[0].partial and [s.offset for s in sent[:4]] == [0, 2, 0, 2]
    assert [len(s.values) for s in sent[:2]] == [181, 180]
    run = mcapio.read_run(tmp_path / "run.mcap")
    complete = bits(P.values_to_ranges(values, "mm"))
    # each scan is one of the source's complete scans, merged bit for bit from its two partials; which ones is
    # not checked (without indices a loaded machine's late reads look like lost telegrams, and the partials of
    # such a scan are dropped rather than merged across rotations)
    which = [[k for k in range(len(values)) if np.array_equal(row, complete[k])] for row in bits(run.ranges)]
    assert len(which) == 6 and all(len(w) == 1 for w in which), which


def test_log_source_serves_a_log(tmp_path):
    g = ScanGeometry(-np.pi / 2, np.radians(0.5), 361, 0.0, 8.0)
    ranges = np.round(np.random.default_rng(0).uniform(0.5, 7.5, (5, 361)), 3).astype(np.float32)
    ranges[:, 10] = np.inf
    ranges[:, 11] = np.nan
    src = tmp_path / "src.mcap"
    with mcapio.LogWriter(src) as w:
        w.write_scans(ScanRun(np.arange(5) * 10**8, ranges, g))
    with Emulator(LogSource(src)) as emu:
        run_record(emu, tmp_path / "run.mcap", scans=5)
    run = mcapio.read_run(tmp_path / "run.mcap")
    assert np.array_equal(bits(run.ranges), bits(ranges))


def test_streaming_file_is_readable_after_a_power_cut(tmp_path):
    out = tmp_path / "run.mcap"
    stop = threading.Event()
    with Emulator(scene()) as emu:
        t = threading.Thread(target=run_record, args=(emu, out), kwargs={"stop": stop})
        t.start()
        try:
            deadline = time.monotonic() + 15
            while len(emu.sent) < 60 and time.monotonic() < deadline:  # ~1.6 s of scans
                time.sleep(0.05)
            tmp = next(tmp_path.glob(".run.mcap.*.tmp"))
            sent_at_cut = len(emu.sent)
            cut = tmp_path / "cut.mcap"
            shutil.copyfile(tmp, cut)  # what a power cut now would leave on disk
        finally:
            stop.set()
            t.join(10)
        sent = emu.good_scans()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = mcapio.read_log(cut, topics=[mcapio.TOPIC_SCAN])
    assert log.truncated and any(issubclass(w.category, mcapio.TruncatedLogWarning) for w in caught)
    run = mcapio.run_from_log(log)
    assert sent_at_cut - len(run) <= 1.0 * 37.5 + 2  # at most about a second lost
    assert_bit_exact(run, sent[: len(run)])
    assert len(mcapio.read_run(out)) >= sent_at_cut - 1  # the finished file has everything


# ------------------------------------------------------------------------------------ CLI and errors


def test_disconnect_keeps_the_file_and_says_so(tmp_path):
    out = tmp_path / "run.mcap"
    with Emulator(scene(), faults=Faults(disconnect=25)) as emu:
        res = CliRunner().invoke(cli, ["record", "--port", emu.device_path, "-o", str(out), "--baud", "500000"])
        sent = emu.good_scans()
    assert res.exit_code == 1
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("datmo: error: ") and "disconnected" in last and "last good scan (25 scans)" in last
    assert "Traceback" not in res.output
    run = mcapio.read_run(out)
    assert_bit_exact(run, sent)
    assert not mcapio.read_log(out).truncated


def _datmo(*args: str) -> list[str]:
    return [sys.executable, "-c", "from datmo_cli.cli import main; main()", *args]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_signal_stops_the_stream_and_finishes_the_file(tmp_path, sig):
    out = tmp_path / "run.mcap"
    with Emulator(scene()) as emu:
        proc = subprocess.Popen(
            _datmo("record", "--port", emu.device_path, "-o", str(out), "--baud", "500000"),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            deadline = time.monotonic() + 20
            while len(emu.sent) < 30 and time.monotonic() < deadline and proc.poll() is None:
                time.sleep(0.05)
            proc.send_signal(sig)
            _, err = proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
        assert settled(lambda: emu.mode == P.MODE_STOP and emu.baud == 9600)  # stream stopped, baud restored
        sent = emu.good_scans()
    assert proc.returncode == 128 + sig, err  # 130 Ctrl-C, 143 SIGTERM
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"{out}: ") and f"(interrupted: {signal.Signals(sig).name})" in last, err
    assert "Traceback" not in err
    run = mcapio.read_run(out)
    assert len(run) >= 20
    assert_bit_exact(run, sent[: len(run)])
    assert not mcapio.read_log(out).truncated
    assert not list(tmp_path.glob(".*.tmp"))


def test_a_second_ctrl_c_gives_up_at_once_keeping_what_reached_the_disk(tmp_path):
    out = tmp_path / "run.mcap"
    with Emulator(scene()) as emu:
        proc = subprocess.Popen(
            _datmo("record", "--port", emu.device_path, "-o", str(out), "--baud", "500000"),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        try:
            deadline = time.monotonic() + 20
            while len(emu.sent) < 40 and time.monotonic() < deadline and proc.poll() is None:
                time.sleep(0.05)
            proc.send_signal(signal.SIGINT)
            time.sleep(0.02)
            proc.send_signal(signal.SIGINT)
            _, err = proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                proc.kill()
        sent = emu.good_scans()
    # 130; or killed by the SIGINT itself (the shell shows 130 too) when the second one comes as the interpreter
    # exits, after the file was finished and its handlers were reset
    assert proc.returncode in (130, -signal.SIGINT), err
    assert "Traceback" not in err
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mcapio.TruncatedLogWarning)  # cut at its last flush, if it came to that
        run = mcapio.read_run(out)
    assert len(run) >= 10
    assert_bit_exact(run, sent[: len(run)])
    assert not list(tmp_path.glob(".*.tmp"))


class _StoppedAfter(LMS2xx):
    """A driver whose read_scan raises `exc` (a second Ctrl-C, a SIGTERM, a bug) after `n` scans."""

    def __init__(self, *args, n: int, exc: BaseException, **kw) -> None:
        super().__init__(*args, **kw)
        self.n, self.exc = n, exc

    def read_scan(self, timeout: float = 0.2):
        if self.n <= 0:
            raise self.exc
        scan = super().read_scan(timeout)
        self.n -= scan is not None
        return scan


@pytest.mark.parametrize(
    "exc, code", [(KeyboardInterrupt(), 130), (outputs.Terminated(signal.SIGTERM), 143), (ValueError("a bug"), 70)]
)
def test_a_failure_while_recording_keeps_the_flushed_scans(tmp_path, monkeypatch, exc, code):
    monkeypatch.setattr(recorder, "FLUSH_EVERY_S", 0.05)
    out = tmp_path / "run.mcap"
    with Emulator(scene()) as emu:
        driver = _StoppedAfter(emu.device_path, baud=500000, n=25, exc=exc)
        writer = mcapio.LogWriter(out, streaming=True)
        with pytest.raises(recorder.RecordingCut) as caught:
            record(driver, writer, describe=record_cmd.failure)  # a bug said as datmo record says it
        assert settled(lambda: emu.mode == P.MODE_STOP) == isinstance(exc, Exception)  # stopped after a bug
        sent = emu.good_scans()
    message = str(caught.value)
    kept = int(re.search(r"keeps the (\d+) scans? that reached the disk", message).group(1))
    assert caught.value.exit_code == code and "\n" not in message
    assert 0 < kept <= 25 and (str(out) in message)
    with pytest.warns(mcapio.TruncatedLogWarning):
        run = mcapio.read_run(out)
    assert len(run) == kept
    assert_bit_exact(run, sent[:kept])
    assert not list(tmp_path.glob(".*.tmp")) and not outputs.live()


def test_the_file_size_limit_while_recording_keeps_the_scans_on_disk(tmp_path):
    """A real EFBIG (ulimit -f), with the partial buffered writes it makes: the scans of the last flush kept."""
    limit = 40_000
    out = tmp_path / "run.mcap"
    values = (np.arange(361, dtype=np.uint16)[None] * 7 + np.arange(16, dtype=np.uint16)[:, None] * 13) % 8000

    def limited() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    with Emulator(ArraySource(values)) as emu:
        proc = subprocess.run(
            _datmo("record", "--port", emu.device_path, "-o", str(out), "--baud", "500000", "--scans", "500"),
            capture_output=True,
            text=True,
            timeout=60,
            preexec_fn=limited,
        )
        sent = emu.good_scans()
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 1 and len(lines) == 1 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[0].startswith(f"datmo: error: {out}: file too large for the file-size limit"), lines
    kept = int(re.search(r"keeps the (\d+) scans? that reached the disk", lines[0]).group(1))
    assert 0 < kept < 500 and out.stat().st_size <= limit
    with pytest.warns(mcapio.TruncatedLogWarning):
        run = mcapio.read_run(out)
    assert len(run) == kept
    assert_bit_exact(run, sent[:kept])
    assert [p.name for p in tmp_path.iterdir()] == ["run.mcap"]


def _flushed_writer(path, n: int = 5) -> mcapio.LogWriter:
    g = ScanGeometry(-np.pi / 2, np.radians(0.5), 361, 0.0, 8.0)
    writer = mcapio.LogWriter(path, streaming=True)
    for i in range(n):
        writer.write_scan(i * 10**8, np.full(361, 1.0 + i, np.float32), g)
    writer.flush()
    writer.write_scan(n * 10**8, np.full(361, 9.0, np.float32), g)  # after the flush: not kept
    return writer


def test_keep_flushed_cuts_the_file_at_the_last_flush(tmp_path):
    writer = _flushed_writer(tmp_path / "run.mcap")
    assert writer.keep_flushed() == writer.flushed > 0 and not writer.complete
    with pytest.warns(mcapio.TruncatedLogWarning):
        run = mcapio.read_run(tmp_path / "run.mcap")
    assert len(run) == 5 and np.all(run.ranges[:, 0] == 1.0 + np.arange(5))
    assert [p.name for p in tmp_path.iterdir()] == ["run.mcap"] and not outputs.live()


def test_keep_flushed_with_nothing_flushed_leaves_nothing(tmp_path):
    writer = mcapio.LogWriter(tmp_path / "run.mcap", streaming=True)
    assert writer.keep_flushed() == 0
    assert not list(tmp_path.iterdir()) and not outputs.live()


@pytest.mark.parametrize("finished", [False, True])
def test_a_recording_that_cannot_be_renamed_is_left_in_its_temporary_file(tmp_path, monkeypatch, finished):
    writer = _flushed_writer(tmp_path / "run.mcap")

    def refuse(src, dst):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(OutputError) as caught:
        writer.close() if finished else writer.keep_flushed()
    monkeypatch.undo()
    message = str(caught.value)
    assert message.startswith(f"{writer.tmp}: holds the data written so far") and "read-only file system" in message
    assert "rename it yourself" in message and "\n" not in message
    assert not (tmp_path / "run.mcap").exists() and writer.tmp.exists() and not outputs.live()
    with pytest.raises(OutputError):  # asked again, it says so again: never "nothing kept"
        writer.keep_flushed()
    with warnings.catch_warnings(record=True) as caught_warnings:
        warnings.simplefilter("always")
        run = mcapio.read_run(writer.tmp)
    assert len(run) == (6 if finished else 5)
    assert bool(caught_warnings) != finished  # the finished file is whole, the other one cut
    writer.tmp.unlink()


def _one_line_error(res, *needles: str) -> None:
    assert res.exit_code == 1, res.output
    assert res.output.count("\n") == 1 and res.output.startswith("datmo: error: "), res.output
    for n in needles:
        assert n in res.output
    assert "Traceback" not in res.output


def test_missing_port(tmp_path):
    res = CliRunner().invoke(cli, ["record", "--port", "/dev/ttyNOPE9", "-o", str(tmp_path / "r.mcap")])
    _one_line_error(res, "/dev/ttyNOPE9", "cannot open serial port")
    assert not list(tmp_path.iterdir())


def test_silent_device(tmp_path):
    master, slave = os.openpty()
    try:
        res = CliRunner().invoke(cli, ["record", "--port", os.ttyname(slave), "-o", str(tmp_path / "r.mcap")])
    finally:
        os.close(master)
        os.close(slave)
    _one_line_error(res, "no answer from an LMS2xx", "9600")
    assert not list(tmp_path.iterdir())


def test_garbage_device(tmp_path):
    master, slave = os.openpty()
    done = threading.Event()

    def babble() -> None:
        rng = np.random.default_rng(0)
        while not done.is_set():
            try:
                os.write(master, rng.integers(0, 256, 64, np.uint8).tobytes())
            except OSError:
                return
            time.sleep(0.01)

    t = threading.Thread(target=babble, daemon=True)
    t.start()
    try:
        res = CliRunner().invoke(cli, ["record", "--port", os.ttyname(slave), "-o", str(tmp_path / "r.mcap")])
    finally:
        done.set()
        t.join()
        os.close(master)
        os.close(slave)
    _one_line_error(res, "garbage at every baud")


def test_existing_output_refused_before_touching_the_device(tmp_path):
    out = tmp_path / "r.mcap"
    out.write_bytes(b"x")
    res = CliRunner().invoke(cli, ["record", "--port", "/dev/ttyNOPE9", "-o", str(out)])
    _one_line_error(res, "exists; use --force")
