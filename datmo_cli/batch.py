"""Batches of `datmo run`: input discovery, output names, the manifest (the batch's ledger), resume, and
the one task every executor runs per input.

A batch turns INPUTS (files, folders searched recursively for .mcap logs, globs; local paths or fsspec
URLs) into one output per input under the output folder, and appends one JSON line per input to
OUT_DIR/manifest.jsonl as it finishes. Rerunning the same command skips the inputs whose latest line
says done with the same input SHA-256 and the same parameters' hash, and redoes the rest. The executor
(local processes here, Dask in `cluster.py`) only runs `run_task` on `Task`s and hands back records.

Paths: local inputs and outputs are absolute (the workers share the filesystem); `file://` URLs are
local paths; other fsspec URLs (`s3://...`) are staged through a local temporary folder on the worker.
"""

from __future__ import annotations

import errno
import glob
import hashlib
import json
import math
import os
import socket
import stat
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

from . import __version__
from .errors import DatmoError, InputError, OutputExistsError

if TYPE_CHECKING:
    from .config import DatmoConfig

MANIFEST = "manifest.jsonl"
LOG_SUFFIXES = (".mcap",)
DONE, FAILED, SKIPPED, CANCELLED = "done", "failed", "skipped", "cancelled"
TRACK_CLASSES = ("person", "circle_object", "rectangular_object", "unknown")


class Cancelled(BaseException):
    """The batch was cancelled while this task ran; its partial output is dropped."""


class BatchInterrupted(DatmoError):
    """Ctrl-C: the batch stopped; finished outputs and their manifest lines are kept."""

    exit_code = 130


# ------------------------------------------------------------------------------------- paths and URLs


def remote(url: str) -> bool:
    """True for an fsspec URL that is not a local path (`s3://b/k`; not `file://` nor a plain path)."""
    return "://" in url and not url.startswith("file://")


def local(path: str) -> str:
    """A plain path for a local path or file:// URL."""
    return path[len("file://") :] if path.startswith("file://") else path


def _fs(url: str):
    from .extras import require

    fsspec = require("fsspec", for_=f"{url}: reading a URL")
    try:
        return fsspec.core.url_to_fs(url)
    except (ImportError, ValueError) as exc:
        raise InputError(f"{url}: no fsspec driver for this URL ({exc})") from None


def join(folder: str, name: str) -> str:
    return f"{folder.rstrip('/')}/{name}" if remote(folder) else str(Path(local(folder)) / name)


def exists(path: str) -> bool:
    if remote(path):
        fs, p = _fs(path)
        return fs.exists(p)
    return os.path.exists(local(path))


def _is_log(name: str) -> bool:
    base = os.path.basename(name)
    return base.lower().endswith(LOG_SUFFIXES) and not base.startswith(".")


def discover(specs: list[str], out_dir: str, bag_dir: bool = False) -> list[tuple[str, str]]:
    """(input, output) for every log that `specs` name, in order, without repeats.

    A file is taken as it is (its output is OUT_DIR/STEM.mcap); a folder is searched recursively for .mcap
    logs (hidden files and the output folder itself left out) and its logs keep their relative paths under
    OUT_DIR; a glob (`*`, `?`, `[`, `**`) takes the logs it matches. A glob or folder without logs, or two
    inputs with the same output, is an InputError naming them. With `bag_dir` each output is the log file of a
    ROS 2 bag folder, OUT_DIR/STEM/STEM_0.mcap (log.bagdir.member_path).
    """
    out_root = None if remote(out_dir) else os.path.abspath(local(out_dir))
    pairs: list[tuple[str, str]] = []
    for spec in specs:
        for src, rel in _expand(spec, out_root):
            name = str(Path(rel).with_suffix(".mcap"))
            if bag_dir:
                from .log.bagdir import member_path

                name = member_path(name)
            pairs.append((src, join(out_dir, name)))
    seen_in: set[str] = set()
    seen_out: dict[str, str] = {}
    out: list[tuple[str, str]] = []
    for src, dst in pairs:
        if src in seen_in:
            continue
        seen_in.add(src)
        if dst in seen_out:
            raise InputError(f"{src}: same output name as {seen_out[dst]} ({dst}); rename one of them")
        seen_out[dst] = src
        out.append((src, dst))
    return out


