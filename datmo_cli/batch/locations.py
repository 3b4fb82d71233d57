"""Where a batch's inputs and outputs are: local paths and fsspec URLs (`file://` URLs are local paths; others,
`s3://...`, are read through fsspec), an input's size, mtime and SHA-256, and the temporary files an unfinished
write leaves beside its output."""

from __future__ import annotations

import glob
import hashlib
import os
from pathlib import Path

from ..errors import DatmoError, InputError


def remote(url: str) -> bool:
    """True for an fsspec URL that is not a local path (`s3://b/k`; not `file://` nor a plain path)."""
    return "://" in url and not url.startswith("file://")


def local(path: str) -> str:
    """A plain path for a local path or file:// URL."""
    return path[len("file://") :] if path.startswith("file://") else path


def fs_of(url: str):
    from ..extras import require

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
                fs, p = fs_of(pattern)
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
        from ..log.mcapio import sha256_of

        return sha256_of(local(path))
    fs, p = fs_of(path)
    h = hashlib.sha256()
    with fs.open(p, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
