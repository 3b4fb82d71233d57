"""Safe outputs: the one place that decides whether a path may be written, and how.

Every command that writes a file goes through here (LogWriter, plots, leg models, manifests):

- `check_output` refuses what must not be replaced before any work: an existing output without --force,
  and, even with --force, anything but a regular file or a symlink (a folder, FIFO, device or socket). A
  symlink is replaced itself (the rename puts the new file where the link was); its target is never written.
  A missing or read-only folder, a name over the file system's limit (255 bytes) and an output that is
  an input are refused too, each with a one-line OutputError naming the path.
- The data goes to a temporary file beside the output (`.NAME.PID.N.tmp`, mode as umask allows), synced
  and renamed over the output only when complete (`commit`). Live temporary files are kept in a registry
  of this process; `remove_live` deletes them on every way out (errors, Ctrl-C, SIGTERM, SIGHUP, exit).
  Temporary files are only ever found by their names, never by a pattern: a batch's tasks also record each
  name in the batch's journal (`journal_to`, `note`), from which the batch removes what a dead worker left.
- `handle_signals` turns SIGTERM and SIGHUP into `Terminated` (a BaseException, like KeyboardInterrupt for
  SIGINT), so `with` blocks unwind and drop their temporary files; the CLI then exits 128 + the signal's
  number (130 Ctrl-C, 143 SIGTERM, 129 SIGHUP). A signal arriving inside `critical()` (creating, renaming or
  removing a temporary file) is held until the block ends, so the registry always matches the disk.
"""

from __future__ import annotations

import atexit
import errno
import os
import signal
import stat
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO

from .errors import OutputError, OutputExistsError

NAME_MAX = 255  # bytes in one file name on Linux file systems (used when pathconf cannot say)

_LIVE: dict[str, int] = {}  # temporary file -> pid of the process that made it
_LOCK = threading.Lock()
_COUNTER = [0]


class Terminated(BaseException):
    """SIGTERM or SIGHUP arrived: unwind, drop temporary files, exit 128 + signum."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    def __str__(self) -> str:
        return f"stopped by {signal.Signals(self.signum).name}"


# ------------------------------------------------------------------------------------------- signals

_state = {"depth": 0}
_PENDING: list[int] = []


def interrupt_in(exc: BaseException | None) -> BaseException | None:
    """The KeyboardInterrupt or Terminated that `exc` is, or stands for; else None.

    A signal handler can raise while a compiled (numba) call is boxing its result. CPython then reports a
    SystemError ("... returned a result with an exception set") caused by the interrupt: that is a stop
    request, not a bug, and is handled as the interrupt itself."""
    while exc is not None:
        if isinstance(exc, (KeyboardInterrupt, Terminated)):
            return exc
        if not isinstance(exc, SystemError):
            return None
        exc = exc.__cause__ or exc.__context__
    return None


def _raise_for(signum: int) -> None:
    if signum == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(signum)


RESEND_AFTER_S = 0.05


def must_not_raise(frame) -> bool:
    """Whether `frame` runs where an exception raised by a signal handler does harm:
    - inside a callback from native code (llvmlite's object cache callbacks, which numba's compiler calls while
      it compiles or loads a kernel): ctypes ignores the exception and LLVM is left broken (the process then
      dies of SIGSEGV);
    - in code that `exec` runs from a string, where the signal lands (dataclasses and namedtuples make their
      methods so, as modules are imported): a KeyboardInterrupt that leaves it makes CPython (3.11) end the
      process by SIGINT at exit, whatever exit code datmo chose (-2, not 130), even when the exception was caught.
      Only the innermost frame counts: `python -c` and pytest-xdist's workers run everything below such a frame."""
    if frame is not None and frame.f_code.co_filename == "<string>" and frame.f_back is not None:
        return True
    while frame is not None:
        if "llvmlite" in frame.f_code.co_filename:
            return True
        frame = frame.f_back
    return False


def _handler(signum: int, frame) -> None:
    if _state["depth"]:
        _PENDING.append(signum)
        return
    if must_not_raise(frame):  # such code is short: the same signal again, a moment later
        threading.Timer(RESEND_AFTER_S, os.kill, (os.getpid(), signum)).start()
        return
    _raise_for(signum)


@contextmanager
def critical() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP (as handled by `handle_signals`) until the block ends."""
    _state["depth"] += 1
    try:
        yield
    finally:
        _state["depth"] -= 1
    if not _state["depth"] and _PENDING:
        signum = _PENDING[0]
        _PENDING.clear()
        _raise_for(signum)


HANDLED = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


@contextmanager
def handle_signals() -> Iterator[None]:
    """Within the block (main thread only): SIGINT raises KeyboardInterrupt, SIGTERM and SIGHUP raise
    Terminated, except inside `critical()`; the previous handlers are restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {}
    for sig in HANDLED:
        try:
            old[sig] = signal.signal(sig, _handler)
        except (OSError, ValueError):
            pass
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


