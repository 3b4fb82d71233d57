"""The one module that owns MCAP: topic names, reading logs into arrays, and writing logs safely.

Reading uses a linear record scanner over the file (fast, and it recovers every complete chunk of a
truncated file). Writing uses mcap's Writer with zstd chunks and the `ros2` profile, so Foxglove and
`ros2 bag` open the files; messages are CDR with their `ros2msg` schemas embedded.
"""

from __future__ import annotations

import hashlib
import json
import mmap
import os
import struct
import warnings
from collections.abc import Iterable, Iterator
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

MAGIC = b"\x89MCAP0\r\n"
# A reliable, transient-local QoS as rosbag2 writes it: `ros2 bag play` needs it in the channel metadata.
QOS_YAML = (
    "- history: 3\n  depth: 0\n  reliability: 1\n  durability: 2\n"
    "  deadline:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  lifespan:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    nsec: 4294967295\n"
    "  avoid_ros_namespace_conventions: false\n"
)
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
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not an MCAP log")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: empty file")
    return path


def _string(buf, pos: int) -> tuple[str, int]:
    n = _U32.unpack_from(buf, pos)[0]
    return bytes(buf[pos + 4:pos + 4 + n]).decode("utf-8", "replace"), pos + 4 + n


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
    complete chunk) for a file cut short.
    """
    out = LogContents(path=Path(path))
    messages = out.messages
    for topic, stamp, payload in _walk_file(path, topics, out):
        stamps, payloads = messages[topic]
        stamps.append(stamp)
        payloads.append(payload)
    return out


def iter_messages(path: str | Path, topics: Iterable[str] | None = None, contents: LogContents | None = None, *,
                  warn: bool = True) -> Iterator[tuple[str, int, bytes]]:
    """(topic, log time ns, payload) of every message on `topics` (all when None), in file order, one chunk
    in memory at a time: how commands stream a log of any length. `contents`, when given, is filled with
    the channels and metadata met on the way (as read_log fills them). Errors as read_log; the warning of
    a truncated file only with `warn` (a second pass over a file need not say it again)."""
    out = contents if contents is not None else LogContents(path=Path(path))
    yield from _walk_file(path, topics, out, warn)


def _walk_file(path: str | Path, topics: Iterable[str] | None, out: LogContents,
               warn: bool = True) -> Iterator[tuple[str, int, bytes]]:
    path = _check_input(Path(path))
    out.path, out.size = path, path.stat().st_size
    want = None if topics is None else set(topics)
    schemas: dict[int, tuple[str, str, bytes]] = {}
    wanted_ids: set[int] = set()
    with open(path, "rb") as f:
        try:
            buf = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        except ValueError as exc:
            raise InputError(f"{path}: cannot map file: {exc}") from None
        with buf:
            if buf[:8] != MAGIC:
                raise InputError(f"{path}: not an MCAP file (bad magic bytes)")
            try:
                yield from _scan(buf, 8, len(buf), out, schemas, want, wanted_ids, top=True)
                out.truncated = buf[-8:] != MAGIC or len(buf) < 16  # no footer: cut after the data
            except _Truncated:
                out.truncated = True
            except (struct.error, UnicodeDecodeError, ValueError) as exc:
                raise InputError(f"{path}: corrupt MCAP data ({exc})") from None
    if out.truncated and warn:
        warnings.warn(f"{path}: truncated MCAP file; read the {out.chunks} complete chunk(s) before the cut",
                      TruncatedLogWarning, stacklevel=3)


_RELEASE = 8 << 20   # give back the pages of a mapped file every 8 MB read


class _Truncated(Exception):
    pass


def _scan(buf, pos: int, end: int, out: LogContents, schemas: dict, want: set[str] | None,
          wanted_ids: set[int], top: bool) -> Iterator[tuple[str, int, bytes]]:
    """Walk the records in buf[pos:end], filling `out`'s channels and metadata and yielding (topic, log
    time, payload) of the wanted channels' messages."""
    import zstandard

    channels = out.channels
    released = [0]   # bytes of a mapped file given back to the system (see _RELEASE)
    while pos < end:
        if pos + 9 > end:
            raise _Truncated
        op = buf[pos]
        length = _U64.unpack_from(buf, pos + 1)[0]
        body = pos + 9
        pos = body + length
        if pos > end:
            raise _Truncated
        if op == _OP_MESSAGE:
            cid, _seq, log_time, _pub = _MSG_HEAD.unpack_from(buf, body)
            ch = channels.get(cid)
            if ch is None:
                raise ValueError(f"message on unknown channel {cid}")
            if ch.count == 0:
                ch.first_ns = log_time
            ch.count += 1
            ch.last_ns = log_time
            if cid in wanted_ids:
                yield ch.topic, log_time, bytes(buf[body + 22:pos])
        elif op == _OP_CHUNK:
            cpos = body + 8 * 3 + 4
            compression, cpos = _string(buf, cpos)
            size = _U64.unpack_from(buf, cpos)[0]
            data = buf[cpos + 8:cpos + 8 + size]
            if compression == "zstd":
                uncompressed = _U64.unpack_from(buf, body + 16)[0]
                data = zstandard.ZstdDecompressor().decompress(data, max_output_size=uncompressed)
            elif compression == "lz4":
                import lz4.frame

                data = lz4.frame.decompress(data)
            elif compression:
                raise ValueError(f"unsupported chunk compression {compression!r}")
            else:
                data = bytes(data)
            yield from _scan(memoryview(data), 0, len(data), out, schemas, want, wanted_ids, top=False)
            out.chunks += 1
            if top and isinstance(buf, mmap.mmap) and pos - released[0] >= _RELEASE:
                # pages of the file read so far leave this process's memory (a long log is not held whole)
                upto = pos - pos % mmap.PAGESIZE
                buf.madvise(mmap.MADV_DONTNEED, released[0], upto - released[0])
                released[0] = upto
        elif op == _OP_SCHEMA:
            sid = _U16.unpack_from(buf, body)[0]
            name, p = _string(buf, body + 2)
            encoding, p = _string(buf, p)
            n = _U32.unpack_from(buf, p)[0]
            schemas[sid] = (name, encoding, bytes(buf[p + 4:p + 4 + n]))
        elif op == _OP_CHANNEL:
            cid, sid = struct.unpack_from("<HH", buf, body)
            topic, p = _string(buf, body + 4)
            enc, p = _string(buf, p)
            meta, p = _map(buf, p)
            if cid not in channels:
                name, senc, sdata = schemas.get(sid, ("", "", b""))
                channels[cid] = Channel(cid, topic, name, enc, senc, sdata, meta)
                if want is None or topic in want:
                    wanted_ids.add(cid)
                    out.messages.setdefault(topic, ([], []))
        elif op == _OP_METADATA:
            name, p = _string(buf, body)
            meta, _ = _map(buf, p)
            out.metadata[name] = meta
        elif op == _OP_HEADER:
            out.profile, p = _string(buf, body)
            out.library, _ = _string(buf, p)
        elif op == _OP_DATA_END and top:
            return


