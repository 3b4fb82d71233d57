"""`datmo track`: track and classify objects in a log (method.md §6), writing /datmo/tracks and markers."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import click

from ..tracking.params import TrackingParams

D = TrackingParams()

def features_leg_model(log) -> str:  # noqa: ANN001 - mcapio.Log
    """The leg detector a log's /datmo/features were made with, from its provenance ("paper" for features
    made before datmo had a detector, whose legs are the paper's circles)."""
    import json

    for name in ("datmo.params", "input/datmo.params"):
        raw = log.metadata.get(name, {}).get("features")
        if raw:
            try:
                return str(json.loads(raw).get("leg_model", "paper"))
            except (ValueError, AttributeError):
                return "paper"
    return "paper"


def track_file(src: Path, out: Path, *, force: bool = False, params=None, feature_params=None,  # noqa: ANN001
               leg_model: str | None = None, progress: Callable[[int, int], None] | None = None,
               feature_progress: Callable[[int, int], None] | None = None) -> tuple[int, bool]:
    """Track `src` into `out` (its channels copied, /datmo/tracks and /datmo/markers/tracks added).
    Features come from src's /datmo/features when present (people then by the rule of the leg detector
    they were made with; `leg_model`, when given, must be that one); else segmentation and features run
    here (with `leg_model` when given) and their channels are written too, as datmo run writes them.
    `progress` and `feature_progress` are called with (scans done, total) as tracking and feature
    extraction go. Returns (scans, whether features were computed here)."""
    from ..cli import invocation
    from ..errors import InputError
    from ..log import mcapio
    from ..perception.features import derive_features, leg_model_provenance
    from ..perception.params import FeatureParams
    from ..pipeline import estimated_odometry
    from ..tracking.params import TrackingParams
    from ..tracking.pipeline import decode_features, derive_tracks, iter_run_features

    params = params or TrackingParams()
    log = mcapio.read_log(src, topics=None)
    run = mcapio.run_from_log(log)
    odometry = mcapio.odometry_from_log(log)
    computed = not log.has(mcapio.TOPIC_FEATURES)
    odometry, derived = estimated_odometry(run, odometry, params.ego_motion)
    effective: dict = {"track": params.to_dict()}
    if computed:
        feature_params = (feature_params or FeatureParams()).replace(leg_model=leg_model)
        used = feature_params.leg_model
        if feature_progress is not None:
            feature_progress(0, len(run))
        channels, run_features = derive_features(run, odometry=odometry, params=feature_params,
                                                 progress=feature_progress)
        derived |= channels
        features = list(iter_run_features(run_features))
        effective["features"] = feature_params.to_dict()
    else:
        used = features_leg_model(log)
        if leg_model is not None and leg_model != used:
            raise InputError(f"{src}: its features were made with leg model {used!r}, not {leg_model!r}; run "
                             f"datmo features --leg-model {leg_model} on it first, or drop --leg-model")
        stamps, payloads = log.messages[mcapio.TOPIC_FEATURES]
        if len(payloads) != len(run):
            raise InputError(f"{src}: {len(payloads)} messages on {mcapio.TOPIC_FEATURES} for {len(run)} scans; "
                             "run datmo features again")
        features = decode_features(payloads)
    if progress is not None:
        progress(0, len(run))
    effective["leg_model"] = leg_model_provenance(used) if used == "paper" or computed else {"model": used}
    derived |= derive_tracks(run, features, odometry=odometry, params=params, learned=used != "paper",
                             progress=progress)
    provenance = mcapio.Provenance("track", effective, [src], invocation("track"))
    with mcapio.LogWriter(out, force=force, provenance=provenance) as writer:
        writer.copy_from(log, exclude=list(derived))
        for topic, (msgtype, stamps, payloads) in derived.items():
            writer.write_many(topic, msgtype, stamps, payloads)
    return len(run), computed


