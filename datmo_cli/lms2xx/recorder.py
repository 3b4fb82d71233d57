"""Recording a SICK LMS2xx into a log, safely (the loop behind `datmo record`; its panel is the command's).

The log is written in streaming mode and flushed at least twice a second, so a power cut loses at most
about half a second (the reader recovers every complete chunk of the temporary file). A stop request
(`stop`, set by the command on Ctrl-C, SIGTERM or SIGHUP) stops the scanner's output and finishes the file; a
disconnect finishes it up to the last good scan. A failure after streaming started (the disk full, the
file-size limit, a second Ctrl-C) keeps what the last flush put on disk: the temporary file is cut there,
after its last complete chunk, and renamed to the output; RecordingCut says how many scans it holds.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from ..base.errors import DatmoError, OutputError
from ..base.outputs import Terminated
from ..logs import mcapio, transforms
from ..logs.scan import TELEGRAM, encode_telegram
from .driver import DeviceDisconnected
from .stream_records import DriverStats

FLUSH_EVERY_S = 0.5


@dataclass
class RecordResult:
    """What a recording did: scans written, why it ended, the driver's counts."""

    path: Path
    scans: int = 0
    seconds: float = 0.0
    reason: str = ""
    stats: dict = field(default_factory=dict)
    disconnect: str | None = None


class RecordingCut(DatmoError):
    """A recording ended by a failure after it started (the disk full, a second signal, a device error): the
    message says what happened and what the output keeps."""

    def __init__(self, message: str, exit_code: int = 1) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def record(
    driver,
    writer,
    *,
    duration: float | None = None,
    max_scans: int | None = None,
    raw: bool = False,
    stop: threading.Event | None = None,
    on_scan=None,
    progress: Callable[[int, float, DriverStats], None] | None = None,
    describe: Callable[[BaseException], tuple[str, int]] | None = None,
) -> RecordResult:
    """Connect `driver` (an LMS2xx), stream scans into `writer` (a streaming LogWriter) until `duration`
    seconds, `max_scans`, `stop` or a disconnect; stop the scanner and close the writer (also after a
    disconnect). An error before the scanner streams aborts the writer and propagates; any failure after
    (the disk full, a second Ctrl-C) keeps the scans flushed before it (writer.keep_flushed) and raises
    RecordingCut saying so, in the words of `describe(exc)` -> (phrase, exit code) for a failure other than
    Ctrl-C or a signal (default: the error's message). `on_scan` is called with each scan once it is written
    (the live view); `progress(scans, seconds, driver stats)` when streaming starts and about four times a
    second (the command's panel)."""

    stop = stop or threading.Event()
    result = RecordResult(writer.path)
    if raw:

        def on_telegram(frame, stamp: int) -> None:
            writer.write(mcapio.TOPIC_TELEGRAM, TELEGRAM, stamp, encode_telegram(frame.raw))

        driver.on_telegram = on_telegram
    try:
        status = driver.connect()
        meta = status.as_metadata()
        meta.update(
            port=str(driver.name),
            recorded_baud=str(driver.baud),
            config_hex=driver.config.raw.hex() if driver.config else "",
            indices=str(bool(driver.config and driver.config.indices)),
        )
        writer.add_metadata("lms2xx.status", meta)
        geometry = driver.geometry()
        driver.start()
    except BaseException:
        writer.abort()
        driver.close()
        raise
    t0 = time.monotonic()
    last_flush = t0
    flushed = 0  # scans on disk at the last flush
    last_view = t0
    try:
        if progress is not None:
            progress(0, 0.0, driver.stats)
        while True:
            now = time.monotonic()
            if stop.is_set():
                result.reason = "interrupted"
                break
            if duration is not None and now - t0 >= duration:
                result.reason = "duration"
                break
            if max_scans is not None and result.scans >= max_scans:
                result.reason = "scans"
                break
            try:
                scan = driver.read_scan(timeout=0.1)
            except DeviceDisconnected as exc:
                result.disconnect = str(exc)
                result.reason = "disconnected"
                break
            if scan is not None:
                writer.write_scan(scan.stamp_ns, scan.ranges, geometry)
                result.scans += 1
                if on_scan is not None:
                    on_scan(scan.stamp_ns, scan.ranges, geometry)
            now = time.monotonic()
            if now - last_flush >= FLUSH_EVERY_S:
                writer.flush()
                flushed = result.scans
                last_flush = now
            if progress is not None and now - last_view >= 0.25:
                progress(result.scans, now - t0, driver.stats)
                last_view = now
        result.seconds = time.monotonic() - t0
        if result.disconnect is None:
            _stop_scanner(driver)
        result.stats = driver.stats.as_dict()
        writer.add_metadata("lms2xx.stats", result.stats)
        writer.close()
    except BaseException as exc:
        result.seconds = time.monotonic() - t0
        cut = _cut(writer, result, flushed, exc, (describe or _message)(exc) if _failure(exc) else _signalled(exc))
        if isinstance(exc, Exception) and result.disconnect is None:
            try:
                _stop_scanner(driver)  # the disk full: the scanner need not stream on
            except (KeyboardInterrupt, Terminated):  # not waited for; the data is kept already
                pass
        raise cut from exc
    finally:
        driver.close()
    return result


