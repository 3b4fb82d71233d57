"""`datmo export`'s work as a call (datmo_cli.api.export): every track's state after every scan of processed logs
(and their features), or a simulated log's ground truth, as one CSV, NDJSON or Parquet table (export: positions
and velocities in the scan's sensor frame, world_* in the odometry frame; m, m/s, int64 ns). The command keeps
the line it says and how a reader that stops early ends it."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path


@dataclass
class ExportResult:
    """What an export wrote: `output` ("-": stdout), `rows`, the `fmt`, the `scans` read, the `files` and
    whether it was their `ground_truth`."""

    output: str
    rows: int
    fmt: str
    scans: int
    files: list[Path]
    ground_truth: bool = False

    @property
    def summary(self) -> str:
        """The line `datmo export` says."""
        where = "stdout" if self.output == "-" else self.output
        if self.ground_truth:
            return (
                f"{where}: {self.rows:,} rows ({self.fmt}) of ground truth from {self.scans:,} scans of {self.files[0]}"
            )
        n = len(self.files)
        return f"{where}: {self.rows:,} rows ({self.fmt}) from {self.scans:,} scans of {n} file{'s' if n != 1 else ''}"


def export_files(
    files: Sequence[str | os.PathLike],
    output: str | os.PathLike,
    *,
    fmt: str | None = None,
    features: bool = False,
    ground_truth: bool = False,
    include_occluded: bool = False,
    force: bool = False,
) -> ExportResult:
    """`datmo export FILES -o OUTPUT`: the tracks of `files` (logs that went through `datmo track` or `run`), in
    the order given, as one table written to `output` ("-": stdout, CSV or NDJSON); `fmt` "csv", "ndjson" or
    "parquet" (None: from the output's suffix); `features`: also every feature's row. `ground_truth`: instead,
    one simulated log's /datmo/ground_truth as the stamp_ns,id,x,y,class table `evaluate --gt` reads (with
    `include_occluded`, also the targets no beam hits). The file is written under a temporary name and renamed
    when complete (an existing one only with `force`). A progress bar on stderr in a terminal. Returns the
    ExportResult; ConfigError for options that do not go together."""
    from .. import export

    paths = [Path(f) for f in files]
    fmt = export.format_for(Path(output), fmt)
    if fmt == "parquet":
        export.require_pyarrow()
    stream = export.to_stdout(fmt) if os.fsdecode(output) == "-" else None
    if ground_truth or include_occluded:
        return _ground_truth(paths, output, fmt, features, ground_truth, include_occluded, force, stream)
    from ..base.progress import bar
    from ..logs import mcapio

    p = export.plan(paths, features)
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
            sink = _to_stream(export.sink_for(stream, fmt, features, terminal=_terminal()), write)
        else:
            sink = _to_file(output, force, paths, lambda f: export.sink_for(f, fmt, features), write)
    return ExportResult(os.fsdecode(output), sink.rows, fmt, scans, paths)


def _ground_truth(files, output, fmt, features, ground_truth, include_occluded, force, stream) -> ExportResult:
    """`ground_truth`: one log's targets as the table evaluate --gt reads."""
    from .. import export
    from ..base.errors import ConfigError
    from ..base.progress import bar
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
            sink = _to_stream(export.sink_for(stream, fmt, cols=cols, terminal=_terminal()), write)
        else:
            sink = _to_file(output, force, files, lambda f: export.sink_for(f, fmt, cols=cols), write)
    out = "-" if stream is not None else os.fsdecode(output)
    return ExportResult(out, sink.rows, fmt, scans, list(files), ground_truth=True)


def _to_file(output, force: bool, inputs, make_sink, write):
    """Write the rows to `output` (atomic_output) with `write(sink)`; on an error or Ctrl-C the sink is closed at
    once, while its file is open (ParquetSink.abort), and the error goes on (the unfinished file is removed)."""
    from ..base.outputs import atomic_output

    with atomic_output(Path(output), force=force, inputs=inputs) as f:
        sink = make_sink(f)
        try:
            write(sink)
        except BaseException:
            sink.abort()
            raise
        sink.close()
    return sink


def _to_stream(sink, write):
    """Write the rows to stdout with `write(sink)` (BrokenPipeError when its reader stops early: `| head`)."""
    write(sink)
    sink.close()
    return sink


def _terminal() -> bool:
    """Whether stdout is a terminal (CSV written there has its text's control characters escaped)."""
    import sys

    from ..base.progress import is_terminal

    return is_terminal(sys.stdout)
