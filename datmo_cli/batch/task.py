"""The one task every executor runs per input (`run_task`): the input staged (a remote one copied here), a bag
converted, the log processed into its output in one pass (pipeline.process_file), and the manifest line it
ends in. `Task` and `RunOptions` travel to the workers pickled, by this module's path."""

from __future__ import annotations

import hashlib
import json
import os
import socket
import stat
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .. import __version__
from ..base.errors import DatmoError, InputError, OutputExistsError
from .discovery import bag_of
from .locations import fs_of, input_sha256, input_stat, local, remote
from .manifest import CANCELLED, DONE, FAILED, SUMMARY_KEY, TRACK_CLASSES

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


class Cancelled(BaseException):
    """The batch was cancelled while this task ran; its partial output is dropped."""


# ------------------------------------------------------------------------------------------ parameters


@dataclass(frozen=True)
class RunOptions:
    """The switches of `datmo run` that are not parameters of the stages: `markers` (--markers: store the
    Foxglove drawings), `covariance` (--covariance: store the tracks' covariance), `topic` and `odom_topic`
    (--topic, --odom-topic: the channels a bag is converted from) and `bag_dir` (--bag-dir: each output a ROS 2
    bag folder)."""

    markers: bool = False
    covariance: bool = False
    topic: str | None = None
    odom_topic: str | None = None
    bag_dir: bool = False


def params_hash(config: DatmoConfig | None = None, options: RunOptions | None = None) -> str:
    """SHA-256 (first 16 hex digits) of the effective parameters: features and track tables and the leg
    model's SHA-256, so the same settings hash alike wherever they were given (defaults, TOML, options); and
    the options that change the output (--markers, --covariance, --topic, --odom-topic; a default run hashes
    without them, as it did when it stored markers and covariance: an output of then holds all a lean one
    does)."""
    from ..passes.config import DatmoConfig
    from ..perception.features import leg_model_provenance

    config, options = config or DatmoConfig(), options or RunOptions()
    model = leg_model_provenance(config.features.leg_model)
    doc = {
        "features": config.features.to_dict(),
        "track": config.track.to_dict(),
        "leg_model": model.get("sha256", model.get("model")),
    }
    for key in ("markers", "covariance"):
        if getattr(options, key):
            doc[key] = True
    for key in ("topic", "odom_topic"):
        if getattr(options, key) is not None:
            doc[key] = getattr(options, key)
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()[:16]


# ----------------------------------------------------------------------------------------------- tasks


@dataclass
class Task:
    """One input of a batch, as an executor ships it to a worker."""

    index: int
    input: str
    output: str
    force: bool
    config: DatmoConfig | None
    options: RunOptions
    params_hash: str
    command_line: str | None
    threads: int | None = None  # --threads: perception threads on a Dask worker (None: one per task there)
    journal: str | None = None  # where the task records the temporary files it makes (locations.new_journal)


def record(task: Task, status: str, **fields) -> dict:
    """A manifest line for `task` (figures default to nothing done)."""
    rec = {
        "input": task.input,
        "input_sha256": None,
        "input_size": None,
        "input_mtime_ns": None,
        "output": task.output,
        "status": status,
        "error": None,
        "scans": 0,
        "seconds": 0.0,
        "scans_per_s": 0.0,
        "tracks": None,
        "datmo_version": __version__,
        "params_hash": task.params_hash,
        "finished": datetime.now(UTC).isoformat(timespec="seconds"),
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }
    rec.update(fields)
    return rec


def failed(task: Task, error: str) -> dict:
    """A failed line: its error names the input, unless it names the output (a full disk, a folder in the
    way: the input is not at fault)."""
    text = error if error.startswith((task.input, task.output)) else f"{task.input}: {error}"
    return record(task, FAILED, error=text.splitlines()[0] if text else text)


def headline(summary) -> dict:
    """The run's headline figures from its report (a report.RunSummary): confirmed tracks, by class, and
    dynamic ones."""
    row = summary.file_row()
    return {"confirmed": row["tracks"], **{c: row[c] for c in TRACK_CLASSES}, "dynamic": row["dynamic"]}