def write_mount(writer, pose: tuple) -> None:
    """/tf_static base_link -> laser (the scanner's frame) of a laser pose (x, y m, yaw rad), and its metadata
    record: a recording has no odometry, so this is its only transform."""
    mount, now = transforms.LaserPose(*pose), time.time_ns()
    writer.add_metadata(transforms.LASER_POSE_RECORD, mount.record(transforms.BASE_FRAME, "laser"))
    writer.write_transforms([now], [transforms.mount_tf(now, transforms.BASE_FRAME, "laser", mount)], static=True)


def _stop_scanner(driver) -> None:
    """Stop the scanner's output and restore its baud; a warning if it does not answer."""
    try:
        driver.stop()
    except Exception as exc:  # finish the file whatever the device does now
        import warnings

        warnings.warn(f"{driver.name}: could not stop the scanner cleanly ({exc})", stacklevel=2)


def _failure(exc: BaseException) -> bool:
    """Whether `exc` is a failure rather than Ctrl-C or a terminating signal."""
    return not isinstance(exc, (KeyboardInterrupt, Terminated))


def _signalled(exc: BaseException) -> tuple[str, int]:
    """Ctrl-C or a signal that stopped a recording, as a phrase, and the exit code it gives."""
    if isinstance(exc, KeyboardInterrupt):
        return "interrupted (Ctrl-C) before the file was finished", 130
    return f"{exc} before the file was finished", int(getattr(exc, "exit_code", 1))


def _message(exc: BaseException) -> tuple[str, int]:
    """A failure as its message, and its exit code (a DatmoError's, else 1)."""
    return str(exc), exc.exit_code if isinstance(exc, DatmoError) else 1


def _scans(n: int) -> str:
    return f"{n} scan" if n == 1 else f"{n} scans"


def _cut(writer, result: RecordResult, flushed: int, exc: BaseException, cause: tuple[str, int]) -> RecordingCut:
    """Keep what reached the disk after `exc` stopped the recording (`cause`: it as a phrase, and the exit
    code); the error that says what and where."""
    what, code = cause
    try:
        writer.keep_flushed()
    except OutputError as left:
        return RecordingCut(what if left is exc else f"{what}; {left}", code)
    if writer.complete:
        return RecordingCut(f"{what}; {writer.path} is complete ({result.scans} scans)", code)
    if writer.kept:
        lost = result.scans - flushed
        return RecordingCut(
            f"{what}; {writer.path} keeps the {_scans(flushed)} that reached the disk before that "
            f"(readable, cut after its last complete chunk; later scans lost: {lost})",
            code,
        )
    return RecordingCut(f"{what}; no scan had reached the disk, so no {writer.path} was written", code)
