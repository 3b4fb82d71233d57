"""`datmo track`: track and classify objects in a log (method.md §6), writing /datmo/tracks and markers."""

from __future__ import annotations

from pathlib import Path

import click

from ..bounds import TRACK, option, pair_option
from ..inputs import scan_log
from ..tracking.params import TrackingParams
from .options import config_options, input_options, no_stdout, quiet_option

D = TrackingParams()


@click.command(name="track")
@click.argument("input", type=click.Path(path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path), callback=no_stdout(),
              help="The log to write (MCAP): the input's channels plus /datmo/tracks and /datmo/markers/tracks.")
@click.option("--force", is_flag=True, help="Overwrite the output if it exists.")
@click.option("--no-markers", is_flag=True, help="Do not write /datmo/markers/* (Foxglove drawings).")
@click.option("--bag-dir", is_flag=True, is_eager=True,
              help="Write OUTPUT as a ROS 2 bag folder for ros2 bag play: OUTPUT/ holding OUTPUT_0.mcap and "
                   "metadata.yaml (--force replaces only a bag folder).")
@config_options("TOML file with a [track] table of parameters (names as in the options below and more), and "
                "a [features] table used when the input has no features.")
@option("--process-noise", bound=TRACK["process_noise"], default=None,
        help=f"White-noise acceleration variance q, (m/s²)² per Hz [default: {D.process_noise:g}].")
@option("--measurement-noise", bound=TRACK["measurement_noise"], default=None,
        help=f"Sigma of a measured model centre, m [default: {D.measurement_noise:g}].")
@option("--gate", bound=TRACK["gate"], default=None,
        help=f"Gate on the squared Mahalanobis distance [default: {D.gate:g}, chi² 2 dof 99.9 %].")
@pair_option("--confirm", "confirm", bounds=(TRACK["confirm_hits"], TRACK["confirm_window"]), names=("M", "N"),
             default=None,
             help=f"Confirm a track after M hits in N scans [default: {D.confirm_hits} {D.confirm_window}].")
@option("--delete-after", bound=TRACK["delete_after"], default=None,
        help=f"Seconds a confirmed track lives unseen when it should be seen [default: {D.delete_after:g}].")
@option("--delete-after-occluded", bound=TRACK["delete_after_occluded"], default=None,
        help=f"Seconds a confirmed track lives unseen while occluded or out of view "
             f"[default: {D.delete_after_occluded:g}].")
@option("--d-max", bound=TRACK["d_max"], default=None,
        help=f"Objects larger than this are static, m [default: {D.d_max:g}].")
@click.option("--ego-motion", type=click.Choice(["auto", "on", "off"]), default=None,
              help="For a log without /odom: track in poses estimated by scan matching (written to /odom, frame "
                   "scan_odom) when the scanner moves ('auto'), always ('on') or never ('off') [default: auto].")
@click.option("--leg-model", default=None, metavar="MODEL",
              help="Leg detector for inputs without features: 'default' (shipped), a file from datmo train-legs, "
                   "or 'paper' (the paper's circle rule and walking pattern). Inputs with features keep theirs.")
@input_options
@quiet_option
def command(input: Path, output: Path, force: bool, no_markers: bool, bag_dir: bool, config: Path | None,
            process_noise: float | None,
            measurement_noise: float | None, gate: float | None, confirm: tuple[int, int] | None,
            delete_after: float | None, delete_after_occluded: float | None, d_max: float | None,
            ego_motion: str | None, leg_model: str | None, topic: str | None, odom_topic: str | None) -> None:
    """Track and classify the objects of a log: Kalman filter, gating and global nearest-neighbour
    association, occlusion-aware track life cycle, people from paired legs and their walking pattern.

    Writes the input's channels plus /datmo/tracks (every scan: id, class, mobility, position and velocity
    in the sensor frame and, with /odom, the world frame, covariance, age, hits, misses, occluded) and
    /datmo/markers/tracks for Foxglove. Segmentation and features run first when the input lacks
    /datmo/features. Options override the config file, which overrides the defaults. INPUT is a datmo log,
    or a ROS 1/2 bag converted on the fly (--topic, --odom-topic).

    Example: datmo track sample_logs/hall.mcap -o hall-tracks.mcap

    Example: datmo track sample_logs/hall.mcap -o hall-bag --bag-dir && ros2 bag play hall-bag
    """
    from ..perception.params import FeatureParams
    from ..perception.params import load_toml as load_features
    from ..tracking.params import load_toml

    params = load_toml(config) if config is not None else TrackingParams()
    feature_params = load_features(config) if config is not None else FeatureParams()
    hits, window = confirm if confirm is not None else (None, None)
    params = params.replace(process_noise=process_noise, measurement_noise=measurement_noise, gate=gate,
                            confirm_hits=hits, confirm_window=window, delete_after=delete_after,
                            delete_after_occluded=delete_after_occluded, d_max=d_max, ego_motion=ego_motion)
    from ..cli import invocation
    from ..config import provenance_line
    from ..log import bagdir
    from ..pipeline import track_file
    from ..progress import bar, say
    from ..streaming import LogStream

    with (bagdir.output(output, bag_dir, force=force, inputs=[input]) as out,
          scan_log(input, out, topic, odom_topic, force=force) as src):
        stream = LogStream(src)   # a bad input is said before the progress bar starts
        with bar("tracking", stream.n_scans) as progress, progress.compile_notice() as report:
            scans, computed = track_file(stream, out, force=force, params=params, feature_params=feature_params,
                                         leg_model=leg_model, command_line=provenance_line(invocation("track")),
                                         markers=not no_markers, progress=report)
    how = " (segmented and extracted features first)" if computed else ""
    say(f"{output}: tracks for {scans:,} scans{how}")