def follow(
    cancelled: Callable[[], bool] | None, scans: Callable[[int, int], None] | None
) -> Callable[[int, int], None]:
    """A task's progress callback for the pass over its log: `progress(done, total)` raises Cancelled when
    `cancelled()` says so, and passes the scans done of all to `scans` (either may be None)."""

    def progress(done: int, total: int) -> None:
        if cancelled is not None and cancelled():
            raise Cancelled()
        if scans is not None:
            scans(done, total)

    return progress


def run_task(
    task: Task,
    *,
    cancelled: Callable[[], bool] | None = None,
    scans: Callable[[int, int], None] | None = None,
    raise_unexpected: bool = False,
) -> dict:
    """Process one input into its output and return its manifest line.

    A DatmoError (bad input, refused overwrite) gives a failed line with the one-line error; any other
    exception too, unless `raise_unexpected` (Dask then retries the task). `cancelled()` is polled as the
    scans go by; when it says so the task stops, drops its partial output and returns a "cancelled" line.
    `scans(done, total)` follows the scans of this input. A bag (ROS 1 file, ROS 2 folder) and, with a topic
    in the parameters, any input is converted here first (`converted`), so a skipped input never is.
    A done line carries the output's report (report.RunSummary, gathered as the output is written) under
    SUMMARY_KEY, which the manifest does not keep. The temporary files the task makes are recorded in
    task.journal, when it has one.
    """
    if hasattr(task, "run"):  # another kind of batch task (datmo tune's evaluations): it runs itself
        return task.run(cancelled=cancelled, scans=scans, raise_unexpected=raise_unexpected)
    from ..base.outputs import journal_to

    t0 = time.perf_counter()
    progress = follow(cancelled, scans)
    if cancelled is not None and cancelled():
        return record(task, CANCELLED)
    journal_to(task.journal)
    try:
        return _run(task, t0, progress, raise_unexpected)
    finally:
        journal_to(None)


def _run(task: Task, t0: float, progress: Callable[[int, int], None], raise_unexpected: bool) -> dict:
    from ..passes import pipeline
    from ..report import RunAccumulator

    try:
        size, mtime = input_stat(task.input)
        with _staged_input(task.input) as src, _staged_output(task.output, task.force) as out:
            sha = input_sha256(src)
            notes: list[str] = []
            with converted(src, out, task, notes.append) as log:
                origin: dict[str, Any] = (
                    {} if Path(log) == Path(src) else {"origin": src}
                )  # provenance hashes the bag, not the copy
                report = RunAccumulator(str(Path(task.output)))
                n = pipeline.process_file(
                    log,
                    out,
                    force=task.force,
                    config=task.config,
                    markers=task.options.markers,
                    covariance=task.options.covariance,
                    bag_dir=task.options.bag_dir,
                    command_line=task.command_line,
                    progress=progress,
                    input_name=task.input if remote(task.input) else None,
                    report=report,
                    **origin,
                )
            summary = report.summary()
        out_size, out_mtime = input_stat(task.output)  # what resume checks the output against
        out_sha = input_sha256(task.output)
        seconds = time.perf_counter() - t0
        return record(
            task,
            DONE,
            input_sha256=sha,
            input_size=size,
            input_mtime_ns=mtime,
            output_sha256=out_sha,
            output_size=out_size,
            output_mtime_ns=out_mtime,
            scans=n,
            seconds=round(seconds, 3),
            scans_per_s=round(n / seconds, 1) if seconds > 0 else 0.0,
            tracks=headline(summary),
            **({"notes": notes} if notes else {}),
            **{SUMMARY_KEY: summary},
        )
    except Cancelled:
        return record(task, CANCELLED)
    except DatmoError as exc:
        return failed(task, str(exc))
    except OSError as exc:  # reading the input (a write error is an OutputError naming the output)
        if raise_unexpected:
            raise
        from ..base.outputs import os_error

        return failed(task, str(os_error(exc)))
    except Exception as exc:
        from ..base.outputs import interrupt_in

        if (stop := interrupt_in(exc)) is not None:
            raise stop from None  # Ctrl-C or SIGTERM inside a compiled call: the batch stops, no failed line
        if raise_unexpected:
            raise
        return failed(task, f"failed: {type(exc).__name__}: {exc}")