@click.command(name="track")
@click.argument("input", type=click.Path(path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The log to write (MCAP): the input's channels plus /datmo/tracks and /datmo/markers/tracks.")
@click.option("--force", is_flag=True, help="Overwrite the output if it exists.")
@click.option("--config", "config", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="TOML file with a [track] table of parameters (names as in the options below and more), and "
                   "a [features] table used when the input has no features.")
@click.option("--process-noise", type=click.FloatRange(min=0, min_open=True), default=None,
              help=f"White-noise acceleration variance q, (m/s²)² per Hz [default: {D.process_noise:g}].")
@click.option("--measurement-noise", type=click.FloatRange(min=0, min_open=True), default=None,
              help=f"Sigma of a measured model centre, m [default: {D.measurement_noise:g}].")
@click.option("--gate", type=click.FloatRange(min=0, min_open=True), default=None,
              help=f"Gate on the squared Mahalanobis distance [default: {D.gate:g}, chi² 2 dof 99.9 %].")
@click.option("--confirm", "confirm", type=(int, int), default=None, metavar="M N",
              help=f"Confirm a track after M hits in N scans [default: {D.confirm_hits} {D.confirm_window}].")
@click.option("--delete-after", type=click.FloatRange(min=0, min_open=True), default=None,
              help=f"Seconds a confirmed track lives unseen when it should be seen [default: {D.delete_after:g}].")
@click.option("--delete-after-occluded", type=click.FloatRange(min=0, min_open=True), default=None,
              help=f"Seconds a confirmed track lives unseen while occluded or out of view "
                   f"[default: {D.delete_after_occluded:g}].")
@click.option("--d-max", type=click.FloatRange(min=0, min_open=True), default=None,
              help=f"Objects larger than this are static, m [default: {D.d_max:g}].")
@click.option("--ego-motion", type=click.Choice(["auto", "on", "off"]), default=None,
              help="For a log without /odom: track in poses estimated by scan matching (written to /odom, frame "
                   "scan_odom) when the scanner moves ('auto'), always ('on') or never ('off') [default: auto].")
@click.option("--leg-model", default=None, metavar="MODEL",
              help="Leg detector for inputs without features: 'default' (shipped), a file from datmo train-legs, "
                   "or 'paper' (the paper's circle rule and walking pattern). Inputs with features keep theirs.")
def command(input: Path, output: Path, force: bool, config: Path | None, process_noise: float | None,
            measurement_noise: float | None, gate: float | None, confirm: tuple[int, int] | None,
            delete_after: float | None, delete_after_occluded: float | None, d_max: float | None,
            ego_motion: str | None, leg_model: str | None) -> None:
    """Track and classify the objects of a log: Kalman filter, gating and global nearest-neighbour
    association, occlusion-aware track life cycle, people from paired legs and their walking pattern.

    Writes the input's channels plus /datmo/tracks (every scan: id, class, mobility, position and velocity
    in the sensor frame and, with /odom, the world frame, covariance, age, hits, misses, occluded) and
    /datmo/markers/tracks for Foxglove. Segmentation and features run first when the input lacks
    /datmo/features. Options override the config file, which overrides the defaults.

    Example: datmo track sample_logs/hall.mcap -o hall-tracks.mcap
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
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

    from .compiling import compile_notice

    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), console=Console(stderr=True),
                  transient=True) as bar:
        task = bar.add_task("reading", total=None)
        with compile_notice(bar, task, armed=False) as report:
            def stage(label: str) -> Callable[[int, int], None]:
                def start_or_report(done: int, total: int) -> None:
                    if done == 0:
                        bar.update(task, description=label)
                    report(done, total)
                return start_or_report

            scans, computed = track_file(input, output, force=force, params=params, feature_params=feature_params,
                                         leg_model=leg_model, progress=stage("tracking"),
                                         feature_progress=stage("features"))
    how = " (segmented and extracted features first)" if computed else ""
    click.echo(f"{output}: tracks for {scans:,} scans{how}", err=True)
