"""`datmo track`: track and classify objects in a log (docs/method.md §6), writing /datmo/tracks and markers."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

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

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


@click.command(name="track")
@click.argument("input", type=click.Path(path_type=Path))
@output_option(
    "The log to write (MCAP): the input's channels plus /datmo/tracks (and /datmo/markers/tracks with --markers).",
    file=False,
)
@force_option()
@click.option(
    "--markers/--no-markers",
    default=False,
    show_default=True,
    help="Also store /datmo/markers/* (Foxglove drawings); datmo play draws them from the tracks anyway.",
)
@click.option(
    "--covariance",
    is_flag=True,
    help="Store each track's covariance in /datmo/tracks (otherwise its 16 numbers are NaN).",
)
@click.option(
    "--bag-dir",
    is_flag=True,
    is_eager=True,
    help="Write OUTPUT as a ROS 2 bag folder for ros2 bag play: OUTPUT/ holding OUTPUT_0.mcap and "
    "metadata.yaml (--force replaces only a bag folder).",
)
@config_options(
    "TOML file with a [track] table of parameters (names as in the options below and more), and "
    "a [features] table used when the input has no features."
)
@param_option("track.process_noise")
@param_option("track.measurement_noise")
@param_option("track.gate")
@param_pair_option(
    "--confirm", "track.confirm_hits", "track.confirm_window", ("M", "N"), "Confirm a track after M hits in N scans."
)
@param_option("track.delete_after")
@param_option("track.delete_after_occluded")
@param_option("track.d_max")
@param_option("track.ego_motion")
@param_option("track.hindsight_lag")
@param_option(
    "features.leg_model",
    expose=True,
    help="Leg detector for inputs without features: 'default' (shipped), a file from datmo train-legs, or "
    "'paper' (the paper's circle rule and walking pattern). Inputs with features keep theirs, which "
    "a given MODEL must be.",
)
@input_options
@quiet_option
def command(
    input: Path,
    output: Path,
    force: bool,
    markers: bool,
    covariance: bool,
    bag_dir: bool,
    cfg: DatmoConfig,
    leg_model: str | None,
    topic: str | None,
    odom_topic: str | None,
) -> None:
    """Track and classify the objects of a log: Kalman filter, gating and global nearest-neighbour
    association, occlusion-aware track life cycle, people from paired legs and their walking pattern.

    Writes the input's channels plus /datmo/tracks (every scan: id, class, mobility, position and velocity
    in the sensor frame and, with /odom, the world frame, age, hits, misses, occluded; the covariance with
    --covariance) and, with --markers, /datmo/markers/tracks for Foxglove. Segmentation and features run
    first when the input lacks /datmo/features. Options override the config file, which overrides the
    defaults. INPUT is a datmo log, or a ROS 1/2 bag converted on the fly (--topic, --odom-topic).

    Example: datmo track sample_logs/hall.mcap -o hall-tracks.mcap

    Example: datmo track sample_logs/hall.mcap -o hall-bag --bag-dir && ros2 bag play hall-bag
    """
    from ..base.progress import bar, say
    from ..cli import invocation
    from ..logs import bagdir
    from ..passes.config import provenance_line
    from ..passes.stage_files import track_file
    from ..passes.streaming import LogStream

    with (
        bagdir.output(output, bag_dir, force=force, inputs=[input]) as out,
        scan_log(input, out, topic, odom_topic, force=force) as src,
    ):
        stream = LogStream(src)  # a bad input is said before the progress bar starts
        with bar("tracking", stream.n_scans) as progress, progress.compile_notice() as report:
            scans, computed = track_file(
                stream,
                out,
                force=force,
                config=cfg,
                leg_model=leg_model,
                command_line=provenance_line(invocation("track")),
                markers=markers,
                covariance=covariance,
                progress=report,
            )
    how = " (segmented and extracted features first)" if computed else ""
    say(f"{output}: tracks for {scans:,} scans{how}")
