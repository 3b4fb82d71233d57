"""OUT_DIR/manifest.jsonl, a batch's ledger: its lines (one per input each time a batch finishes it), the
statuses they hold, the check of their fields, and the figures of a batch folder read from it (`datmo report
DIR`)."""

from __future__ import annotations

import errno
import json
import math
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from ..base.errors import InputError
from .locations import exists, fs_of, inside, join, local, remote

MANIFEST = "manifest.jsonl"


DONE, FAILED, SKIPPED, CANCELLED = "done", "failed", "skipped", "cancelled"
TRACK_CLASSES = ("person", "circle_object", "rectangular_object", "unknown")


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
        from ..base.input_files import MAX_MANIFEST_BYTES

        if self._remote:
            fs, p = fs_of(self.path)
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
        from ..base.input_files import open_regular

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
            from ..base.errors import OutputError

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
        from ..base.outputs import atomic_output

        with atomic_output(p, force=True, what="manifest") as f:
            f.write("".join(lines).encode("utf-8"))

    def append(self, record: dict) -> None:
        line = json.dumps(record, sort_keys=True) + "\n"
        with self._lock:
            if self._remote:
                self._lines.append(line)
                self._put()
                return
            from ..base.outputs import writing

            with writing(local(self.path)), self._open_for_append() as f:
                f.write(line.encode("utf-8"))
                f.flush()
                os.fsync(f.fileno())

    def _open_for_append(self):
        """The local manifest opened to append, never through a symbolic link (O_NOFOLLOW) nor into a FIFO
        or a device (opened without blocking, then checked)."""
        import stat

        from ..base.errors import OutputError

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
            fs, p = fs_of(self.path)
            fs.pipe_file(p, "".join(self._lines).encode())
            self._last_put = time.monotonic()


def _lines_of(f, limit: int) -> Iterator[bytes]:
    """The lines of binary file `f`, up to `limit` bytes in all; a line longer than MAX_MANIFEST_LINE_BYTES is
    passed over without being held (it is no manifest line)."""
    from ..base.input_files import MAX_MANIFEST_LINE_BYTES

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
    "output_sha256": (_or_none(_text), "a string or null"),
    "output_size": (_or_none(_count), "a whole number of bytes or null"),
    "output_mtime_ns": (
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


SUMMARY_KEY = "summary"  # a done line's report (report.RunSummary) as the task returns it; not in the manifest


def manifest_line(rec: dict) -> dict:
    """`rec` as the manifest keeps it: without the report a task returns with it."""
    return {k: v for k, v in rec.items() if k != SUMMARY_KEY}


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
        if inside(key, root) and key != root:
            by_output.pop(key, None)
            by_output[key] = rec  # the latest line naming it, in file order
    kept = list(by_output.values())
    return (kept, len(latest) - len(kept)) if with_left_out else kept
