"""Decoding a processed log's channels into arrays: `decode_channel` (one channel's CDR payloads), `RunData`
(the channels the report, the plot and evaluate use, of an already-read log) and `require` (a channel that
must be there, naming the command that writes it)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..base.errors import MissingChannelError
from ..logs import cdr, mcapio, types

if TYPE_CHECKING:
    from ..logs.scan import Odometry, ScanRun


@dataclass
class Decoded:
    """One channel decoded into arrays: message k's elements of sequence field f are
    `items[f][offsets[f][k]:offsets[f][k + 1]]`; `scalars[name][k]` are its numeric scalar fields."""

    stamps: np.ndarray  # (N,) int64, header stamps, ns
    frame_id: str
    scalars: dict[str, np.ndarray] = field(default_factory=dict)
    items: dict[str, np.ndarray] = field(default_factory=dict)
    offsets: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.stamps)

    def counts(self, name: str) -> np.ndarray:
        """Elements of sequence `name` in each message, (N,) int64."""
        return np.diff(self.offsets[name])

    def message_index(self, name: str) -> np.ndarray:
        """For each element of sequence `name`, the index of its message."""
        return np.repeat(np.arange(len(self.stamps)), self.counts(name))


def decode_channel(msgtype: str, payloads: list[bytes], first: int = 0) -> Decoded:
    """Decode every CDR payload of a flat datmo_msgs type into a Decoded (cdr.DecodeError names a damaged one,
    counted from `first`: wrap the call in mcapio.decoding to name the file and topic too)."""
    decoded = cdr.decode_many(msgtype, payloads, first)
    stamps = np.array([d["stamp_ns"] for d in decoded], np.int64)
    out = Decoded(stamps, decoded[0]["frame_id"] if decoded else "")
    if not decoded:
        return out
    for name, value in decoded[0].items():
        if name in ("stamp_ns", "frame_id") or isinstance(value, str):
            continue
        if isinstance(value, np.ndarray) and value.dtype.names:
            parts = [d[name] for d in decoded]  # joined as bytes: np.concatenate promotes the dtype per part
            out.items[name] = np.frombuffer(b"".join([p.tobytes() for p in parts]), value.dtype).copy()
            out.offsets[name] = np.concatenate([[0], np.cumsum([len(p) for p in parts])]).astype(np.int64)
        elif not isinstance(value, np.ndarray):
            out.scalars[name] = np.array([d[name] for d in decoded])
    return out


def require(log: mcapio.LogContents, topic: str) -> None:
    """Raise MissingChannelError naming the command that makes `topic` when the log has no messages on it."""
    if not log.has(topic):
        maker = mcapio.PRODUCER.get(topic)
        hint = f"; run {maker} first" if maker else ""
        raise MissingChannelError(f"{log.path}: no messages on {topic}{hint}")


@dataclass
class RunData:
    """The decoded channels of one processed log that the report, the plot and evaluate use."""

    name: str
    metadata: dict[str, dict[str, str]]
    scan_stamps: np.ndarray  # (N,) int64 ns
    n_beams: int
    tracks: Decoded
    features: Decoded | None = None
    landmarks: Decoded | None = None
    ground_truth: Decoded | None = None
    scans: ScanRun | None = None  # for the plot
    odometry: Odometry | None = None

    @classmethod
    def from_log(cls, log: mcapio.LogContents, *, keep_scans: bool = False) -> RunData:
        """Decode a log read with (at least) /scan and /datmo/tracks; the other channels when present.

        Raises MissingChannelError naming the command to run first when /scan or /datmo/tracks is absent.
        """
        require(log, mcapio.TOPIC_SCAN)
        require(log, mcapio.TOPIC_TRACKS)
        run = mcapio.run_from_log(log)

        def channel(topic: str, msgtype: str) -> Decoded | None:
            stamps, payloads = log.messages.get(topic, ([], []))
            with mcapio.decoding(log.path, topic):
                return decode_channel(msgtype, payloads) if payloads else None

        return cls(
            name=str(log.path),
            metadata=log.metadata,
            scan_stamps=run.stamps,
            n_beams=run.geometry.n_beams,
            tracks=channel(mcapio.TOPIC_TRACKS, types.TRACKS) or decode_channel(types.TRACKS, []),
            features=channel(mcapio.TOPIC_FEATURES, types.FEATURES),
            landmarks=channel(mcapio.TOPIC_LANDMARKS, types.LANDMARKS),
            ground_truth=channel(mcapio.TOPIC_GROUND_TRUTH, types.GROUND_TRUTH),
            scans=run if keep_scans else None,
            odometry=mcapio.odometry_from_log(log),
        )
