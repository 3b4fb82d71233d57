"""`datmo export`: every track's state per scan (and optionally every feature) as CSV, NDJSON or Parquet."""

from __future__ import annotations

from pathlib import Path

import click

from ..progress import quiet_option

FORMATS = ("csv", "ndjson", "parquet")   # as datmo_cli.export.FORMATS, which imports numpy


@click.command(name="export")
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, allow_dash=True, path_type=Path),
              help="The table to write; '-' writes CSV or NDJSON to stdout.")
@click.option("--format", "fmt", type=click.Choice(FORMATS), default=None,
              help="csv, ndjson (one JSON object a line) or parquet (needs pip install 'datmo[parquet]') "
                   "[default: from OUT's suffix .csv, .ndjson/.jsonl, .parquet/.pq; csv for '-'].")
@click.option("--features", is_flag=True,
              help="Also one row per line, circle, blob, point and leg of every scan (kind column; the feature "
                   "columns follow the track columns). Needs /datmo/features (datmo features or datmo run).")
@click.option("--force", is_flag=True, help="Overwrite the output if it exists.")
@quiet_option
def command(files: tuple[Path, ...], output: Path, fmt: str | None, features: bool, force: bool) -> None:
    """Write every track's state after every scan of processed logs as one table: file, scan, stamp_ns,
    frame_id, kind, id, class, mobility, status, x_m, y_m, vx_mps, vy_mps, world_x_m, world_y_m,
    world_vx_mps, world_vy_mps, size_m, occluded, age, hits, misses (positions and velocities in the scan's
    sensor frame, world_* in the odometry frame and empty without odometry; m, m/s, ns). The schema, with
    the --features columns, is in datmo_cli/export.py.

    FILES are logs that went through datmo track or datmo run; their rows follow one another in the order
    given (with --features: every file's track states, then every file's features). Memory stays the same
    whatever the logs' length: rows are written 1,000 messages at a time.

    Example: datmo export out/hall.mcap -o hall-tracks.csv
    """
    from .. import export
    from ..outputs import atomic_output
    from ..progress import bar, say

    fmt = export.format_for(output, fmt)
    if fmt == "parquet":
        export.require_pyarrow()
    stdout = str(output) == "-"
    stream = export.to_stdout(fmt) if stdout else None
    p = export.plan(list(files), features)
    scans = p.total(export.mcapio.TOPIC_TRACKS)
    with bar("tracks", scans) as b:
        shown = {"topic": export.mcapio.TOPIC_TRACKS}

        def progress(topic: str, n: int) -> None:
            if topic != shown["topic"]:   # the features pass, after every file's tracks: its own count of scans
                shown["topic"] = topic
                b.update(0, p.total(topic), description="features")
            b.advance(n)

        if stdout:
            sink = _to_stdout(p, stream, fmt, features, progress)
        else:
            with atomic_output(output, force=force, inputs=files) as f:
                sink = export.sink_for(f, fmt, features)
                export.export(p, sink, features=features, progress=progress)
                sink.close()
    say(f"{'stdout' if stdout else output}: {sink.rows:,} rows ({fmt}) from {scans:,} scans of {len(files)} "
        f"file{'s' if len(files) != 1 else ''}")


def _to_stdout(p, stream, fmt: str, features: bool, progress):  # noqa: ANN001, ANN202 - export.Plan, sink
    """Write the rows to stdout; a reader that stops early (| head) ends the command quietly, exit 141 as a
    shell gives a process killed by SIGPIPE."""
    import os
    import sys

    from .. import export

    sink = export.sink_for(stream, fmt, features)
    try:
        export.export(p, sink, features=features, progress=progress)
        sink.close()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())   # no second error flushing at exit
        raise SystemExit(141) from None
    return sink
