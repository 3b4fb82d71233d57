"""`datmo play`: a log's messages published at its own rate (LogSource, Pace, play), its scans processed on the
fly when it has no /datmo/tracks, and the markers of a processed log stored without them drawn as it plays
(DrawnMarkers)."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..logs import mcapio, types
from ..logs.scan import Odometry
from .control import PlaybackControl
from .messages import STATIC_EVERY_NS, TOPIC_TF, Message, Stages, Transforms

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig
    from .server import LiveServer


MIN_LOOP_PASS_S = 1.0  # play --loop: a pass of the log lasts at least this long (s, wall time)


class DrawnMarkers:
    """The Foxglove markers of a processed log stored without them (datmo run, track and features store them
    only with --markers), drawn as it plays, as the stages draw them: /datmo/markers/tracks from /datmo/tracks
    (each track's tail from its positions in the scans before, `tail_length` of them) and
    /datmo/markers/features from /datmo/features and /datmo/landmarks. `odometry`: the log's (tracks and
    landmarks then in its world frame)."""

    def __init__(self, stream, odometry: Odometry | None, tail_length: int = 20) -> None:
        self.tracks = stream.has(mcapio.TOPIC_TRACKS) and not stream.has(mcapio.TOPIC_MARKERS_TRACKS)
        self.features = stream.has(mcapio.TOPIC_FEATURES) and not stream.has(mcapio.TOPIC_MARKERS_FEATURES)
        self.path = stream.path
        self.odometry = odometry if odometry is not None and len(odometry) else None
        self.tail_length = max(int(tail_length), 1)
        self.tails: dict[int, tuple[np.ndarray, int]] = {}  # track id: (ring of positions (T, 2), positions written)

    def topics(self) -> dict[str, str]:
        """{topic: message type} of what `messages` gives."""
        return ({mcapio.TOPIC_MARKERS_FEATURES: types.MARKER_ARRAY} if self.features else {}) | (
            {mcapio.TOPIC_MARKERS_TRACKS: types.MARKER_ARRAY} if self.tracks else {}
        )

    def messages(self, copies: dict[str, tuple[list[int], list[bytes]]]) -> list[Message]:
        """The markers of a block's messages ({topic: (log times, payloads)}, as streaming.Block.copies)."""
        from ..logs import cdr

        out: list[Message] = []
        if self.features and mcapio.TOPIC_FEATURES in copies:
            from ..perception.markers import scan_feature_markers

            stamps, payloads = copies[mcapio.TOPIC_FEATURES]
            lm_stamps, lm_payloads = copies.get(mcapio.TOPIC_LANDMARKS, ([], []))
            landmarks = dict(zip(lm_stamps, lm_payloads, strict=True))
            poses = self.odometry.at(np.asarray(stamps, np.int64)) if self.odometry is not None and stamps else None
            for k, (stamp, payload) in enumerate(zip(stamps, payloads, strict=True)):
                with mcapio.decoding(self.path, mcapio.TOPIC_FEATURES):
                    f = cdr.decode(types.FEATURES, payload)
                lm = landmarks.get(stamp)
                with mcapio.decoding(self.path, mcapio.TOPIC_LANDMARKS):
                    elems = cdr.decode(types.LANDMARKS, lm)["landmarks"] if lm is not None else None
                drawn = scan_feature_markers(
                    f["stamp_ns"],
                    f["frame_id"],
                    f["lines"],
                    f["circles"],
                    f["blobs"],
                    elems,
                    poses[k] if poses is not None and elems is not None else None,
                )
                out.append(Message(int(stamp), mcapio.TOPIC_MARKERS_FEATURES, types.MARKER_ARRAY, drawn))
        if self.tracks and mcapio.TOPIC_TRACKS in copies:
            from ..tracking.markers import track_markers

            world = self.odometry is not None
            for stamp, payload in zip(*copies[mcapio.TOPIC_TRACKS], strict=True):
                with mcapio.decoding(self.path, mcapio.TOPIC_TRACKS):
                    msg = cdr.decode(types.TRACKS, payload)
                tracks = msg["tracks"]
                tail, count = self._tails(tracks, world)
                frame = self.odometry.frame_id if self.odometry is not None else msg["frame_id"]
                drawn = track_markers(msg["stamp_ns"], frame, tracks, tail, count, world=world)
                out.append(Message(int(stamp), mcapio.TOPIC_MARKERS_TRACKS, types.MARKER_ARRAY, drawn))
        return out

    def _tails(self, tracks: np.ndarray, world: bool) -> tuple[np.ndarray, np.ndarray]:
        """Each track's ring of recent positions with this scan's added (as the tracker keeps them), and the
        positions written to it; tracks gone are forgotten."""
        T = self.tail_length
        xs, ys = tracks["world_x" if world else "x"].tolist(), tracks["world_y" if world else "y"].tolist()
        tail = np.zeros((len(tracks), T, 2))
        count = np.zeros(len(tracks), np.int64)
        kept = {}
        for k, tid in enumerate(tracks["id"].tolist()):
            ring, n = self.tails.get(tid) or (np.zeros((T, 2)), 0)
            ring[n % T] = xs[k], ys[k]
            kept[tid] = (ring, n + 1)
            tail[k], count[k] = ring, n + 1
        self.tails = kept
        return tail, count


