"""`datmo report`: the per-run classification summary of processed logs."""

from __future__ import annotations

from pathlib import Path

import click

from ..base.bounds import OPTIONS
from ..report import FORMATS, SORT_KEYS
from .options import force_option, quiet_option
from .types import option

PLOT_KINDS = ("auto", "top", "counts", "speeds", "all")


@click.command(name="report")
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "--format",
    "fmt",
    type=click.Choice(FORMATS),
    default="rich",
    show_default=True,
    help="rich tables for a terminal; json, csv or markdown for scripts and CI.",
)
@option(
    "--top",
    bound=OPTIONS["top"],
    default=None,
    help="Tracks in each file's track table (0: all) [default: 20 for rich and markdown, all for json, csv].",
)
@click.option(
    "--sort",
    type=click.Choice(SORT_KEYS),
    default="lifetime",
    show_default=True,
    help="Order of the track tables (lifetime, distance and speed: largest first).",
)
@click.option(
    "--tracks",
    "track_table",
    is_flag=True,
    help="csv: one row per confirmed track (with a file column) instead of one per file; json: add that tracks list.",
)
@click.option(
    "--all",
    "all_tracks",
    is_flag=True,
    help="Report every confirmed track in full (static pieces too) and label all of them in the plot.",
)
@click.option(
    "--plot",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also draw the run into this .png, .svg or .pdf "
    "(several files: one plot each, named PLOT-STEM.png). Needs the plot extra (matplotlib).",
)
@click.option(
    "--plot-kind",
    type=click.Choice(PLOT_KINDS),
    default="auto",
    show_default=True,
    help="top: the run from above; counts: confirmed tracks per class over time; speeds: the moving "
    "tracks' speeds over time; all: the three side by side; auto: all when something moves, "
    "else top.",
)
@force_option("Overwrite existing plots.")
@quiet_option
def command(
    files: tuple[Path, ...],
    fmt: str,
    top: int | None,
    sort: str,
    track_table: bool,
    all_tracks: bool,
    plot: Path | None,
    plot_kind: str,
    force: bool,
) -> None:
    """Summarise what processed runs saw, leading with what moves: run facts, features, landmarks, people
    and dynamic tracks in full (lifetimes, distance travelled, speeds, occlusions, last position), and the
    static pieces (walls, furniture) per class: how many and where.

    FILES are logs that went through datmo track or datmo run. Every format has one shape whatever the
    number of files: csv gives one row per file and a total row (--tracks: one row per track, with a file
    column); json gives {"schema": "datmo.report/1", "files": [...], "total": {...}, "batches": [...]} (and
    "tracks" with --tracks); rich and markdown the files table, then each file's tables.

    A folder is a batch of datmo run (-o DIR): its outputs that are done join FILES, and its manifest.jsonl
    gives the batch's figures (inputs done and failed, scans, tracks by class, failures): rich and markdown
    tables before the report, json "batches". Only outputs inside the folder count, each once.

    With several files --plot writes PLOT-STEM.png for each, PLOT-FOLDER-STEM.png where two stems are alike.

    Example: datmo report out/hall.mcap --plot out/hall.png
    """
    from .. import api
    from ..base.progress import say

    result = api.report(files, plot=plot, plot_kind=plot_kind, all_tracks=all_tracks, force=force)
    _print(result.summaries, result.batches, fmt, top=top, sort=sort, tracks=track_table, all_tracks=all_tracks)
    for line in result.written:
        say(line)


def _print(summaries: list, batches: list[tuple[Path, list[dict]]], fmt: str, **options) -> None:
    """Print the report of `summaries` (report.RunSummary) and of the batch folders in `fmt` on stdout."""
    from ..report import render

    if fmt == "json":
        from ..batch import summary

        click.echo(
            render(
                summaries,
                fmt,
                **options,
                batches=[{"folder": str(d), "summary": summary(recs), "inputs": recs} for d, recs in batches],
            )
        )
    elif fmt == "rich":
        from ..report import console

        render(summaries, fmt, **options, console=console(), before=_batch_tables(batches))
    else:
        click.echo(render(summaries, fmt, **options, before=_batch_tables(batches)), nl=False)


def _batch_tables(batches: list[tuple[Path, list[dict]]]) -> list:
    """The report's tables of batch folders: figures, tracks by class, failures and missing outputs."""
    from ..batch import TRACK_CLASSES, summary
    from ..report import Table

    if not batches:
        return []
    sums = [(d, summary(recs)) for d, recs in batches]
    figures = Table(
        "Batches (from each folder's manifest.jsonl)",
        ["folder", "inputs", "done", "failed", "scans", "task s", "scans/s per task", "datmo", "parameters"],
        [
            [
                str(d),
                s["inputs"],
                s["done"],
                s["failed"],
                s["scans"],
                s["task_seconds"],
                s["scans_per_task_second"],
                ", ".join(s["versions"]),
                ", ".join(s["params_hashes"]),
            ]
            for d, s in sums
        ],
        numeric={1, 2, 3, 4, 5, 6},
    )
    keys = ("confirmed", *TRACK_CLASSES, "dynamic")
    tracks = Table(
        "Confirmed tracks by class, every input of the batch",
        ["folder", *(k.replace("_", " ") for k in keys)],
        [[str(d), *(s["tracks"][k] for k in keys)] for d, s in sums],
        numeric=set(range(1, len(keys) + 1)),
    )
    out = [figures, tracks]
    failures = [[str(d), f["input"], f["error"]] for d, s in sums for f in s["failures"]]
    if failures:
        out.append(
            Table("Failed inputs (run the same command again to retry them)", ["folder", "input", "error"], failures)
        )
    missing = [[str(d), m] for d, s in sums for m in s["missing_outputs"]]
    if missing:
        out.append(Table("Done in the manifest but missing", ["folder", "output"], missing))
    return out
