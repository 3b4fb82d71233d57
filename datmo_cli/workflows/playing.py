"""`datmo play`'s work as a call (datmo_cli.api.play, Player): a log served to Foxglove over its WebSocket
protocol at the log's rate (live: LiveServer, LogSource, play), processed on the fly when it has no tracks, with
Foxglove's playback control over the log's span (times: the log's int64 ns stamps). The command keeps what it
prints and how Ctrl-C ends it."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from . import Config


class Player:
    """A log ready to serve: the live view's server listening on `host`:`port` (0: any free port; `url` says
    which), the log read (`scans`; `processed`: it has tracks, served as it is, else segmented, its features
    extracted and tracked as it plays, with `config` as api.process takes it), the playback control offered
    at `rate` times the log's speed. `wait_for_client()` waits for a subscription; `run(loop)` plays (returns
    the scans sent); `close()` (or the end of a `with`) stops the server. Needs the live extra."""

    def __init__(
        self,
        input: str | os.PathLike,
        *,
        host: str = "127.0.0.1",
        port: int = 8765,
        rate: float = 1.0,
        config: Config = None,
    ) -> None:
        from .. import live
        from . import as_config

        self.input, self.rate = input, rate
        self.server = live.LiveServer(host, port)  # the package and the port are checked before the log is read
        try:
            self.source = live.LogSource(Path(input), as_config(config))
            self.control = live.PlaybackControl(*self.source.span, rate)
            self.server.offer_playback(self.control)
            self.source.declare(self.server)
        except BaseException:
            self.server.close()
            raise

    @property
    def url(self) -> str:
        """The ws:// address clients connect to."""
        return self.server.url

    @property
    def app_url(self) -> str:
        """The Foxglove app's address that opens this server."""
        return self.server.app_url

    @property
    def scans(self) -> int:
        """Scans in the log."""
        return self.source.stream.n_scans

    @property
    def processed(self) -> bool:
        """Whether the log has tracks (served as it is) rather than made on the fly."""
        return bool(self.source.processed)

    @property
    def sent(self) -> int:
        """Messages served so far."""
        return self.server.sent

    def wait_for_client(self, poll_s: float = 0.2) -> None:
        """Wait until a client subscribes to a channel."""
        while not self.server.subscribed.wait(poll_s):
            pass

    def run(self, loop: bool = False) -> int:
        """Play the log (from the start again at its end with `loop`, until interrupted); the scans sent."""
        from .. import live

        return live.play(self.source, self.server, rate=self.rate, loop=loop, control=self.control)

    def close(self) -> None:
        self.server.close()

    def __enter__(self) -> Player:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def play(
    input: str | os.PathLike,
    *,
    host: str = "127.0.0.1",
    port: int = 8765,
    rate: float = 1.0,
    loop: bool = False,
    wait: bool = True,
    config: Config = None,
) -> int:
    """`datmo play INPUT`: serve `input` to Foxglove (Player's options), after a client subscribes with `wait`,
    once or, with `loop`, until interrupted; returns the scans sent."""
    with Player(input, host=host, port=port, rate=rate, config=config) as player:
        if wait:
            player.wait_for_client()
        return player.run(loop)
