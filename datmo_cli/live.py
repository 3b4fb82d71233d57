"""The live view: a log's channels served to Foxglove over its WebSocket protocol (foxglove-sdk), as they are
made.

`datmo play` publishes a log at its own rate (scans segmented, their features extracted and tracked on the
fly when the log has no /datmo/tracks); `datmo record --live` publishes each scan as it arrives from the
scanner. Every channel goes out with its ROS 2 schema (ros2msg) and CDR payloads, as in the log files, so
Foxglove decodes them as it decodes a datmo log. Transforms: the log's own /tf and /tf_static when it has
them; else, with odometry, odom -> base_link at every scan stamp on /tf (and base_link -> the scan's frame,
identity, on /tf_static when the frames differ). Static transforms are sent again every second, so a client
that subscribes late still places the scan.

Times are the log's (header stamps, ns): the server advertises the time capability and broadcasts each
scan's stamp, so Foxglove's clock follows the log (and restarts with it when `play --loop` starts over).

Clients: foxglove-sdk's server accepts only the subprotocol `foxglove.sdk.v1` (Foxglove's app today), while
the public protocol (github.com/foxglove/ws-protocol) and the clients written to it (`@foxglove/ws-protocol`,
Lichtblick, older apps) ask for `foxglove.websocket.v1`: the same protocol under its older name. So the SDK's
server listens on a loopback port of its own, and a small front (`_Front`, on `websockets`) takes the
clients on the port asked for, accepts either name, and relays each client's frames to and from the SDK's
server unchanged.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING
from urllib.parse import quote

import numpy as np

from .errors import ConfigError
from .extras import require
from .log import mcapio, types
from .log.scan import Odometry, ScanGeometry, ScanRun
from .log.transforms import Transform, encode_tf

if TYPE_CHECKING:
    from .config import DatmoConfig

TOPIC_TF = "/tf"
TOPIC_TF_STATIC = "/tf_static"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
STATIC_EVERY_NS = 1_000_000_000  # static transforms are sent again after this much log time
SUBPROTOCOL = "foxglove.sdk.v1"  # what the SDK's server speaks (the app's WebSocket data source)
PUBLIC_SUBPROTOCOL = "foxglove.websocket.v1"  # the public spec's name for the same protocol
SUBPROTOCOLS = (SUBPROTOCOL, PUBLIC_SUBPROTOCOL)  # what the front accepts, the first preferred
MIN_LOOP_PASS_S = 1.0  # play --loop: a pass of the log lasts at least this long (s, wall time)
_APP = "https://app.foxglove.dev/"


def require_foxglove():
    """The foxglove module (with its websocket module loaded), or MissingExtraError naming the live extra
    (which also brings websockets, for the front)."""
    require("foxglove.websocket", for_="the live view")
    require("websockets.asyncio.server", for_="the live view")
    return require("foxglove", for_="the live view")


def ws_url(host: str, port: int) -> str:
    """The WebSocket URL a client on this machine or the network opens: a wildcard host ('0.0.0.0', '::',
    '') becomes this machine's name."""
    import socket

    if host in ("", "0.0.0.0", "::"):
        host = socket.gethostname()
    if ":" in host and not host.startswith("["):
        host = f"[{host}]"  # an IPv6 address
    return f"ws://{host}:{port}"


def app_url(host: str, port: int) -> str:
    """The Foxglove web app's URL that opens the server at `host`:`port` as its data source."""
    return f"{_APP}?ds=foxglove-websocket&ds.url={quote(ws_url(host, port), safe='')}"


@dataclass(frozen=True)
class Message:
    """One message to publish: its time (the header stamp, ns), topic, ROS 2 type and CDR payload."""

    stamp: int
    topic: str
    msgtype: str
    payload: bytes


# ------------------------------------------------------------------------------------------- transforms


def tf_payload(stamp: int, transforms: Iterable[tuple[str, str, float, float, float]]) -> bytes:
    """CDR of a tf2_msgs/msg/TFMessage stamped `stamp` (ns) holding `transforms`: (parent frame, child
    frame, x m, y m, yaw rad) each, in the plane."""
    return encode_tf([Transform.planar(stamp, parent, child, x, y, yaw) for parent, child, x, y, yaw in transforms])


