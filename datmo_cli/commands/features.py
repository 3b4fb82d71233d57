"""`datmo features`: Hough lines and circles, blobs and landmarks of every scan (method.md sections 5, 6.2)."""

from __future__ import annotations

from pathlib import Path

import click

from ..bounds import FEATURES, OPTIONS, option, pair_option
from ..inputs import scan_log
from ..perception.params import FeatureParams
from .options import config_options, input_options, no_stdout, quiet_option
from .segment import feature_params

D = FeatureParams()


@click.command(name="features")
@click.argument("input", type=click.Path(path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path), callback=no_stdout(),
              help="The log to write (MCAP): the input's channels plus /datmo/features, /datmo/landmarks and "
                   "/datmo/markers/features (and /datmo/segments when the input has none).")
@click.option("--force", is_flag=True, help="Overwrite the output if it exists.")
@config_options("TOML file with a [features] table: any parameter of datmo_cli/perception/params.py.")
@click.option("--resegment", is_flag=True, help="Segment again even when the input has /datmo/segments.")
@click.option("--no-markers", is_flag=True, help="Do not write /datmo/markers/features (Foxglove drawings).")
@option("--c0", bound=FEATURES["c0"], default=None, help=f"Segmentation threshold C0, m [default: {D.c0:g}].")
@option("--min-points", bound=FEATURES["min_points"], default=None,
        help=f"Drop segments with fewer points [default: {D.min_points}; the paper's is 5].")
@option("--theta-resolution", bound=FEATURES["theta_resolution"], default=None,
        help=f"HTL theta cell, degrees [default: {D.theta_resolution:g}].")
@option("--rho-resolution", bound=FEATURES["rho_resolution"], default=None,
        help=f"HTL rho cell, m [default: {D.rho_resolution:g}].")
@pair_option("--circle-radius", "circle_radius", bounds=(FEATURES["circle_radius_min"], FEATURES["circle_radius_max"]),
             names=("MIN", "MAX"), default=None,
             help=f"HTC radius range, m [default: {D.circle_radius_min:g} {D.circle_radius_max:g}].")
@click.option("--leg-model", default=None, metavar="MODEL",
              help="Leg detector: 'default' (the model shipped with datmo), a model file from datmo train-legs, "
                   "or 'paper' (no detector: legs by the paper's circle rule) [default: default].")
@option("--d-max", bound=FEATURES["d_max"], default=None,
        help=f"Lines longer than this are walls (static), m [default: {D.d_max:g}].")
@option("--threads", bound=OPTIONS["threads"], default=None,
        help="Threads for the per-scan perception (segmentation, features, leg detector) [default: all "
             "cores]; the results are the same for any number.")
@input_options
@quiet_option
def command(input: Path, output: Path, force: bool, config: Path | None, resegment: bool, no_markers: bool,
            c0: float | None,
            min_points: int | None, theta_resolution: float | None, rho_resolution: float | None,
            circle_radius: tuple[float, float] | None, leg_model: str | None, d_max: float | None,
            threads: int | None, topic: str | None, odom_topic: str | None) -> None:
    """Extract the features of every scan: lines by the Hough transform for lines (accumulators adapted to
    each segment, several lines per segment by following the peak, refined by least squares), circles by
    the Hough transform for circles (centre from P_ini, P_near, P_end; refined by least squares), the
    paper's rule choosing between them, blobs, and landmarks (corners, wall deflections, line ends,
    columns, benches) accumulated into a database (in the odom frame when the log has /odom).

    Writes /datmo/features, /datmo/landmarks and /datmo/markers/features (for Foxglove), segmenting first
    when the input has no /datmo/segments. Options override the config file, which overrides the defaults;
    the effective parameters go into the output's metadata. INPUT is a datmo log, or a ROS 1/2 bag
    converted on the fly (--topic, --odom-topic).

    Example: datmo features sample_logs/hall.mcap -o hall-features.mcap
    """
    from ..cli import invocation
    from ..config import provenance_line
    from ..perception.threads import set_default
    from ..pipeline import features_file
    from ..progress import bar, say
    from ..streaming import LogStream

    set_default(threads)

    rmin, rmax = circle_radius if circle_radius is not None else (None, None)
    params = feature_params(config, c0=c0, min_points=min_points, theta_resolution=theta_resolution,
                            rho_resolution=rho_resolution, circle_radius_min=rmin, circle_radius_max=rmax,
                            leg_model=leg_model, d_max=d_max)
    with scan_log(input, output, topic, odom_topic, force=force) as src:
        stream = LogStream(src)   # a bad input is said before the progress bar starts
        with bar("features", stream.n_scans) as progress, progress.compile_notice() as report:
            c = features_file(stream, output, params, resegment=resegment, force=force, markers=not no_markers,
                              command_line=provenance_line(invocation("features")), progress=report)
    say(f"{output}: {c.scans:,} scans; per scan {c.per_scan('lines'):.1f} lines, {c.per_scan('circles'):.1f} "
        f"circles, {c.per_scan('blobs'):.1f} blobs; {c.landmarks} landmarks")
