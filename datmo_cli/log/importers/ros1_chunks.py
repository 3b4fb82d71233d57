"""ROS 1 bag chunks decompressed within bounds: rosbags' reader decompresses a bz2 or lz4 chunk whole, whatever
its header declares (a 12 KB bag can hold a chunk that decompresses to gigabytes). `bound_ros1_chunks` makes
its chunk reader decompress each chunk as a stream, to at most the uncompressed size the chunk's header
declares, and refuse a chunk that declares more than MAX_BAG_CHUNK_BYTES. A refused chunk raises rosbags'
ReaderError, which the importer reports as a bag it cannot read, naming the file."""

from __future__ import annotations

import functools
import os

MAX_BAG_CHUNK_BYTES = 256 << 20  # uncompressed bytes a ROS 1 bag chunk may declare: rosbag writes chunks of
# 768 KiB (its default chunk threshold) plus one message; more is damage or a decompression bomb, never read


class ChunkTooLarge(Exception):
    """A chunk declares, or decompresses to, more than it may."""


def decompress(compression: str, declared: int, data: bytes) -> bytes:
    """`data`, a chunk compressed by `compression` ("none", "bz2", "lz4"), decompressed to at most `declared`
    bytes (one more is read to tell that it holds more: ChunkTooLarge)."""
    if compression == "bz2":
        import bz2

        d = bz2.BZ2Decompressor()
        out = d.decompress(data, max_length=declared + 1)
    elif compression == "lz4":
        import lz4.frame

        d = lz4.frame.LZ4FrameDecompressor()
        out = d.decompress(data, max_length=declared + 1)
    else:
        out = data
    if len(out) > declared:
        raise ChunkTooLarge(f"a {compression} chunk decompresses to more than the {declared:,} bytes its header says")
    return out


def bound_ros1_chunks() -> None:
    """Replace rosbags' ROS 1 chunk reader by one whose decompression is bounded (see the module docstring);
    done once per process."""
    from rosbags.rosbag1 import reader as r1

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
        if declared > MAX_BAG_CHUNK_BYTES:
            raise r1.ReaderError(
                f"a chunk declares {declared:,} bytes uncompressed, more than a chunk may hold "
                f"({MAX_BAG_CHUNK_BYTES:,})"
            )
        return r1.Chunk(datasize, datapos, functools.partial(decompress, compression, declared))

    read_chunk.datmo_bounded = True  # type: ignore[attr-defined]
    r1.Reader.read_chunk = read_chunk  # type: ignore[method-assign]