def _expand(spec: str, out_root: str | None) -> list[tuple[str, str]]:
    """(input, output path relative to OUT_DIR) for one INPUTS item."""
    magic = glob.has_magic(spec.split("://", 1)[-1])
    if remote(spec):
        fs, path = _fs(spec)
        if magic and not fs.exists(path):  # a name holding [, * or ? that exists is that file, not a pattern
            found = [p for p in sorted(fs.glob(path)) if _is_log(p) and fs.isfile(p)]
            if not found:
                raise InputError(f"{spec}: no .mcap log matches")
            return [(fs.unstrip_protocol(p), os.path.basename(p)) for p in found]
        if fs.isdir(path):
            found = [p for p in sorted(fs.find(path)) if _is_log(p)]
            if not found:
                raise InputError(f"{spec}: no .mcap logs in this folder")
            return [(fs.unstrip_protocol(p), os.path.relpath(p, path)) for p in found]
        return [(spec, os.path.basename(path))]
    path = local(spec)
    magic = magic and not os.path.lexists(path)  # a name holding [, * or ? that exists is that file or folder
    bag = _bag_of(path)
    if bag is not None and not magic:
        return [(bag, os.path.basename(bag))]
    if magic:
        found = [os.path.abspath(p) for p in sorted(glob.glob(path, recursive=True)) if os.path.isfile(p)]
        found = [p for p in found if _is_log(p) and not _inside(p, out_root)]
        if not found:
            raise InputError(f"{spec}: no .mcap log matches")
        return [(p, os.path.basename(p)) for p in found]
    if os.path.isdir(path):
        root = os.path.abspath(path)
        found = []
        for folder, dirs, files in os.walk(root):
            dirs[:] = sorted(
                d for d in dirs if not d.startswith(".") and not _inside(os.path.join(folder, d), out_root)
            )
            found += [os.path.join(folder, f) for f in sorted(files) if _is_log(f)]
        if not found:
            raise InputError(f"{spec}: no .mcap logs in this folder")
        return [(p, os.path.relpath(p, root)) for p in found]
    return [(os.path.abspath(path), os.path.basename(path))]  # a missing file fails as its own input


def _bag_of(path: str) -> str | None:
    """The absolute path of the ROS 2 bag folder that local `path` names (the folder, or its .db3 file), else
    None. A bag is one input, converted by its task (run_task), and its output is named after the folder."""
    folder = os.path.dirname(path) if path.endswith(".db3") else path
    if os.path.isdir(folder) and os.path.isfile(os.path.join(folder, "metadata.yaml")):
        return os.path.abspath(folder)
    return None


def _inside(path: str, folder: str | None) -> bool:
    return folder is not None and (path == folder or path.startswith(folder.rstrip(os.sep) + os.sep))


def tmp_pattern(output: str) -> str:
    """The glob of the temporary files a writer of `output` leaves beside it (LogWriter and remote uploads)."""
    name = os.path.basename(output.rstrip("/"))
    return join(
        os.path.dirname(output.rstrip("/")) if remote(output) else str(Path(local(output)).parent),
        f".{glob.escape(name)}.*tmp",
    )


def remove_partial(outputs: list[str]) -> int:
    """Remove the temporary files of unfinished writes of `outputs`; returns how many."""
    n = 0
    for out in outputs:
        pattern = tmp_pattern(out)
        try:
            if remote(pattern):
                fs, p = _fs(pattern)
                for f in fs.glob(p):
                    fs.rm(f)
                    n += 1
            else:
                for f in glob.glob(pattern):
                    os.unlink(f)
                    n += 1
        except OSError:
            pass
    return n


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
    from .config import DatmoConfig
    from .perception.features import leg_model_provenance

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


# -------------------------------------------------------------------------------------------- manifest


