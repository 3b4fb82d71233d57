"""`datmo evaluate`: CLEAR-MOT and identity scores of a tracked log against ground truth."""

from __future__ import annotations

from pathlib import Path

import click

from ..bounds import OPTIONS, option

COLUMNS = {"mota": "MOTA", "motp": "MOTP m", "idf1": "IDF1", "num_objects": "objects", "num_matches": "matches",
           "num_false_positives": "false pos.", "num_misses": "misses", "num_switches": "ID switches",
           "precision": "precision", "recall": "recall", "mostly_tracked": "mostly tracked",
           "mostly_lost": "mostly lost", "num_unique_objects": "objects (unique)",
           "ignored_hypotheses": "ignored tracks"}


def score_file(path: Path, *, gt_csv: Path | None = None, match_radius: float = 0.5, include_occluded: bool = False,
               exclude_static: bool = False) -> dict:
    """Read `path` (and the CSV) and score it: {"file", "ground_truth", "match_radius_m", "scores": {...}}."""
    import numpy as np

    from .. import evaluate as ev
    from ..errors import InputError, MissingChannelError
    from ..log import mcapio, types
    from ..report import decode_channel, require

    topics = [mcapio.TOPIC_TRACKS] + ([] if gt_csv else [mcapio.TOPIC_GROUND_TRUTH])
    log = mcapio.read_log(path, topics=topics)
    require(log, mcapio.TOPIC_TRACKS)
    tracks = decode_channel(types.TRACKS, log.messages[mcapio.TOPIC_TRACKS][1])
    hyps = ev.track_frames(tracks.stamps, tracks.offsets["tracks"], tracks.items["tracks"],
                           include_coasting=include_occluded, exclude_static=exclude_static)
    if gt_csv is not None:
        gt, regions = ev.read_ground_truth_csv(gt_csv), None
        dt = np.diff(np.sort(tracks.stamps))
        tolerance = int(np.median(dt) // 2) if len(dt) else 0  # annotation stamps may be rounded
        source = str(gt_csv)
    else:
        if not log.has(mcapio.TOPIC_GROUND_TRUTH):
            raise MissingChannelError(f"{path}: no messages on {mcapio.TOPIC_GROUND_TRUTH}; run datmo simulate "
                                      "first, or give annotations with --gt FILE.csv (stamp_ns,id,x,y)")
        truth = decode_channel(types.GROUND_TRUTH, log.messages[mcapio.TOPIC_GROUND_TRUTH][1])
        gt, regions = ev.ground_truth_frames(truth.stamps, truth.offsets["objects"], truth.items["objects"],
                                             truth.scalars.get("sensor_theta"), include_occluded=include_occluded)
        tolerance = 0
        source = mcapio.TOPIC_GROUND_TRUTH
        if not (np.isfinite(gt.x).all() and np.isfinite(gt.y).all()):
            raise InputError(f"{path}: {source} holds positions that are not finite numbers")
    scores = ev.evaluate(gt, hyps, regions=regions, match_radius=match_radius, stamp_tolerance_ns=tolerance)
    if scores["all"]["frames_without_tracks"] == len(gt.stamps):
        raise InputError(f"{path}: no Tracks message has the stamp of any ground-truth frame of {source}")
    return {"file": str(path), "ground_truth": source, "match_radius_m": match_radius,
            "include_occluded": include_occluded, "exclude_static": exclude_static, "scores": scores}


def _table(result: dict, by_metric: bool = False):  # noqa: ANN202 - report.Table
    """The scores as a table: one row per class, or (by_metric, narrow enough for a terminal) per metric."""
    from ..report import Table

    scores = result["scores"]
    title = (f"{result['file']} against {result['ground_truth']} "
             f"(match radius {result['match_radius_m']:g} m, {scores['all']['num_frames']:,} frames)")

    def value(v: object) -> object:
        return f"{v:.3f}" if isinstance(v, float) else v

    if by_metric:
        rows = [[label] + [value(s.get(k)) for s in scores.values()] for k, label in COLUMNS.items()]
        return Table(title, ["metric"] + list(scores), rows, set(range(1, len(scores) + 1)))
    rows = [[name] + [value(s.get(k)) for k in COLUMNS] for name, s in scores.items()]
    return Table(title, ["class"] + list(COLUMNS.values()), rows, set(range(1, len(COLUMNS) + 1)))


@click.command(name="evaluate")
@click.argument("file", type=click.Path(path_type=Path))
@click.option("--gt", "gt_csv", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Ground truth as CSV (stamp_ns,id,x,y in the sensor frame, metres; optional class column) "
                   "instead of the log's /datmo/ground_truth channel.")
@option("--match-radius", bound=OPTIONS["match_radius"], default=0.5, show_default=True,
        help="Largest distance, metres, at which a track can match a ground-truth object.")
@click.option("--include-occluded", is_flag=True,
              help="Also score movers no beam hits, with coasting tracks as hypotheses.")
@click.option("--exclude-static", is_flag=True, help="Do not count tracks the tracker classifies static.")
@click.option("--format", "fmt", type=click.Choice(["rich", "json", "markdown"]), default="rich", show_default=True,
              help="rich tables for a terminal; json or markdown for scripts and CI.")
@option("--min-mota", bound=OPTIONS["min_mota"], default=None,
        help="Exit with status 1 when the overall MOTA is below this (for CI).")
def command(file: Path, gt_csv: Path | None, match_radius: float, include_occluded: bool, exclude_static: bool,
            fmt: str, min_mota: float | None) -> None:
    """Score FILE's tracks against ground truth: MOTA, MOTP, IDF1, false positives, misses and identity
    switches (py-motmetrics), overall and per class.

    Targets are the ground-truth people, circle and rectangular objects that move during the run, in the
    scans where the scanner hits them; hypotheses are confirmed tracks; a track matches a target within
    --match-radius metres in the sensor frame. Tracks on scene structure, on objects that never move or
    on hidden targets are ignored (neither matches nor false positives). MOTP is the mean distance of
    matches, in metres.

    Example: datmo evaluate out/hall.mcap --format json --min-mota 0.6
    """
    from ..errors import DatmoError
    from ..report import render_markdown, render_rich, to_json

    result = score_file(file, gt_csv=gt_csv, match_radius=match_radius, include_occluded=include_occluded,
                        exclude_static=exclude_static)
    if fmt == "json":
        click.echo(to_json(result))
    elif fmt == "markdown":
        click.echo(render_markdown([_table(result)]), nl=False)
    else:
        from ..report import console

        render_rich([_table(result, by_metric=True)], console())
    mota = result["scores"]["all"]["mota"]
    if min_mota is not None and (mota is None or mota < min_mota):
        shown = "undefined" if mota is None else f"{mota:.3f}"
        raise DatmoError(f"{file}: MOTA {shown} is below --min-mota {min_mota:g}")
