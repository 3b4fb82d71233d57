"""Bag chunks decompressed within bounds. rosbags' readers decompress a chunk whole, whatever its header
declares: a ROS 1 bag's bz2 or lz4 chunk, and a ROS 2 bag's MCAP member's zstd chunk whose frame states its
own size (a 12 KB bag can hold a chunk that decompresses to gigabytes). `bound_bag_chunks` makes both readers
decompress each chunk as a stream, to at most the uncompressed size the chunk's header declares, and refuse a
chunk that declares more than MAX_BAG_CHUNK_BYTES. A refused chunk raises ChunkTooLarge, which the importer
reports as a bag it cannot read, naming the file."""

from __future__ import annotations

import functools
import os
from pathlib import Path, PurePath

MAX_BAG_CHUNK_BYTES = 256 << 20  # uncompressed bytes a bag chunk may declare: rosbag writes chunks of 768 KiB
# (its default chunk threshold), rosbag2's MCAP storage of 4 MiB, plus one message; more is damage or a bomb


class ChunkTooLarge(Exception):
    """A chunk declares, or decompresses to, more than it may."""


def _check_declared(declared: int) -> None:
    if declared > MAX_BAG_CHUNK_BYTES:
        raise ChunkTooLarge(
            f"a chunk declares {declared:,} bytes uncompressed, more than a chunk may hold ({MAX_BAG_CHUNK_BYTES:,})"
        )


def _zstd(data: bytes, limit: int) -> bytes:
    import zstandard

    with zstandard.ZstdDecompressor().stream_reader(data) as reader:
        parts, got = [], 0
        while got < limit and (part := reader.read(limit - got)):
            parts.append(part)
            got += len(part)
    return b"".join(parts)


def decompress(compression: str, declared: int, data: bytes) -> bytes:
    """`data`, a chunk compressed by `compression` ("" or "none", "bz2", "lz4", "zstd"), decompressed to at most
    `declared` bytes (one more is read to tell that it holds more: ChunkTooLarge)."""
    _check_declared(declared)
    if compression == "bz2":
        import bz2

        out = bz2.BZ2Decompressor().decompress(data, max_length=declared + 1)
    elif compression == "lz4":
        import lz4.frame

        out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=declared + 1)
    elif compression == "zstd":
        out = _zstd(data, declared + 1)
    else:
        out = data
    if len(out) > declared:
        raise ChunkTooLarge(f"a {compression} chunk decompresses to more than the {declared:,} bytes its header says")
    return out


def bound_bag_chunks() -> None:
    """Make rosbags' ROS 1 chunk reader and ROS 2 MCAP chunk decompressors bounded (see the module docstring);
    done once per process."""
    from rosbags.rosbag1 import reader as r1
    from rosbags.rosbag2 import storage_mcap

    if getattr(r1.Reader.read_chunk, "datmo_bounded", False):
        return

    def read_chunk(self):
        header = r1.Header.read(self.bio, r1.RecordType.CHUNK)
        compression = header.get_string("compression")
        declared = header.get_uint32("size")
        datasize = r1.read_uint32(self.bio)
        datapos = self.bio.tell()
        self.bio.seek(datasize, os.SEEK_CUR)
        if compression not in ("none", "bz2", "lz4"):
            raise r1.ReaderError(f"Compression {compression!r} is not supported.")
        _check_declared(declared)
        return r1.Chunk(datasize, datapos, functools.partial(decompress, compression, declared))

    read_chunk.datmo_bounded = True  # type: ignore[attr-defined]
    r1.Reader.read_chunk = read_chunk  # type: ignore[method-assign]
    for name in ("lz4", "zstd"):
        storage_mcap.DECOMPRESSORS[name] = functools.partial(_mcap_chunk, name)
    from rosbags.rosbag2 import reader as r2

    r2.zstd = _BoundedZstd(r2.zstd)  # type: ignore[assignment]


# A ROS 2 bag member compressed whole (compression_mode: file), which rosbags decompresses into a temporary
# folder, decompresses to at most MAX_BAG_FILE_RATIO times its size plus 64 MiB, and at most MAX_BAG_FILE_BYTES
# (zstd makes a bag 2 to 10 times smaller; a bomb of 1,000 times more would fill the disk)
MAX_BAG_FILE_RATIO = 1000
MAX_BAG_FILE_BYTES = 64 << 30


class _BoundedZstd:
    """rosbags' zstd module with `open` reading at most the bound above from a member (ChunkTooLarge past it)."""

    def __init__(self, module) -> None:
        self._module = module

    def __getattr__(self, name: str):
        return getattr(self._module, name)

    def open(self, file, mode: str = "rb", **kwargs):
        try:
            size = os.fstat(file.fileno()).st_size
        except (AttributeError, OSError, ValueError):
            size = 0
        limit = min(MAX_BAG_FILE_BYTES, MAX_BAG_FILE_RATIO * size + (64 << 20))
        return _Limited(self._module.open(file, mode, **kwargs), limit, getattr(file, "name", "a member"))


class _Limited:
    """A file read at most `limit` bytes: ChunkTooLarge when it holds more."""

    def __init__(self, file, limit: int, name: str) -> None:
        self._file, self._left, self._limit, self._name = file, limit, limit, name

    def read(self, size: int = -1) -> bytes:
        want = self._left + 1 if size is None or size < 0 else min(size, self._left + 1)
        data = self._file.read(want)
        self._left -= len(data)
        if self._left < 0:
            raise ChunkTooLarge(
                f"{os.fsdecode(self._name)}: decompresses to more than {self._limit:,} bytes "
                f"({MAX_BAG_FILE_RATIO:,} times its size plus 64 MiB, at most {MAX_BAG_FILE_BYTES:,})"
            )
        return data

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self._file.close()

    def __getattr__(self, name: str):
        return getattr(self._file, name)


def _mcap_chunk(compression: str, data: bytes, declared: int) -> bytes:
    return decompress(compression, declared, data)


MAX_BAG_METADATA_BYTES = 16 << 20  # a ROS 2 bag's metadata.yaml: a few kilobytes a topic and a file


def check_bag_folder(folder: Path) -> None:
    """Refuse, in one line naming the path, a ROS 2 bag folder whose metadata.yaml or a member it lists is not
    a regular file (a FIFO would hang rosbags' read, /dev/zero never end) or whose metadata.yaml is over
    MAX_BAG_METADATA_BYTES; before rosbags opens any of them."""
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    from ...base.input_files import check, read_text

    text = read_text(folder / "metadata.yaml", MAX_BAG_METADATA_BYTES, "bag's metadata.yaml")
    try:
        doc = YAML(typ="safe").load(text)
    except (YAMLError, ValueError, RecursionError):
        return  # rosbags says what is wrong with it
    info = doc.get("rosbag2_bagfile_information") if isinstance(doc, dict) else None
    names = info.get("relative_file_paths") if isinstance(info, dict) else None
    for name in names if isinstance(names, list) else ():
        check(folder / PurePath(str(name)).name)  # where rosbags looks for it
