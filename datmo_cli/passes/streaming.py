"""Streaming a log through the stages: read it a block of scans at a time, derive the block's channels,
write them with the input's own messages of the same stretch, and forget the block.

Every command that turns a log into a log (segment, features, track, run) goes through `write_derived`, so
its memory holds one block (BLOCK_SCANS scans with the messages between them) whatever the log's length.
What is kept whole: the input's odometry (four numbers a pose) and, for a log without odometry whose
scanner moves, the scans themselves while ego-motion is estimated (see `stream_odometry`).

Blocks end right before the scan that would make them longer than the block size, so the messages a
stage derived from a scan at the same stamp (a log's /datmo/features after its /scan) fall in that scan's
block. Each channel's messages are written in log-time order (then channel order: the input's channels
before derived ones), as a whole-run write would order them, but a window of log time at a time, a channel's
after another's (log.mcap_chunks), so the file holds a channel's messages of a stretch after another
channel's of a later stretch (within CHUNK_SECONDS): `blocks` reads the channels by their chunks' times
(mcap_reader.iter_stretches), not by their places in the file.

A log whose scan stamps go backwards or repeat is refused when it is opened (`StampOrder`), with the count
and the first such scan: the tracker's time comes from the stamps, and `datmo import` puts such a log in
time order (dropping repeated stamps) with a warning.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol

import numpy as np

from ..base.errors import InputError
from ..logs import mcapio, transforms
from ..logs.poses import sane as sane_poses
from ..logs.scan import Odometry, ScanGeometry, ScanRun, stamp_problem

_STAMP = struct.Struct("<iI")  # a CDR header stamp: sec, nanosec
BLOCK_SCANS = 1024  # scans per block: large enough that per-block costs vanish, small enough to stay flat
# How the logs written here are chunked: each channel in zstd chunks of its own (poses and their transforms
# together: /tf repeats /odom's stamps and poses), a chunk ending at CHUNK_BYTES or after CHUNK_BLOCKS blocks.
# Measured on datmo run's lean output of CARMEN intel (910 scans, one block) against the interleaved chunks at
# level 3 (3.40x its input): by channel 3.21x at level 3, 3.04x at level 9 (0.11 s for its 6.1 MB, against
# 0.03 s), 2.96x at level 16 (0.64 s: too slow for long logs); poses with /tf saves 34 KB of 1.2 MB. The
# message indexes (16 bytes a message, uncompressed, which Foxglove's indexed reader uses) are 0.3x of it.
# On the 20,000-scan hall of benchmarks/bench_scale (level 9): chunks ending each block 1.70x, after 2 blocks
# 1.16x, 4 or 8 blocks 1.01x; that log repeats every 300 scans, which chunks spanning blocks profit from as
# real logs would not. CHUNK_SECONDS: messages go in windows of log time into one stream of chunks of
# CHUNK_BYTES (log.mcap_chunks), so the file is in time order within 5 s without its index; 32 MiB chunks keep
# the output within 0-3 % of chunks by channel without the bound (4 MiB chunks in one stream: +11 % on a 5 Hz
# log; docs/performance.md has the sizes); CHUNK_BLOCKS then has no effect.
CHUNK_BYTES = 32 << 20
CHUNK_LEVEL = 9
CHUNK_BLOCKS = 4
CHUNK_SECONDS = 5.0
CHUNK_GROUPS = {mcapio.TOPIC_ODOM: "poses", mcapio.TOPIC_TF: "poses", mcapio.TOPIC_TF_STATIC: "poses"}


@dataclass
class Block:
    """One block of a log: its scans, the payloads of the topics aligned with them (one per scan), and the
    input's messages of the block to copy ({topic: (stamps, payloads)}, file order)."""

    first: int  # index of the block's first scan in the log
    run: ScanRun
    aligned: dict[str, list[bytes]] = field(default_factory=dict)
    copies: dict[str, tuple[list[int], list[bytes]]] = field(default_factory=dict)


