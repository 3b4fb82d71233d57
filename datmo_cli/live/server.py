"""The live view's server: foxglove-sdk's WebSocket server on a loopback port of its own (LiveServer), behind a
small front (`_Front`, on `websockets`) on the port asked for, which accepts either name of the protocol
(`foxglove.sdk.v1`, `foxglove.websocket.v1`) and relays each client's frames unchanged."""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
from collections.abc import Iterable
from urllib.parse import quote

from ..base.errors import ConfigError
from ..base.extras import require
from ..logs import mcapio, types
from .control import ENDED, PAUSED, PLAYING, PlaybackControl, State
from .messages import TOPIC_TF_STATIC, Message

SUBPROTOCOL = "foxglove.sdk.v1"  # what the SDK's server speaks (the app's WebSocket data source)
PUBLIC_SUBPROTOCOL = "foxglove.websocket.v1"  # the public spec's name for the same protocol
SUBPROTOCOLS = (SUBPROTOCOL, PUBLIC_SUBPROTOCOL)  # what the front accepts, the first preferred


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


class LiveServer:
    """A Foxglove WebSocket server on `host`:`port` (0: any free port) publishing ROS 2 messages.

    `declare` advertises a channel before it has messages (so a client can subscribe and playback wait for
    it); `publish` sends a Message (the channel declared on first use); `subscribed` is set once a client
    subscribes to any channel. Static transforms are kept and sent again with `repeat_static`. `option`:
    the port's option, as errors name it."""

    def __init__(self, host: str = "127.0.0.1", port: int = 8765, name: str = "datmo", option: str = "--port") -> None:
        foxglove = require_foxglove()
        from ..base.progress import Limited, route_logs

        # what the SDK logs about a client (a bad frame names its op, which the client chose): escaped and
        # rate-limited on stderr, until close() (it went to Python's last-resort handler, raw, one line a frame)
        self._told = Limited("datmo live view")
        self._restore_log = route_logs(("foxglove",), self._told)

        self._foxglove = foxglove
        self.host = host
        self.context = foxglove.Context()
        self.subscribed = threading.Event()
        self.channels: dict[str, object] = {}
        self.static: dict[str, Message] = {}
        self.sent = 0
        self.name = name
        self.listener = _Listener(self.subscribed)
        self.control: PlaybackControl | None = None
        try:
            self.server = self._start_backend()
        except Exception as exc:  # the SDK raises its own errors
            self._restore_log()
            raise ConfigError(f"{option} {port}: cannot start the live view's server ({_reason(exc)})") from None
        try:
            self.front = _Front(host, port, f"ws://127.0.0.1:{self.server.port}")
        except Exception as exc:  # OSError for a busy port, a bad host or a name that does not resolve
            self.server.stop()
            self._restore_log()
            raise ConfigError(f"{option} {port}: cannot serve on {host}:{port} ({_reason(exc)})") from None
        self.port = self.front.port

    def _start_backend(self):
        """foxglove-sdk's server on a loopback port of its own: the time capability, and playback control over
        the log's span when `self.control` is set."""
        from foxglove.websocket import Capability

        c = self.control
        return self._foxglove.start_server(
            name=self.name,
            host="127.0.0.1",
            port=0,
            capabilities=[Capability.Time],
            server_listener=self.listener,
            context=self.context,
            playback_time_range=(c.start, c.end) if c is not None else None,
        )

    def offer_playback(self, control: PlaybackControl) -> None:
        """Offer Foxglove's playback control (pause, seek, speed) over `control`'s span, `control` taking the
        clients' requests. Call before a client connects: the SDK's server starts again with the capability
        (its channels are kept: they belong to the context), and the front relays to the new one."""
        self.control = self.listener.control = control
        old = self.server
        self.server = self._start_backend()
        self.front.backend = f"ws://127.0.0.1:{self.server.port}"
        old.stop()

    def playback_state(self, state: State) -> None:
        """Tell the clients the playback's state (when it changed by itself: a request is answered by the SDK)."""
        self.server.broadcast_playback_state(_sdk_state(state, None))

    @property
    def subscribers(self) -> int:
        """The clients' subscriptions to channels, now."""
        return self.listener.subscriptions

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
        self._restore_log()
        self._told.close()


class _Listener:
    """The server's listener: notes the first subscription and counts them. The SDK calls on_unsubscribe for
    each channel a client leaves (it is not optional: without it every client that leaves printed an
    AttributeError). A playback control request goes to `control` (set with the capability), and its new state
    is the answer."""

    def __init__(self, subscribed: threading.Event) -> None:
        self.subscribed = subscribed
        self.subscriptions = 0
        self.control: PlaybackControl | None = None
        self._lock = threading.Lock()

    def on_subscribe(self, client, channel) -> None:
        with self._lock:
            self.subscriptions += 1
        self.subscribed.set()

    def on_unsubscribe(self, client, channel) -> None:
        with self._lock:
            self.subscriptions = max(self.subscriptions - 1, 0)

    def on_playback_control_request(self, request):
        from foxglove.websocket import PlaybackCommand

        if self.control is None:
            return None
        seek = request.seek_time
        state = self.control.request(request.playback_command == PlaybackCommand.Play, request.playback_speed, seek)
        return _sdk_state(state, request.request_id)


def _sdk_state(state: State, request_id: str | None):
    """foxglove-sdk's PlaybackState of `state`, answering `request_id` (None: no request)."""
    from foxglove.websocket import PlaybackState, PlaybackStatus

    status = {PLAYING: PlaybackStatus.Playing, PAUSED: PlaybackStatus.Paused, ENDED: PlaybackStatus.Ended}
    return PlaybackState(
        status=status[state.status],
        current_time=state.time,
        playback_speed=state.speed,
        did_seek=state.sought,
        request_id=request_id,
    )


_QUIET = logging.getLogger("datmo.live.front")  # the front's connection log: kept off the terminal
_QUIET.addHandler(logging.NullHandler())
_QUIET.propagate = False


MAX_CLIENT_FRAME_BYTES = 1 << 20  # a client's message: its subscribe and unsubscribe requests take well under a
# kilobyte; a frame whose header declares more is refused (close 1009) before its payload is read


class _Front:
    """The port clients connect to: a WebSocket server (its own thread and event loop) that accepts a client
    asking for any of SUBPROTOCOLS (else HTTP 400, as the SDK's server answers), opens a connection of its own
    to the SDK's server at `backend` (a ws:// URL), and relays every frame both ways,
    unchanged, until either side closes; then it closes the other. A client frame over MAX_CLIENT_FRAME_BYTES
    closes that client's connection, refused on its header before any of it is buffered. Nothing is printed
    when a client leaves or fails. Raises OSError when it cannot listen on `host`:`port`."""

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
                self._relay,
                host,
                port,
                subprotocols=list(SUBPROTOCOLS),
                compression=None,
                max_size=MAX_CLIENT_FRAME_BYTES,
                logger=_QUIET,
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
