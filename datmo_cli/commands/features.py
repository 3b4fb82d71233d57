"""`datmo features`: Hough lines and circles, blobs and landmarks of every scan (docs/method.md §5 and §6.2)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..base.bounds import OPTIONS
from ..passes.input_logs import scan_log
from .options import (
    config_options,
    force_option,
    input_options,
    output_option,
    param_option,
    param_pair_option,
    quiet_option,
)
from .types import option

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


@click.command(name="features")
@click.argument("input", type=click.Path(path_type=Path))
@output_option(
    "The log to write (MCAP): the input's channels plus /datmo/features and /datmo/landmarks (and "
    "/datmo/segments when the input has none, /datmo/markers/features with --markers)."
)
@force_option()
@config_options("TOML file with a [features] table: any parameter of datmo_cli/perception/params.py.")
@click.option("--resegment", is_flag=True, help="Segment again even when the input has /datmo/segments.")
@click.option(
    "--markers/--no-markers",
    default=False,
    show_default=True,
    help="Also store /datmo/markers/features (Foxglove drawings); datmo play draws them from the features anyway.",
)
@param_option("features.c0")
@param_option("features.min_points")
@param_option("features.theta_resolution")
@param_option("features.rho_resolution")
@param_pair_option(
    "--circle-radius", "features.circle_radius_min", "features.circle_radius_max", ("MIN", "MAX"), "HTC radius range."
)
@param_option("features.leg_model")
@param_option("features.d_max")
@option(
    "--threads",
    bound=OPTIONS["threads"],
    default=None,
    help="Threads for the per-scan perception (segmentation, features, leg detector) [default: all "
    "cores]; the results are the same for any number.",
)
@input_options
@quiet_option
def command(
    input: Path,
    output: Path,
    force: bool,
    cfg: DatmoConfig,
    resegment: bool,
    markers: bool,
    threads: int | None,
    topic: str | None,
    odom_topic: str | None,
) -> None:
    """Extract the features of every scan: lines by the Hough transform for lines (accumulators adapted to
    each segment, several lines per segment by following the peak, refined by least squares), circles by
    the Hough transform for circles (centre from P_ini, P_near, P_end; refined by least squares), the
    paper's rule choosing between them, blobs, and landmarks (corners, wall deflections, line ends,
    columns, benches) accumulated into a database (in the odom frame when the log has /odom).

    Writes /datmo/features and /datmo/landmarks (and /datmo/markers/features for Foxglove with --markers),
    segmenting first when the input has no /datmo/segments. Options override the config file, which
    overrides the defaults; the effective parameters go into the output's metadata. INPUT is a datmo log, or
    a ROS 1/2 bag converted on the fly (--topic, --odom-topic).

    Example: datmo features sample_logs/hall.mcap -o hall-features.mcap
    """
    from ..base.progress import bar, say
    from ..cli import invocation
    from ..passes.config import provenance_line
    from ..passes.stage_files import features_file
    from ..passes.streaming import LogStream
    from ..perception.threads import set_default

    set_default(threads)
    with scan_log(input, output, topic, odom_topic, force=force) as src:
        stream = LogStream(src)  # a bad input is said before the progress bar starts
        with bar("features", stream.n_scans) as progress, progress.compile_notice() as report:
            c = features_file(
                stream,
                output,
                cfg,
                resegment=resegment,
                force=force,
                markers=markers,
                command_line=provenance_line(invocation("features")),
                progress=report,
            )
    say(
        f"{output}: {c.scans:,} scans; per scan {c.per_scan('lines'):.1f} lines, {c.per_scan('circles'):.1f} "
        f"circles, {c.per_scan('blobs'):.1f} blobs; {c.landmarks} landmarks"
    )
