"""Reading MCAP logs: a linear record scanner over the mapped file that yields the messages of the topics asked
for and fills a LogContents with every channel (message counts, time ranges) and metadata record.

`iter_stretches` gives the messages a chunk at a time, each stretch with the earliest log time of the chunks
after it in the file: how a reader of a file whose chunks overlap in time (datmo writes each channel in
chunks of its own) knows when it has every message before a time.

The scanner is fast, and it recovers every complete chunk of a truncated file. Each chunk's CRC-32 and size are
checked before its records are parsed: a corrupt chunk is skipped, counted and warned about, never decoded.
Log times are int64 nanoseconds.
"""

from __future__ import annotations

import mmap
import struct
import warnings
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from ..base.errors import InputError

MAGIC = b"\x89MCAP0\r\n"

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
_OP_CHUNK, _OP_METADATA, _OP_DATA_END, _OP_STATISTICS = 0x06, 0x0C, 0x0F, 0x0B
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
_MSG_HEAD = struct.Struct("<HIQQ")


class TruncatedLogWarning(UserWarning):
    """A log ended mid-record; every complete chunk before that point was read."""


class CorruptLogWarning(UserWarning):
    """Chunks of a log failed their CRC or did not decompress; they were skipped, the others read."""


@dataclass
class Channel:
    """One channel of a log: topic, message type and what the file holds of it."""

    id: int
    topic: str
    msgtype: str
    message_encoding: str
    schema_encoding: str
    schema_data: bytes
    metadata: dict[str, str]
    count: int = 0
    first_ns: int = 0
    last_ns: int = 0


@dataclass
class LogContents:
    """What a linear read of a log found. `messages[topic]` holds (log_time_ns, payload) for the
    topics that were asked for; channels always carry counts and time ranges."""

    path: Path
    profile: str = ""
    library: str = ""
    channels: dict[int, Channel] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    messages: dict[str, tuple[list[int], list[bytes]]] = field(default_factory=dict)
    chunks: int = 0
    truncated: bool = False
    size: int = 0
    corrupt_chunks: int = 0  # chunks skipped: CRC mismatch, bad size or compressed data that does not decode
    corrupt_bytes: int = 0  # bytes of the file those chunks took
    corrupt_problem: str = ""  # what was wrong with the first of them, and where
    bad_length_at: int = 0  # byte of a record whose length runs past the end of a file that ends whole

    def topics(self) -> dict[str, Channel]:
        return {c.topic: c for c in self.channels.values()}

    def has(self, topic: str) -> bool:
        return any(c.topic == topic and c.count for c in self.channels.values())

    @property
    def start_ns(self) -> int:
        firsts = [c.first_ns for c in self.channels.values() if c.count]
        return min(firsts) if firsts else 0

    @property
    def end_ns(self) -> int:
        lasts = [c.last_ns for c in self.channels.values() if c.count]
        return max(lasts) if lasts else 0


def _check_input(path: Path) -> Path:
    from ..base.input_files import check

    path = Path(path)
    check(path, folder_ok=True)  # a regular file (or a folder, refused below): a FIFO or a device never ends
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not an MCAP log")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")
    return path


def _string(buf, pos: int) -> tuple[str, int]:
    n = _U32.unpack_from(buf, pos)[0]
    return bytes(buf[pos + 4 : pos + 4 + n]).decode("utf-8", "replace"), pos + 4 + n


def _map(buf, pos: int) -> tuple[dict[str, str], int]:
    n = _U32.unpack_from(buf, pos)[0]
    end = pos + 4 + n
    pos += 4
    out = {}
    while pos < end:
        k, pos = _string(buf, pos)
        v, pos = _string(buf, pos)
        out[k] = v
    return out, end


def read_log(path: str | Path, topics: Iterable[str] | None = ()) -> LogContents:
    """Read a log's channels, metadata and the payloads of `topics` (all topics when topics is None).

    Raises InputError for files that are not MCAP; warns TruncatedLogWarning (and returns every
    complete chunk) for a file cut short, CorruptLogWarning (and returns every sound chunk) for chunks
    whose CRC does not match or that do not decompress: their messages are never decoded.
    """
    out = LogContents(path=Path(path))
    messages = out.messages
    for topic, stamp, payload in _walk_file(path, topics, out):
        stamps, payloads = messages[topic]
        stamps.append(stamp)
        payloads.append(payload)
    return out