def _ordered(messages: list[Message], order: dict[str, int]) -> list[Message]:
    """In time order; at one instant the scan first, then the channels in `order` (the log's, then derived)."""
    return sorted(messages, key=lambda m: (m.stamp, order.get(m.topic, len(order))))


class LogSource:
    """A log's messages as the live view publishes them, a short block at a time, in time order: the log's
    channels, and when it has no /datmo/tracks, segmentation, features and tracks made from its scans (with
    the transforms; the channels those stages make replace any the log has); a processed log stored without
    markers gets them drawn from its tracks and features (DrawnMarkers)."""

    def __init__(self, path: str | Path, config: DatmoConfig | None = None, block_scans: int = 32) -> None:
        from ..passes.pipeline import open_stages
        from ..passes.streaming import LogStream

        self.stream = LogStream(path)
        self.block_scans = block_scans
        self.config = config
        self.processed = self.stream.has(mcapio.TOPIC_TRACKS)
        self.odometry, self.estimated = None, False
        self.derived: dict[str, str] = {}
        if not self.processed:
            stages = open_stages(self.stream, config)
            self.odometry, self.estimated, self.derived = stages.odometry, stages.estimated, stages.derived()
        else:
            self.odometry = self.stream.odometry
        self.drawn = self._drawn().topics() if self.processed else {}
        self.transforms = Transforms(
            self.odometry, self._scan_frame(), self.stream.has(TOPIC_TF) or TOPIC_TF in self.derived
        )
        topics = [c.topic for c in self.stream.log.topics().values() if c.count and c.topic not in self.derived]
        self.copied = topics
        self.order = {
            t: i for i, t in enumerate([self.stream.scan_topic] + topics + list(self.derived) + list(self.drawn))
        }

    def _drawn(self) -> DrawnMarkers:
        from ..passes.config import DatmoConfig

        return DrawnMarkers(self.stream, self.odometry, (self.config or DatmoConfig()).track.tail_length)

    def declare(self, server: LiveServer) -> None:
        """Advertise every channel this source will publish (transforms as they come)."""
        server.declare_log(self.stream.log, exclude=self.derived)
        for topic, msgtype in (self.derived | self.drawn | self.transforms.topics()).items():
            server.declare(topic, msgtype)

    @property
    def span(self) -> tuple[int, int]:
        """The log times (ns) of its first and last scans."""
        scans = self.stream.log.topics().get(self.stream.scan_topic)
        return (scans.first_ns, scans.last_ns) if scans is not None and scans.count else (0, 0)

    def batches(self, start: int | None = None) -> Iterator[list[Message]]:
        """The log from its start, or from its first scan at or after log time `start` (ns), a block of scans
        at a time (the block's messages in time order). From `start`, the log's messages before it are not
        given, and the stages (a log processed on the fly) start there as on a log that started there: tracks
        start over (a processed log's are its own)."""
        stages = (
            None
            if self.processed
            else Stages(self.odometry, self.stream.geometry, self.config, self.estimated, has_tf=True)
        )
        transforms = Transforms(self.transforms.odometry, self.transforms.scan_frame, False)
        drawn = self._drawn() if self.drawn else None
        for block in self.stream.blocks(self.block_scans, copy=set(self.copied)):
            if start is not None and not _from(block, start):
                continue
            out = []
            for topic, (stamps, payloads) in block.copies.items():
                msgtype = self.stream.log.topics()[topic].msgtype
                out += [Message(int(s), topic, msgtype, bytes(p)) for s, p in zip(stamps, payloads, strict=True)]
            out += transforms.messages(block.run.stamps)
            if drawn is not None:
                out += drawn.messages(block.copies)
            if stages is not None:
                out += stages.messages(block.run)
            yield _ordered(out, self.order)

    def _scan_frame(self) -> str:
        for run in self.stream.scans(1):
            return run.geometry.frame_id
        return "laser"


def _from(block, start: int) -> bool:
    """Trim `block` (a streaming.Block) to its scans at or after `start` (ns) and the messages at or after
    it; False when none of its scans is."""
    stamps = block.run.stamps
    if not len(stamps) or stamps[-1] < start:
        return False
    k = int(np.searchsorted(stamps, start))
    if k:
        block.run = block.run.slice(k, len(stamps))
        block.copies = {
            topic: ([s for s in times if s >= start], [p for s, p in zip(times, payloads, strict=True) if s >= start])
            for topic, (times, payloads) in block.copies.items()
        }
    return True


