"""`datmo segment`: adaptive-threshold segmentation of every scan (docs/method.md §4)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..passes.input_logs import scan_log
from .options import config_options, force_option, input_options, output_option, param_option, quiet_option

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


@click.command(name="segment")
@click.argument("input", type=click.Path(path_type=Path))
@output_option("The log to write (MCAP): the input's channels plus /datmo/segments.")
@force_option()
@config_options("TOML file with a [features] table (c0, min_points and the feature parameters).")
@param_option("features.c0")
@param_option("features.min_points")
@input_options
@quiet_option
def command(
    input: Path, output: Path, force: bool, cfg: DatmoConfig, topic: str | None, odom_topic: str | None
) -> None:
    """Split each scan into segments: consecutive points join while their distance is at most
    C0 + C1·min(r_i, r_i+1), C1 = sqrt(2(1 − cos Δα)) from the scan's angle step; invalid returns (NaN,
    inf, at or beyond the range limits) break segments. Writes /datmo/segments: each scan's beam index
    ranges [start, end). INPUT is a datmo log, or a ROS 1/2 bag converted on the fly (--topic).

    Example: datmo segment sample_logs/hall.mcap -o hall-segments.mcap
    """
    from ..base.progress import bar, say
    from ..cli import invocation
    from ..passes.config import provenance_line
    from ..passes.stage_files import segment_file
    from ..passes.streaming import LogStream

    with scan_log(input, output, topic, odom_topic, force=force) as src:
        stream = LogStream(src)  # a bad input is said before the progress bar starts
        with bar("segmenting", stream.n_scans) as progress:
            scans = segment_file(
                stream, output, cfg, force=force, progress=progress, command_line=provenance_line(invocation("segment"))
            )
    say(f"{output}: segments of {scans:,} scans")