def iter_messages(
    path: str | Path, topics: Iterable[str] | None = None, contents: LogContents | None = None, *, warn: bool = True
) -> Iterator[tuple[str, int, bytes]]:
    """(topic, log time ns, payload) of every message on `topics` (all when None), in file order, one chunk
    in memory at a time: how commands stream a log of any length. `contents`, when given, is filled with
    the channels and metadata met on the way (as read_log fills them). Errors as read_log; the warning of
    a truncated file only with `warn` (a second pass over a file need not say it again)."""
    out = contents if contents is not None else LogContents(path=Path(path))
    yield from _walk_file(path, topics, out, warn)


END_OF_TIME = (1 << 63) - 1


def iter_stretches(
    path: str | Path, topics: Iterable[str] | None = None, contents: LogContents | None = None, *, warn: bool = True
) -> Iterator[tuple[int, list[tuple[str, int, bytes]]]]:
    """(horizon, messages) for each chunk (or message outside chunks) of the file in file order: the chunk's
    messages on `topics` as iter_messages gives them (the list may be empty), and a log time that every
    message of the file after this chunk is at or after (from the chunks' headers; END_OF_TIME after the
    last). Arguments and errors as iter_messages."""
    out = contents if contents is not None else LogContents(path=Path(path))
    stretch: list[tuple[str, int, bytes]] = []
    for item in _walk_file(path, topics, out, warn, marks=True):
        if item[0] is _MARK:
            yield item[1], stretch
            stretch = []
        else:
            stretch.append(item)
    if stretch:
        yield END_OF_TIME, stretch


_MARK = "\0end of a chunk"  # a string no topic is (compared by identity)


def _horizons(buf) -> list[int]:
    """For each chunk or message record at the top of a mapped file, the earliest log time of those after it
    (chunk headers' start times; END_OF_TIME after the last); a damaged tail ends the list."""
    starts = []
    pos, end = 8, len(buf)
    while pos + 9 <= end:
        op, length = buf[pos], _U64.unpack_from(buf, pos + 1)[0]
        body = pos + 9
        if op == _OP_DATA_END or body + length > end:
            break
        if op == _OP_CHUNK and length >= 8:
            starts.append(_U64.unpack_from(buf, body)[0])
        elif op == _OP_MESSAGE and length >= 14:
            starts.append(_U64.unpack_from(buf, body + 6)[0])
        pos = body + length
    out = [END_OF_TIME] * len(starts)
    for i in range(len(starts) - 2, -1, -1):
        out[i] = min(out[i + 1], starts[i + 1])
    return out


def _walk_file(
    path: str | Path, topics: Iterable[str] | None, out: LogContents, warn: bool = True, marks: bool = False
) -> Iterator[tuple[str, int, bytes]]:
    path = _check_input(Path(path))
    out.path, out.size = path, path.stat().st_size
    with open(path, "rb") as f:
        try:
            buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        except ValueError as exc:
            raise InputError(f"{path}: cannot map file: {exc}") from None
        with buf:
            if buf[:8] != MAGIC:
                from .kind_hint import not_mcap

                raise InputError(f"{path}: not an MCAP file{not_mcap(path, buf[:65536])}")
            walk = _Walk(buf, out, None if topics is None else set(topics))
            if marks:
                walk.horizons = _horizons(buf)
            try:
                yield from walk.scan(buf, 8, len(buf), top=True)
                out.truncated = buf[-8:] != MAGIC or len(buf) < 16  # no footer: cut after the data
                if not out.truncated:
                    walk.count_missing_chunks()
            except _Truncated as exc:
                out.truncated = True
                if len(buf) >= 16 and buf[-8:] == MAGIC:  # the file ends as a whole one does: a corrupt length
                    out.bad_length_at = exc.args[0]
            except struct.error:
                raise InputError(
                    f"{path}: corrupt MCAP data (a record's fields run past the end of the file or chunk)"
                ) from None
            except (UnicodeDecodeError, ValueError) as exc:
                raise InputError(f"{path}: corrupt MCAP data ({exc})") from None
    if out.corrupt_chunks and warn:
        warnings.warn(
            f"{path}: skipped {out.corrupt_chunks} corrupt chunk(s) ({out.corrupt_bytes:,} bytes; first: "
            f"{out.corrupt_problem}); read the {out.chunks} sound chunk(s)",
            CorruptLogWarning,
            stacklevel=3,
        )
    if out.bad_length_at and warn:
        warnings.warn(
            f"{path}: the record at byte {out.bad_length_at} runs past the end of the file (a corrupt "
            f"length); read the {out.chunks} complete chunk(s) before it",
            CorruptLogWarning,
            stacklevel=3,
        )
    elif out.truncated and warn:
        warnings.warn(
            f"{path}: truncated MCAP file; read the {out.chunks} complete chunk(s) before the cut",
            TruncatedLogWarning,
            stacklevel=3,
        )


