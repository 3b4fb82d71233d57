"""The MCAP record writer under LogWriter: header, schemas and channels (outside chunks), messages in zstd
chunks of their channel's group, metadata, and the summary (schemas, channels, statistics, chunk and metadata
indexes, summary offsets) with the footer, as the MCAP spec lays them out; mcap's record classes serialise the
records other than messages.

Unlike mcap's Writer, which fills one chunk with every channel's messages in the order they come, each group
of channels (a channel alone unless it is given a group) fills chunks of its own, so a chunk holds messages of
one kind, which compress far better than CDR floats of several message types mixed in one zstd stream. A
group's chunk ends when it holds `chunk_size` bytes, or at `end_block` once it has been open for `span` blocks,
or at `flush`/`finish`. A file written so has chunks that overlap in time: MCAP readers that read in log-time
order merge them by the chunk indexes, and datmo's own (mcap_reader.iter_stretches) by the chunk start times.

Time order without the index (`seconds` > 0): messages added in log-time order are taken in windows of
`seconds` of log time, and every window goes into one stream of chunks, a window after another (in a window,
the groups' messages a group after another, each in the order added, so zstd meets runs of one message type);
a chunk ends at the first window's end at which it holds `chunk_size` bytes. So a reader that reads the file
from start to end without its index (a pipe, a cut download, `mcap cat` without the summary) meets no message
more than `seconds` of log time after a later one. One stream of large chunks keeps the history zstd matches
against (the scans of the windows before) that chunks of one channel and one window would lose: measured on
`datmo run`'s outputs (level 9), chunks of 32 MiB in one stream are 0.0 % (the simulated hall) to +3 % (a 5 Hz
patrol) larger than chunks by channel of 4 MiB without the bound, where chunks by channel cut at each window
were +7 % and +11 % (docs/performance.md). A chunk of up to SMALL bytes (the last, a short log's) is compressed
with zstd's parameters for 256 KB inputs at its level (the ones zstd picks itself below 256 KB).
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from typing import BinaryIO

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Channel,
    Chunk,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MessageIndex,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)

MAGIC = b"\x89MCAP0\r\n"
SMALL = 512 << 10  # bytes: a chunk up to this size is compressed with the parameters for 256 KB inputs
_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log time, publish time


@dataclass
class _OpenChunk:
    """The messages of a chunk in progress: (log time, channel id, record head, data), in the order added."""

    records: list[tuple[int, int, bytes, bytes]] = field(default_factory=list)
    size: int = 0
    blocks: int = 0  # end_block calls since it opened

    def add(self, log_time: int, channel_id: int, head: bytes, data: bytes) -> None:
        self.records.append((log_time, channel_id, head, data))
        self.size += len(head) + len(data)


class ChunkWriter:
    """Writes an MCAP file into `stream` (see the module docstring); `level`: zstd's compression level;
    `seconds`: the log time a window covers (0: no windows, chunks by group only)."""

    def __init__(
        self, stream: BinaryIO, *, chunk_size: int, level: int = 3, span: int = 0, seconds: float = 0.0
    ) -> None:
        import zstandard

        self._stream = stream
        self.chunk_size = chunk_size
        self.span = span  # blocks a chunk may stay open (0: no limit; not used with windows)
        self._reach = int(seconds * 1e9) if seconds > 0 else 0  # a window's log time, ns
        self._window_end: int | None = None  # log time (ns) at which the current window ends
        self._shared = _OpenChunk()  # the shared chunk in progress (windows only)
        self._zstd = zstandard.ZstdCompressor(level=level)
        small = zstandard.ZstdCompressionParameters.from_level(level, source_size=256 << 10)
        self._zstd_small = zstandard.ZstdCompressor(compression_params=small)
        self._schemas: list[Schema] = []
        self._channels: list[Channel] = []
        self._group_of: dict[int, int] = {}  # channel id -> group
        self._open: dict[int, _OpenChunk] = {}  # group -> its chunk in progress (groups in the order they opened)
        self._chunk_indexes: list[ChunkIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        self._stats = Statistics(
            message_count=0,
            schema_count=0,
            channel_count=0,
            attachment_count=0,
            metadata_count=0,
            chunk_count=0,
            message_start_time=0,
            message_end_time=0,
            channel_message_counts={},
        )

    def _record(self, record) -> int:
        """Write one record outside chunks; returns its offset."""
        builder = RecordBuilder()
        record.write(builder)
        at = self._stream.tell()
        self._stream.write(builder.end())
        return at

    def start(self, profile: str, library: str) -> None:
        self._stream.write(MAGIC)
        self._record(Header(profile=profile, library=library))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas.append(schema)
        self._stats.schema_count += 1
        self._record(schema)
        return schema.id

    def register_channel(
        self, topic: str, message_encoding: str, schema_id: int, metadata: dict[str, str], group: int | None = None
    ) -> int:
        """A new channel's id; its messages share chunks with the other channels of `group` (None: all the
        channels given no group share one)."""
        channel = Channel(
            id=len(self._channels) + 1,
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata=metadata,
        )
        self._channels.append(channel)
        self._group_of[channel.id] = -1 if group is None else group
        self._stats.channel_count += 1
        self._record(channel)
        return channel.id

    def add_message(self, channel_id: int, log_time: int, data: bytes, sequence: int) -> None:
        """One message (publish time = log time) into its group's chunk, which ends once it holds chunk_size
        (or, with windows, at the end of the window: the module docstring)."""
        if self._reach:
            if self._window_end is None:
                self._window_end = log_time + self._reach
            elif log_time >= self._window_end:
                self._end_window()
                self._window_end = log_time + self._reach
        group = self._group_of[channel_id]
        chunk = self._open.get(group)
        if chunk is None:
            chunk = self._open[group] = _OpenChunk()
        chunk.add(
            log_time, channel_id, _MESSAGE.pack(0x05, 22 + len(data), channel_id, sequence, log_time, log_time), data
        )
        stats = self._stats
        if not stats.message_count:
            stats.message_start_time = stats.message_end_time = log_time
        stats.message_start_time = min(stats.message_start_time, log_time)
        stats.message_end_time = max(stats.message_end_time, log_time)
        stats.message_count += 1
        stats.channel_message_counts[channel_id] = stats.channel_message_counts.get(channel_id, 0) + 1
        if chunk.size >= self.chunk_size:
            if self._reach:  # a window larger than a chunk: what it holds so far ends the stream's chunk
                self._end_window()
                self._write_shared()
            else:
                self._write(self._open.pop(group))

    def _end_window(self) -> None:
        """The window's messages into the shared chunk, a group after another (each group's in the order added);
        the shared chunk is written once it holds `chunk_size` bytes."""
        for group in list(self._open):
            for record in self._open.pop(group).records:
                self._shared.add(*record)
        if self._shared.size >= self.chunk_size:
            self._write_shared()

    def _write_shared(self) -> None:
        if self._shared.records:
            self._write(self._shared)
            self._shared = _OpenChunk()

    def end_block(self) -> None:
        """A block of the log was added: end the chunks open for `span` blocks (without windows)."""
        if self._reach:
            return
        for group in list(self._open):
            chunk = self._open[group]
            chunk.blocks += 1
            if self.span and chunk.blocks >= self.span:
                self._write(self._open.pop(group))

    def _write(self, chunk: _OpenChunk) -> None:
        """Write `chunk` as a Chunk record with its message indexes, and note its ChunkIndex."""
        index: dict[int, list[tuple[int, int]]] = {}  # channel -> (log time, offset)
        parts: list[bytes] = []
        offset = 0
        for log_time, cid, head, data in chunk.records:
            index.setdefault(cid, []).append((log_time, offset))
            parts += (head, data)
            offset += len(head) + len(data)
        start = min(r[0] for r in chunk.records)
        end = max(r[0] for r in chunk.records)
        data = b"".join(parts)
        compressed = (self._zstd_small if len(data) <= SMALL else self._zstd).compress(data)
        record = Chunk(
            message_start_time=start,
            message_end_time=end,
            uncompressed_size=len(data),
            uncompressed_crc=zlib.crc32(data),
            compression="zstd",
            data=compressed,
        )
        at = self._record(record)
        indexes = self._stream.tell()
        offsets = {}
        builder = RecordBuilder()
        for cid, entries in index.items():
            offsets[cid] = indexes + builder.count
            MessageIndex(channel_id=cid, records=entries).write(builder)
        self._stream.write(builder.end())
        self._chunk_indexes.append(
            ChunkIndex(
                message_start_time=start,
                message_end_time=end,
                chunk_start_offset=at,
                chunk_length=indexes - at,
                message_index_offsets=offsets,
                message_index_length=self._stream.tell() - indexes,
                compression="zstd",
                compressed_size=len(compressed),
                uncompressed_size=len(data),
            )
        )
        self._stats.chunk_count += 1

    def flush(self) -> None:
        """End every chunk in progress: with windows, the current window joins the shared chunk, which is
        written; without, the groups' chunks in the order they opened."""
        if self._reach:
            self._end_window()
            self._write_shared()
        for group in list(self._open):
            self._write(self._open.pop(group))

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        at = self._record(Metadata(name=name, metadata=data))
        self._metadata_indexes.append(MetadataIndex(offset=at, length=self._stream.tell() - at, name=name))
        self._stats.metadata_count += 1

    def finish(self) -> None:
        """End the chunks in progress and write the data end, the summary, the footer and the closing magic."""
        self.flush()
        self._record(DataEnd(data_section_crc=0))
        start = self._stream.tell()
        builder = RecordBuilder()
        offsets = []
        groups: list[tuple[Opcode, list]] = [
            (Opcode.SCHEMA, self._schemas),
            (Opcode.CHANNEL, self._channels),
            (Opcode.STATISTICS, [self._stats]),
            (Opcode.CHUNK_INDEX, self._chunk_indexes),
            (Opcode.METADATA_INDEX, self._metadata_indexes),
        ]
        for opcode, records in groups:
            if not records:
                continue
            first = builder.count
            for record in records:
                record.write(builder)
            offsets.append(
                SummaryOffset(group_opcode=opcode, group_start=start + first, group_length=builder.count - first)
            )
        offset_start = start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = builder.end()
        crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 20, start, offset_start), zlib.crc32(summary))
        self._stream.write(summary)
        self._record(Footer(summary_start=start, summary_offset_start=offset_start, summary_crc=crc))
        self._stream.write(MAGIC)