class Transforms:
    """The transforms a log lacks, scan by scan: with odometry, odom -> base_link at each scan's stamp
    (/tf) and base_link -> the scan's frame, identity, when the two differ (/tf_static, every second of log
    time). Nothing when the log has /tf of its own or no odometry."""

    def __init__(self, odometry: Odometry | None, scan_frame: str, has_own: bool) -> None:
        self.odometry = odometry if odometry is not None and len(odometry) and not has_own else None
        self.scan_frame = scan_frame
        self._static_at: int | None = None

    def topics(self) -> dict[str, str]:
        """{topic: message type} of what `messages` gives (to advertise them before the first)."""
        if self.odometry is None:
            return {}
        static = self.odometry.child_frame_id != self.scan_frame
        return {TOPIC_TF: TF_MESSAGE} | ({TOPIC_TF_STATIC: TF_MESSAGE} if static else {})

    def messages(self, stamps: np.ndarray) -> list[Message]:
        o = self.odometry
        if o is None or not len(stamps):
            return []
        out = []
        static = o.child_frame_id != self.scan_frame
        for stamp, (x, y, yaw) in zip(stamps.tolist(), o.at(stamps).tolist(), strict=True):
            if static and (
                self._static_at is None or stamp - self._static_at >= STATIC_EVERY_NS or stamp < self._static_at
            ):
                out.append(
                    Message(
                        stamp,
                        TOPIC_TF_STATIC,
                        TF_MESSAGE,
                        tf_payload(stamp, [(o.child_frame_id, self.scan_frame, 0.0, 0.0, 0.0)]),
                    )
                )
                self._static_at = stamp
            out.append(
                Message(stamp, TOPIC_TF, TF_MESSAGE, tf_payload(stamp, [(o.frame_id, o.child_frame_id, x, y, yaw)]))
            )
        return out


# ------------------------------------------------------------------------------------------- the server


class LiveServer:
    """A Foxglove WebSocket server on `host`:`port` (0: any free port) publishing ROS 2 messages.

    `declare` advertises a channel before it has messages (so a client can subscribe and playback wait for
    it); `publish` sends a Message (the channel declared on first use); `subscribed` is set once a client
    subscribes to any channel. Static transforms are kept and sent again with `repeat_static`. `option`:
    the port's option, as errors name it."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "datmo", option: str = "--port") -> None:
        foxglove = require_foxglove()
        from foxglove.websocket import Capability

        self._foxglove = foxglove
        self.host = host
        self.context = foxglove.Context()
        self.subscribed = threading.Event()
        self.channels: dict[str, object] = {}
        self.static: dict[str, Message] = {}
        self.sent = 0
        try:
            self.server = foxglove.start_server(
                name=name,
                host="127.0.0.1",
                port=0,
                capabilities=[Capability.Time],
                server_listener=_Listener(self.subscribed),
                context=self.context,
            )
        except Exception as exc:  # the SDK raises its own errors
            raise ConfigError(f"{option} {port}: cannot start the live view's server ({_reason(exc)})") from None
        try:
            self.front = _Front(host, port, f"ws://127.0.0.1:{self.server.port}")
        except Exception as exc:  # OSError for a busy port, a bad host or a name that does not resolve
            self.server.stop()
            raise ConfigError(f"{option} {port}: cannot serve on {host}:{port} ({_reason(exc)})") from None
        self.port = self.front.port

    @property
    def url(self) -> str:
        return ws_url(self.host, self.port)

    @property
    def app_url(self) -> str:
        return app_url(self.host, self.port)

    def declare(self, topic: str, msgtype: str, schema: bytes | None = None, encoding: str = "ros2msg") -> None:
        """Advertise `topic` with its ROS 2 type's schema (`schema`: the log's own text, else datmo's)."""
        if topic in self.channels:
            return
        data = schema if schema else types.schema_text(msgtype).encode()
        self.channels[topic] = self._foxglove.Channel(
            topic,
            schema=self._foxglove.Schema(name=msgtype, encoding=encoding, data=data),
            message_encoding="cdr",
            context=self.context,
        )

    def declare_log(self, log: mcapio.LogContents, exclude: Iterable[str] = ()) -> None:
        """Advertise every channel of `log` that holds messages (but `exclude`), with the log's own schemas."""
        skip = set(exclude)
        for ch in log.topics().values():
            if ch.count and ch.topic not in skip and ch.message_encoding == "cdr":
                self.declare(ch.topic, ch.msgtype, ch.schema_data, ch.schema_encoding or "ros2msg")

    def publish(self, message: Message) -> None:
        if message.topic not in self.channels:
            self.declare(message.topic, message.msgtype)
        self.channels[message.topic].log(message.payload, log_time=message.stamp)
        if message.topic == TOPIC_TF_STATIC:
            self.static[message.topic] = message
        self.sent += 1

    def repeat_static(self, stamp: int) -> None:
        """Send the static transforms again (for clients that subscribed after they went out)."""
        for m in self.static.values():
            self.channels[m.topic].log(m.payload, log_time=stamp)

    def time(self, stamp: int) -> None:
        """Tell the clients the log's time is now `stamp` (ns)."""
        self.server.broadcast_time(int(stamp))

    def restart(self) -> None:
        """A new session: clients drop what they hold (the log's time starts over)."""
        self.static.clear()
        self.server.clear_session()

    def close(self) -> None:
        self.front.close()
        for ch in self.channels.values():
            ch.close()
        self.server.stop()


