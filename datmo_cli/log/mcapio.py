"""The one module that owns MCAP: topic names, reading logs into arrays, and writing logs safely.

Reading uses a linear record scanner over the file (fast, and it recovers every complete chunk of a
truncated file). Each chunk's CRC-32 and size are checked before its records are parsed: a corrupt chunk is
skipped, counted and warned about, never decoded. Writing uses mcap's Writer with zstd chunks and the `ros2`
profile, so Foxglove and `ros2 bag` open the files; messages are CDR with their `ros2msg` schemas embedded.
"""

from __future__ import annotations

import hashlib
import json
import mmap
import os
import struct
import warnings
import zlib
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import __version__
from ..errors import GeometryError, InputError, MissingChannelError
from . import types
from .scan import GeometryChangeError, Odometry, ScanGeometry, ScanRun, decode_scans, encode_scan, encode_scans

TOPIC_SCAN = "/scan"
TOPIC_ODOM = "/odom"
TOPIC_SEGMENTS = "/datmo/segments"
TOPIC_FEATURES = "/datmo/features"
TOPIC_LANDMARKS = "/datmo/landmarks"
TOPIC_TRACKS = "/datmo/tracks"
TOPIC_GROUND_TRUTH = "/datmo/ground_truth"
TOPIC_MARKERS_FEATURES = "/datmo/markers/features"
TOPIC_MARKERS_TRACKS = "/datmo/markers/tracks"
TOPIC_TELEGRAM = "/lms2xx/telegram"
TOPIC_TF = "/tf"
TOPIC_TF_STATIC = "/tf_static"

MAGIC = b"\x89MCAP0\r\n"


def _qos_yaml(durability: int) -> str:
    """An offered QoS profile as rosbag2 records it in a channel's metadata (rmw's enums: history 3 and depth 0
    are what an offer reports; reliability 1 reliable; durability 1 transient-local, 2 volatile)."""
    return (
        f"- history: 3\n  depth: 0\n  reliability: 1\n  durability: {durability}\n"
        "  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n"
        "  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n"
        "  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n"
        "  avoid_ros_namespace_conventions: false\n"
    )


# Reliable and volatile, as rosbag2 records a topic of an ordinary publisher (a driver's /scan, /tf): `ros2 bag
# play` offers each topic with the recorded reliability and durability, which subscribers with the default QoS
# (RViz, tf2's /tf listener) accept, and a late subscriber is not sent old messages.
QOS_YAML = _qos_yaml(durability=2)
# Reliable and transient-local, for a latched topic (/tf_static): tf2's listener asks for transient-local, which
# a volatile offer cannot serve, and a late subscriber still gets the last message.
QOS_YAML_LATCHED = _qos_yaml(durability=1)

# Which command makes each derived channel: named in errors about missing channels.
PRODUCER = {
    TOPIC_SCAN: "datmo import, datmo simulate or datmo record",
    TOPIC_SEGMENTS: "datmo segment",
    TOPIC_FEATURES: "datmo features",
    TOPIC_LANDMARKS: "datmo features",
    TOPIC_TRACKS: "datmo track (or datmo run)",
    TOPIC_GROUND_TRUTH: "datmo simulate",
}

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
_OP_CHUNK, _OP_METADATA, _OP_DATA_END, _OP_STATISTICS = 0x06, 0x0C, 0x0F, 0x0B
_U16, _U32, _U64 = struct.Struct("<H"), struct.Struct("<I"), struct.Struct("<Q")
_MSG_HEAD = struct.Struct("<HIQQ")


class TruncatedLogWarning(UserWarning):
    """A log ended mid-record; every complete chunk before that point was read."""


class CorruptLogWarning(UserWarning):
    """Chunks of a log failed their CRC or did not decompress; they were skipped, the others read."""


# --------------------------------------------------------------------------------------------- reading


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
    from ..input_files import check

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


def read_log(path: str | Path, topics: Iterable[str] = ()) -> LogContents:
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


