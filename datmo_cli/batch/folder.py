"""A batch's output folder: made and resolved (`out_folder`), and held by one `datmo run` at a time
(`folder_lock`)."""

from __future__ import annotations

import os
import socket
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

from ..base.errors import DatmoError, InputError
from .locations import local, remote


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
        from ..base.outputs import os_error

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

    from ..base.errors import OutputError

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
                from ..base.outputs import os_error

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