class _Listener:
    """The server's listener: notes the first subscription. The SDK calls on_unsubscribe for each channel a
    client leaves (it is not optional: without it every client that leaves printed an AttributeError)."""

    def __init__(self, subscribed: threading.Event) -> None:
        self.subscribed = subscribed

    def on_subscribe(self, client, channel) -> None:
        self.subscribed.set()

    def on_unsubscribe(self, client, channel) -> None:
        pass


_QUIET = logging.getLogger("datmo.live.front")  # the front's connection log: kept off the terminal
_QUIET.addHandler(logging.NullHandler())
_QUIET.propagate = False


class _Front:
    """The port clients connect to: a WebSocket server (its own thread and event loop) that accepts a client
    asking for any of SUBPROTOCOLS (else HTTP 400, as the SDK's server answers), opens a connection of its own
    to the SDK's server at `backend` (a ws:// URL), and relays every frame both ways,
    unchanged, until either side closes; then it closes the other. Nothing is printed when a client leaves or
    fails. Raises OSError when it cannot listen on `host`:`port`."""

    def __init__(self, host: str, port: int, backend: str) -> None:
        self.backend = backend
        self.loop = asyncio.new_event_loop()
        self._server = None
        started: concurrent.futures.Future = concurrent.futures.Future()
        self._thread = threading.Thread(
            target=self._run, args=(host, port, started), name="datmo-live-front", daemon=True
        )
        self._thread.start()
        self.port = started.result()

    def _run(self, host: str, port: int, started: concurrent.futures.Future) -> None:
        from websockets.asyncio.server import serve

        async def listen():
            return await serve(
                self._relay, host, port, subprotocols=list(SUBPROTOCOLS), compression=None, max_size=None, logger=_QUIET
            )

        asyncio.set_event_loop(self.loop)
        try:
            self._server = self.loop.run_until_complete(listen())
        except BaseException as exc:
            started.set_exception(exc)
            self.loop.close()
            return
        started.set_result(self._server.sockets[0].getsockname()[1])
        try:
            self.loop.run_forever()
        finally:
            self.loop.close()

    async def _relay(self, client) -> None:
        from websockets.asyncio.client import connect

        try:
            async with connect(
                self.backend, subprotocols=[SUBPROTOCOL], compression=None, max_size=None, logger=_QUIET
            ) as backend:
                pipes = [asyncio.create_task(_pipe(client, backend)), asyncio.create_task(_pipe(backend, client))]
                _, pending = await asyncio.wait(pipes, return_when=asyncio.FIRST_COMPLETED)
                for task in pending:
                    task.cancel()
                await asyncio.gather(*pipes, return_exceptions=True)  # each outcome taken: none is logged
        except Exception:  # the client or the SDK's server went away: nothing to tell
            pass

    def close(self, timeout: float = 5.0) -> None:
        """Stop listening and close every client's connection (and its relay)."""
        if self._server is None or self.loop.is_closed():
            return

        async def stop() -> None:
            self._server.close()
            await self._server.wait_closed()
            self.loop.stop()

        try:
            asyncio.run_coroutine_threadsafe(stop(), self.loop)
        except RuntimeError:  # the loop already closed
            return
        self._thread.join(timeout)


