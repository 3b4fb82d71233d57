"""Writing MCAP logs safely: zstd chunks (log.mcap_chunks) and the `ros2` profile, so Foxglove and `ros2 bag`
open the files; messages are CDR with their `ros2msg` schemas embedded; the file appears under its name only
when complete (or, streaming, as far as it was flushed). A `grouped` writer puts each channel (or group of
channels) in chunks of its own, block by block (see LogWriter.drain), each covering less than `seconds` of
log time when that is given (so the file is in time order within `seconds` without its index).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import BinaryIO, cast

import numpy as np

from .. import __version__
from . import types
from .mcap_reader import LogContents, read_log
from .odometry_msgs import encode_odometry
from .provenance import Provenance
from .scan import Odometry, ScanGeometry, ScanRun, encode_scan, encode_scans
from .topics import QOS_YAML, QOS_YAML_LATCHED, TOPIC_ODOM, TOPIC_SCAN, TOPIC_TF, TOPIC_TF_STATIC


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
        grouped: bool = False,
        groups: dict[str, str] | None = None,
        level: int = 3,
        span: int = 0,
        seconds: float = 0.0,
    ) -> None:
        from ..base import outputs
        from .mcap_chunks import ChunkWriter

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
                self._writer = ChunkWriter(
                    cast(BinaryIO, self._file),  # Guarded: a binary file that names the output in its errors
                    chunk_size=chunk_size,
                    level=level,
                    span=span if grouped else 0,
                    seconds=seconds if grouped else 0.0,
                )
                self._writer.start(profile="ros2", library=f"datmo {__version__}")
                self._streaming = streaming
                self._grouped = grouped
                self._groups: dict[str, int] = {}
                self._group_names = dict(groups or {})  # topic -> group, for channels given none
                self._schemas: dict[str, int] = {}
                self._channels: dict[str, int] = {}
                self._buffer: list[tuple[np.ndarray, int, list[bytes]]] = []  # (stamps, channel id, payloads)
                self._seq: dict[int, int] = {}  # channel -> its messages so far (their sequence numbers)
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
        group: str | None = None,
    ) -> int:
        """The id of `topic`'s channel, registering it (and its schema) on first use. A grouped writer puts its
        messages in chunks of their own, shared with the channels of the same `group` (default: the topic's
        own)."""
        if topic in self._channels:
            return self._channels[topic]
        key = f"{schema_encoding}:{msgtype}"
        if key not in self._schemas:
            text = schema_text if schema_text is not None else types.schema_text(msgtype)
            self._schemas[key] = self._writer.register_schema(msgtype, schema_encoding, text.encode())
        meta = {"offered_qos_profiles": QOS_YAML} if metadata is None else metadata
        gid = None
        if self._grouped:
            name = group or self._group_names.get(topic, topic)
            gid = self._groups.setdefault(name, len(self._groups))
        cid = self._writer.register_channel(topic, message_encoding, self._schemas[key], meta, gid)
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
            seq = self._seq.get(cid, 0)
            for t, p in zip(stamps.tolist(), payloads, strict=True):
                add(cid, t, p, seq)
                seq += 1
            self._seq[cid] = seq
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
        block whatever the log's length. A grouped writer puts them in the chunks of their groups (each
        channel's messages in that same order); a block is counted (ChunkWriter.end_block)."""
        if not self._buffer:
            self._writer.end_block()
            return
        stamps = np.concatenate([b[0] for b in self._buffer])
        cids = np.concatenate([np.full(len(b[0]), b[1], np.int64) for b in self._buffer])
        payloads = [p for b in self._buffer for p in b[2]]
        self._buffer.clear()
        order = np.lexsort((cids, stamps))
        add = self._writer.add_message
        seqs = self._seq
        for i, t, c in zip(order.tolist(), stamps[order].tolist(), cids[order].tolist(), strict=True):
            seq = seqs.get(c, 0)
            add(c, t, payloads[i], seq)
            seqs[c] = seq + 1
        self._writer.end_block()  # ends nothing unless grouped (its span is 0 otherwise)

    # -- finishing
    def flush(self) -> None:
        """Close the current chunk and push everything written so far to disk (streaming mode); `flushed`
        becomes the file's length then (bytes), where `keep_flushed` can cut it."""
        from ..base import outputs

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
        from ..base import outputs

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
        from ..base import outputs
        from ..base.errors import DatmoError, OutputError

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
        from ..base import outputs

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