def summary(path: str | Path) -> LogContents:
    """Channels (with message counts and time ranges) and metadata of a log, without payloads."""
    return read_log(path, topics=())


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


def check_scan_channel(log: LogContents, topic: str = TOPIC_SCAN) -> int:
    """The number of scans on `topic` (read or not); raises when it holds none or not CDR LaserScans."""
    ch = log.topics().get(topic)
    if ch is not None and ch.count and ch.msgtype not in (types.LASERSCAN, "sensor_msgs/LaserScan"):
        raise InputError(f"{log.path}: {topic} holds {ch.msgtype}, not sensor_msgs/msg/LaserScan")
    if ch is not None and ch.count and ch.message_encoding != "cdr":
        raise InputError(f"{log.path}: {topic} is {ch.message_encoding}-encoded; convert it with datmo import")
    if ch is None or not ch.count:
        hint = f"; run {PRODUCER[topic]} first" if topic in PRODUCER else ""
        raise MissingChannelError(f"{log.path}: no messages on {topic}{hint}")
    return ch.count


def decode_scan_block(path: Path, payloads: list[bytes], first: int = 0, geometry: ScanGeometry | None = None,
                      topic: str = TOPIC_SCAN) -> ScanRun:
    """The ScanRun of a block of LaserScan payloads, scans first.. of the log at `path`; refuses a geometry
    that changes within the block or from `geometry` (the blocks' before)."""
    try:
        run = decode_scans(payloads)
    except GeometryChangeError as exc:
        raise GeometryError(f"{path}: {exc}; split the log before processing it") from None
    except ValueError as exc:
        raise InputError(f"{path}: bad LaserScan message on {topic}: {exc}") from None
    if geometry is not None and not run.geometry.same_beams(geometry):
        raise GeometryError(f"{path}: scan geometry changes at scan {first}: {geometry.describe()} -> "
                            f"{run.geometry.describe()}; split the log before processing it")
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
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(np.sin(th / 2)),
                                                          w=float(np.cos(th / 2))))
        zero = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        msg = T[types.ODOMETRY](
            header=header, child_frame_id=odom.child_frame_id,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=cov))
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
    """What made a file: the command, its effective parameters and its inputs (hashed on write)."""

    command: str
    params: dict = field(default_factory=dict)
    inputs: list = field(default_factory=list)
    command_line: str | None = None
    names: list | None = None   # what the inputs are called in the records (e.g. the URL a local copy came from)

    def records(self) -> dict[str, dict[str, str]]:
        from ..cli import invocation

        line = self.command_line if self.command_line is not None else invocation(self.command)
        return {
            "datmo": {"tool": "datmo", "version": __version__, "command": self.command,
                      "command_line": _text(line)},
            "datmo.params": {str(k): json.dumps(v, sort_keys=True, default=str) for k, v in self.params.items()},
            "datmo.inputs": {_text(str(name)): sha256_of(p)
                             for name, p in zip(self.names or self.inputs, self.inputs, strict=True)},
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
    `close()`, the temporary file is removed; write errors are OutputErrors naming `path`.
    """

    def __init__(self, path: str | Path, *, force: bool = False, provenance: Provenance | None = None,
                 streaming: bool = False, chunk_size: int = 1 << 20) -> None:
        from mcap.writer import CompressionType, Writer

        from .. import outputs

        self.path = outputs.check_output(path, force=force, inputs=provenance.inputs if provenance else ())
        self.force = force
        self._closed = False
        self.tmp, file = outputs.open_temp(self.path)
        self._file = outputs.Guarded(file, self.path)   # a write error names the output, not the temporary file
        try:
            with outputs.writing(self.path):
                self._writer = Writer(self._file, chunk_size=chunk_size, compression=CompressionType.ZSTD)
                self._writer.start(profile="ros2", library=f"datmo {__version__}")
                self._streaming = streaming
                self._schemas: dict[str, int] = {}
                self._channels: dict[str, int] = {}
                self._buffer: list[tuple[np.ndarray, int, list[bytes]]] = []  # (stamps, channel id, payloads)
                self._seq = 0
                if provenance is not None:
                    for name, data in provenance.records().items():
                        self._writer.add_metadata(name, data)
        except BaseException:
            self.abort()
            raise

    # -- channels
    def channel(self, topic: str, msgtype: str, *, schema_text: str | None = None,
                schema_encoding: str = "ros2msg", message_encoding: str = "cdr",
                metadata: dict[str, str] | None = None) -> int:
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

    def write_scan(self, stamp_ns: int, ranges, geometry: ScanGeometry, intensities=None,
                   topic: str = TOPIC_SCAN) -> None:
        """One scan (ranges in metres, float32) as sensor_msgs/msg/LaserScan."""
        self.write(topic, types.LASERSCAN, stamp_ns, encode_scan(stamp_ns, ranges, geometry, intensities))

    def write_odometry(self, odom: Odometry, topic: str = TOPIC_ODOM) -> None:
        """Poses as nav_msgs/msg/Odometry."""
        self.write_many(topic, types.ODOMETRY, odom.stamps, encode_odometry(odom))

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})

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
            ids[ch.topic] = self.channel(ch.topic, ch.msgtype, schema_text=ch.schema_data.decode("utf-8", "replace"),
                                         schema_encoding=ch.schema_encoding, message_encoding=ch.message_encoding,
                                         metadata=ch.metadata)
        for name, data in log.metadata.items():
            self._writer.add_metadata(name if name.startswith("input/") else f"input/{name}", data)
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
        """Close the current chunk and push everything written so far to disk (streaming mode)."""
        from .. import outputs

        with outputs.writing(self.path):
            self._writer.flush()
            self._file.flush()
            os.fsync(self._file.fileno())

    def close(self) -> Path:
        """Write buffered messages in time order, finish the file, sync it and rename it to `path`. On any
        error (the disk full, a signal) the temporary file is removed and `path` is left as it was."""
        from .. import outputs

        if self._closed:
            return self.path
        try:
            with outputs.writing(self.path):
                self.drain()
                self._writer.finish()
                self._file.flush()
                os.fsync(self._file.fileno())
                self._file.close()
            outputs.commit(self.tmp, self.path, self.force)
        except BaseException:
            self.abort()
            raise
        self._closed = True
        return self.path

    def abort(self) -> None:
        """Drop the temporary file; `path` is left as it was."""
        from .. import outputs

        if not self._closed:
            self._closed = True
            try:
                self._file.close()
            except Exception:  # noqa: BLE001 - the buffered rest could not be written: the file goes anyway
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