async def _pipe(source, sink) -> None:
    """Send every message from WebSocket connection `source` on `sink`, as it came (text or binary)."""
    async for message in source:
        await sink.send(message)


def _reason(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    text = str(exc).strip().splitlines()
    return text[0].removeprefix("FoxgloveError: ") if text else type(exc).__name__


# ------------------------------------------------------------------------------------ what gets published


class Stages:
    """Segmentation, features and tracking of scans as they come (pipeline.RunStages, its state carried from
    call to call): `messages(run)` gives the derived messages of the next scans, with the transforms."""

    def __init__(
        self,
        odometry: Odometry | None,
        config: DatmoConfig | None = None,
        estimated: bool = False,
        has_tf: bool = False,
        scan_frame: str = "laser",
    ) -> None:
        from .pipeline import RunStages

        self.stages = RunStages(odometry, config, estimated=estimated)
        self.derived = self.stages.derived()
        self.transforms = Transforms(odometry, scan_frame, has_tf or TOPIC_TF in self.derived)
        self.first = 0

    def messages(self, run: ScanRun) -> list[Message]:
        from .streaming import Block

        out = self.transforms.messages(run.stamps)
        for topic, (msgtype, stamps, payloads) in self.stages(Block(self.first, run)).items():
            out += [Message(int(s), topic, msgtype, bytes(p)) for s, p in zip(stamps, payloads, strict=True)]
        self.first += len(run)
        return out


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
        from .log import cdr

        out: list[Message] = []
        if self.features and mcapio.TOPIC_FEATURES in copies:
            from .perception.markers import scan_feature_markers

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
            from .tracking.markers import track_markers

            world = self.odometry is not None
            for stamp, payload in zip(*copies[mcapio.TOPIC_TRACKS], strict=True):
                with mcapio.decoding(self.path, mcapio.TOPIC_TRACKS):
                    msg = cdr.decode(types.TRACKS, payload)
                tracks = msg["tracks"]
                tail, count = self._tails(tracks, world)
                frame = self.odometry.frame_id if world else msg["frame_id"]
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
        from .pipeline import open_stages
        from .streaming import LogStream

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
        from .config import DatmoConfig

        return DrawnMarkers(self.stream, self.odometry, (self.config or DatmoConfig()).track.tail_length)

    def declare(self, server: LiveServer) -> None:
        """Advertise every channel this source will publish (transforms as they come)."""
        server.declare_log(self.stream.log, exclude=self.derived)
        for topic, msgtype in (self.derived | self.drawn | self.transforms.topics()).items():
            server.declare(topic, msgtype)

    def batches(self) -> Iterator[list[Message]]:
        """The log from its start, a block of scans at a time (the block's messages in time order)."""
        stages = None if self.processed else Stages(self.odometry, self.config, self.estimated, has_tf=True)
        transforms = Transforms(self.transforms.odometry, self.transforms.scan_frame, False)
        drawn = self._drawn() if self.drawn else None
        for block in self.stream.blocks(self.block_scans, copy=set(self.copied)):
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
    sleep: Callable[[float], None] = time.sleep,
    clock: Callable[[], float] = time.monotonic,
) -> int:
    """Publish `source` on `server` at `rate` times the log's speed, from the start again after the end with
    `loop` (a new session each time, each pass lasting at least MIN_LOOP_PASS_S, so that a log of one scan
    does not spin); returns the number of scans sent. `sleep` and `clock`: time.sleep and time.monotonic."""
    scans = 0
    while True:
        pace = Pace(rate, clock)
        started = clock()
        last_static: int | None = None
        for batch in source.batches():
            for m in batch:
                pace.wait(m.stamp, sleep)
                if m.topic == source.stream.scan_topic:
                    server.time(m.stamp)
                    scans += 1
                    if last_static is None or m.stamp - last_static >= STATIC_EVERY_NS:
                        server.repeat_static(m.stamp)
                        last_static = m.stamp
                server.publish(m)
        if not loop:
            return scans
        rest = started + MIN_LOOP_PASS_S - clock()
        if rest > 0:
            sleep(rest)
        server.restart()