_RELEASE = 8 << 20  # give back the pages of a mapped file every 8 MB read
_MAX_LOG_TIME = (1 << 63) - 1  # ns; datmo keeps log times as int64 (a later time is a corrupt record)
_FOOTER = struct.Struct("<BQQQI")  # opcode, record length, summary start, summary offset start, summary CRC
_STATS_CHUNKS = struct.Struct("<QHIIII")  # a Statistics record's counts up to chunk_count


class _Truncated(Exception):
    pass


class _CorruptChunk(Exception):
    pass


MAX_CHUNK_BYTES = 256 << 20  # uncompressed bytes a chunk may declare: writers close a chunk at 1-32 MiB (datmo 1-32,
# rosbag2 0.75) plus one message; a declared size beyond this is damage or a decompression bomb, never read


def _chunk_records(buf, body: int, end: int) -> bytes | memoryview:
    """The records of the chunk whose body is buf[body:end], decompressed and checked against the chunk's
    uncompressed size and CRC-32 (0: none recorded); raises _CorruptChunk saying what is wrong. A chunk that
    declares more than MAX_CHUNK_BYTES is not decompressed, and no chunk decompresses to more than it declares
    (the memory a chunk takes is bounded before it is spent)."""
    import zstandard

    try:
        uncompressed, crc = _U64.unpack_from(buf, body + 16)[0], _U32.unpack_from(buf, body + 24)[0]
        compression, cpos = _string(buf, body + 28)
        size = _U64.unpack_from(buf, cpos)[0]
        if cpos + 8 + size > end:
            raise _CorruptChunk("its records run past its end")
        if uncompressed > MAX_CHUNK_BYTES:
            raise _CorruptChunk(
                f"declares {uncompressed:,} bytes uncompressed, more than a chunk may hold ({MAX_CHUNK_BYTES:,})"
            )
        data = buf[cpos + 8 : cpos + 8 + size]
        if compression == "zstd":
            data = _zstd(data, uncompressed)
        elif compression == "lz4":
            data = _lz4(data, uncompressed)
        elif compression:
            raise _CorruptChunk(f"unsupported compression {compression!r}")
        else:
            data = bytes(data)  # a copy: no view may outlive the mapped file
    except (struct.error, zstandard.ZstdError, RuntimeError, MemoryError, OverflowError, ValueError) as exc:
        raise _CorruptChunk(f"does not decompress ({exc})") from None
    if len(data) != uncompressed:
        raise _CorruptChunk(f"{len(data)} bytes uncompressed, its header says {uncompressed}")
    if crc and zlib.crc32(data) != crc:
        raise _CorruptChunk("CRC mismatch")
    return data


def _zstd(data, uncompressed: int) -> bytes:
    """A zstd frame decompressed to at most `uncompressed` bytes (one more tells that it holds more). Read as a
    stream: `ZstdDecompressor.decompress` allocates whatever size the frame itself states, which may be far
    more than the chunk's header declares."""
    import zstandard

    with zstandard.ZstdDecompressor().stream_reader(data) as reader:
        parts, got = [], 0
        while got <= uncompressed and (part := reader.read(uncompressed + 1 - got)):
            parts.append(part)
            got += len(part)
    if got > uncompressed:
        raise _CorruptChunk(f"decompresses to more than the {uncompressed:,} bytes its header says")
    return b"".join(parts)


