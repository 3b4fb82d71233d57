"""Streaming a log through the stages: read it a block of scans at a time, derive the block's channels,
write them with the input's own messages of the same stretch, and forget the block.

Every command that turns a log into a log (segment, features, track, run) goes through `stream_log`, so
its memory holds one block (BLOCK_SCANS scans with the messages between them) whatever the log's length.
What is kept whole: the input's odometry (four numbers a pose) and, for a log without odometry whose
scanner moves, the scans themselves while ego-motion is estimated (see `stream_odometry`).

Blocks end right before the scan that would make them longer than the block size, so the messages a
stage derived from a scan at the same stamp (a log's /datmo/features after its /scan) fall in that scan's
block. Within a block, messages are written in log-time order (then channel order: the input's channels
before derived ones), as a whole-run write would order them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import InputError
from .log import mcapio
from .log.scan import Odometry, ScanGeometry, ScanRun

BLOCK_SCANS = 1024   # scans per block: large enough that per-block costs vanish, small enough to stay flat


@dataclass
class Block:
    """One block of a log: its scans, the payloads of the topics aligned with them (one per scan), and the
    input's messages of the block to copy ({topic: (stamps, payloads)}, file order)."""

    first: int                     # index of the block's first scan in the log
    run: ScanRun
    aligned: dict[str, list[bytes]] = field(default_factory=dict)
    copies: dict[str, tuple[list[int], list[bytes]]] = field(default_factory=dict)


class LogStream:
    """An input log opened for streaming: its channels, metadata, scan count and odometry (one pass that
    keeps no other payloads), then `blocks` in file order."""

    def __init__(self, path: str | Path, scan_topic: str = mcapio.TOPIC_SCAN) -> None:
        self.path = Path(path)
        self.scan_topic = scan_topic
        self.log = mcapio.read_log(self.path, topics=[mcapio.TOPIC_ODOM])
        self.n_scans = mcapio.check_scan_channel(self.log, scan_topic)
        self.odometry = mcapio.odometry_from_log(self.log)
        self.log.messages.pop(mcapio.TOPIC_ODOM, None)   # copied block by block like every other channel

    def has(self, topic: str) -> bool:
        return self.log.has(topic)

    def count(self, topic: str) -> int:
        ch = self.log.topics().get(topic)
        return ch.count if ch is not None else 0

    def blocks(self, size: int = BLOCK_SCANS, aligned: tuple[str, ...] = (),
               copy: set[str] | None = None) -> Iterator[Block]:
        """The log's blocks of up to `size` scans. `aligned` topics must have one message per scan in each
        block (else InputError naming the command to run again); `copy`: the topics whose messages the
        blocks carry for copying (None: none)."""
        copy = copy or set()
        scan_topic, path = self.scan_topic, self.path
        scans: list[bytes] = []
        lined: dict[str, list[bytes]] = {t: [] for t in aligned}
        copies: dict[str, tuple[list[int], list[bytes]]] = {}
        first, geometry = 0, None

        def emit() -> Block:
            nonlocal geometry
            run = mcapio.decode_scan_block(path, scans, first, geometry, scan_topic)
            geometry = run.geometry
            for t, payloads in lined.items():
                if len(payloads) != len(scans):
                    raise InputError(f"{path}: {len(payloads)} messages on {t} for the {len(scans)} scans from scan "
                                     f"{first}; run {mcapio.PRODUCER.get(t, 'the stage that made it')} again")
            return Block(first, run, dict(lined), copies)

        for topic, stamp, payload in mcapio.iter_messages(path, None, warn=False):
            if topic == scan_topic:
                if len(scans) == size:
                    yield emit()
                    first += len(scans)
                    scans, copies = [], {}
                    lined = {t: [] for t in aligned}
                scans.append(payload)
            elif topic in lined:
                lined[topic].append(payload)
            if topic in copy:
                stamps, payloads = copies.setdefault(topic, ([], []))
                stamps.append(stamp)
                payloads.append(payload)
        if scans:
            yield emit()

    def scans(self, size: int = BLOCK_SCANS) -> Iterator[ScanRun]:
        """Just the scans, block by block."""
        for block in self.blocks(size):
            yield block.run


Stage = Callable[[Block], dict[str, tuple[str, np.ndarray, list]]]