# ---------------------------------------------------------------------------------- record --live


class LiveFeed:
    """Scans as they arrive (from a recording, or `datmo node`'s subscription), processed and published on a
    thread of their own so that whoever brings them never waits: `scan(stamp, ranges, geometry)` queues a scan;
    `close()` finishes. When processing is behind by `backlog` scans, a scan is dropped and counted: the new one,
    or with `drop_oldest` the oldest waiting. A scan of another geometry than the one before, or stamped before
    it, starts the stages over (new tracks; counted in `restarts`, and `on_restart(why)` is called); one stamped
    the same as the one before is skipped (`skipped`). `odometry`: poses of the sensor's base as they arrive
    (PoseBuffer), which put tracking in the world frame; `scans`: also publish each scan on /scan (the live
    view; `datmo node` does not, the robot has it). A failure stops the feed, not its source (`failure` says
    what it was)."""

    def __init__(
        self,
        server,
        config: DatmoConfig | None = None,
        backlog: int = 256,
        batch: int = 16,
        *,
        odometry: PoseBuffer | None = None,
        drop_oldest: bool = False,
        scans: bool = True,
        on_restart: Callable[[str], None] | None = None,
    ) -> None:
        self.server = server
        self.config = config
        self.batch = batch
        self.odometry = odometry
        self.drop_oldest = drop_oldest
        self.scans = scans
        self.on_restart = on_restart
        self.queue: queue.Queue = queue.Queue(maxsize=backlog)
        self.dropped = 0
        self.published = 0
        self.restarts = 0
        self.skipped = 0
        self.failure: str | None = None
        self._thread = threading.Thread(target=self._run, name="datmo-live", daemon=True)
        self._thread.start()

    def warm_up(self) -> None:
        """Load the stages' compiled kernels now, on a made-up scan: loading them takes the interpreter for
        a second or so, which must happen before the scanner streams, not while its bytes arrive."""
        geometry = ScanGeometry(
            angle_min=-math.pi / 2, angle_increment=math.pi / 360, n_beams=361, range_min=0.0, range_max=8.0
        )
        run = ScanRun(np.array([0, 100_000_000]), np.full((2, geometry.n_beams), 3.0, np.float32), geometry)
        Stages(None, self.config).messages(run)

    def scan(self, stamp_ns: int, ranges: np.ndarray, geometry: ScanGeometry) -> None:
        if self.failure is not None:
            return
        item = (int(stamp_ns), np.array(ranges, np.float32), geometry)
        try:
            self.queue.put_nowait(item)
        except queue.Full:
            self.dropped += 1
            if not self.drop_oldest:
                return
            try:
                self.queue.get_nowait()
            except queue.Empty:  # the feed took them all meanwhile
                pass
            try:
                self.queue.put_nowait(item)
            except queue.Full:  # another caller filled it again: this one goes
                pass

    def close(self, timeout: float = 5.0) -> None:
        """Stop the thread (after the queued scans, waiting at most `timeout` seconds)."""
        try:
            self.queue.put(None, timeout=timeout)
        except queue.Full:  # the thread has stopped (a failure) with the queue full
            return
        self._thread.join(timeout)

    def _run(self) -> None:
        stages: Stages | None = None
        last: tuple[int, ScanGeometry] | None = None
        try:
            while True:
                items = [self.queue.get()]
                while items[-1] is not None and len(items) < self.batch:
                    try:
                        items.append(self.queue.get_nowait())
                    except queue.Empty:
                        break
                run: list[tuple[int, np.ndarray, ScanGeometry]] = []
                for item in items:
                    if item is None:
                        break
                    stamp, _, geometry = item
                    why = None if last is None else _why_restart(last, stamp, geometry)
                    if why == "":
                        self.skipped += 1
                        continue
                    if why is not None:
                        self._publish(stages, run)
                        run, stages = [], None
                        self.restarts += 1
                        if self.on_restart is not None:
                            self.on_restart(why)
                    if stages is None:
                        stages = Stages(
                            self.odometry, self.config, has_tf=self.odometry is not None, scan_frame=geometry.frame_id
                        )
                    run.append(item)
                    last = (stamp, geometry)
                self._publish(stages, run)
                if items[-1] is None:
                    return
        except Exception as exc:  # the view may fail; the recording goes on
            self.failure = f"{type(exc).__name__}: {exc}"

    def _publish(self, stages: Stages | None, scans: list[tuple[int, np.ndarray, ScanGeometry]]) -> None:
        """Process `scans` (one geometry, stamps increasing) and publish them and what they gave."""
        from .log.scan import encode_scan

        if not scans or stages is None:
            return
        geometry = scans[0][2]
        run = ScanRun(np.array([s for s, _, _ in scans], np.int64), np.stack([r for _, r, _ in scans]), geometry)
        derived = stages.messages(run)
        for stamp, ranges, g in scans:
            self.server.time(stamp)
            if self.scans:
                self.server.publish(Message(stamp, mcapio.TOPIC_SCAN, types.LASERSCAN, encode_scan(stamp, ranges, g)))
        for m in derived:
            self.server.publish(m)
        self.published += len(scans)


