"""`datmo record`: stream a SICK LMS200 over a serial port into a log, safely.

The log is written in streaming mode and flushed at least twice a second, so a power cut loses at most
about half a second (the reader recovers every complete chunk of the temporary file). Ctrl-C, SIGTERM and
SIGHUP stop the scanner's output and finish the file, then the command exits 130, 143 or 129; a disconnect
finishes it up to the last good scan (exit 1). A failure after that point (the disk full, the file-size
limit, a second Ctrl-C) keeps what the last flush put on disk: the temporary file is cut there, after its
last complete chunk, and renamed to the output; the error says how many scans it holds.

The recording loop is lms2xx.recorder.record; here are the options, the signals, its panel and the live view.
"""

from __future__ import annotations

import math
import signal
import threading
from pathlib import Path

import click

from ..bounds import OPTIONS
from .options import force_option, output_option, quiet_option
from .types import laser_pose_option, option


def _panel(scans: int, elapsed: float, stats, port: str, baud: int):
    from rich.table import Table

    t = Table.grid(padding=(0, 2))
    rate = scans / elapsed if elapsed > 0 else 0.0
    t.add_row("[bold]recording[/]", f"{port} at {baud} Bd", f"{elapsed:6.1f} s")
    t.add_row("scans", f"{scans:,}", f"{rate:6.2f} Hz")
    t.add_row("crc errors", f"{stats.crc_errors:,}", f"length errors {stats.length_errors:,}")
    t.add_row("resyncs", f"{stats.resyncs:,}", f"dropped scans {stats.dropped:,}")
    return t


class _Panel:
    """The recording's counts in a progress.Panel on stderr (recorder.record's progress callback), started at
    the first report; nothing when stderr is not a terminal or with --quiet."""

    def __init__(self, port: str, baud: int) -> None:
        from ..progress import Panel

        self.port, self.baud = port, baud
        self.panel = Panel()

    def __call__(self, scans: int, elapsed: float, stats) -> None:
        if self.panel.shown:
            self.panel.show(_panel(scans, elapsed, stats, self.port, self.baud))

    def stop(self) -> None:
        self.panel.stop()


def failure(exc: BaseException) -> tuple[str, int]:
    """A failure that stopped a recording as the command says it (cli.clean_error), and its exit code."""
    from ..cli import clean_error

    clean = clean_error(exc)
    return (clean.format_message(), clean.exit_code) if clean is not None else (str(exc), 1)