def stream_log(stream: LogStream, out: str | Path, *, command: str, params: dict, derived: dict[str, str],
               stage: Stage, force: bool = False, command_line: str | None = None,
               aligned: tuple[str, ...] = (), block_scans: int = BLOCK_SCANS,
               progress: Callable[[int, int], None] | None = None, input_name: str | None = None) -> int:
    """Write `out`: the input's channels (those in `derived` replaced) and the `derived` channels ({topic:
    message type}, in this order) that `stage(block)` gives block by block ({topic: (msgtype, stamps,
    payloads)}), with provenance (`command`, its effective `params`). Returns the number of scans.
    `progress(done, total)` follows the scans; `input_name`: what provenance calls the input (default its path,
    e.g. the URL a local copy was fetched from)."""
    from .numba_runtime import prepare

    prepare()   # the stages load numba kernels: numba's set-up without its scipy.linalg import
    provenance = mcapio.Provenance(command, params, [stream.path], command_line,
                                   names=[input_name] if input_name else None)
    total = stream.n_scans
    with mcapio.LogWriter(out, force=force, provenance=provenance) as writer:
        copy_ids = writer.copy_channels(stream.log, exclude=list(derived))
        ids = {topic: writer.channel(topic, msgtype) for topic, msgtype in derived.items()}
        done = 0
        if progress is not None:
            progress(0, total)
        for block in stream.blocks(block_scans, aligned=aligned, copy=set(copy_ids)):
            for topic, (stamps, payloads) in block.copies.items():
                writer.write_ids(copy_ids[topic], stamps, payloads)
            for topic, (_, stamps, payloads) in stage(block).items():
                writer.write_ids(ids[topic], stamps, payloads)
            writer.drain()
            done += len(block.run)
            if progress is not None:
                progress(done, total)
    return done


# ------------------------------------------------------------------------------------------- odometry


def stream_odometry(stream: LogStream, mode: str, block_scans: int = BLOCK_SCANS) -> tuple[Odometry | None, bool]:
    """The odometry to track `stream`'s log in and whether it was estimated here (see
    perception.egomotion.odometry_for): the log's own; else, for mode "on" or "auto" when sampled pairs of
    consecutive scans show the scanner moving, poses from scan matching. Only that estimate holds the scans
    (float32 ranges) in memory: the matcher's map carries over the whole log."""
    from .perception.egomotion import EGO_MOTION_MODES, estimate_odometry, is_moving, pairs_move

    if mode not in EGO_MOTION_MODES:
        raise ValueError(f"ego-motion mode {mode!r} is not one of {', '.join(EGO_MOTION_MODES)}")
    odometry, n = stream.odometry, stream.n_scans
    if (odometry is not None and len(odometry)) or mode == "off" or n < 2:
        return odometry, False
    from .numba_runtime import prepare

    prepare()   # scan matching loads numba kernels
    if mode == "auto":
        pairs = sample_pairs(stream, block_scans=block_scans)
        if not pairs_move(pairs, n):
            return None, False
    run = mcapio.read_run(stream.path, stream.scan_topic)
    estimate = estimate_odometry(run)
    if mode == "auto" and not is_moving(estimate):
        return None, False
    return estimate, True


def sample_pairs(stream: LogStream, samples: int = 100, block_scans: int = BLOCK_SCANS) -> ScanRun:
    """Up to `samples` pairs of consecutive scans spread over the log (scans k and k + 1 at rows 2i and
    2i + 1), gathered in one streaming pass."""
    from .perception.egomotion import pair_picks

    picks = pair_picks(stream.n_scans, samples)
    want = np.zeros(stream.n_scans + 1, bool)
    want[picks] = want[picks + 1] = True
    rows: dict[int, np.ndarray] = {}
    geometry: ScanGeometry | None = None
    stamps: dict[int, int] = {}
    for block in stream.blocks(block_scans):
        block_run, first = block.run, block.first
        geometry = block_run.geometry
        for i in np.flatnonzero(want[first:first + len(block_run)]).tolist():
            rows[first + i] = block_run.ranges[i]
            stamps[first + i] = int(block_run.stamps[i])
    order = [k for p in picks.tolist() for k in (p, p + 1)]
    return ScanRun(np.array([stamps[k] for k in order], np.int64), np.stack([rows[k] for k in order]), geometry)

