"""`datmo segment`: adaptive-threshold segmentation of every scan (method.md section 4)."""

from __future__ import annotations

from pathlib import Path

import click

from ..bounds import FEATURES, option
from ..inputs import scan_log
from ..perception.params import FeatureParams
from .options import config_options, input_options, no_stdout, quiet_option

D = FeatureParams()


def feature_params(config: Path | None, **options) -> FeatureParams:
    """Defaults, overridden by the config file's [features] table, overridden by the options given."""
    from ..perception.params import load_toml

    params = load_toml(config) if config is not None else FeatureParams()
    return params.replace(**options)


@click.command(name="segment")
@click.argument("input", type=click.Path(path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              callback=no_stdout(), help="The log to write (MCAP): the input's channels plus /datmo/segments.")
@click.option("--force", is_flag=True, help="Overwrite the output if it exists.")
@config_options("TOML file with a [features] table (c0, min_points and the feature parameters).")
@option("--c0", bound=FEATURES["c0"], default=None,
        help=f"C0 of the threshold C0 + C1·min(r_i, r_i+1), m [default: {D.c0:g}].")
@option("--min-points", bound=FEATURES["min_points"], default=None,
        help=f"Drop segments with fewer points [default: {D.min_points}; the paper's is 5].")
@input_options
@quiet_option
def command(input: Path, output: Path, force: bool, config: Path | None, c0: float | None,
            min_points: int | None, topic: str | None, odom_topic: str | None) -> None:
    """Split each scan into segments: consecutive points join while their distance is at most
    C0 + C1·min(r_i, r_i+1), C1 = sqrt(2(1 − cos Δα)) from the scan's angle step; invalid returns (NaN,
    inf, at or beyond the range limits) break segments. Writes /datmo/segments: each scan's beam index
    ranges [start, end). INPUT is a datmo log, or a ROS 1/2 bag converted on the fly (--topic).

    Example: datmo segment sample_logs/hall.mcap -o hall-segments.mcap
    """
    from ..cli import invocation
    from ..config import provenance_line
    from ..pipeline import segment_file
    from ..progress import bar, say
    from ..streaming import LogStream

    params = feature_params(config, c0=c0, min_points=min_points)
    with scan_log(input, output, topic, odom_topic, force=force) as src:
        stream = LogStream(src)   # a bad input is said before the progress bar starts
        with bar("segmenting", stream.n_scans) as progress:
            scans = segment_file(stream, output, params, force=force, progress=progress,
                                 command_line=provenance_line(invocation("segment")))
    say(f"{output}: segments of {scans:,} scans")
