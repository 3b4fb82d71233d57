"""`datmo config`: the effective configuration, as TOML that datmo reads back identically."""

from __future__ import annotations

from pathlib import Path

import click

from .options import config_options, quiet_option

STDOUT = "-"


def effective(config: Path | None) -> tuple[dict[str, dict], dict[str, dict[str, str]]]:
    """The [features] and [track] tables the commands would use with `config` (None: defaults only), and
    where each value comes from ('default' or the config file's name) with its unit (bounds.py)."""
    from ..bounds import FEATURES, TRACK
    from ..config import read_table
    from ..perception.params import FeatureParams
    from ..perception.params import load_toml as load_features
    from ..tracking.params import TrackingParams
    from ..tracking.params import load_toml as load_track

    tables = {"features": (load_features(config) if config is not None else FeatureParams()).to_dict(),
              "track": (load_track(config) if config is not None else TrackingParams()).to_dict()}
    sources = {}
    for stage, table in tables.items():
        given = set(read_table(config, stage)) if config is not None else set()
        bounds = FEATURES if stage == "features" else TRACK
        sources[stage] = {key: (f"from {config}" if key in given else "default")
                          + (f"; {bounds[key].unit}" if key in bounds and bounds[key].unit else "") for key in table}
    return tables, sources


@click.command(name="config")
@config_options("TOML file of parameters ([features] and [track] tables) to show merged with the defaults.")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=STDOUT,
              show_default=True, help="Where to write the TOML ('-': stdout).")
@click.option("--force", is_flag=True, help="Overwrite the output if it exists.")
@quiet_option
def command(config: Path | None, output: Path, force: bool) -> None:
    """Print the effective configuration: every [features] and [track] parameter with its value (the
    defaults, overridden by --config or ./datmo.toml), each followed by a comment saying where it came
    from. The output is a config file: `datmo config > datmo.toml` then edit; datmo reads it back to
    the same parameters.

    Example: datmo config --no-config > datmo.toml
    """
    from ..config import to_toml

    tables, sources = effective(config)
    header = (f"datmo's effective configuration: the defaults, overridden by {config}" if config is not None
              else "datmo's effective configuration: the defaults (no config file)")
    text = to_toml(tables, sources, header)
    if str(output) == STDOUT:
        click.echo(text, nl=False)
        return
    from ..outputs import atomic_output
    from ..progress import say

    with atomic_output(output, force=force, mode="w", what="config") as f:
        f.write(text)
    say(f"{output}: configuration written")
