"""`datmo segment`: adaptive-threshold segmentation of every scan (method.md section 4)."""

from __future__ import annotations

from pathlib import Path

import click

from ..bounds import FEATURES, option
from ..perception.params import FeatureParams

D = FeatureParams()


def feature_params(config: Path | None, **options) -> FeatureParams:  # noqa: ANN003 - option values
    """Defaults, overridden by the config file's [features] table, overridden by the options given."""
    from ..perception.params import load_toml

    params = load_toml(config) if config is not None else FeatureParams()
    return params.replace(**options)


@click.command(name="segment")
@click.argument("input", type=click.Path(path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The log to write (MCAP): the input's channels plus /datmo/segments.")
@click.option("--force", is_flag=True, help="Overwrite the output if it exists.")
@click.option("--config", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="TOML file with a [features] table (c0, min_points and the feature parameters).")
@option("--c0", bound=FEATURES["c0"], default=None,
        help=f"C0 of the threshold C0 + C1·min(r_i, r_i+1), m [default: {D.c0:g}].")
@option("--min-points", bound=FEATURES["min_points"], default=None,
        help=f"Drop segments with fewer points [default: {D.min_points}; the paper's is 5].")
def command(input: Path, output: Path, force: bool, config: Path | None, c0: float | None,
            min_points: int | None) -> None:
    """Split each scan into segments: consecutive points join while their distance is at most
    C0 + C1·min(r_i, r_i+1), C1 = sqrt(2(1 − cos Δα)) from the scan's angle step; invalid returns (NaN,
    inf, at or beyond the range limits) break segments. Writes /datmo/segments: each scan's beam index
    ranges [start, end).

    Example: datmo segment sample_logs/hall.mcap -o hall-segments.mcap
    """
    from ..cli import invocation
    from ..pipeline import segment_file

    params = feature_params(config, c0=c0, min_points=min_points)
    scans = segment_file(input, output, params, force=force, command_line=invocation("segment"))
    click.echo(f"{output}: segments of {scans:,} scans", err=True)
