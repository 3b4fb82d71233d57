"""`datmo config`: the effective configuration, as TOML that datmo reads back identically."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from .options import STDOUT, config_options, force_option, output_option, quiet_option

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


def sources(cfg: DatmoConfig, config: Path | None) -> dict[str, dict[str, str]]:
    """Where each value of `cfg` comes from ('default' or the config file's name) with its unit, by section
    and key (a parameter written outside its home section, as [track] d_max, counts for its home)."""
    from ..passes.config import BOUNDS, SECTIONS, STAGES, read_tables, same_as

    tables = read_tables(config) if config is not None else {}
    given = {s: set(tables.get(s, ())) for s in STAGES}
    for s in STAGES:
        for name, key in same_as(SECTIONS[s]).items():
            home, _, home_key = key.partition(".")
            if name in given[s]:
                given[home].add(home_key)
    out = {}
    for stage, table in cfg.to_dict().items():
        bounds = BOUNDS[stage]
        out[stage] = {
            key: (f"from {config}" if key in given[stage] else "default")
            + (f"; {bounds[key].unit}" if key in bounds and bounds[key].unit else "")
            for key in table
        }
    return out


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
    from ..passes.config import to_toml

    header = (
        f"datmo's effective configuration: the defaults, overridden by {config}"
        if config is not None
        else "datmo's effective configuration: the defaults (no config file)"
    )
    text = to_toml(cfg.to_dict(), sources(cfg, config), header)
    if str(output) == STDOUT:
        click.echo(text, nl=False)
        return
    from ..base.outputs import atomic_output
    from ..base.progress import say

    read = [p for p in (config, cfg.features.leg_model) if p]  # its inputs: refused as outputs, even with --force
    with atomic_output(output, force=force, mode="w", inputs=read, what="config") as f:
        f.write(text)
    say(f"{output}: configuration written")