class LogStream:
    """An input log opened for streaming: its channels, metadata, scan count and odometry (one pass that
    keeps no other payloads, and checks that the scan stamps increase), then `blocks` in file order."""

    def __init__(self, path: str | Path, scan_topic: str = mcapio.TOPIC_SCAN) -> None:
        self.path = Path(path)
        self.scan_topic = scan_topic
        self.log = mcapio.LogContents(path=self.path)
        odom: tuple[list[int], list[bytes]] = ([], [])
        order = StampOrder()
        statics: list[bytes] = []
        self.scan_frame = ""
        self._first_scan = b""
        for topic, stamp, payload in mcapio.iter_messages(
            self.path, [mcapio.TOPIC_ODOM, mcapio.TOPIC_TF_STATIC, scan_topic], self.log
        ):
            if topic == scan_topic:
                if not order.n:
                    self.scan_frame = _frame(payload)
                    self._first_scan = payload
                order.add(payload)
            elif topic == mcapio.TOPIC_ODOM:
                odom[0].append(stamp)
                odom[1].append(payload)
            else:
                statics.append(payload)
        self.n_scans = mcapio.check_scan_channel(self.log, scan_topic)
        order.check(self.path, scan_topic)
        self.log.messages = {mcapio.TOPIC_ODOM: odom}
        self.statics = [t for p in statics for t in _transforms(self.path, p)]
        # the tracker and the landmarks take the scanner's poses: the base's composed with its mount
        self.odometry = transforms.sensor_odometry(mcapio.odometry_from_log(self.log), self.statics, self.scan_frame)
        self.log.messages = {}  # every channel is copied block by block
        self._geometry: ScanGeometry | None = None

    @property
    def geometry(self) -> ScanGeometry:
        """The scans' geometry (beams, range limits, frame), from the first scan: the blocks refuse scans of
        another (log.channels.decode_scan_block), so it is every block's."""
        if self._geometry is None:
            self._geometry = mcapio.decode_scan_block(self.path, [self._first_scan], 0, None, self.scan_topic).geometry
        return self._geometry

    def has(self, topic: str) -> bool:
        return self.log.has(topic)

    def count(self, topic: str) -> int:
        ch = self.log.topics().get(topic)
        return ch.count if ch is not None else 0

    def blocks(
        self, size: int = BLOCK_SCANS, aligned: tuple[str, ...] = (), copy: set[str] | None = None
    ) -> Iterator[Block]:
        """The log's blocks of up to `size` scans. `aligned` topics must have one message per scan in each
        block (else InputError naming the command to run again); `copy`: the topics whose messages the
        blocks carry for copying (None: none).

        A block holds, of each other topic, its messages (in file order) up to the first at or after the next
        block's first scan, by (log time, channel id): in a log written in time order, those between the
        block's first scan and the next block's, wherever the file keeps them. A block is given once the
        chunks read so far hold every message before that point (mcapio.iter_stretches), so the blocks are
        the same whatever the chunks and their order in the file; memory holds the stretch of the log that
        the chunks of different channels are apart in the file (CHUNK_SECONDS of a log written here)."""
        from collections import deque

        copy = copy or set()
        scan_topic, path = self.scan_topic, self.path
        others = (set(aligned) | copy) - {scan_topic}
        ids = {c.topic: c.id for c in sorted(self.log.channels.values(), key=lambda c: -c.id)}
        scan_id = ids.get(scan_topic, 0)
        scans: deque[tuple[int, bytes]] = deque()
        held: dict[str, deque[tuple[int, bytes]]] = {t: deque() for t in others}
        state = {"first": 0, "geometry": None}

        def emit(n: int, end: tuple[int, int] | None) -> Block:
            """The block of the next `n` scans, with the held messages before `end` (None: all)."""
            block_scans = [scans.popleft() for _ in range(n)]
            payloads = [p for _, p in block_scans]
            first = state["first"]
            run = mcapio.decode_scan_block(path, payloads, first, state["geometry"], scan_topic)
            state["geometry"] = run.geometry
            taken: dict[str, tuple[list[int], list[bytes]]] = {}
            for topic, queue in held.items():
                cid = ids.get(topic, 0)
                stamps, out = [], []
                while queue and (end is None or (queue[0][0], cid) < end):
                    t, p = queue.popleft()
                    stamps.append(t)
                    out.append(p)
                taken[topic] = (stamps, out)
            lined = {t: taken[t][1] for t in aligned}
            for t, got in lined.items():
                if len(got) != n:
                    raise InputError(
                        f"{path}: {len(got)} messages on {t} for the {n} scans from scan "
                        f"{first}; run {mcapio.PRODUCER.get(t, 'the stage that made it')} again"
                    )
            copies = {t: v for t, v in taken.items() if t in copy and v[1]}
            if scan_topic in copy:
                copies[scan_topic] = ([t for t, _ in block_scans], payloads)
            state["first"] = first + n
            return Block(first, run, lined, copies)

        wanted = {scan_topic} | others
        for horizon, stretch in mcapio.iter_stretches(path, wanted, warn=False):
            for topic, stamp, payload in stretch:
                (scans if topic == scan_topic else held[topic]).append((stamp, payload))
            while len(scans) > size and scans[size][0] < horizon:
                yield emit(size, (scans[size][0], scan_id))
        while len(scans) > size:
            yield emit(size, (scans[size][0], scan_id))
        if scans:
            yield emit(len(scans), None)

    def scans(self, size: int = BLOCK_SCANS) -> Iterator[ScanRun]:
        """Just the scans, block by block."""
        for block in self.blocks(size):
            yield block.run


