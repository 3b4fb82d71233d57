"""`datmo record`'s work as a call (datmo_cli.api.record, Recording): a SICK LMS200 on a serial port (or the
emulator's pseudo-terminal, `datmo emulate`) streamed into a log by lms2xx.recorder.record, with the
recording's provenance, the streaming writer, the driver and the optional live view assembled here. The
command keeps the terminal's part: the signals that stop a recording, the panel of counts, what it prints."""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..lms2xx.recorder import RecordResult


class Recording:
    """A recording ready to start: the output opened (refused before the device is touched when it exists and
    not `force`), the driver made, the live view serving when `live`. `run()` records; `close()` stops the
    live view (warning if it failed or fell behind); as a context manager it closes itself.

    `port`: the serial device (/dev/ttyUSB0, or the path `datmo emulate` prints); `output`: the MCAP log,
    written in streaming mode (flushed at least twice a second). `baud` to record at (9600, 19200, 38400,
    500000), `angle` 180 or 100 degrees, `resolution` 1, 0.5 or 0.25 degrees (0.25 with angle 100 only),
    `units` "mm" or "cm", `indices`, `interlaced`, `raw` (also /lms2xx/telegram), `duration` s and
    `max_scans` (None: until stopped), `laser_pose` (x m, y m, yaw rad: the scanner on the robot, into
    /tf_static), `live`/`live_host`/`live_port`: serve the scans, features and tracks to Foxglove
    (`on_live(line)` gets the line naming its URL; None: said on stderr). `command_line` goes into the
    provenance."""

    def __init__(
        self,
        port: str,
        output: str | os.PathLike,
        *,
        baud: int | str = 38400,
        angle: int | str = 180,
        resolution: float | str = 0.5,
        units: str = "mm",
        duration: float | None = None,
        max_scans: int | None = None,
        indices: bool = False,
        interlaced: bool = False,
        raw: bool = False,
        force: bool = False,
        laser_pose: tuple[float, float, float] | None = None,
        live: bool = False,
        live_host: str = "127.0.0.1",
        live_port: int = 8765,
        on_live: Callable[[str], None] | None = None,
        command_line: str | None = None,
    ) -> None:
        from ..base.errors import InputError
        from ..lms2xx.driver import LMS2xx
        from ..lms2xx.recorder import write_mount
        from ..logs import mcapio

        baud, angle, resolution = int(baud), int(angle), float(resolution)  # numbers or their text (the options')
        if angle == 180 and resolution == 0.25:
            raise InputError(f"{port}: 0.25° is available only with angle 100")
        params: dict[str, Any] = {
            "port": port,
            "baud": baud,
            "angle": angle,
            "resolution": resolution,
            "units": units,
            "duration": duration,
            "scans": max_scans,
            "indices": indices,
            "interlaced": interlaced,
            "raw": raw,
        }
        if laser_pose is not None:
            params["laser_pose"] = {"x_m": laser_pose[0], "y_m": laser_pose[1], "yaw_deg": math.degrees(laser_pose[2])}
        if command_line is None:
            command_line = f"datmo_cli.api.record({port!r}, {os.fsdecode(output)!r})"
        provenance = mcapio.Provenance("record", params, [], command_line)
        self.output = output
        self.duration, self.max_scans, self.raw = duration, max_scans, raw
        self.writer = mcapio.LogWriter(Path(output), force=force, provenance=provenance, streaming=True)
        if laser_pose is not None:
            write_mount(self.writer, laser_pose)
        self.driver = LMS2xx(
            port,
            baud=baud,
            angle=angle,
            resolution=resolution,
            units=units,
            indices=indices,
            interlaced=interlaced,
        )
        self.feed = _live_feed(live_host, live_port, on_live) if live else None

    def run(
        self,
        *,
        stop: threading.Event | None = None,
        progress: Callable[[int, float, Any], None] | None = None,
        describe: Callable[[BaseException], tuple[str, int]] | None = None,
    ) -> RecordResult:
        """Record until the duration, the scan count, `stop` set or a disconnect (lms2xx.recorder.record):
        the file finished, the scanner's output stopped. `progress(scans, seconds, stats)` about twice a
        second; `describe(exc)` says a failure as the caller does. Returns the RecordResult (.scans,
        .seconds, .stats, .reason, .disconnect: the error that ended it, or None)."""
        from ..lms2xx.recorder import record

        feed = self.feed
        return record(
            self.driver,
            self.writer,
            duration=self.duration,
            max_scans=self.max_scans,
            raw=self.raw,
            stop=stop,
            on_scan=feed.scan if feed is not None else None,
            progress=progress,
            describe=describe,
        )

    def close(self) -> None:
        """Stop the live view; a warning if it failed or fell behind (the recording is whole either way)."""
        import warnings

        feed, self.feed = self.feed, None
        if feed is None:
            return
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

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def record(
    port: str, output: str | os.PathLike, *, stop: threading.Event | None = None, **options: Any
) -> RecordResult:
    """`datmo record --port PORT -o OUTPUT`: record until `options`' duration or max_scans, or `stop` set (from
    another thread), into `output`; the options are Recording's. Returns the RecordResult."""
    with Recording(port, output, **options) as recording:
        return recording.run(stop=stop)


def _live_feed(host: str, port: int, on_live: Callable[[str], None] | None):
    """The live view of a recording, its URL said (the port is checked before the scanner starts)."""
    from ..base.progress import say
    from ..live import LiveFeed, LiveServer
    from ..passes.warm import warm_up

    server = LiveServer(host, port, option="--live-port")
    (on_live or say)(f"datmo record: live view on {server.url}; open {server.app_url}")
    feed = LiveFeed(server)
    warm_up()  # the compiled stages load now, not while the scanner streams
    return feed