def _walk_file(
    path: str | Path, topics: Iterable[str] | None, out: LogContents, warn: bool = True
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
                raise InputError(f"{path}: not an MCAP file (bad magic bytes)")
            walk = _Walk(buf, out, None if topics is None else set(topics))
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


MAX_CHUNK_BYTES = 256 << 20  # uncompressed bytes a chunk may declare: writers close a chunk at 1-4 MiB (datmo 1,
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
            data = zstandard.ZstdDecompressor().decompress(data, max_output_size=uncompressed)
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


def read_messages(path: str | Path, topic: str, *, required: bool = True) -> tuple[np.ndarray, list[bytes]]:
    """(log times in ns as int64, payloads) of one topic, in file order."""
    log = read_log(path, topics=[topic])
    return _messages_of(log, topic, required)


def _messages_of(log: LogContents, topic: str, required: bool = True) -> tuple[np.ndarray, list[bytes]]:
    stamps, payloads = log.messages.get(topic, ([], []))
    if required and not payloads:
        maker = PRODUCER.get(topic)
        hint = f"; run {maker} first" if maker else ""
        raise MissingChannelError(f"{log.path}: no messages on {topic}{hint}")
    return np.array(stamps, np.int64), payloads


@contextmanager
def decoding(path: str | Path, topic: str) -> Iterator[None]:
    """Decode errors of `topic`'s messages (cdr.DecodeError: a damaged payload in a sound chunk) as one InputError
    naming the file and the topic."""
    from .cdr import DecodeError

    try:
        yield
    except DecodeError as exc:
        raise InputError(f"{path}: bad message on {topic}: {exc}") from None


def several_channels(log: LogContents, topic: str) -> str | None:
    """What is wrong when two channels of the log hold messages on `topic` (two streams, which a read by topic
    would interleave), else None."""
    on = [c for c in sorted(log.channels.values(), key=lambda c: c.id) if c.topic == topic and c.count]
    if len(on) < 2:
        return None
    which = ", ".join(f"id {c.id}: {c.count} {c.msgtype}" for c in on)
    return (
        f"{log.path}: {topic} is on {len(on)} channels ({which}); their messages would interleave into one "
        "stream: keep one channel, or give each its own topic"
    )


def check_scan_channel(log: LogContents, topic: str = TOPIC_SCAN) -> int:
    """The number of scans on `topic` (read or not); raises when it holds none or not CDR LaserScans, or when
    two channels of the file hold messages on it (two scan streams, which a read by topic would interleave)."""
    problem = several_channels(log, topic)
    if problem:
        raise InputError(problem)
    ch = log.topics().get(topic)
    if ch is not None and ch.count and ch.msgtype not in (types.LASERSCAN, "sensor_msgs/LaserScan"):
        raise InputError(f"{log.path}: {topic} holds {ch.msgtype}, not sensor_msgs/msg/LaserScan")
    if ch is not None and ch.count and ch.message_encoding != "cdr":
        raise InputError(f"{log.path}: {topic} is {ch.message_encoding}-encoded; convert it with datmo import")
    if ch is None or not ch.count:
        hint = f"; run {PRODUCER[topic]} first" if topic in PRODUCER else ""
        raise MissingChannelError(f"{log.path}: no messages on {topic}{hint}")
    return ch.count


def decode_scan_block(
    path: Path, payloads: list[bytes], first: int = 0, geometry: ScanGeometry | None = None, topic: str = TOPIC_SCAN
) -> ScanRun:
    """The ScanRun of a block of LaserScan payloads, scans first.. of the log at `path`; refuses a geometry
    that changes within the block or from `geometry` (the blocks' before)."""
    try:
        run = decode_scans(payloads, first)
    except GeometryChangeError as exc:
        raise GeometryError(f"{path}: {exc}; split the log before processing it") from None
    except ValueError as exc:
        raise InputError(f"{path}: bad LaserScan message on {topic}: {exc}") from None
    if geometry is not None and not run.geometry.same_beams(geometry):
        raise GeometryError(
            f"{path}: scan geometry changes at scan {first}: {geometry.describe()} -> "
            f"{run.geometry.describe()}; split the log before processing it"
        )
    return run


def run_from_log(log: LogContents, topic: str = TOPIC_SCAN) -> ScanRun:
    """The ScanRun of `topic` in an already-read log (see read_run)."""
    ch = log.topics().get(topic)
    if ch is not None and ch.count:
        check_scan_channel(log, topic)
    _, payloads = _messages_of(log, topic)
    try:
        return decode_scans(payloads)
    except GeometryChangeError as exc:
        raise GeometryError(f"{log.path}: {exc}; split the log before processing it") from None
    except ValueError as exc:
        raise InputError(f"{log.path}: bad LaserScan message on {topic}: {exc}") from None


def read_run(path: str | Path, topic: str = TOPIC_SCAN) -> ScanRun:
    """All scans of `topic` as one ScanRun. Refuses a run whose geometry changes."""
    return run_from_log(read_log(path, topics=[topic]), topic)


def odometry_from_log(log: LogContents, topic: str = TOPIC_ODOM) -> Odometry | None:
    """Odometry poses of an already-read log, or None when it has none on `topic`."""
    stamps, payloads = _messages_of(log, topic, required=False)
    if not payloads:
        return None
    store = types.typestore()
    xs, ys, ths = np.empty(len(payloads)), np.empty(len(payloads)), np.empty(len(payloads))
    frame = child = ""
    for i, p in enumerate(payloads):
        msg = store.deserialize_cdr(p, types.ODOMETRY)
        pose = msg.pose.pose
        q = pose.orientation
        xs[i], ys[i] = pose.position.x, pose.position.y
        ths[i] = np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        frame, child = msg.header.frame_id, msg.child_frame_id
    return Odometry(stamps, xs, ys, ths, frame or "odom", child or "base_link")


def read_odometry(path: str | Path, topic: str = TOPIC_ODOM) -> Odometry | None:
    """The log's odometry (world-frame poses of the sensor's base), or None when it has none."""
    return odometry_from_log(read_log(path, topics=[topic]), topic)


def encode_odometry(odom: Odometry) -> list[bytes]:
    """CDR payloads of nav_msgs/msg/Odometry, one per pose (planar: z = 0, yaw = theta)."""
    store = types.typestore()
    T = store.types
    out = []
    cov = np.zeros(36)
    for t, x, y, th in zip(odom.stamps, odom.x, odom.y, odom.theta, strict=True):
        stamp = T["builtin_interfaces/msg/Time"](sec=int(t // 1_000_000_000), nanosec=int(t % 1_000_000_000))
        header = T["std_msgs/msg/Header"](stamp=stamp, frame_id=odom.frame_id)
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](
                x=0.0, y=0.0, z=float(np.sin(th / 2)), w=float(np.cos(th / 2))
            ),
        )
        zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        msg = T[types.ODOMETRY](
            header=header,
            child_frame_id=odom.child_frame_id,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov
            ),
        )
        out.append(bytes(store.serialize_cdr(msg, types.ODOMETRY)))
    return out