def _lz4(data, uncompressed: int) -> bytes:
    """An lz4 frame decompressed to at most `uncompressed` bytes (one more tells that it holds more)."""
    import lz4.frame

    decompressor = lz4.frame.LZ4FrameDecompressor()
    out = decompressor.decompress(bytes(data), max_length=uncompressed + 1)
    if len(out) > uncompressed:
        raise _CorruptChunk(f"decompresses to more than the {uncompressed:,} bytes its header says")
    if not decompressor.eof:
        raise _CorruptChunk("its lz4 frame ends early")
    return out


class _Walk:
    """One linear read of a mapped log into `out`: the schemas met so far, which channels are wanted, and the
    summary section, read only when corruption calls for it."""

    def __init__(self, file, out: LogContents, want: set[str] | None) -> None:
        self.file, self.out, self.want = file, out, want
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.wanted_ids: set[int] = set()
        self.released = 0  # bytes of the mapped file given back to the system (see _RELEASE)
        self._summary: list[tuple[int, int]] | None = None
        self._recovered = False
        self.horizons: list[int] | None = None  # see _horizons: a mark is yielded after each chunk when set
        self.units = 0  # chunks and messages met at the top of the file

    def scan(self, buf, pos: int, end: int, top: bool) -> Iterator[tuple[str, int, bytes]]:
        """Walk the records in buf[pos:end], filling the channels and metadata and yielding (topic, log
        time, payload) of the wanted channels' messages."""
        out = self.out
        channels = out.channels
        while pos < end:
            if pos + 9 > end:
                raise _Truncated(pos)
            op = buf[pos]
            length = _U64.unpack_from(buf, pos + 1)[0]
            body = pos + 9
            pos = body + length
            if pos > end:
                raise _Truncated(body - 9)
            if op == _OP_MESSAGE:
                cid, _seq, log_time, _pub = _MSG_HEAD.unpack_from(buf, body)
                ch = channels.get(cid)
                if ch is None:
                    ch = self.recover_channel(cid)
                if log_time > _MAX_LOG_TIME:
                    raise ValueError(f"message log time {log_time} ns is past the year 2262")
                if ch.count == 0:
                    ch.first_ns = log_time
                ch.count += 1
                ch.last_ns = log_time
                if cid in self.wanted_ids:
                    yield ch.topic, log_time, bytes(buf[body + 22 : pos])
                if top and self.horizons is not None:
                    yield self.mark()
            elif op == _OP_CHUNK:
                try:
                    data = _chunk_records(buf, body, pos)
                except _CorruptChunk as exc:
                    if not out.corrupt_chunks:
                        out.corrupt_problem = f"the chunk at byte {body - 9}: {exc}"
                    out.corrupt_chunks += 1
                    out.corrupt_bytes += pos - body + 9
                else:
                    try:
                        yield from self.scan(memoryview(data), 0, len(data), top=False)
                    except _Truncated as exc:
                        raise ValueError(
                            f"the record at byte {exc.args[0]} of the chunk at byte {body - 9} runs "
                            "past the chunk's end"
                        ) from None
                    out.chunks += 1
                if self.horizons is not None:
                    yield self.mark()
                if top and isinstance(buf, mmap.mmap) and pos - self.released >= _RELEASE:
                    # pages of the file read so far leave this process's memory (a long log is not held whole)
                    upto = pos - pos % mmap.PAGESIZE
                    buf.madvise(mmap.MADV_DONTNEED, self.released, upto - self.released)
                    self.released = upto
            elif op in (_OP_SCHEMA, _OP_CHANNEL):
                self.define(op, buf, body)
            elif op == _OP_METADATA:
                name, p = _string(buf, body)
                meta, _ = _map(buf, p)
                out.metadata[name] = meta
            elif op == _OP_HEADER:
                out.profile, p = _string(buf, body)
                out.library, _ = _string(buf, p)
            elif op == _OP_DATA_END and top:
                return

    def mark(self) -> tuple[str, int, bytes]:
        """The end of a chunk (or message) at the top of the file, with the earliest time of those after it."""
        horizons = self.horizons or []
        at = horizons[self.units] if self.units < len(horizons) else END_OF_TIME
        self.units += 1
        return _MARK, at, b""

    def define(self, op: int, buf, body: int) -> None:
        """Register the schema or channel whose record body starts at buf[body] (a channel seen before stays)."""
        if op == _OP_SCHEMA:
            sid = _U16.unpack_from(buf, body)[0]
            name, p = _string(buf, body + 2)
            encoding, p = _string(buf, p)
            n = _U32.unpack_from(buf, p)[0]
            self.schemas[sid] = (name, encoding, bytes(buf[p + 4 : p + 4 + n]))
            return
        cid, sid = struct.unpack_from("<HH", buf, body)
        topic, p = _string(buf, body + 4)
        enc, p = _string(buf, p)
        meta, p = _map(buf, p)
        if cid not in self.out.channels:
            name, senc, sdata = self.schemas.get(sid, ("", "", b""))
            self.out.channels[cid] = Channel(cid, topic, name, enc, senc, sdata, meta)
            if self.want is None or topic in self.want:
                self.wanted_ids.add(cid)
                self.out.messages.setdefault(topic, ([], []))

    def recover_channel(self, cid: int) -> Channel:
        """The channel of a message whose definition was not met (it was in a corrupt chunk), from the summary
        section, which repeats every schema and channel; ValueError when the file has no sound summary."""
        if not self._recovered:
            self._recovered = True
            for op, body in self.summary_records():
                if op in (_OP_SCHEMA, _OP_CHANNEL):
                    self.define(op, self.file, body)
        ch = self.out.channels.get(cid)
        if ch is None:
            raise ValueError(f"message on unknown channel {cid}")
        return ch

    def summary_records(self) -> list[tuple[int, int]]:
        """(opcode, body offset) of the records of the file's summary section; none when the file has no
        footer, or its summary is damaged (CRC mismatch, a length past the footer)."""
        if self._summary is None:
            self._summary = []
            buf = self.file
            foot = len(buf) - 8 - _FOOTER.size
            if foot < 8 or buf[-8:] != MAGIC:
                return self._summary
            op, length, start, _, crc = _FOOTER.unpack_from(buf, foot)
            if op != _OP_FOOTER or length != _FOOTER.size - 9 or not 8 <= start <= foot:
                return self._summary
            if crc and zlib.crc32(buf[start : foot + _FOOTER.size - 4]) != crc:
                return self._summary
            records, pos = [], start
            while pos + 9 <= foot:
                op, length = buf[pos], _U64.unpack_from(buf, pos + 1)[0]
                if pos + 9 + length > foot:
                    return self._summary
                records.append((op, pos + 9))
                pos += 9 + length
            self._summary = records
        return self._summary

    def count_missing_chunks(self) -> None:
        """Count as corrupt the chunks the summary's statistics list beyond those met: a chunk whose record
        header was damaged is read as some other record and would otherwise vanish without a word."""
        for op, body in self.summary_records():
            if op == _OP_STATISTICS and body + _STATS_CHUNKS.size <= len(self.file):
                expected = _STATS_CHUNKS.unpack_from(self.file, body)[5]
                missing = expected - self.out.chunks - self.out.corrupt_chunks
                if missing > 0:
                    if not self.out.corrupt_chunks:
                        self.out.corrupt_problem = (
                            f"{missing} of the {expected} chunks the summary lists were not "
                            "found (a damaged record header)"
                        )
                    self.out.corrupt_chunks += missing


def summary(path: str | Path, *, warn: bool = True) -> LogContents:
    """Channels (with message counts and time ranges) and metadata of a log, without payloads. `warn`: say
    that the file is truncated or has corrupt chunks (the command that reads it next says it otherwise)."""
    out = LogContents(path=Path(path))
    for _ in _walk_file(path, (), out, warn):
        pass
    return out