def _frame(payload: bytes) -> str:
    try:
        return transforms.header_frame(payload)
    except (ValueError, struct.error):
        return ""  # the scan decoder names what is wrong with it


def _transforms(path: Path, payload: bytes) -> list[transforms.Transform]:
    try:
        return transforms.decode_tf(payload)
    except ValueError as exc:
        raise InputError(f"{path}: bad tf2_msgs/msg/TFMessage on {mcapio.TOPIC_TF_STATIC}: {exc}") from None


class StampOrder:
    """Whether a log's scan stamps (header stamps, ns) increase, one scan payload at a time: how many are at
    or before a stamp that came before them, and the first such scan's index.

    The stages take a log in file order and the tracker's time from the stamps, so a scan stamped before the
    one before it, or at the same instant, would make time stand still or run back. Such a log is refused
    (`check`) before anything is written; `datmo import` rewrites it in time order without the repeats. A stamp
    that is not a time (before 1970, nanosec of 10^9 or more) is refused as what it is, not as out of order."""

    def __init__(self) -> None:
        self.n = 0
        self.bad = 0
        self.first_bad: int | None = None
        self.not_a_time: str | None = None  # the first stamp that is not one, as "scan K: problem"
        self._top: int | None = None

    def add(self, payload: bytes) -> None:
        """One CDR LaserScan payload (a payload too short for a header, or not little-endian, is left to
        the decoder to refuse)."""
        if len(payload) >= 12 and payload[1] == 1:
            sec, nanosec = _STAMP.unpack_from(payload, 4)
            problem = stamp_problem(sec, nanosec)
            if problem:
                self.not_a_time = self.not_a_time or f"scan {self.n}: {problem}"
                self.n += 1
                return
            t = sec * 1_000_000_000 + nanosec
            if self._top is not None and t <= self._top:
                self.bad += 1
                if self.first_bad is None:
                    self.first_bad = self.n
            else:
                self._top = t
        self.n += 1

    def check(self, path: Path, topic: str = mcapio.TOPIC_SCAN) -> None:
        """Raise InputError naming `path`, the count and the first scan when the stamps do not increase (or the
        first scan whose stamp is not a time)."""
        if self.not_a_time:
            raise InputError(f"{path}: bad LaserScan message on {topic}: {self.not_a_time}")
        if self.bad:
            raise InputError(
                f"{path}: scan stamps go backwards or repeat at {self.bad} of {self.n} scans (first "
                f"at scan {self.first_bad}); datmo import {path} -o FIXED.mcap writes them in time "
                "order without the repeats"
            )


