"""`datmo play`: serve a log to Foxglove over its WebSocket protocol at the log's rate (the live view): the options,
datmo_cli.api.Player (workflows.playing) and what it prints."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..base.bounds import OPTIONS
from .options import config_options, quiet_option
from .types import option

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


def host_option(*decls: str, help_: str = "Address to serve on (0.0.0.0: every interface).") -> click.decorators.FC:
    return click.option(*decls, default="127.0.0.1", show_default=True, metavar="HOST", help=help_)


@click.command(name="play")
@click.argument("input", type=click.Path(path_type=Path))
@host_option("--host")
@option(
    "--port",
    bound=OPTIONS["live_port"],
    default=8765,
    show_default=True,
    help="WebSocket port to serve on (0: any free port; the URL printed says which).",
)
@option(
    "--rate",
    bound=OPTIONS["play_rate"],
    default=1.0,
    show_default=True,
    help="Play at this multiple of the log's speed.",
)
@click.option("--loop", is_flag=True, help="Start over at the end of the log (until Ctrl-C).")
@click.option(
    "--wait/--no-wait",
    default=True,
    show_default=True,
    help="Start playing when a client subscribes to a channel (else at once).",
)
@config_options("TOML file with [features] and [track] tables, for a log that is processed on the fly.")
@quiet_option
def command(input: Path, host: str, port: int, rate: float, loop: bool, wait: bool, cfg: DatmoConfig) -> None:
    """Serve a log to Foxglove (its WebSocket protocol, to clients asking for foxglove.sdk.v1 or
    foxglove.websocket.v1) at the log's rate: the scan, features, tracks, markers and transforms, every
    channel with its ROS 2 schema.

    A log without /datmo/tracks is segmented, its features extracted and tracked on the fly, as datmo run
    would; a processed log is served as it is, its markers drawn from its tracks and features when it holds
    none (datmo run stores them only with --markers). Transforms come from the log's /tf and /tf_static, else from
    its odometry. Open the URL printed, or in Foxglove desktop: Open connection, Foxglove WebSocket, the
    ws:// address. The layout foxglove-layouts/datmo-layout.json of the datmo repository shows the scan,
    features and tracks and plots track velocities (Layouts, Import from file). Ctrl-C stops (exit 130).
    Needs the live extra: pip install 'datmo-cli[live]'.

    What the viewer can do: show every channel as it plays, on the log's clock (the server sends the log's
    time, so plots and the timeline follow it), and drive the playback from Foxglove's playback bar (the
    server offers its playback control over the log's span): pause and play, seek to a time in the log
    (playing goes on from the first scan at or after it; a log processed on the fly starts its tracks over
    there), and change the speed (--rate is the speed to start at). At the log's end, without --loop, the
    server says so and waits while a client is subscribed: seek back, or play to start over. What it cannot
    do: step a scan at a time, or play backwards; a client without playback control follows the log's time
    only.

    Example: datmo play sample_logs/hall.mcap --rate 2 --loop
    """
    from .. import api
    from ..base import outputs
    from ..base.progress import say
    from ..base.text import printable

    player = None
    try:
        player = api.Player(input, host=host, port=port, rate=rate, config=cfg)
        what = "as it is" if player.processed else "segmented, features and tracks made on the fly"
        click.echo(f"datmo play: serving {printable(input)} ({player.scans:,} scans, {what}) on {player.url}")
        click.echo(f"  open {player.app_url}")
        click.echo(f"  or in Foxglove desktop: Open connection > Foxglove WebSocket > {player.url}")
        if wait:
            say("  waiting for a client to subscribe (Ctrl-C to stop)")
            player.wait_for_client()
        scans = player.run(loop)
        say(f"datmo play: {scans:,} scans served")
    except (KeyboardInterrupt, outputs.Terminated) as exc:
        code = 130 if isinstance(exc, KeyboardInterrupt) else exc.exit_code
        sent = player.sent if player is not None else 0
        say(f"datmo play: stopped ({'Ctrl-C' if code == 130 else exc}); {sent:,} messages served")
        raise click.exceptions.Exit(code) from None
    finally:
        if player is not None:
            player.close()
