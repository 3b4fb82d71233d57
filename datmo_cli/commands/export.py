"""`datmo export`: every track's state per scan (and optionally every feature), or a simulated log's ground
truth, as CSV, NDJSON or Parquet."""

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
    from .. import export
    from ..base.outputs import atomic_output
    from ..base.progress import bar, say
    from ..logs import mcapio

    fmt = export.format_for(output, fmt)
    if fmt == "parquet":
        export.require_pyarrow()
    stdout = str(output) == "-"
    stream = export.to_stdout(fmt) if stdout else None
    if ground_truth or include_occluded:
        _ground_truth(files, output, fmt, features, ground_truth, include_occluded, force, stream)
        return
    p = export.plan(list(files), features)
    scans = p.total(mcapio.TOPIC_TRACKS)
    with bar("tracks", scans) as b:
        shown = {"topic": mcapio.TOPIC_TRACKS}

        def progress(topic: str, n: int) -> None:
            if topic != shown["topic"]:  # the features pass, after every file's tracks: its own count of scans
                shown["topic"] = topic
                b.update(0, p.total(topic), description="features")
            b.advance(n)

        def write(sink) -> None:
            export.export(p, sink, features=features, progress=progress)

        if stream is not None:
            sink = _to_stdout(stream, export.sink_for(stream, fmt, features, terminal=_terminal()), write)
        else:
            with atomic_output(output, force=force, inputs=files) as f:
                sink = export.sink_for(f, fmt, features)
                _write_file(sink, write)
    say(
        f"{'stdout' if stdout else output}: {sink.rows:,} rows ({fmt}) from {scans:,} scans of {len(files)} "
        f"file{'s' if len(files) != 1 else ''}"
    )


def _ground_truth(
    files: tuple[Path, ...],
    output: Path,
    fmt: str,
    features: bool,
    ground_truth: bool,
    include_occluded: bool,
    force: bool,
    stream,
) -> None:
    """`--ground-truth`: one log's targets as the table evaluate --gt reads."""
    from .. import export
    from ..base.errors import ConfigError
    from ..base.outputs import atomic_output
    from ..base.progress import bar, say
    from ..logs import mcapio

    if not ground_truth:
        raise ConfigError("--include-occluded: only with --ground-truth (the targets no beam hits)")
    if features:
        raise ConfigError(
            "--ground-truth with --features: the ground truth is a table of its own "
            "(stamp_ns,id,x,y,class); export it and the tracks with two commands"
        )
    if len(files) != 1:
        raise ConfigError(f"--ground-truth: give one FILE (evaluate --gt scores one log), not {len(files)}")
    p = export.plan(list(files), ground_truth=True)
    scans = p.total(mcapio.TOPIC_GROUND_TRUTH)
    with bar("moving ids", scans) as b:
        shown = {"stage": "movers"}

        def progress(stage: str, n: int) -> None:
            if stage != shown["stage"]:  # the second pass: the rows
                shown["stage"] = stage
                b.update(0, scans, description="ground truth")
            b.advance(n)

        def write(sink) -> None:
            export.export_ground_truth(files[0], sink, include_occluded=include_occluded, progress=progress)

        cols = export.GROUND_TRUTH_COLUMNS
        if stream is not None:
            sink = _to_stdout(stream, export.sink_for(stream, fmt, cols=cols, terminal=_terminal()), write)
        else:
            with atomic_output(output, force=force, inputs=files) as f:
                sink = export.sink_for(f, fmt, cols=cols)
                _write_file(sink, write)
    say(
        f"{'stdout' if stream is not None else output}: {sink.rows:,} rows ({fmt}) of ground truth from {scans:,} "
        f"scans of {files[0]}"
    )


def _write_file(sink, write) -> None:
    """Write the rows to a file with `write(sink)`; on an error or Ctrl-C the sink is closed at once, while its
    file is open (ParquetSink.abort), and the error goes on (the unfinished file is removed)."""
    try:
        write(sink)
    except BaseException:
        sink.abort()
        raise
    sink.close()


def _terminal() -> bool:
    """Whether stdout is a terminal (CSV written there has its text's control characters escaped)."""
    import sys

    from ..base.progress import is_terminal

    return is_terminal(sys.stdout)


def _to_stdout(stream, sink, write):
    """Write the rows to stdout with `write(sink)`; a reader that stops early (| head) ends the command
    quietly, exit 141 as a shell gives a process killed by SIGPIPE."""
    import os
    import sys

    try:
        write(sink)
        sink.close()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error flushing at exit
        raise SystemExit(141) from None
    return sink