class Manifest:
    """OUT_DIR/manifest.jsonl: one JSON object per line, one line per input each time a batch finishes it;
    the latest line of an input is its state. Lines are appended and flushed (fsync) one at a time, so a
    crash leaves at most a torn last line, which reading skips. On an fsspec URL that cannot append (object
    stores) the whole file is rewritten, at most every few seconds and at the end.

    A local manifest is a regular file in its folder: a symbolic link there is refused, never read or written
    through (it could point anywhere, a shell's rc file), and so is a FIFO or a device; it is read a line at a
    time, at most MAX_MANIFEST_BYTES in all. A line whose fields have the wrong types (check_record) is an
    InputError naming the file and the line."""

    def __init__(self, out_dir: str) -> None:
        self.path = join(out_dir, MANIFEST)
        self._remote = remote(self.path)
        self._lines: list[str] = []  # remote: every line, rewritten whole
        self._last_put = 0.0
        self._lock = threading.Lock()

    def read(self) -> list[dict]:
        """Every intact line, oldest first (a torn or foreign line, one that is not a JSON object with an
        input and a status, is skipped)."""
        from .input_files import MAX_MANIFEST_BYTES

        if self._remote:
            fs, p = _fs(self.path)
            if not fs.exists(p):
                return []
            size = int(fs.info(p).get("size") or 0)
            if size > MAX_MANIFEST_BYTES:
                raise InputError(
                    f"{self.path}: {size:,} bytes; a manifest is at most {MAX_MANIFEST_BYTES:,} bytes "
                    "(split the batch by folder)"
                )
            return self._parse(fs.cat_file(p).splitlines(keepends=True))
        p = local(self.path)
        if not os.path.lexists(p):
            return []
        self._refuse_link()
        from .input_files import open_regular

        with open_regular(p) as f:
            size = os.fstat(f.fileno()).st_size
            if size > MAX_MANIFEST_BYTES:
                raise InputError(
                    f"{self.path}: {size:,} bytes; a manifest is at most {MAX_MANIFEST_BYTES:,} bytes "
                    "(split the batch by folder)"
                )
            return self._parse(_lines_of(f, MAX_MANIFEST_BYTES))

    def _parse(self, lines: Iterable[bytes]) -> list[dict]:
        records = []
        for n, line in enumerate(lines, 1):
            try:
                rec = json.loads(line)
            except ValueError:
                continue
            if isinstance(rec, dict) and "input" in rec and "status" in rec:
                check_record(rec, f"{self.path}: line {n}")
                records.append(rec)
        return records

    def _refuse_link(self) -> None:
        if not self._remote and os.path.islink(local(self.path)):
            from .errors import OutputError

            raise OutputError(
                f"{self.path}: is a symbolic link; datmo reads and writes a batch's manifest only as a "
                "regular file in its folder (remove the link)"
            )

    def latest(self) -> dict[str, dict]:
        """The latest line of each input."""
        return {r["input"]: r for r in self.read()}

    def compact(self, keep: dict[str, dict] | None = None) -> None:
        """Rewrite the file with one line per input (its latest), atomically; drops torn lines."""
        latest = self.latest() if keep is None else keep
        lines = [json.dumps(r, sort_keys=True) + "\n" for r in latest.values()]
        if self._remote:
            self._lines = lines
            self._put(force=True)
            return
        p = Path(local(self.path))
        if not lines and not os.path.lexists(p):
            return
        self._refuse_link()
        from .outputs import atomic_output

        with atomic_output(p, force=True, what="manifest") as f:
            f.write("".join(lines).encode("utf-8"))

    def append(self, record: dict) -> None:
        line = json.dumps(record, sort_keys=True) + "\n"
        with self._lock:
            if self._remote:
                self._lines.append(line)
                self._put()
                return
            from .outputs import writing

            with writing(local(self.path)), self._open_for_append() as f:
                f.write(line.encode("utf-8"))
                f.flush()
                os.fsync(f.fileno())

    def _open_for_append(self):
        """The local manifest opened to append, never through a symbolic link (O_NOFOLLOW) nor into a FIFO
        or a device (opened without blocking, then checked)."""
        import stat

        from .errors import OutputError

        path = local(self.path)
        flags = (
            os.O_WRONLY
            | os.O_APPEND
            | os.O_CREAT
            | getattr(os, "O_NOFOLLOW", 0)
            | getattr(os, "O_NONBLOCK", 0)
            | getattr(os, "O_CLOEXEC", 0)
        )
        try:
            fd = os.open(path, flags, 0o666)
        except OSError as exc:
            if os.path.islink(path):
                self._refuse_link()
            if exc.errno == errno.ENXIO:  # a FIFO nobody reads
                raise OutputError(
                    f"{self.path}: is a FIFO (named pipe), not a regular file; datmo writes a "
                    "batch's manifest only as a regular file"
                ) from None
            raise
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            os.close(fd)
            raise OutputError(
                f"{self.path}: is not a regular file; datmo writes a batch's manifest only as a regular file"
            )
        os.set_blocking(fd, True)
        return os.fdopen(fd, "ab")

    def close(self) -> None:
        if self._remote:
            self._put(force=True)

    def _put(self, force: bool = False) -> None:
        if force or time.monotonic() - self._last_put > 5.0:
            fs, p = _fs(self.path)
            fs.pipe_file(p, "".join(self._lines).encode())
            self._last_put = time.monotonic()


def _lines_of(f, limit: int) -> Iterator[bytes]:
    """The lines of binary file `f`, up to `limit` bytes in all; a line longer than MAX_MANIFEST_LINE_BYTES is
    passed over without being held (it is no manifest line)."""
    from .input_files import MAX_MANIFEST_LINE_BYTES

    total = 0
    while total <= limit:
        line = f.readline(MAX_MANIFEST_LINE_BYTES + 1)
        if not line:
            return
        total += len(line)
        if len(line) > MAX_MANIFEST_LINE_BYTES and not line.endswith(b"\n"):
            while line and not line.endswith(b"\n") and total <= limit:  # the rest of the long line
                line = f.readline(1 << 16)
                total += len(line)
            continue
        yield line