Channels = dict[str, tuple[str, np.ndarray, list]]


class Pipelined(Protocol):
    """A stage that gives (block, its channels) for blocks in order, holding some back (hindsight, the perception
    of the next blocks beside this one's tracking)."""

    def pipelined(self, blocks: Iterator[Block]) -> Iterator[tuple[Block, Channels]]: ...


Stage = Callable[[Block], Channels] | Pipelined


def write_derived(
    stream: LogStream,
    out: str | Path,
    *,
    command: str,
    params: dict,
    derived: dict[str, str],
    stage: Stage,
    force: bool = False,
    command_line: str | None = None,
    aligned: tuple[str, ...] = (),
    block_scans: int = BLOCK_SCANS,
    progress: Callable[[int, int], None] | None = None,
    input_name: str | None = None,
    origin: str | Path | None = None,
    report=None,
) -> int:
    """Write `out`: the input's channels (those in `derived` replaced) and the `derived` channels ({topic:
    message type}, in this order) that `stage(block)` gives block by block ({topic: (msgtype, stamps,
    payloads)}), with provenance (`command`, its effective `params`). Returns the number of scans.
    `progress(done, total)` follows the scans; `input_name`: what provenance calls the input (default its path,
    e.g. the URL a local copy was fetched from); `origin`: the file provenance hashes as the input (default the
    stream's; a bag the stream's log was converted from); `report`: a report.RunAccumulator the stage feeds
    (pipeline.RunStages), given the output's metadata records once it is complete."""
    from ..base.numba_runtime import prepare

    prepare()  # the stages load numba kernels: numba's set-up without its scipy.linalg import
    provenance = mcapio.Provenance(
        command, params, [origin or stream.path], command_line, names=[input_name] if input_name else None
    )
    total = stream.n_scans
    with mcapio.LogWriter(
        out,
        force=force,
        provenance=provenance,
        chunk_size=CHUNK_BYTES,
        grouped=True,
        groups=CHUNK_GROUPS,
        level=CHUNK_LEVEL,
        span=CHUNK_BLOCKS,
        seconds=CHUNK_SECONDS,
    ) as writer:
        copy_ids = writer.copy_channels(stream.log, exclude=list(derived))
        ids = {topic: writer.channel(topic, msgtype) for topic, msgtype in derived.items()}
        tf = _DerivedTf(stream, writer, mcapio.TOPIC_ODOM in derived)
        done = 0
        if progress is not None:
            progress(0, total)
        blocks = stream.blocks(block_scans, aligned=aligned, copy=set(copy_ids))
        pipelined = getattr(stage, "pipelined", None)  # RunStages: the next block's perception beside this one
        staged = pipelined(blocks) if pipelined is not None else ((b, stage(b)) for b in blocks)
        for block, out_channels in staged:
            for topic, (stamps, payloads) in block.copies.items():
                writer.write_ids(copy_ids[topic], stamps, payloads)
            for topic, (_, stamps, payloads) in out_channels.items():
                writer.write_ids(ids[topic], stamps, payloads)
            odom = (
                out_channels[mcapio.TOPIC_ODOM][1:]
                if mcapio.TOPIC_ODOM in out_channels
                else block.copies.get(mcapio.TOPIC_ODOM)
            )
            tf.block(block, odom)
            writer.drain()
            done += len(block.run)
            if progress is not None:
                progress(done, total)
        metadata = writer.metadata
    if report is not None:
        report.metadata = metadata
    return done


