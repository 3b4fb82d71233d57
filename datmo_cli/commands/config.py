"""`datmo config`: the effective configuration, as TOML that datmo reads back identically: one call of
datmo_cli.api.config (workflows.inspecting) and what it prints."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from .options import STDOUT, config_options, force_option, output_option, quiet_option

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


@click.command(name="config")
@config_options("TOML file of parameters ([features] and [track] tables) to show merged with the defaults.", path=True)
@output_option("Where to write the TOML ('-': stdout).", dash=True, default=STDOUT, show_default=True)
@force_option()
@quiet_option
def command(cfg: DatmoConfig, config: Path | None, output: Path, force: bool) -> None:
    """Print the effective configuration: every [features] and [track] parameter with its value (the
    defaults, overridden by --config or ./datmo.toml), each followed by a comment saying where it came
    from. The output is a config file: `datmo config > datmo.toml` then edit; datmo reads it back to
    the same parameters.

    Example: datmo config --no-config > datmo.toml
    """
    from .. import api
    from ..base.progress import say

    stdout = str(output) == STDOUT
    text = api.config(cfg, None if stdout else output, force=force, source=config)
    if stdout:
        click.echo(text, nl=False)
    else:
        say(f"{output}: configuration written")
