"""Files the user names for reading (logs, bags, leg models, scene files, --config, --gt, a batch's manifest):
the one check every reader makes before it opens one, and reads of text files bounded by what a sane file of
its kind holds.

datmo reads regular files only (and folders where a reader takes one, such as a ROS 2 bag folder). A FIFO
blocks its reader until something writes into it, and a device such as /dev/zero never ends: each is refused
in one line naming the path and what it is, never opened for reading (`open_regular` opens without blocking
and checks again what it opened, so a FIFO put in the file's place between the check and the open is refused
too). A text input read whole is refused, before it is read, when it is larger than its kind's limit
(MAX_CONFIG_BYTES, MAX_GROUND_TRUTH_BYTES, MAX_MANIFEST_BYTES), so no input makes datmo read until memory
runs out.
"""

from __future__ import annotations

import errno
import os
import stat
from typing import BinaryIO

from .errors import InputError

MAX_CONFIG_BYTES = 1 << 20  # a TOML file of parameters: two tables of a few dozen keys
MAX_GROUND_TRUTH_BYTES = 256 << 20  # a ground-truth CSV: ~6 million rows of about 40 bytes
MAX_MANIFEST_BYTES = 4 << 30  # a batch's manifest: ~5 million lines of about 800 bytes
MAX_MANIFEST_LINE_BYTES = 1 << 20  # one manifest line (under a kilobyte; notes can add a few)


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "a special file"


def _shown(path: str | os.PathLike, name: str | None) -> str:
    return name if name is not None else os.fsdecode(path)


def _reason(exc: OSError) -> str:
    if exc.errno == errno.ENOENT:
        return "no such file"
    if exc.errno in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if exc.errno == errno.ENOTDIR:
        return "no such file (a part of the path is not a folder)"
    if exc.errno == errno.ELOOP:
        return "too many levels of symbolic links"
    if exc.errno == errno.ENAMETOOLONG:
        return "file name too long"
    return exc.strerror or str(exc)


def check(path: str | os.PathLike, *, folder_ok: bool = False, name: str | None = None) -> os.stat_result:
    """The stat of `path` when datmo may read it: a regular file (or, with `folder_ok`, a folder); else
    InputError naming it (`name`, when given, instead of the path): no such file, permission denied, a folder,
    a FIFO, a device or a socket. Symbolic links are followed (a link to a log is that log)."""
    shown = _shown(path, name)
    try:
        st = os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ENOENT and os.path.islink(path):
            raise InputError(
                f"{shown}: a symbolic link to {os.fsdecode(os.readlink(os.fspath(path)))}, which does not exist"
            ) from None
        raise InputError(f"{shown}: {_reason(exc)}") from None
    except ValueError as exc:  # a NUL byte in the name
        raise InputError(f"{shown}: not a usable file name ({exc})") from None
    if stat.S_ISDIR(st.st_mode):
        if folder_ok:
            return st
        raise InputError(f"{shown}: is a directory, not a file")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{shown}: is {_kind(st.st_mode)}, not a regular file; datmo reads only regular files")
    if not os.access(path, os.R_OK):
        raise InputError(f"{shown}: permission denied")
    return st


def open_regular(path: str | os.PathLike, *, name: str | None = None) -> BinaryIO:
    """`path` opened for reading in binary, when `check` accepts it as a regular file (InputError otherwise).
    The file is opened without blocking (a FIFO's open would wait for a writer) and what was opened is
    checked again."""
    check(path, name=name)
    shown = _shown(path, name)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise InputError(f"{shown}: {_reason(exc)}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(f"{shown}: is {_kind(st.st_mode)}, not a regular file; datmo reads only regular files")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bytes(path: str | os.PathLike, limit: int, what: str, *, name: str | None = None) -> bytes:
    """The whole of regular file `path`, at most `limit` bytes: a larger file is refused (InputError naming it,
    its size and the limit of a `what`, e.g. "configuration file") before it is read."""
    shown = _shown(path, name)
    with open_regular(path, name=name) as f:
        size = os.fstat(f.fileno()).st_size
        data = f.read(limit + 1) if size <= limit else b""
    if size > limit or len(data) > limit:
        raise InputError(f"{shown}: {max(size, len(data)):,} bytes; a {what} is at most {limit:,} bytes")
    return data


def read_text(path: str | os.PathLike, limit: int, what: str, *, name: str | None = None) -> str:
    """The whole of regular text file `path` as UTF-8, at most `limit` bytes (read_bytes); text that is not
    UTF-8 is an InputError naming the file and the byte."""
    data = read_bytes(path, limit, what, name=name)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{_shown(path, name)}: not UTF-8 text (byte {exc.start}), not a {what}") from None


def is_regular(path: str | os.PathLike) -> bool:
    """Whether `path` is (or links to) a regular file (no exception; for a reader deciding what to try)."""
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except (OSError, ValueError):
        return False


__all__ = [
    "MAX_CONFIG_BYTES",
    "MAX_GROUND_TRUTH_BYTES",
    "MAX_MANIFEST_BYTES",
    "MAX_MANIFEST_LINE_BYTES",
    "check",
    "is_regular",
    "open_regular",
    "read_bytes",
    "read_text",
]
