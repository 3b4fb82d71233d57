"""Where a batch's inputs and outputs are: local paths and fsspec URLs (`file://` URLs are local paths; others,
`s3://...`, are read through fsspec), an input's size, mtime and SHA-256, and the temporary files an unfinished
write leaves beside its output."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from ..base.errors import DatmoError, InputError


def remote(url: str) -> bool:
    """True for an fsspec URL that is not a local path (`s3://b/k`; not `file://` nor a plain path)."""
    return "://" in url and not url.startswith("file://")


def local(path: str) -> str:
    """A plain path for a local path or file:// URL."""
    return path[len("file://") :] if path.startswith("file://") else path


def fs_of(url: str):
    from ..base.extras import require

    fsspec = require("fsspec", for_=f"{url}: reading a URL")
    try:
        return fsspec.core.url_to_fs(url)
    except (ImportError, ValueError) as exc:
        raise InputError(f"{url}: no fsspec driver for this URL ({exc})") from None


def join(folder: str, name: str) -> str:
    return f"{folder.rstrip('/')}/{name}" if remote(folder) else str(Path(local(folder)) / name)


def exists(path: str) -> bool:
    if remote(path):
        fs, p = fs_of(path)
        return fs.exists(p)
    return os.path.exists(local(path))


def inside(path: str, folder: str | None) -> bool:
    return folder is not None and (path == folder or path.startswith(folder.rstrip(os.sep) + os.sep))


def new_journal() -> str:
    """A new, empty journal file (mode 0600, in the system's temporary folder, removed on every way out) where
    a batch's tasks record the temporary files they make (outputs.journal_to)."""
    import tempfile

    from ..base.outputs import track

    fd, path = tempfile.mkstemp(prefix="datmo-run-", suffix=".journal")
    os.close(fd)
    track(Path(path))
    return path


def remove_recorded(journal: str | None) -> int:
    """Remove the temporary files and folders `journal` records as made and not kept that are still there
    (left by a task that was stopped, or a worker that died, mid-write); returns how many. Only those names:
    nothing else in an output's folder is looked at."""
    import json
    import shutil
    import stat

    if journal is None:
        return 0
    made: dict[str, None] = {}
    try:
        with open(journal, "rb") as f:
            for line in f:
                try:
                    sign, name = json.loads(line)
                except ValueError:
                    continue  # a line cut by a worker's death
                if sign == "+":
                    made[name] = None
                else:
                    made.pop(name, None)
    except OSError:
        return 0
    n = 0
    for name in made:
        try:
            if remote(name):
                fs, p = fs_of(name)
                if fs.exists(p):
                    fs.rm(p)
                    n += 1
                continue
            mode = os.lstat(name).st_mode
            if stat.S_ISDIR(mode):
                shutil.rmtree(name)
            else:
                os.unlink(name)
            n += 1
        except (OSError, DatmoError):
            pass
    return n


def input_stat(path: str) -> tuple[int | None, int | None]:
    """(size, mtime in ns) of an input, (None, None) when it cannot be seen; for a ROS 2 bag folder the size of
    its files in all and the latest mtime of the folder and its files."""
    try:
        if remote(path):
            fs, p = fs_of(path)
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
        from ..logs.mcapio import sha256_of

        return sha256_of(local(path))
    fs, p = fs_of(path)
    h = hashlib.sha256()
    with fs.open(p, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
