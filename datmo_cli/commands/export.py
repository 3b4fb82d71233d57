"""`datmo export`: every track's state per scan (and optionally every feature), or a simulated log's ground
truth, as CSV, NDJSON or Parquet: the options, one call of datmo_cli.api.export (workflows.exporting) and the
line it says."""

from __future__ import annotations

from pathlib import Path

import click

from .options import force_option, output_option, quiet_option

FORMATS = ("csv", "ndjson", "parquet")  # as datmo_cli.export.FORMATS, which imports numpy


@click.command(name="export")
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@output_option("The table to write; '-' writes CSV or NDJSON to stdout.", dash=True)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(FORMATS),
    default=None,
    help="csv, ndjson (one JSON object a line) or parquet (needs the parquet extra, pyarrow) "
    "[default: from OUT's suffix .csv, .ndjson/.jsonl, .parquet/.pq; csv for '-'].",
)
@click.option(
    "--features",
    is_flag=True,
    help="Also one row per line, circle, blob, point and leg of every scan (kind column; the feature "
    "columns follow the track columns). Needs /datmo/features (datmo features or datmo run).",
)
@click.option(
    "--ground-truth",
    is_flag=True,
    help="Instead of tracks, the log's /datmo/ground_truth (datmo simulate) as the stamp_ns,id,x,y,class "
    "table datmo evaluate --gt reads: the targets evaluate scores (movers that move, in the scans "
    "a beam hits them), sensor frame, m. One FILE.",
)
@click.option(
    "--include-occluded",
    is_flag=True,
    help="With --ground-truth: also the targets no beam hits (what evaluate --include-occluded scores).",
)
@force_option()
@quiet_option
def command(
    files: tuple[Path, ...],
    output: Path,
    fmt: str | None,
    features: bool,
    ground_truth: bool,
    include_occluded: bool,
    force: bool,
) -> None:
    """Write every track's state after every scan of processed logs as one table: file, scan, stamp_ns,
    frame_id, kind, id, class, mobility, status, x_m, y_m, vx_mps, vy_mps, world_x_m, world_y_m,
    world_vx_mps, world_vy_mps, size_m, occluded, age, hits, misses (positions and velocities in the scan's
    sensor frame, world_* in the odometry frame and empty without odometry; m, m/s, ns). The schema, with
    the --features columns and their types, is in docs/export.md.

    FILES are logs that went through datmo track or datmo run; their rows follow one another in the order
    given (with --features: every file's track states, then every file's features). Memory stays the same
    whatever the logs' length: rows are written 1,000 messages at a time.

    With --ground-truth FILE is one simulated log (raw or processed) and the table holds its ground truth
    as stamp_ns,id,x,y,class rows, a row with only stamp_ns for a scan without targets, so that
    `datmo evaluate FILE --gt OUT` scores the same targets and frames as evaluate on the channel. The CSV
    cannot carry the don't-care regions (scene structure, movers that never move, hidden targets): scored
    against it, tracks on them are false positives (evaluate on the channel reports them as ignored tracks).

    Example: datmo export out/hall.mcap -o hall-tracks.csv
    """
    import os
    import sys

    from .. import api
    from ..base.progress import say

    try:
        result = api.export(
            files,
            output,
            fmt=fmt,
            features=features,
            ground_truth=ground_truth,
            include_occluded=include_occluded,
            force=force,
        )
    except BrokenPipeError:  # a reader that stopped early (| head): quietly, exit 141 as a shell gives for SIGPIPE
        if str(output) != "-":
            raise
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error flushing at exit
        raise SystemExit(141) from None
    say(result.summary)