# ---------------------------------------------------------------------------------------- provenance


def sha256_of(path: str | Path) -> str:
    """SHA-256 of a file, or of a directory's files (sorted by relative path) for ROS 2 bag folders."""
    path = Path(path)
    h = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for p in files:
        if path.is_dir():
            h.update(str(p.relative_to(path)).encode())
        with open(p, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


@dataclass
class Provenance:
    """What made a file: the command, its effective parameters and its inputs (hashed on write).
    `command_line`: the command line as the caller was started with it (default `datmo COMMAND`)."""

    command: str
    params: dict = field(default_factory=dict)
    inputs: list = field(default_factory=list)
    command_line: str | None = None
    names: list | None = None  # what the inputs are called in the records (e.g. the URL a local copy came from)

    def records(self) -> dict[str, dict[str, str]]:
        line = self.command_line if self.command_line is not None else f"datmo {self.command}"
        return {
            "datmo": {"tool": "datmo", "version": __version__, "command": self.command, "command_line": _text(line)},
            "datmo.params": {str(k): json.dumps(v, sort_keys=True, default=str) for k, v in self.params.items()},
            "datmo.inputs": {
                _text(str(name)): sha256_of(p) for name, p in zip(self.names or self.inputs, self.inputs, strict=True)
            },
        }


def _text(name: str) -> str:
    """`name` as valid UTF-8 text: the bytes of a file name that is not UTF-8 (os.fsdecode gives them as
    surrogates, which MCAP cannot store) as \\xNN escapes."""
    return os.fsencode(name).decode("utf-8", "backslashreplace")


# ---------------------------------------------------------------------------------------------- writing


class LogWriter:
    """Writes a datmo log safely: into a temporary file beside `path`, renamed when complete.

    Use as a context manager. Messages are buffered and written in log-time order on close
    (`streaming=True` writes them at once instead, for `record`, with `flush()` to push data to disk).
    `path` is checked by outputs.check_output (an existing file needs `force`; a folder, FIFO or device is
    never replaced; a symlink is replaced itself). On any error or signal, in the `with` block or in
    `close()`, the temporary file is removed; write errors are OutputErrors naming `path`. In streaming
    mode a failed `close()` leaves the temporary file for `keep_flushed` (removed at exit if not kept).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        force: bool = False,
        provenance: Provenance | None = None,
        streaming: bool = False,
        chunk_size: int = 1 << 20,
    ) -> None:
        from mcap.writer import CompressionType, Writer

        from .. import outputs

        self.path = outputs.check_output(path, force=force, inputs=provenance.inputs if provenance else ())
        self.force = force
        self._closed = False
        self.flushed = 0  # bytes of the temporary file known to be on disk, ending after a complete record
        self.kept = 0  # bytes kept in `path` by keep_flushed
        self._whole = False
        self._left: Exception | None = None
        self.tmp, file = outputs.open_temp(self.path)
        self._file = outputs.Guarded(file, self.path)  # a write error names the output, not the temporary file
        try:
            with outputs.writing(self.path):
                self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
                self._writer.start(profile="ros2", library=f"datmo {__version__}")
                self._streaming = streaming
                self._schemas: dict[str, int] = {}
                self._channels: dict[str, int] = {}
                self._buffer: list[tuple[np.ndarray, int, list[bytes]]] = []  # (stamps, channel id, payloads)
                self._seq = 0
                self.metadata: dict[str, dict[str, str]] = {}  # the metadata records written, by name
                if provenance is not None:
                    for name, data in provenance.records().items():
                        self._metadata(name, data)
        except BaseException:
            self.abort()
            raise

    # -- channels
    def channel(
        self,
        topic: str,
        msgtype: str,
        *,
        schema_text: str | None = None,
        schema_encoding: str = "ros2msg",
        message_encoding: str = "cdr",
        metadata: dict[str, str] | None = None,
    ) -> int:
        """The id of `topic`'s channel, registering it (and its schema) on first use."""
        if topic in self._channels:
            return self._channels[topic]
        key = f"{schema_encoding}:{msgtype}"
        if key not in self._schemas:
            text = schema_text if schema_text is not None else types.schema_text(msgtype)
            self._schemas[key] = self._writer.register_schema(msgtype, schema_encoding, text.encode())
        meta = {"offered_qos_profiles": QOS_YAML} if metadata is None else metadata
        cid = self._writer.register_channel(topic, message_encoding, self._schemas[key], meta)
        self._channels[topic] = cid
        return cid

    # -- messages
    def write(self, topic: str, msgtype: str, stamp_ns: int, payload: bytes) -> None:
        """One CDR message on `topic`, stamped `stamp_ns` (log and publish time)."""
        self.write_many(topic, msgtype, np.array([stamp_ns], np.int64), [payload])

    def write_many(self, topic: str, msgtype: str, stamps_ns, payloads: list[bytes]) -> None:
        """Many CDR messages on one topic; stamps in ns (one per payload)."""
        cid = self.channel(topic, msgtype)
        self._add(cid, stamps_ns, payloads)

    def _add(self, cid: int, stamps_ns, payloads: list[bytes]) -> None:
        stamps = np.asarray(stamps_ns, np.int64)
        if len(stamps) != len(payloads):
            raise ValueError("one stamp per payload")
        if self._streaming:
            add = self._writer.add_message
            for t, p in zip(stamps.tolist(), payloads, strict=True):
                add(cid, t, p, t, self._seq)
                self._seq += 1
        else:
            self._buffer.append((stamps, cid, payloads))

    def write_scans(self, run: ScanRun, topic: str = TOPIC_SCAN) -> None:
        """Every scan of `run` as sensor_msgs/msg/LaserScan."""
        self.write_many(topic, types.LASERSCAN, run.stamps, encode_scans(run))

    def write_scan(
        self, stamp_ns: int, ranges, geometry: ScanGeometry, intensities=None, topic: str = TOPIC_SCAN
    ) -> None:
        """One scan (ranges in metres, float32) as sensor_msgs/msg/LaserScan."""
        self.write(topic, types.LASERSCAN, stamp_ns, encode_scan(stamp_ns, ranges, geometry, intensities))

    def write_odometry(self, odom: Odometry, topic: str = TOPIC_ODOM) -> None:
        """Poses as nav_msgs/msg/Odometry."""
        self.write_many(topic, types.ODOMETRY, odom.stamps, encode_odometry(odom))

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._metadata(name, {str(k): str(v) for k, v in data.items()})

    def _metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name, data)
        self.metadata[name] = dict(data)

    def copy_from(self, src: str | Path | LogContents, exclude: Iterable[str] = ()) -> None:
        """Copy `src`'s channels byte for byte (no re-encoding), except `exclude`d topics.

        `src` may be a path or a LogContents read with all topics (topics=None). The source's own
        metadata is kept under names prefixed "input/".
        """
        log = src if isinstance(src, LogContents) else read_log(src, topics=None)
        for topic, cid in self.copy_channels(log, exclude).items():
            stamps, payloads = log.messages.get(topic, ([], []))
            if payloads:
                self._add(cid, stamps, payloads)

    def copy_channels(self, log: LogContents, exclude: Iterable[str] = ()) -> dict[str, int]:
        """Register `log`'s channels that hold messages (except `exclude`d topics) as they are in `log`, and
        keep its metadata under names prefixed "input/"; returns {topic: channel id} for write_ids. How a
        streaming copy starts: the messages follow block by block."""
        skip = set(exclude)
        ids = {}
        for ch in sorted(log.channels.values(), key=lambda c: c.id):
            if ch.topic in skip or not ch.count or ch.topic in ids:
                continue
            ids[ch.topic] = self.channel(
                ch.topic,
                ch.msgtype,
                schema_text=ch.schema_data.decode("utf-8", "replace"),
                schema_encoding=ch.schema_encoding,
                message_encoding=ch.message_encoding,
                metadata=ch.metadata,
            )
        for name, data in log.metadata.items():
            self._metadata(name if name.startswith("input/") else f"input/{name}", data)
        return ids

    def write_ids(self, cid: int, stamps_ns, payloads: list[bytes]) -> None:
        """Messages on a channel registered before (channel or copy_channels)."""
        self._add(cid, stamps_ns, payloads)

    def drain(self) -> None:
        """Write the messages added so far, in log-time order (then channel order: a scan before what was
        derived from it), and forget them: a streaming command drains after each block, so memory holds one
        block whatever the log's length."""
        if not self._buffer:
            return
        stamps = np.concatenate([b[0] for b in self._buffer])
        cids = np.concatenate([np.full(len(b[0]), b[1], np.int64) for b in self._buffer])
        payloads = [p for b in self._buffer for p in b[2]]
        self._buffer.clear()
        order = np.lexsort((cids, stamps))
        add = self._writer.add_message
        seq = self._seq
        for i, t, c in zip(order.tolist(), stamps[order].tolist(), cids[order].tolist(), strict=True):
            add(c, t, payloads[i], t, seq)
            seq += 1
        self._seq = seq

    # -- finishing
    def flush(self) -> None:
        """Close the current chunk and push everything written so far to disk (streaming mode); `flushed`
        becomes the file's length then (bytes), where `keep_flushed` can cut it."""
        from .. import outputs

        with outputs.writing(self.path):
            self._writer.flush()
            self._file.flush()
            os.fsync(self._file.fileno())
            self.flushed = self._file.tell()

    def close(self) -> Path:
        """Write buffered messages in time order, finish the file, sync it and rename it to `path`. On any
        error (the disk full, a signal) the temporary file is removed and `path` is left as it was; in
        streaming mode it is left for `keep_flushed` instead, and a finished file that cannot be renamed
        stays where it is, named in the error."""
        from .. import outputs

        if self._closed:
            return self.path
        try:
            with outputs.writing(self.path):
                self.drain()
                self._writer.finish()
                self._file.flush()
                os.fsync(self._file.fileno())
                end = self._file.tell()
                self._file.close()
            if self._streaming:
                self.flushed, self._whole = end, True
                self.keep_flushed()
            else:
                outputs.commit(self.tmp, self.path, self.force)
        except BaseException:
            if self._streaming:
                self._release()  # keep_flushed keeps what reached the disk (remove_live drops it otherwise)
            else:
                self.abort()
            raise
        self._closed = True
        return self.path

    @property
    def complete(self) -> bool:
        """Whether `path` now holds the whole finished file (not only a flushed part of it)."""
        return self._whole and self.kept > 0

    def _release(self) -> None:
        """Close the temporary file, whatever its buffered rest does (a full disk refuses it)."""
        try:
            self._file.close()
        except Exception:  # the rest is cut off or dropped by the caller
            pass

    def keep_flushed(self) -> int:
        """After a failure in streaming mode (the disk full, a second Ctrl-C): keep what reached the disk.

        The temporary file is cut at the last `flush()` (after complete chunks, which the reader recovers
        with a truncation warning), synced and renamed to `path`; returns the bytes kept (`kept`). With
        nothing flushed the temporary file is removed and 0 returned. If the cut or the rename fails, the
        temporary file is left where it is (no longer removed on exit) and an OutputError names it (again
        on a later call).
        """
        from .. import outputs
        from ..errors import DatmoError, OutputError

        if self._closed:
            if self._left is not None:
                raise self._left
            return self.kept
        self._closed = True
        self._release()
        if self.flushed <= 0:
            outputs.discard(self.tmp)
            return 0
        with outputs.critical():  # a signal waits until `kept` says where the data is
            try:
                fd = os.open(self.tmp, os.O_WRONLY | getattr(os, "O_CLOEXEC", 0))
                try:
                    os.ftruncate(fd, self.flushed)
                    os.fsync(fd)
                finally:
                    os.close(fd)
                outputs.check_replaceable(self.path, self.force)
                os.replace(self.tmp, self.path)
            except (OSError, DatmoError) as exc:
                outputs.forget(self.tmp)
                why = outputs.reason(exc) if isinstance(exc, OSError) else str(exc)
                self._left = OutputError(
                    f"{os.fsdecode(self.tmp)}: holds the data written so far (its first {self.flushed:,} bytes are "
                    f"complete) but could not become {os.fsdecode(self.path)} ({why}); rename it yourself"
                )
                raise self._left from exc
            outputs.forget(self.tmp)
            self.kept = self.flushed
        return self.kept

    def abort(self) -> None:
        """Drop the temporary file; `path` is left as it was."""
        from .. import outputs

        if not self._closed:
            self._closed = True
            try:
                self._file.close()
            except Exception:  # the buffered rest could not be written: the file goes anyway
                pass
            finally:
                outputs.discard(self.tmp)

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- transforms
    def transform_channel(self, static: bool = False) -> int:
        """The id of /tf (or /tf_static) as tf2_msgs/msg/TFMessage; /tf_static offered transient-local, as tf2's
        static broadcaster publishes it, so `ros2 bag play` hands it to nodes that start later."""
        from . import transforms

        topic = TOPIC_TF_STATIC if static else TOPIC_TF
        qos = QOS_YAML_LATCHED if static else QOS_YAML
        return self.channel(
            topic, transforms.TF_MESSAGE, schema_text=transforms.SCHEMA, metadata={"offered_qos_profiles": qos}
        )

    def write_transforms(self, stamps_ns, payloads: list[bytes], static: bool = False) -> None:
        """TFMessage payloads (transforms.encode_tf) on /tf, or on /tf_static; stamps in ns."""
        self._add(self.transform_channel(static), stamps_ns, payloads)