class _Signals:
    """Turn SIGINT, SIGTERM and SIGHUP (the terminal closed) into a stop request while recording (main thread
    only): the file is finished up to the last scan, then the command exits 128 + the signal's number. A
    second signal gives up at once (outputs.interrupt), keeping the scans flushed before it."""

    def __init__(self, stop: threading.Event) -> None:
        self.stop = stop
        self.signum: int | None = None
        self.old: dict[int, object] = {}

    def _handler(self, signum, frame) -> None:
        from .. import outputs

        if self.stop.is_set():
            outputs.interrupt(signum)
            return
        self.signum = signum
        self.stop.set()

    def __enter__(self) -> _Signals:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
                self.old[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, old in self.old.items():
            signal.signal(sig, old)


@click.command(name="record")
@click.option(
    "--port",
    required=True,
    metavar="PORT",
    help="Serial device of the LMS200 (e.g. /dev/ttyUSB0, or the path `datmo emulate` prints).",
)
@output_option("The log to write (MCAP).")
@click.option(
    "--baud",
    type=click.Choice(["9600", "19200", "38400", "500000"]),
    default="38400",
    show_default=True,
    help="Baud to record at; the device's current baud is found automatically. 500000 needs RS-422.",
)
@click.option(
    "--angle", type=click.Choice(["180", "100"]), default="180", show_default=True, help="Field of view, degrees."
)
@click.option(
    "--resolution",
    type=click.Choice(["1", "0.5", "0.25"]),
    default="0.5",
    show_default=True,
    help="Angular resolution, degrees (0.25 only with --angle 100).",
)
@click.option(
    "--units",
    type=click.Choice(["mm", "cm"]),
    default="mm",
    show_default=True,
    help="Distance units the device reports (changed in its EEPROM only when different).",
)
@option("--duration", bound=OPTIONS["record_duration"], default=None, help="Stop after this many seconds.")
@option("--scans", "max_scans", bound=OPTIONS["scans"], default=None, help="Stop after this many scans.")
@click.option(
    "--indices",
    is_flag=True,
    help="Have the device send real-time scan indices (exact dropped-scan counts; one EEPROM write "
    "if it does not send them yet).",
)
@click.option(
    "--interlaced", is_flag=True, help="Interlaced output (20 2A): partial scans merged into complete ones by the host."
)
@click.option("--raw", is_flag=True, help="Also store every telegram's bytes on /lms2xx/telegram.")
@force_option()
@click.option(
    "--live",
    is_flag=True,
    help="Also serve the scans, features, tracks and markers to Foxglove while "
    "recording (WebSocket; needs pip install 'datmo-cli[live]'); the URL to open is printed.",
)
@click.option(
    "--live-host",
    default="127.0.0.1",
    show_default=True,
    metavar="HOST",
    help="Address the live view serves on (0.0.0.0: every interface).",
)
@option(
    "--live-port",
    bound=OPTIONS["live_port"],
    default=8765,
    show_default=True,
    help="WebSocket port of the live view (0: any free port).",
)
@laser_pose_option()
@quiet_option
def command(
    port: str,
    output: Path,
    baud: str,
    angle: str,
    resolution: str,
    units: str,
    duration: float | None,
    max_scans: int | None,
    indices: bool,
    interlaced: bool,
    raw: bool,
    force: bool,
    live: bool,
    live_host: str,
    live_port: int,
    laser_pose: tuple | None = None,
) -> None:
    """Record a SICK LMS200 over a serial port into a log.

    Finds the scanner's baud, switches to --baud, sets the variant and units only when they differ,
    and streams scans to /scan (sensor_msgs/LaserScan, stamped with the host time of each telegram's
    first byte) until --duration, --scans, Ctrl-C or SIGTERM; the scanner's output is then stopped, the
    file finished, and the exit status is 130 after Ctrl-C, 143 after SIGTERM, 129 after SIGHUP. Data
    reaches the disk at least twice a second; if the disk fills, the scans already there are kept. The
    device status goes into the log's metadata (lms2xx.status), with the counts of CRC errors, resyncs and
    dropped scans (lms2xx.stats). With --live, each scan is also segmented, its features extracted and
    tracked as it arrives and served to Foxglove (see datmo play); the view never holds up the recording.

    Example: datmo record --port /dev/ttyUSB0 -o run.mcap --live
    """
    from ..cli import invocation
    from ..errors import DeviceError
    from ..lms2xx.driver import LMS2xx
    from ..lms2xx.recorder import record, write_mount
    from ..log import mcapio
    from ..progress import say

    if angle == "180" and resolution == "0.25":
        raise click.BadParameter("0.25° is available only with --angle 100", param_hint="--resolution")
    params = {
        "port": port,
        "baud": int(baud),
        "angle": int(angle),
        "resolution": float(resolution),
        "units": units,
        "duration": duration,
        "scans": max_scans,
        "indices": indices,
        "interlaced": interlaced,
        "raw": raw,
    }
    if laser_pose is not None:
        params["laser_pose"] = {"x_m": laser_pose[0], "y_m": laser_pose[1], "yaw_deg": math.degrees(laser_pose[2])}
    provenance = mcapio.Provenance("record", params, [], invocation("record"))
    writer = mcapio.LogWriter(output, force=force, provenance=provenance, streaming=True)
    if laser_pose is not None:
        write_mount(writer, laser_pose)
    driver = LMS2xx(
        port,
        baud=int(baud),
        angle=int(angle),
        resolution=float(resolution),
        units=units,
        indices=indices,
        interlaced=interlaced,
    )
    stop = threading.Event()
    feed = _live_feed(live_host, live_port) if live else None
    panel = _Panel(driver.name, driver.baud)
    try:
        with _Signals(stop) as signals:
            result = record(
                driver,
                writer,
                duration=duration,
                max_scans=max_scans,
                raw=raw,
                stop=stop,
                on_scan=feed.scan if feed is not None else None,
                progress=panel,
                describe=failure,
            )
    finally:
        panel.stop()
        if feed is not None:
            _close_live(feed)
    s = result.stats
    rate = result.scans / result.seconds if result.seconds > 0 else 0.0
    why = "" if signals.signum is None else f" (interrupted: {signal.Signals(signals.signum).name})"
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
    if signals.signum is not None:
        raise click.exceptions.Exit(128 + signals.signum)


def _live_feed(host: str, port: int):
    """The live view of a recording, its URL printed (the port is checked before the scanner starts)."""
    from ..live import LiveFeed, LiveServer

    server = LiveServer(host, port, option="--live-port")
    click.echo(f"datmo record: live view on {server.url}; open {server.app_url}", err=True)
    feed = LiveFeed(server)
    feed.warm_up()
    return feed


def _close_live(feed) -> None:
    """Stop the live view; a warning if it failed or fell behind (the recording is whole either way)."""
    import warnings

    feed.close()
    feed.server.close()
    if feed.failure is not None:
        warnings.warn(f"the live view stopped ({feed.failure}); the recording went on", stacklevel=2)
    elif feed.dropped:
        warnings.warn(
            f"the live view fell behind and skipped {feed.dropped} of {feed.published + feed.dropped} "
            "scans (all are in the recording)",
            stacklevel=2,
        )
