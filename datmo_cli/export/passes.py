"""The passes over the logs (see the package docstring): the summary pass that checks every input before anything
is written (`plan`), then the rows of each channel streamed to a sink, `block` messages at a time (`export`,
`export_ground_truth`)."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..base.errors import InputError, MissingChannelError
from ..evaluate.frames import moved_ids
from ..logs import mcapio, types
from .rows import Batch, decode_messages, feature_batch, ground_truth_batch, track_batch
from .sinks import ParquetSink, TextSink

BLOCK_MESSAGES = 1000  # messages decoded and written at once (one batch, one Parquet row group)


@dataclass
class Plan:
    """What the summary pass of each input found: its path and its message counts per exported topic."""

    files: list[Path]
    counts: list[dict[str, int]] = field(default_factory=list)

    def total(self, topic: str) -> int:
        return sum(c.get(topic, 0) for c in self.counts)


def require_channel(log: mcapio.LogContents, topic: str, msgtype: str) -> int:
    """The number of `msgtype` messages on `topic` of `log`; MissingChannelError naming the command that writes
    them when there are none, InputError when the channel holds another type."""
    ch = log.topics().get(topic)
    if ch is None or not ch.count:
        if topic == mcapio.TOPIC_GROUND_TRUTH:
            raise MissingChannelError(
                f"{log.path}: no messages on {topic}; only {mcapio.PRODUCER[topic]} writes "
                "ground truth (annotate a real log as a stamp_ns,id,x,y CSV instead)"
            )
        raise MissingChannelError(f"{log.path}: no messages on {topic}; run {mcapio.PRODUCER[topic]} first")
    if ch.msgtype != msgtype or ch.message_encoding != "cdr":
        raise InputError(f"{log.path}: {topic} holds {ch.message_encoding} {ch.msgtype}, not CDR {msgtype}")
    return ch.count


def plan(files: list[Path], features: bool = False, ground_truth: bool = False) -> Plan:
    """Summary pass over every input (mcapio.summary): refuses, before anything is written, an input that is
    not a log or has no /datmo/tracks (or, with `features`, no /datmo/features; with `ground_truth` only
    /datmo/ground_truth is needed), naming the command to run."""
    out = Plan(list(files))
    for path in files:
        log = mcapio.summary(path)
        if ground_truth:
            out.counts.append(
                {mcapio.TOPIC_GROUND_TRUTH: require_channel(log, mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH)}
            )
            continue
        counts = {mcapio.TOPIC_TRACKS: require_channel(log, mcapio.TOPIC_TRACKS, types.TRACKS)}
        if features:
            counts[mcapio.TOPIC_FEATURES] = require_channel(log, mcapio.TOPIC_FEATURES, types.FEATURES)
        out.counts.append(counts)
    return out


def _batches(path: Path, topic: str, block: int) -> Iterator[tuple[int, list[bytes]]]:
    """(index of the first, payloads) of each block of `block` messages on `topic` of the log at `path`."""
    pending: list[bytes] = []
    first = 0
    for _, _, payload in mcapio.iter_messages(path, [topic], warn=False):
        pending.append(payload)
        if len(pending) == block:
            yield first, pending
            first += len(pending)
            pending = []
    if pending:
        yield first, pending


ROWS = {mcapio.TOPIC_TRACKS: (types.TRACKS, track_batch), mcapio.TOPIC_FEATURES: (types.FEATURES, feature_batch)}


def row_batches(
    path: Path, topic: str, name: str | None = None, block: int = BLOCK_MESSAGES
) -> Iterator[tuple[int, Batch]]:
    """(messages read, their rows) for each block of `block` messages on `topic` (/datmo/tracks or
    /datmo/features, a key of ROWS) of the log at `path`; `name` fills the file column (default: the path)."""
    msgtype, rows = ROWS[topic]
    name = os.fsdecode(path) if name is None else name
    for first, payloads in _batches(path, topic, block):
        yield len(payloads), rows(name, first, decode_messages(path, msgtype, topic, payloads, first))


def export(
    p: Plan,
    sink: TextSink | ParquetSink,
    *,
    features: bool = False,
    block: int = BLOCK_MESSAGES,
    progress: Callable[[str, int], None] | None = None,
) -> None:
    """Write the rows of every input of `p` to `sink`, `block` messages at a time: every file's track states,
    then (with `features`) every file's features. `progress(topic, n)` after each block of n messages of
    `topic`."""
    for topic in [mcapio.TOPIC_TRACKS] + ([mcapio.TOPIC_FEATURES] if features else []):
        for path in p.files:
            for n, batch in row_batches(path, topic, block=block):
                sink.write(batch)
                if progress is not None:
                    progress(topic, n)


def export_ground_truth(
    path: Path,
    sink: TextSink | ParquetSink,
    *,
    include_occluded: bool = False,
    block: int = BLOCK_MESSAGES,
    progress: Callable[[str, int], None] | None = None,
) -> None:
    """Write the targets of the /datmo/ground_truth channel of the log at `path` to `sink` (of
    GROUND_TRUTH_COLUMNS), `block` messages at a time, in two passes: `progress("movers", n)` after each
    block of the pass that finds the ids that move (and checks that the stamps increase: InputError naming the
    first message that does not), `progress("targets", n)` after each block written."""
    topic, msgtype = mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH
    moved = np.zeros(0, np.int64)
    last = None
    for first, payloads in _batches(path, topic, block):
        decoded = decode_messages(path, msgtype, topic, payloads, first)
        moved = np.union1d(moved, moved_ids(np.concatenate([d["objects"] for d in decoded])))
        stamps = np.array(([] if last is None else [last]) + [d["stamp_ns"] for d in decoded], np.int64)
        back = np.flatnonzero(np.diff(stamps) <= 0)
        if len(back):  # a frame per stamp: evaluate --gt would read two messages of one stamp as one frame
            k = first + int(back[0]) - (last is not None) + 1
            raise InputError(
                f"{path}: {topic} message {k} has stamp_ns {int(stamps[back[0] + 1])}, not after the "
                f"previous message's {int(stamps[back[0]])}"
            )
        last = int(stamps[-1])
        if progress is not None:
            progress("movers", len(payloads))
    for first, payloads in _batches(path, topic, block):
        decoded = decode_messages(path, msgtype, topic, payloads, first)
        sink.write(ground_truth_batch(path, first, decoded, moved, include_occluded=include_occluded))
        if progress is not None:
            progress("targets", len(payloads))