def _why_restart(last: tuple[int, ScanGeometry], stamp: int, geometry: ScanGeometry) -> str | None:
    """Why a scan stamped `stamp` (ns) of `geometry` cannot follow the scan `last` (stamp, geometry) in one run
    of the stages: a sentence; "" when it repeats the last scan's stamp; None when it follows."""
    before, g = last
    if not geometry.same_beams(g) or geometry.frame_id != g.frame_id:
        return (
            f"the scans' geometry changed ({g.n_beams} beams from {math.degrees(g.angle_min):g} deg in "
            f"{g.frame_id!r}, now {geometry.n_beams} from {math.degrees(geometry.angle_min):g} deg in "
            f"{geometry.frame_id!r})"
        )
    if stamp == before:
        return ""
    if stamp < before:
        return f"the scans' time went back by {(before - stamp) / 1e9:.3f} s"
    return None


class PoseBuffer:
    """Odometry as it arrives, for LiveFeed: the latest `keep` poses of the sensor's base in the world frame
    (stamp ns, x and y in metres, theta in radians), read as log.scan.Odometry is (`at`, `len`, the frames).
    A pose stamped at or before the latest one is not kept (`stale` counts them). Thread-safe."""

    def __init__(self, keep: int = 1024) -> None:
        self.keep = keep
        self.frame_id, self.child_frame_id = "odom", "base_link"
        self.stale = 0
        self._poses: list[tuple[int, float, float, float]] = []
        self._lock = threading.Lock()

    def add(self, stamp: int, x: float, y: float, theta: float, frame_id: str = "", child_frame_id: str = "") -> None:
        with self._lock:
            if self._poses and stamp <= self._poses[-1][0]:
                self.stale += 1
                return
            self._poses.append((int(stamp), float(x), float(y), float(theta)))
            if len(self._poses) > 2 * self.keep:
                del self._poses[: -self.keep]
            self.frame_id = frame_id or self.frame_id
            self.child_frame_id = child_frame_id or self.child_frame_id

    def __len__(self) -> int:
        with self._lock:
            return len(self._poses)

    def at(self, stamps: np.ndarray) -> np.ndarray:
        """Poses (K x 3: x, y, theta) at `stamps` (ns), interpolated; the latest held past the end."""
        with self._lock:
            recent = self._poses[-self.keep :]
        if not recent:
            raise ValueError("no odometry has arrived")
        xyt = np.array([p[1:] for p in recent], np.float64)
        stamps_ns = np.fromiter((p[0] for p in recent), np.int64, len(recent))
        return Odometry(stamps_ns, xyt[:, 0], xyt[:, 1], xyt[:, 2]).at(stamps)
