"""What `datmo record` shows and how it stops (workflows.recording does the work): the panel of counts, the
signals that stop a recording, the failure as the command says it, and the closing line and exit status."""

from __future__ import annotations

import signal
import threading
from pathlib import Path
from typing import Any

import click


def panel_table(scans: int, elapsed: float, stats, port: str, baud: int):
    from rich.table import Table

    t = Table.grid(padding=(0, 2))
    rate = scans / elapsed if elapsed > 0 else 0.0
    t.add_row("[bold]recording[/]", f"{port} at {baud} Bd", f"{elapsed:6.1f} s")
    t.add_row("scans", f"{scans:,}", f"{rate:6.2f} Hz")
    t.add_row("crc errors", f"{stats.crc_errors:,}", f"length errors {stats.length_errors:,}")
    t.add_row("resyncs", f"{stats.resyncs:,}", f"dropped scans {stats.dropped:,}")
    return t


class RecordPanel:
    """The recording's counts in a progress.Panel on stderr (recorder.record's progress callback), started at
    the first report; nothing when stderr is not a terminal or with --quiet."""

    def __init__(self, port: str, baud: int) -> None:
        from ..base.progress import Panel

        self.port, self.baud = port, baud
        self.panel = Panel()

    def __call__(self, scans: int, elapsed: float, stats) -> None:
        if self.panel.shown:
            self.panel.show(panel_table(scans, elapsed, stats, self.port, self.baud))

    def stop(self) -> None:
        self.panel.stop()


def failure(exc: BaseException) -> tuple[str, int]:
    """A failure that stopped a recording as the command says it (cli.clean_error), and its exit code."""
    from ..cli import clean_error

    clean = clean_error(exc)
    return (clean.format_message(), clean.exit_code) if clean is not None else (str(exc), 1)


class Signals:
    """Turn SIGINT, SIGTERM and SIGHUP (the terminal closed) into a stop request while recording (main thread
    only): the file is finished up to the last scan, then the command exits 128 + the signal's number. A
    second signal gives up at once (outputs.interrupt), keeping the scans flushed before it."""

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop
        self.signum: int | None = None
        self.old: dict[int, Any] = {}

    def _handler(self, signum, frame) -> None:
        from ..base import outputs

        if self.stop.is_set():
            outputs.interrupt(signum)
            return
        self.signum = signum
        self.stop.set()

    def __enter__(self) -> Signals:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
                self.old[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self.old.items():
            signal.signal(sig, old)


def finished(result, output: Path, signum: int | None) -> None:
    """Say what was recorded (the rate and the link's error counts) and end as the recording ended: a
    disconnect is an error (exit 1), a signal exits 128 + its number."""
    from ..base.errors import DeviceError
    from ..base.progress import say

    s = result.stats
    rate = result.scans / result.seconds if result.seconds > 0 else 0.0
    why = "" if signum is None else f" (interrupted: {signal.Signals(signum).name})"
    try:
        say(
            f"{output}: {result.scans} scans in {result.seconds:.1f} s ({rate:.2f} Hz); "
            f"crc errors {s.get('crc_errors', 0)}, length errors {s.get('length_errors', 0)}, "
            f"resyncs {s.get('resyncs', 0)}, dropped scans {s.get('dropped', 0)}" + why
        )
    except OSError:  # the terminal that would show it hung up (SIGHUP): the file is complete all the same
        pass
    if result.disconnect is not None:
        raise DeviceError(f"{result.disconnect}; {output} is complete up to the last good scan ({result.scans} scans)")
    if signum is not None:
        raise click.exceptions.Exit(128 + signum)