def _count(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _figure(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0


def _text(v: object) -> bool:
    return isinstance(v, str)


def _or_none(test: Callable[[object], bool]) -> Callable[[object], bool]:
    return lambda v: v is None or test(v)


def _tracks(v: object) -> bool:
    return isinstance(v, dict) and all(isinstance(k, str) and _count(n) for k, n in v.items())


# a manifest line's fields: what each must be when present (input and status are always)
RECORD_FIELDS: dict[str, tuple[Callable[[object], bool], str]] = {
    "input": (_text, "a string"),
    "status": (lambda v: v in (DONE, FAILED, SKIPPED), f"one of {DONE}, {FAILED}, {SKIPPED}"),
    "output": (_text, "a string"),
    "input_sha256": (_or_none(_text), "a string or null"),
    "input_size": (_or_none(_count), "a whole number of bytes or null"),
    "input_mtime_ns": (
        _or_none(lambda v: isinstance(v, int) and not isinstance(v, bool)),
        "a whole number of nanoseconds or null",
    ),
    "error": (_or_none(_text), "a string or null"),
    "scans": (_count, "a whole number of scans"),
    "seconds": (_figure, "a finite number of seconds, 0 or more"),
    "scans_per_s": (_figure, "a finite number, 0 or more"),
    "tracks": (_or_none(_tracks), "an object of whole numbers by class, or null"),
    "datmo_version": (_or_none(_text), "a string or null"),
    "params_hash": (_or_none(_text), "a string or null"),
    "finished": (_or_none(_text), "a string or null"),
    "worker": (_or_none(_text), "a string or null"),
    "notes": (lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v), "a list of strings"),
}


def check_record(rec: dict, where: str) -> None:
    """Refuse a manifest line (InputError naming `where`, the file and the line) whose fields have the wrong
    types: a hand-edited or foreign line must not become a wrong resume or a wrong report."""
    for key, (ok, what) in RECORD_FIELDS.items():
        if key in rec and not ok(rec[key]):
            shown = json.dumps(rec[key])
            shown = shown if len(shown) <= 40 else shown[:37] + "..."
            raise InputError(f"{where}: {key} must be {what}, got {shown}; correct or delete the line")


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


SUMMARY_KEY = "summary"  # a done line's report (report.RunSummary) as the task returns it; not in the manifest


def manifest_line(rec: dict) -> dict:
    """`rec` as the manifest keeps it: without the report a task returns with it."""
    return {k: v for k, v in rec.items() if k != SUMMARY_KEY}


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
    text = error if error.startswith(task.input) else f"{task.input}: {error}"
    return record(task, FAILED, error=text.splitlines()[0] if text else text)


def input_stat(path: str) -> tuple[int | None, int | None]:
    """(size, mtime in ns) of an input, (None, None) when it cannot be seen; for a ROS 2 bag folder the size of
    its files in all and the latest mtime of the folder and its files."""
    try:
        if remote(path):
            fs, p = _fs(path)
            return int(fs.info(p)["size"]), None
        st = os.stat(local(path))
        if os.path.isdir(local(path)):
            files = [os.stat(p) for p in Path(local(path)).rglob("*") if p.is_file()]
            return sum(f.st_size for f in files), max([st.st_mtime_ns, *(f.st_mtime_ns for f in files)])
        return st.st_size, st.st_mtime_ns
    except (OSError, KeyError, ValueError, DatmoError):
        return None, None


def input_sha256(path: str) -> str:
    if not remote(path):
        from .log.mcapio import sha256_of

        return sha256_of(local(path))
    fs, p = _fs(path)
    h = hashlib.sha256()
    with fs.open(p, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def headline(summary) -> dict:
    """The run's headline figures from its report (a report.RunSummary): confirmed tracks, by class, and
    dynamic ones."""
    row = summary.file_row()
    return {"confirmed": row["tracks"], **{c: row[c] for c in TRACK_CLASSES}, "dynamic": row["dynamic"]}


_WARM = False


def ensure_warm() -> None:
    """warm_up() once per process (a worker's first task, or the worker plugin): numba kernels loaded."""
    global _WARM
    if not _WARM:
        from .pipeline import warm_up

        warm_up()
        _WARM = True


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
    SUMMARY_KEY, which the manifest does not keep.
    """
    from . import pipeline
    from .report import RunAccumulator

    t0 = time.perf_counter()

    def progress(done: int, total: int) -> None:
        if cancelled is not None and cancelled():
            raise Cancelled()
        if scans is not None:
            scans(done, total)

    try:
        if cancelled is not None and cancelled():
            raise Cancelled()
        size, mtime = input_stat(task.input)
        with _staged_input(task.input) as src, _staged_output(task.output, task.force) as out:
            sha = input_sha256(src)
            notes: list[str] = []
            with converted(src, out, task, notes.append) as log:
                origin = {} if Path(log) == Path(src) else {"origin": src}  # provenance hashes the bag, not the copy
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
        seconds = time.perf_counter() - t0
        return record(
            task,
            DONE,
            input_sha256=sha,
            input_size=size,
            input_mtime_ns=mtime,
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
        from .outputs import os_error

        return failed(task, str(os_error(exc)))
    except Exception as exc:
        from .outputs import interrupt_in

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
    from .inputs import scan_log
    from .outputs import temp_path

    options = task.options
    dest = temp_path(Path(out).parent if options.bag_dir else Path(out))
    return scan_log(Path(src), Path(out), options.topic, options.odom_topic, force=task.force, dest=dest, tell=tell)


@contextmanager
def _staged_input(path: str) -> Iterator[str]:
    """A local path of the input: itself (a file or a ROS 2 bag folder), or a copy of a remote file in a
    temporary folder."""
    if not remote(path):
        if _bag_of(local(path)) == os.path.abspath(local(path)):
            yield local(path)
            return
        from .input_files import check

        if stat.S_ISDIR(check(local(path), folder_ok=True, name=path).st_mode):  # a FIFO or device: refused
            raise InputError(f"{path}: is a directory, not an MCAP log")
        yield local(path)
        return
    fs, p = _fs(path)
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
    from .errors import OutputError

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
            from .outputs import os_error

            raise os_error(exc, folder, "making the output folder") from None
        _refuse_links(folder)
        yield local(path)
        return
    fs, p = _fs(path)
    if fs.exists(p) and not force:
        raise OutputExistsError(f"{path}: exists; use --force to overwrite it")
    with tempfile.TemporaryDirectory(prefix="datmo-out-") as tmp:
        out = os.path.join(tmp, os.path.basename(p))
        yield out
        parent, name = p.rsplit("/", 1) if "/" in p else ("", p)
        part = f"{parent}/.{name}.{os.getpid()}.{time.monotonic_ns()}.tmp" if parent else f".{name}.tmp"
        fs.put_file(out, part)
        fs.mv(part, p)


# --------------------------------------------------------------------------------------------- batches


@dataclass
class Batch:
    """A batch ready to run: its tasks, the manifest lines of the inputs it skips, and its ledger."""

    out_dir: str
    tasks: list[Task]
    skipped: list[dict]
    manifest: Manifest
    outputs: list[str] = field(default_factory=list)
    records: dict[str, dict] = field(default_factory=dict)  # input -> this batch's line

    @property
    def total(self) -> int:
        return len(self.tasks) + len(self.skipped)


def out_folder(out_dir: str) -> str:
    """The batch's output folder: an fsspec URL as it is; a local folder made when missing and resolved
    (absolute, without links: the workers share the path). InputError when it is not a folder."""
    if remote(out_dir):
        return out_dir
    d = Path(local(out_dir))
    if d.exists() and not d.is_dir():
        raise InputError(f"{out_dir}: exists and is not a folder")
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        from .outputs import os_error

        raise os_error(exc, d, "making the output folder") from None
    return str(d.resolve())


LOCK = ".datmo-run.lock"


@contextmanager
def folder_lock(out_dir: str) -> Iterator[str]:
    """Hold the batch's output folder for the block (yields it, as out_folder makes it): a second `datmo run`
    on the same folder at once is refused with one line naming the process that holds it, rather than both
    writing one manifest. The lock is an flock on OUT_DIR/.datmo-run.lock (opened without following a link),
    which holds the holder's pid, host and start; it is released when the process ends, however it ends, and
    the file is removed at the end of the block. An fsspec URL is not locked (object stores have no locks)."""
    import fcntl

    from .errors import OutputError

    folder = out_folder(out_dir)
    if remote(folder):
        yield folder
        return
    path = os.path.join(folder, LOCK)
    flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | os.O_CLOEXEC
    while True:
        try:
            fd = os.open(path, flags, 0o644)
        except OSError as exc:
            why = "is a symbolic link" if os.path.islink(path) else None
            if why is None:
                from .outputs import os_error

                raise os_error(exc, path, "locking the output folder") from None
            raise OutputError(f"{path}: {why}; datmo run keeps its lock only as a regular file (remove it)") from None
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise OutputError(
                f"{path}: is not a regular file; datmo run keeps its lock only as a regular file (remove it)"
            )
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 512, 0).decode("utf-8", "replace").strip() or "a process"
            os.close(fd)
            raise DatmoError(
                f"{folder}: another datmo run is writing into this folder ({holder}); wait for it to "
                "finish or stop it, or give another -o folder"
            ) from None
        except OSError:  # a file system without locks (some network mounts): run unlocked, as before
            break
        try:  # the holder may have removed the file as it finished: hold the one at the path
            if os.path.samestat(os.fstat(fd), os.lstat(path)):
                break
        except FileNotFoundError:
            pass
        os.close(fd)
    started = datetime.now(UTC).isoformat(timespec="seconds")
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}, started {started}\n".encode(), 0)
    except OSError:
        pass
    try:
        yield folder
    finally:
        try:
            os.unlink(path)  # while holding it: a process waiting on this file retries on the path
        except OSError:
            pass
        os.close(fd)


def prepare(
    specs: list[str],
    out_dir: str,
    *,
    config: DatmoConfig | None = None,
    options: RunOptions | None = None,
    force: bool = False,
    command_line: str | None = None,
    threads: int | None = None,
) -> Batch:
    """Find the inputs, read the manifest and decide what to redo.

    An input is skipped when its latest manifest line is done (or skipped) by this datmo version with the
    same parameters' hash and the same input SHA-256 (not rehashed when size and mtime are unchanged) and
    its output exists (a line of another version is redone: outputs of two versions never mix silently);
    `force` redoes everything. An output that exists may be overwritten without `force` only when the
    manifest lists it for this input or it is the leftover of an interrupted batch (its provenance says
    `datmo run` of this input); any other existing output fails as its input with "use --force".
    Call it, and run_many, inside `folder_lock(out_dir)` (as `datmo run` does): two batches at once in one
    folder would each rewrite the other's manifest.
    """
    out_dir = out_folder(out_dir)
    options = options or RunOptions()
    pairs = discover(specs, out_dir, options.bag_dir)
    manifest = Manifest(out_dir)
    ledger = manifest.latest()
    phash = params_hash(config, options)
    tasks, skipped = [], []
    for i, (src, dst) in enumerate(pairs):
        last = ledger.get(src)
        owned = last is not None and last.get("output") == dst and last.get("status") in (DONE, SKIPPED)
        if (
            not force
            and owned
            and last.get("params_hash") == phash
            and last.get("datmo_version") == __version__
            and exists(dst)
            and _same_input(src, last)
        ):
            skipped.append(
                {**last, "status": SKIPPED, "error": None, "finished": datetime.now(UTC).isoformat(timespec="seconds")}
            )
            continue
        overwrite = force or (exists(dst) and (owned or _leftover(dst, src)))
        tasks.append(Task(i, src, dst, overwrite, config, options, phash, command_line, threads))
    if ledger:
        manifest.compact(ledger)  # one line per input before this batch appends its own
    return Batch(out_dir, tasks, skipped, manifest, [d for _, d in pairs])


def _same_input(src: str, last: dict) -> bool:
    from .input_files import is_regular

    size, mtime = input_stat(src)
    if size is None or not (remote(src) or os.path.isdir(local(src)) or is_regular(local(src))):
        return False  # a FIFO or a device now: never hashed here (its task says what it is)
    if mtime is not None and size == last.get("input_size") and mtime == last.get("input_mtime_ns"):
        return True
    try:
        return input_sha256(src) == last.get("input_sha256")
    except OSError:
        return False


def _leftover(dst: str, src: str) -> bool:
    """True when `dst` is a datmo run output of `src` (a batch stopped before recording it)."""
    if remote(dst):
        return False
    from .log import mcapio

    try:
        meta = mcapio.summary(local(dst)).metadata
    except (DatmoError, OSError):
        return False
    return meta.get("datmo", {}).get("command") == "run" and src in meta.get("datmo.inputs", {})


class Executor:
    """Runs tasks somewhere; `run_many` calls `on_record(record)` in this process as each task finishes (in any
    order) and `on_scans(task_index, done, total)` when it can follow scans; Ctrl-C stops the workers'
    tasks (their partial outputs dropped) and is raised again."""

    workers: int = 1
    where: str = "local"

    def run(
        self,
        tasks: list[Task],
        on_record: Callable[[dict], None],
        on_scans: Callable[[int, int, int], None] | None = None,
    ) -> None:
        raise NotImplementedError

    def close(self) -> None:
        pass


class LocalExecutor(Executor):
    """`--jobs N`: one process per job on this machine (forked after warm_up, so kernels are loaded), at most
    one per task; each worker ends with the batch's process, however that ends (die_with_parent)."""

    def __init__(self, jobs: int | None = None) -> None:
        self.workers = jobs or os.cpu_count() or 1
        self.where = _processes(1)

    def run(self, tasks, on_record, on_scans=None) -> None:
        if not tasks:
            return
        n = min(self.workers, len(tasks))
        self.where = _processes(n)  # what ran them, not what --jobs allowed
        if n <= 1:
            for t in tasks:
                on_record(run_task(t, scans=(lambda d, m, i=t.index: on_scans(i, d, m)) if on_scans else None))
            return
        self._pool(tasks, n, on_record, on_scans)

    def _pool(self, tasks, n, on_record, on_scans) -> None:
        import multiprocessing
        from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
        from concurrent.futures.process import BrokenProcessPool

        ensure_warm()
        ctx = multiprocessing.get_context("fork") if hasattr(os, "fork") else multiprocessing.get_context()
        queue = ctx.Queue()  # (task, scans done, scans) from the workers; handed over as they start
        pool = ProcessPoolExecutor(
            max_workers=n, mp_context=ctx, initializer=_worker_started, initargs=(os.getpid(), queue)
        )
        try:
            futures = {pool.submit(_queued_task, t): t for t in tasks}
            pending = set(futures)
            while pending:
                done, pending = wait(pending, timeout=0.1, return_when=FIRST_COMPLETED)
                _drain(queue, on_scans)
                for fut in done:
                    t = futures[fut]
                    try:
                        on_record(fut.result())
                    except BrokenProcessPool as exc:
                        on_record(failed(t, f"worker died ({exc})"))
            _drain(queue, on_scans)
        except BaseException:
            for p in list(getattr(pool, "_processes", {}).values()):
                p.terminate()  # a task still running must not finish an output after the batch stopped
            pool.shutdown(wait=True, cancel_futures=True)
            queue.close()
            raise
        pool.shutdown(wait=True)
        queue.close()


def _processes(n: int) -> str:
    return f"{n} local process{'es' if n > 1 else ''}"


_SCANS: list = []  # in a --jobs worker: the queue its tasks report their scans on


def _worker_started(parent: int, queue) -> None:
    """A --jobs worker's start: end with the batch's process; keep the queue scans are reported on."""
    _SCANS[:] = [queue]
    die_with_parent(parent)


def die_with_parent(parent: int) -> None:
    """Make this process (a worker of process `parent`) end when `parent` ends, however it ends (SIGKILL
    too): on Linux the kernel sends SIGTERM when the parent dies (prctl PR_SET_PDEATHSIG), elsewhere a thread
    watches the parent. The worker then removes its temporary files and exits 143 at once; a SIGTERM while the
    parent lives (the batch stopping its tasks) is handled as before."""
    import signal

    def gone() -> None:
        from .outputs import remove_live

        remove_live()
        os._exit(128 + signal.SIGTERM)

    previous = signal.getsignal(signal.SIGTERM)

    def on_sigterm(signum, frame) -> None:
        if os.getppid() != parent:
            gone()
        if callable(previous):
            previous(signum, frame)
        else:
            signal.signal(signal.SIGTERM, signal.SIG_DFL)
            os.kill(os.getpid(), signal.SIGTERM)

    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, on_sigterm)
    if not _death_signal(signal.SIGTERM):

        def watch() -> None:
            while os.getppid() == parent:
                time.sleep(0.5)
            gone()

        threading.Thread(target=watch, name="datmo-parent-watch", daemon=True).start()
    if os.getppid() != parent:  # it died before the watch began
        gone()


def _death_signal(signum: int) -> bool:
    """Ask Linux to send `signum` to this process when its parent dies (prctl PR_SET_PDEATHSIG); False where
    that cannot be done."""
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(1, int(signum), 0, 0, 0) == 0  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return False


def _queued_task(task: Task) -> dict:
    queue = _SCANS[0]
    return run_task(task, scans=lambda d, n: queue.put((task.index, d, n)))


def _drain(queue, on_scans) -> None:
    import queue as queue_mod

    while True:
        try:
            i, d, n = queue.get_nowait()
        except (queue_mod.Empty, OSError, ValueError):
            return
        if on_scans:
            on_scans(i, d, n)


_DEFERRING: list[int] = []  # SIGINTs caught while a deferring block runs (the outermost block owns it)


@contextmanager
def _interrupt_deferred() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) that arrives inside the block until the end of the outermost such block (main
    thread only)."""
    import signal

    global _DEFERRING
    if threading.current_thread() is not threading.main_thread() or _DEFERRING is not _NOT_DEFERRING:
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda sig, frame: caught.append(sig))
    _DEFERRING = caught
    try:
        yield
    finally:
        _DEFERRING = _NOT_DEFERRING
        signal.signal(signal.SIGINT, previous)
    if caught:
        if callable(previous) and previous is not signal.default_int_handler:
            previous(signal.SIGINT, None)  # an executor's own Ctrl-C handler (see cluster._interrupt_flag)
        else:
            raise KeyboardInterrupt


_NOT_DEFERRING = _DEFERRING


def run_many(
    batch: Batch,
    executor: Executor,
    *,
    on_record: Callable[[dict], None] | None = None,
    on_scans: Callable[[int, int, int], None] | None = None,
) -> list[dict]:
    """Run a prepared batch: skipped inputs' lines first, then each task's line as it finishes, all
    appended to the manifest. Returns this batch's lines in input order. Ctrl-C: the executor stops its
    tasks, partial files are removed and BatchInterrupted says what is kept."""

    def finished(rec: dict) -> None:
        if rec["status"] == CANCELLED:
            return
        with _interrupt_deferred():  # a line is written and counted whole, or not at all
            batch.manifest.append(manifest_line(rec))
            batch.records[rec["input"]] = rec
        if on_record:
            on_record(rec)

    from .outputs import Terminated

    for rec in batch.skipped:
        finished(rec)
    try:
        executor.run(batch.tasks, finished, on_scans)
    except Terminated:  # SIGTERM, SIGHUP: the same clean-up; the CLI exits 143 or 129
        remove_partial([t.output for t in batch.tasks if t.input not in batch.records])
        batch.manifest.close()
        raise
    except KeyboardInterrupt:
        remove_partial([t.output for t in batch.tasks if t.input not in batch.records])
        batch.manifest.close()
        done = sum(r["status"] != FAILED for r in batch.records.values())
        raise BatchInterrupted(
            f"interrupted: {done} of {batch.total} inputs done and in {batch.manifest.path}; "
            "run the same command again to do the rest"
        ) from None
    remove_partial([t.output for t in batch.tasks])  # left by workers that died mid-write
    batch.manifest.close()
    index = {out: i for i, out in enumerate(batch.outputs)}
    return sorted(batch.records.values(), key=lambda r: index.get(r["output"], len(index)))


# --------------------------------------------------------------------------------------------- reports


def summary(records: list[dict]) -> dict:
    """A batch's figures from its manifest's latest lines: inputs by status, scans, task time, tracks by
    class, the datmo versions and parameters' hashes in use, and done inputs whose output is missing."""
    ok = [r for r in records if r["status"] in (DONE, SKIPPED)]
    seconds = sum(r.get("seconds") or 0.0 for r in ok)
    scans = sum(r.get("scans") or 0 for r in ok)
    tracks = {k: sum((r.get("tracks") or {}).get(k, 0) for r in ok) for k in ("confirmed", *TRACK_CLASSES, "dynamic")}
    return {
        "inputs": len(records),
        "done": len(ok),
        "failed": sum(r["status"] == FAILED for r in records),
        "scans": scans,
        "task_seconds": round(seconds, 3),
        "scans_per_task_second": round(scans / seconds, 1) if seconds > 0 else None,
        "tracks": tracks,
        "versions": sorted({r.get("datmo_version") or "?" for r in records}),
        "params_hashes": sorted({r.get("params_hash") or "?" for r in records}),
        "missing_outputs": [r["output"] for r in ok if not exists(r["output"])],
        "failures": [{"input": r["input"], "error": r.get("error")} for r in records if r["status"] == FAILED],
    }


def read_batch(folder: str, *, with_left_out: bool = False) -> list[dict] | tuple[list[dict], int]:
    """The latest manifest line of every input of the batch in `folder`; InputError when it has none.

    Only lines whose output is inside `folder` count, each output once (its latest line): a manifest can be
    edited or copied, and a line naming a file elsewhere must not make the report read it, nor one output
    count as many. With `with_left_out`, (the lines, how many were left out)."""
    manifest = Manifest(folder)
    if not (exists(manifest.path) if remote(folder) else os.path.lexists(local(manifest.path))):
        raise InputError(f"{folder}: no {MANIFEST} (a batch folder is the -o folder of datmo run)")
    latest = list(manifest.latest().values())
    root = folder.rstrip("/") if remote(folder) else os.path.realpath(local(folder))
    by_output: dict[str, dict] = {}
    for rec in latest:
        out = rec.get("output")
        if not isinstance(out, str):
            continue
        key = out if remote(folder) else os.path.realpath(local(out))
        if _inside(key, root) and key != root:
            by_output.pop(key, None)
            by_output[key] = rec  # the latest line naming it, in file order
    kept = list(by_output.values())
    return (kept, len(latest) - len(kept)) if with_left_out else kept
