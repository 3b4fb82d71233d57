"""`datmo run`: options, then datmo_cli.api.run_batch (the work), then what batch_view prints of it."""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from ..base.bounds import OPTIONS
from . import batch_view
from .options import (
    config_options,
    executor_options,
    force_option,
    input_options,
    no_stdout,
    output_option,
    param_option,
    quiet_option,
)
from .types import option

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


@click.command(name="run")
@click.argument("inputs", nargs=-1, required=True)
@output_option(
    "Folder (or fsspec URL) for the outputs: OUT_DIR/NAME.mcap per input file, the relative path "
    "for logs found in a folder; and OUT_DIR/manifest.jsonl, the batch's ledger (created if missing).",
    "-o",
    "--output-dir",
    "out_dir",
    type=str,
    callback=no_stdout("outputs", "a folder"),
)
@executor_options("Inputs processed", "a task", "one task per input")
@force_option(
    "Redo every input and overwrite existing outputs (and plots); without it "
    "inputs the manifest lists as done with the same input and parameters are skipped."
)
@config_options(
    "TOML file of parameters: its [features] table as for datmo features, its [track] table as for datmo track."
)
@click.option(
    "--plot",
    is_flag=True,
    help="Also draw each run from above into OUT_DIR/NAME.png (needs the plot extra, matplotlib).",
)
@click.option(
    "--bag-dir",
    is_flag=True,
    help="Write each output as a ROS 2 bag folder for ros2 bag play: OUT_DIR/NAME/ holding NAME_0.mcap "
    "(the output, as the manifest names it) and metadata.yaml.",
)
@batch_view.report_options
@click.option(
    "--markers/--no-markers",
    default=False,
    show_default=True,
    help="Also store /datmo/markers/* (Foxglove drawings) in the outputs; datmo play draws them from the "
    "tracks and features anyway.",
)
@click.option(
    "--covariance",
    is_flag=True,
    help="Store each track's covariance in /datmo/tracks (otherwise its 16 numbers are NaN).",
)
@param_option("track.ego_motion")
@param_option("track.hindsight_lag")
@param_option("features.leg_model")
@option(
    "--threads",
    bound=OPTIONS["threads"],
    default=None,
    help="Threads for each input's per-scan perception (segmentation, features, leg detector) [default: "
    "all cores; one in each of several local jobs at once, and in each task on a Dask worker]; the "
    "results are the same for any number.",
)
@input_options
@quiet_option
def command(
    inputs: tuple[str, ...],
    out_dir: str,
    cfg: DatmoConfig,
    fmt: str,
    top: int | None,
    sort: str,
    no_report: bool,
    **options,
) -> None:
    """Segment, extract features and track each input in one pass, then print the report.

    Each output holds the input's channels and /datmo/segments, /datmo/features, /datmo/landmarks and
    /datmo/tracks (with --markers the Foxglove markers too, with --covariance the tracks' covariance), with
    the same messages as datmo segment, datmo features and datmo track run one after another. The report is
    gathered as the outputs are written. INPUTS are files, folders (searched recursively for .mcap logs) and globs, or
    fsspec URLs. ROS 1 bags and ROS 2 bag folders or their .db3 (and any input with --topic) are converted as
    by datmo import by the input's own task, into a temporary MCAP beside its output (removed when the task
    ends); the output is named after the bag and its provenance names the bag. Inputs run in parallel in local
    processes (--jobs) or on a Dask cluster (--scheduler); a failing input is reported and the others'
    outputs are kept (the exit status is then 1). A tcp:// scheduler lets whoever reaches it run code as its
    user; a tls:// one takes the certificate of the Dask configuration; local[:N] (N at most the cores) speaks
    TLS with a temporary certificate, so no other user of the machine can reach it.

    OUT_DIR/manifest.jsonl gets one line per input as it finishes (input SHA-256, output, status, scans,
    tracks by class, parameters' hash, which counts --topic and --odom-topic). Running the same command again
    skips the inputs already done with the same input and parameters, bags without converting them, and does
    the rest (after a failure or Ctrl-C); --force redoes all.

    With --bag-dir each output is a ROS 2 bag folder, OUT_DIR/NAME/ holding NAME_0.mcap and metadata.yaml, which
    ros2 bag play and other bag tools open (build datmo_msgs for the /datmo topics); plots stay OUT_DIR/NAME.png.

    Example: datmo run sample_logs/hall.mcap sample_logs/corridor.mcap -o out --plot

    Example: datmo run 'logs/**/*.mcap' -o out --scheduler tcp://10.0.0.5:8786
    """
    from .. import api
    from ..cli import invocation

    result = api.run_batch(
        inputs,
        out_dir,
        config=cfg,
        report=not no_report,
        on_ran=batch_view.ran,
        on_plot=batch_view.plotted,
        command_line=invocation("run"),
        **options,
    )
    if result.summaries is not None and not no_report:
        batch_view.print_report(result.summaries, fmt, top, sort)
    batch_view.exit_status(result)


_report = batch_view.report  # the report at the end of a run (its plots drawn), for scripts and tests