class _DerivedTf:
    """/tf (one transform per /odom pose) and /tf_static (the odometry's child frame -> the scan's frame, the
    identity) for an output with odometry whose input has no /tf (older datmo logs, odometry estimated here);
    nothing when the input's own /tf is copied."""

    def __init__(self, stream: LogStream, writer: mcapio.LogWriter, estimated: bool) -> None:
        self.stream, self.writer = stream, writer
        self.on = not stream.has(mcapio.TOPIC_TF) and (estimated or stream.has(mcapio.TOPIC_ODOM))
        self.static = self.on and not stream.has(mcapio.TOPIC_TF_STATIC)
        self.joined = {stream.scan_frame}  # child frames given a static transform (the scan's own needs none)

    def block(self, block: Block, odom: tuple | None) -> None:
        if not self.on or odom is None or not len(odom[1]):
            return
        stamps, payloads = odom
        try:
            poses = transforms.decode_odometry(payloads)
        except ValueError as exc:
            raise InputError(f"{self.stream.path}: bad nav_msgs/msg/Odometry on {mcapio.TOPIC_ODOM}: {exc}") from None
        ok = sane_poses(poses.x, poses.y, poses.theta)  # the others dropped, as LogStream's odometry says
        if not ok.all():
            stamps = np.asarray(stamps)[ok]
            poses = Odometry(
                poses.stamps[ok], poses.x[ok], poses.y[ok], poses.theta[ok], poses.frame_id, poses.child_frame_id
            )
        self.writer.write_transforms(stamps, transforms.odometry_tf(poses))
        child = poses.child_frame_id
        if self.static and child not in self.joined:
            self.joined.add(child)
            at = int(min(block.run.stamps[0], np.min(stamps)))
            self.writer.write_transforms(
                [at], [transforms.mount_tf(at, child, self.stream.scan_frame, transforms.LaserPose())], static=True
            )


# ------------------------------------------------------------------------------------------- odometry


def stream_odometry(stream: LogStream, mode: str) -> tuple[Odometry | None, bool]:
    """The odometry to track `stream`'s log in and whether it was estimated here (see
    perception.egomotion.odometry_for): the log's own; else, for mode "on" or "auto" when sampled pairs of
    consecutive scans among its first ones (sample_pairs) show the scanner moving, poses from scan matching.
    Only that estimate holds the scans (float32 ranges) in memory: the matcher's map carries over the whole
    log."""
    from ..perception.egomotion import EGO_MOTION_MODES, estimate_odometry, is_moving, pairs_move, sampled_scans

    if mode not in EGO_MOTION_MODES:
        raise ValueError(f"ego-motion mode {mode!r} is not one of {', '.join(EGO_MOTION_MODES)}")
    odometry, n = stream.odometry, stream.n_scans
    if (odometry is not None and len(odometry)) or mode == "off" or n < 2:
        return odometry, False
    from ..base.numba_runtime import prepare

    prepare()  # scan matching loads numba kernels
    if mode == "auto":
        pairs = sample_pairs(stream)
        if not pairs_move(pairs, sampled_scans(n)):
            return None, False
    run = mcapio.read_run(stream.path, stream.scan_topic)
    estimate = estimate_odometry(run)
    if mode == "auto" and not is_moving(estimate):
        return None, False
    return estimate, True


def sample_pairs(stream: LogStream, samples: int = 100) -> ScanRun:
    """Up to `samples` pairs of consecutive scans spread over the log's first scans (egomotion.sampled_scans:
    its first block; scans k and k + 1 at rows 2i and 2i + 1), read from the start of the log alone."""
    from ..perception.egomotion import EGO_SAMPLE_SCANS, pair_picks, sampled_scans

    picks = pair_picks(sampled_scans(stream.n_scans), samples)
    blocks = stream.blocks(EGO_SAMPLE_SCANS)
    try:
        first = next(blocks).run
    finally:
        blocks.close()  # the rest of the log is not read
    order = np.stack([picks, picks + 1], axis=1).ravel()
    return ScanRun(first.stamps[order], first.ranges[order], first.geometry)