# ------------------------------------------------------------------------------------------- checks


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "directory"),
        (stat.S_ISFIFO, "FIFO"),
        (stat.S_ISCHR, "character device"),
        (stat.S_ISBLK, "block device"),
        (stat.S_ISSOCK, "socket"),
    ):
        if test(mode):
            return name
    return "special file"


def name_max(folder: Path) -> int:
    """The longest file name (bytes) `folder`'s file system takes."""
    try:
        return int(os.pathconf(folder, "PC_NAME_MAX"))
    except (OSError, ValueError):
        return NAME_MAX


def folder_of(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.realpath(a) == os.path.realpath(b) or os.path.abspath(a) == os.path.abspath(b)
    except (OSError, ValueError):
        return False


def check_replaceable(path: Path, force: bool, what: str = "output") -> None:
    """Refuse to replace what is at `path`: anything without `force`; with it, all but a regular file or a
    symlink (replaced itself, never written through)."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise os_error(exc, path) from None
    if stat.S_ISREG(st.st_mode) or stat.S_ISLNK(st.st_mode):
        if not force:
            raise OutputExistsError(f"{path}: exists; use --force to overwrite it")
        return
    if stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{path}: is a directory; give a file name for the {what}")
    raise OutputError(
        f"{path}: is a {_kind(st.st_mode)}, not a regular file; datmo replaces only regular files (even with --force)"
    )


def check_folder(folder: Path) -> None:
    """Refuse a missing, non-folder or read-only output folder (one line naming it)."""
    try:
        st = os.stat(folder)
    except FileNotFoundError:
        raise OutputError(f"{folder}: output folder does not exist") from None
    except OSError as exc:
        raise os_error(exc, folder) from None
    if not stat.S_ISDIR(st.st_mode):
        raise OutputError(f"{folder}: is not a folder")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(f"{folder}: output folder is not writable ({_why_not_writable(folder)})")


def _why_not_writable(folder: Path) -> str:
    try:
        if os.statvfs(folder).f_flag & os.ST_RDONLY:
            return "read-only file system"
    except OSError:
        pass
    return "permission denied"


def check_output(
    path: str | Path, *, force: bool = False, inputs: Iterable[str | Path] = (), what: str = "output"
) -> Path:
    """`path` as a Path when it may be written (see the module docstring); else OutputError (or
    OutputExistsError) naming it. `inputs`: files the output must not be."""
    raw = os.fspath(path)
    if not raw or raw.endswith(os.sep) or Path(raw).name in ("", ".", ".."):
        raise OutputError(f"{raw or repr(raw)}: names a folder; give a file name for the {what}")
    p = Path(raw)
    folder = folder_of(p)
    size = len(os.fsencode(p.name))
    if size > name_max(folder if folder.is_dir() else Path(".")):
        raise OutputError(f"{p}: file name too long ({size} bytes; at most {name_max(Path('.'))})")
    check_replaceable(p, force, what)
    for inp in inputs:
        if os.path.lexists(inp) and _same(Path(inp), p):
            raise OutputError(f"{p}: the output would overwrite the input")
    check_folder(folder)
    return p


# ------------------------------------------------------------------------------------- error messages

_REASONS = {
    errno.ENOSPC: "no space left on the device",
    errno.EDQUOT: "disk quota exceeded",
    errno.EFBIG: "file too large for the file-size limit (ulimit -f)",
    errno.EROFS: "read-only file system",
    errno.EACCES: "permission denied",
    errno.EPERM: "operation not permitted (an immutable or protected file or folder)",
    errno.ENAMETOOLONG: "file name too long",
    errno.EIO: "input/output error",
    errno.ENOENT: "no such file or folder",
    errno.ENOTDIR: "a part of the path is not a folder",
    errno.EISDIR: "is a directory",
    errno.ELOOP: "too many levels of symbolic links",
    errno.EXDEV: "on another file system",
}


def reason(exc: OSError) -> str:
    """A short phrase for an OSError (no errno number)."""
    return _REASONS.get(exc.errno if exc.errno is not None else -1, exc.strerror or str(exc))


def os_error(exc: OSError, path: str | Path | None = None, doing: str = "") -> OutputError:
    """An OutputError of one line for `exc`: 'PATH: reason (doing)'."""
    where = path if path is not None else exc.filename
    text = reason(exc) + (f" ({doing})" if doing else "")
    return OutputError(f"{os.fsdecode(where)}: {text}" if where is not None else text)


@contextmanager
def writing(path: str | Path) -> Iterator[None]:
    """Turn an OSError raised in the block into an OutputError naming `path` (e.g. the disk full)."""
    try:
        yield
    except OSError as exc:
        raise os_error(exc, path, "writing it") from exc


class Guarded:
    """A file object whose write errors (the disk full, the file-size limit) are OutputErrors naming `path`,
    the output it will become, rather than OSErrors naming nothing or the temporary file."""

    def __init__(self, file: IO, path: Path) -> None:
        self._file = file
        self._path = path

    def write(self, data) -> int:
        with writing(self._path):
            return self._file.write(data)

    def flush(self) -> None:
        with writing(self._path):
            self._file.flush()

    def close(self) -> None:
        with writing(self._path):
            self._file.close()

    def __getattr__(self, name: str):
        return getattr(self._file, name)


# ------------------------------------------------------------------------------------ temporary files


def temp_path(path: Path) -> Path:
    """A new temporary name beside `path`: .NAME.PID.N.tmp, NAME shortened to fit the name limit."""
    with _LOCK:
        _COUNTER[0] += 1
        n = _COUNTER[0]
    tail = f".{os.getpid()}.{n}.tmp"
    budget = name_max(folder_of(path)) - 1 - len(tail)
    name = os.fsencode(path.name)[: max(budget, 1)]
    return folder_of(path) / os.fsdecode(b"." + name + tail.encode())


_JOURNAL = threading.local()  # .path: where this thread records the temporary files it makes (a batch's)


def journal_to(path: str | None) -> None:
    """Record, from now on in this thread, the name of every temporary file (or folder) made and kept in the
    journal file `path` (None: stop), so that a batch removes exactly the temporary files its tasks made even
    when a worker dies without removing its own (`journal.remove_recorded`)."""
    _JOURNAL.path = path


def note(sign: str, tmp: str | Path) -> None:
    """Append `tmp` to this thread's journal: made ("+") or kept ("-": it stays on disk); one JSON line, written
    in one append. A journal that cannot be written (a worker on another machine) records nothing."""
    path = getattr(_JOURNAL, "path", None)
    if path is None:
        return
    import json

    line = (json.dumps([sign, os.fsdecode(tmp)]) + "\n").encode("utf-8", "surrogateescape")
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return
    try:
        os.write(fd, line)
    except OSError:
        pass
    finally:
        os.close(fd)


def track(tmp: Path) -> None:
    """Register a temporary file made elsewhere (e.g. a symlink), so it is removed on every way out."""
    _LIVE[os.fspath(tmp)] = os.getpid()
    note("+", tmp)


def forget(tmp: str | Path) -> None:
    """Stop tracking `tmp`: it stays on disk (a recording kept, or one that could not be renamed into place)."""
    _LIVE.pop(os.fspath(tmp), None)
    note("-", tmp)


def interrupt(signum: int) -> None:
    """Act on `signum` as `handle_signals` does (held inside `critical()`): for a handler of one's own that
    passes a signal on, e.g. record's second Ctrl-C."""
    _handler(signum, None)


def _file_for(fd: int, mode: str) -> IO:
    """The file object of a temporary file's descriptor (tests replace this to inject write failures)."""
    return os.fdopen(fd, mode)


def open_temp(path: Path, mode: str = "wb") -> tuple[Path, IO]:
    """Create and register a temporary file beside `path`; (its path, the open file)."""
    folder = folder_of(path)
    with critical():
        tmp = temp_path(path)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
        except OSError as exc:
            where = path if exc.errno == errno.ENAMETOOLONG else folder
            raise os_error(exc, where, "creating a file there") from None
        track(tmp)
    try:
        return tmp, _file_for(fd, mode)
    except BaseException:
        os.close(fd)
        discard(tmp)
        raise


def commit(tmp: Path, path: Path, force: bool) -> None:
    """Rename the complete `tmp` over `path` (checked again: it may have appeared while writing)."""
    try:
        check_replaceable(path, force)
    except BaseException:
        discard(tmp)
        raise
    with critical():
        try:
            os.replace(tmp, path)
        except OSError as exc:
            _unlink(tmp)
            raise os_error(exc, path, "renaming the finished file into place") from None
        _LIVE.pop(os.fspath(tmp), None)


def _unlink(tmp: str | Path) -> None:
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass
    except OSError:
        return
    _LIVE.pop(os.fspath(tmp), None)


def discard(tmp: str | Path) -> None:
    """Remove a temporary file (and forget it)."""
    with critical():
        _unlink(tmp)


def live() -> list[str]:
    """This process's temporary files not yet renamed or removed."""
    pid = os.getpid()
    return [t for t, p in list(_LIVE.items()) if p == pid]


def remove_live() -> int:
    """Remove this process's live temporary files (a forked worker leaves its parent's alone)."""
    gone = live()
    with critical():
        for t in gone:
            _unlink(t)
    return len(gone)


atexit.register(remove_live)


@contextmanager
def atomic_output(
    path: str | Path, *, force: bool = False, mode: str = "wb", inputs: Iterable[str | Path] = (), what: str = "output"
) -> Iterator[IO]:
    """An open temporary file for `path` (checked by check_output); renamed over `path` when the block ends
    without an error, removed otherwise. Write errors become one-line OutputErrors naming `path`."""
    p = check_output(path, force=force, inputs=inputs, what=what)
    tmp, f = open_temp(p, mode)
    try:
        with writing(p):
            yield f
            f.flush()
            os.fsync(f.fileno())
            f.close()
        commit(tmp, p, force)
    except BaseException:
        try:
            f.close()
        except OSError:
            pass
        discard(tmp)
        raise
