"""The report of a log read in one streaming pass, BLOCK_MESSAGES messages at a time, in memory that does not
grow with the log's length: `stream_run` and `summarise_file`. The one place of the report that reads a file."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..base.errors import InputError
from ..logs import cdr, mcapio, types
from .accumulate import FEATURE_KINDS, RunAccumulator
from .decode import decode_channel, require
from .summary import RunSummary

BLOCK_MESSAGES = 1000  # messages decoded at once by summarise_file
SUMMARY_TOPICS = (mcapio.TOPIC_SCAN, mcapio.TOPIC_FEATURES, mcapio.TOPIC_LANDMARKS, mcapio.TOPIC_TRACKS)


def summarise_file(
    path: str | Path, *, block: int = BLOCK_MESSAGES, progress: Callable[[int], None] | None = None
) -> RunSummary:
    """The report of the processed log at `path`, read in one streaming pass (see `stream_run`) in memory
    that does not grow with the log's length: the same RunSummary as `summarise(RunData.from_log(...))`
    (but where a track's header stamps go back across blocks, never in a log datmo writes: see TrackStats).

    Raises as RunData.from_log: MissingChannelError naming the command to run first when /scan or
    /datmo/tracks is absent, InputError for a /scan channel that is not LaserScans or whose geometry changes.
    """
    return stream_run(path, block=block, progress=progress).summary()


def stream_run(
    path: str | Path, *, block: int = BLOCK_MESSAGES, progress: Callable[[int], None] | None = None
) -> RunAccumulator:
    """Walk the log at `path` once (mcapio.iter_messages, file order) and feed a RunAccumulator its /scan,
    /datmo/features, /datmo/landmarks and /datmo/tracks messages, `block` messages at a time: it holds at
    most `block` payloads and their decoded forms at once (`peak_messages` says how many it held), so
    memory does not depend on the log's length. Scans are decoded block by block for their header stamps
    and geometry (a change of geometry is refused as RunData.from_log refuses it). `progress(scans)` is
    called after each block with the number of scans read so far."""
    contents = mcapio.LogContents(path=Path(path))
    acc = RunAccumulator(str(Path(path)))
    pending: dict[str, list[bytes]] = {t: [] for t in SUMMARY_TOPICS}
    state: dict = {"geometry": None, "first": 0, "error": None, "seen": dict.fromkeys(SUMMARY_TOPICS, 0)}

    def flush() -> None:
        acc.peak_messages = max(acc.peak_messages, sum(len(p) for p in pending.values()))
        scans = pending[mcapio.TOPIC_SCAN]
        if scans and state["error"] is None:
            try:
                mcapio.check_scan_channel(contents)
                run = mcapio.decode_scan_block(contents.path, scans, state["first"], state["geometry"])
            except InputError as exc:  # raised after the channel checks, as RunData.from_log orders them
                state["error"] = exc
            else:
                state["geometry"] = run.geometry
                acc.add_scans(run.stamps, run.geometry.n_beams)
        state["first"] += len(scans)
        if progress is not None and scans:
            progress(state["first"])
        seen = state["seen"]  # messages of each topic before this block's (to name a damaged one)
        if pending[mcapio.TOPIC_FEATURES]:
            with mcapio.decoding(contents.path, mcapio.TOPIC_FEATURES):
                decoded = cdr.decode_many(types.FEATURES, pending[mcapio.TOPIC_FEATURES], seen[mcapio.TOPIC_FEATURES])
            acc.add_features(
                len(decoded),
                {k: np.array([len(d[k]) for d in decoded], np.int64) for k in FEATURE_KINDS if k in decoded[0]},
            )
        landmarks = pending[mcapio.TOPIC_LANDMARKS]
        if landmarks:
            k = seen[mcapio.TOPIC_LANDMARKS]
            with mcapio.decoding(contents.path, mcapio.TOPIC_LANDMARKS):  # the first and last: frame, database
                (head,) = cdr.decode_many(types.LANDMARKS, landmarks[:1], k)
                (last,) = cdr.decode_many(types.LANDMARKS, landmarks[-1:], k + len(landmarks) - 1)
            acc.add_landmarks(head["frame_id"] if acc.landmark_frame is None else "", last["landmarks"])
        if pending[mcapio.TOPIC_TRACKS]:
            with mcapio.decoding(contents.path, mcapio.TOPIC_TRACKS):
                tracks = decode_channel(types.TRACKS, pending[mcapio.TOPIC_TRACKS], seen[mcapio.TOPIC_TRACKS])
            if "tracks" in tracks.items:
                acc.add_tracks(tracks.stamps[tracks.message_index("tracks")], tracks.items["tracks"])
        for topic, payloads in pending.items():
            seen[topic] += len(payloads)
            payloads.clear()

    held = 0
    for topic, _, payload in mcapio.iter_messages(path, SUMMARY_TOPICS, contents):
        pending[topic].append(payload)
        held += 1
        if held == block:
            flush()
            held = 0
    flush()
    require(contents, mcapio.TOPIC_SCAN)
    require(contents, mcapio.TOPIC_TRACKS)
    if state["error"] is not None:
        raise state["error"]
    if acc.tracks.late:
        import warnings

        warnings.warn(
            f"{contents.path}: {acc.tracks.late} track state(s) come in the file after a later-stamped "
            "state of their track, blocks before; the report takes them in file order (occlusions, "
            "distances)",
            UserWarning,
            stacklevel=2,
        )
    acc.metadata = contents.metadata
    return acc