class Pace:
    """When to send a message of log time `stamp` (ns) so the log plays at `rate` times its own speed:
    `due(stamp)` is the monotonic time (s) to send it at, the clock starting at the first stamp given."""

    def __init__(self, rate: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.rate = rate
        self.clock = clock
        self.origin: tuple[int, float] | None = None

    def due(self, stamp: int) -> float:
        if self.origin is None:
            self.origin = (stamp, self.clock())
        first, start = self.origin
        return start + (stamp - first) / 1e9 / self.rate

    def rebase(self, stamp: int, rate: float) -> None:
        """Play on at `rate` from log time `stamp` (ns), now (after a pause or a change of speed)."""
        self.rate = rate
        self.origin = (stamp, self.clock())

    def wait(self, stamp: int, sleep: Callable[[float], None] = time.sleep) -> None:
        """Sleep until `stamp` is due (at once when it is past)."""
        delay = self.due(stamp) - self.clock()
        if delay > 0:
            sleep(delay)


def play(
    source: LogSource,
    server: LiveServer,
    *,
    rate: float = 1.0,
    loop: bool = False,
    sleep: Callable[[float], None] | None = None,
    clock: Callable[[], float] = time.monotonic,
    control: PlaybackControl | None = None,
) -> int:
    """Publish `source` on `server` at `rate` times the log's speed, from the start again after the end with
    `loop` (a new session each time, each pass lasting at least MIN_LOOP_PASS_S, so that a log of one scan
    does not spin); returns the number of scans sent. `control`: the clients' playback control (its speed
    replaces `rate`): paused, nothing is sent; a seek starts the log again at the first scan at or after the
    time asked, the time sent at once; at the end of the log (without `loop`) the server reports it ended and
    waits, while a client is subscribed, for a seek or play (play starts over), else returns. `sleep` and
    `clock`: time.sleep and time.monotonic (`sleep`: waits that no request cuts short, as tests give)."""
    control = control or PlaybackControl(*source.span, rate)
    wait = control.wait if sleep is None else (lambda _gen, s: sleep(s))
    scans, start = 0, None
    while True:
        if start is not None:
            server.time(start)
        started = clock()
        start, sent = _pass(source, server, control, start, clock, wait)
        scans += sent
        if start is not None:  # a seek
            continue
        if loop:
            rest = started + MIN_LOOP_PASS_S - clock()
            if rest > 0:
                wait(control.snapshot()[0], rest)
            server.restart()
            continue
        start = _hold(server, control)
        if start is None:
            return scans


def _pass(source, server, control, start, clock, wait) -> tuple[int | None, int]:
    """Send `source` from `start` (ns; None: its start) as `control` says: (the time a client sought, or None
    at the log's end; the scans sent)."""
    pace = Pace(control.speed, clock)
    scans = 0
    last_static: int | None = None
    for batch in source.batches(start):
        for m in batch:
            sought = _until_due(m.stamp, pace, control, clock, wait)
            if sought is not None:
                return sought, scans
            if m.topic == source.stream.scan_topic:
                server.time(m.stamp)
                scans += 1
                if last_static is None or m.stamp - last_static >= STATIC_EVERY_NS:
                    server.repeat_static(m.stamp)
                    last_static = m.stamp
            server.publish(m)
            control.sent(m.stamp)
    return None, scans


def _until_due(stamp: int, pace: Pace, control: PlaybackControl, clock, wait) -> int | None:
    """Wait until the message of log time `stamp` (ns) is due, paused as long as `control` is, the pace
    following its speed; the time sought when a client seeks meanwhile (else None)."""
    rebase = False
    while True:
        generation, paused, speed, seeking = control.snapshot()
        if seeking:
            return control.take_seek()
        if paused:
            rebase = True
            wait(generation, 0.5)
            continue
        if (rebase or speed != pace.rate) and pace.origin is not None:
            pace.rebase(control.now, speed)
        pace.rate, rebase = speed, False
        delay = pace.due(stamp) - clock()
        if delay <= 0:
            return None
        wait(generation, delay)


def _hold(server, control: PlaybackControl) -> int | None:
    """At the log's end: report it ended, and while a client is subscribed wait for a seek (or play, from the
    start): its time, or None when no client is left (or the server offers no playback control)."""
    if getattr(server, "control", None) is not control or not server.subscribers:
        return None
    server.playback_state(control.finish())
    while server.subscribers:
        generation, _, _, seeking = control.snapshot()
        if seeking:
            return control.take_seek()
        control.wait(generation, 0.2)
    return None