def converted(src: str, out: str, task: Task, tell: Callable[[str], None]):
    """The datmo log to process for local input `src`: `src` itself, or its conversion as by datmo import (a
    bag, or any input when the options give a topic or an odometry topic) into a temporary MCAP beside output
    `out` (beside the bag folder with options.bag_dir), removed when the block ends, on every way out (scan_log). The
    output is checked first, so a refused output costs no conversion. `tell` gets the lines the conversion says
    (they go in the task's record, "notes", which the command prints: a worker does not print)."""
    from ..base.outputs import temp_path
    from ..passes.input_logs import scan_log

    options = task.options
    dest = temp_path(Path(out).parent if options.bag_dir else Path(out))
    return scan_log(Path(src), Path(out), options.topic, options.odom_topic, force=task.force, dest=dest, tell=tell)


@contextmanager
def _staged_input(path: str) -> Iterator[str]:
    """A local path of the input: itself (a file or a ROS 2 bag folder), or a copy of a remote file in a
    temporary folder."""
    if not remote(path):
        if bag_of(local(path)) == os.path.abspath(local(path)):
            yield local(path)
            return
        from ..base.input_files import check

        if stat.S_ISDIR(check(local(path), folder_ok=True, name=path).st_mode):  # a FIFO or device: refused
            raise InputError(f"{path}: is a directory, not an MCAP log")
        yield local(path)
        return
    fs, p = fs_of(path)
    if not fs.exists(p):
        raise InputError(f"{path}: no such file")
    with tempfile.TemporaryDirectory(prefix="datmo-in-") as tmp:
        dst = os.path.join(tmp, os.path.basename(p))
        fs.get_file(p, dst)
        yield dst


def _refuse_links(folder: str) -> None:
    """Refuse an output folder reached through a symbolic link (OutputError naming the link). A batch's output
    folder is resolved when the batch is prepared, so the folders of its outputs hold no link unless one was
    put there: the output would land wherever it points, outside OUT_DIR."""
    folder = os.path.abspath(folder)
    if os.path.realpath(folder) == folder:
        return
    from ..base.errors import OutputError

    part = folder
    while part != os.path.dirname(part) and not os.path.islink(part):
        part = os.path.dirname(part)
    raise OutputError(
        f"{part if os.path.islink(part) else folder}: is a symbolic link; datmo run writes its "
        "outputs only inside the output folder, never through a link"
    )


@contextmanager
def _staged_output(path: str, force: bool) -> Iterator[str]:
    """Where to write the output: itself (LogWriter renames a temporary file into place; its folder is
    made when missing), or a local temporary file uploaded to a temporary name beside a remote output and
    moved into place when complete."""
    if not remote(path):
        folder = os.path.dirname(local(path)) or "."
        try:
            os.makedirs(folder, exist_ok=True)
        except OSError as exc:
            from ..base.outputs import os_error

            raise os_error(exc, folder, "making the output folder") from None
        _refuse_links(folder)
        yield local(path)
        return
    fs, p = fs_of(path)
    if fs.exists(p) and not force:
        raise OutputExistsError(f"{path}: exists; use --force to overwrite it")
    with tempfile.TemporaryDirectory(prefix="datmo-out-") as tmp:
        out = os.path.join(tmp, os.path.basename(p))
        yield out
        parent, name = p.rsplit("/", 1) if "/" in p else ("", p)
        part = f"{parent}/.{name}.{os.getpid()}.{time.monotonic_ns()}.tmp" if parent else f".{name}.tmp"
        from ..base.outputs import note

        note("+", fs.unstrip_protocol(part))  # removed by the batch if this worker dies before the move
        fs.put_file(out, part)
        fs.mv(part, p)
