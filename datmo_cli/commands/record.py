"""`datmo record`: stream a SICK LMS200 over a serial port into a log, safely.

The log is written in streaming mode and flushed at least twice a second, so a power cut loses at most
about half a second (the reader recovers every complete chunk of the temporary file). Ctrl-C, SIGTERM and
SIGHUP stop the scanner's output and finish the file, then the command exits 130, 143 or 129; a disconnect
finishes it up to the last good scan (exit 1). A failure after that point (the disk full, the file-size
limit, a second Ctrl-C) keeps what the last flush put on disk: the temporary file is cut there, after its
last complete chunk, and renamed to the output; the error says how many scans it holds.

The work is workflows.recording.Recording (datmo_cli.api.Recording, api.record: provenance, writer, driver, live
view, around the loop lms2xx.recorder.record); here are the options, the signals, the panel and what is said.
"""

from __future__ import annotations

import threading
from pathlib import Path

import click

from ..base.bounds import OPTIONS
from .options import force_option, output_option, quiet_option
from .record_view import RecordPanel, Signals, failure, finished
from .types import laser_pose_option, option


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
def command(port: str, output: Path, angle: str, resolution: str, **options) -> None:
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
    from .. import api
    from ..cli import invocation

    if angle == "180" and resolution == "0.25":
        raise click.BadParameter("0.25° is available only with --angle 100", param_hint="--resolution")
    stop = threading.Event()
    recording = api.Recording(
        port,
        output,
        angle=angle,
        resolution=resolution,
        on_live=lambda line: click.echo(line, err=True),
        command_line=invocation("record"),
        **options,
    )
    panel = RecordPanel(recording.driver.name, recording.driver.baud)
    try:
        with Signals(stop) as signals:
            result = recording.run(stop=stop, progress=panel, describe=failure)
    finally:
        panel.stop()
        recording.close()
    finished(result, output, signals.signum)
