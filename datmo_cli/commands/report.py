"""`datmo report`: the per-run classification summary of processed logs."""

from __future__ import annotations

from pathlib import Path

import click

from ..bounds import OPTIONS, option
from ..report import FORMATS, SORT_KEYS

PLOT_SUFFIXES = (".png", ".svg", ".pdf")


def plot_paths(plot: Path, files: list[Path]) -> list[Path]:
    """Where each file's plot goes: `plot` itself for one file, else PLOT-STEM.SUFFIX per file."""
    if len(files) == 1:
        return [plot]
    return [plot.with_name(f"{plot.stem}-{f.stem}{plot.suffix}") for f in files]


def check_plot_outputs(paths: list[Path], force: bool) -> None:
    """Refuse a bad plot suffix or a plot path outputs.check_output refuses (an existing plot without
    --force, a folder or device in the way, a missing or read-only folder), before any work."""
    from ..errors import InputError
    from ..outputs import check_output

    for p in paths:
        if p.suffix.lower() not in PLOT_SUFFIXES:
            raise InputError(f"{p}: plot format must be one of {', '.join(PLOT_SUFFIXES)}")
        check_output(p, force=force, what="plot")


def save_plot(data, path: Path, force: bool) -> None:  # noqa: ANN001 - pipeline.RunData
    """Draw `data` into `path` atomically (a temporary file renamed when the figure is complete)."""
    import matplotlib

    from ..outputs import atomic_output
    from ..plot import plot_run

    with atomic_output(path, force=force, what="plot") as f, \
            matplotlib.rc_context({"savefig.format": path.suffix.lower().lstrip(".")}):
        plot_run(data, f)


@click.command(name="report")
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--format", "fmt", type=click.Choice(FORMATS), default="rich", show_default=True,
              help="rich tables for a terminal; json, csv or markdown for scripts and CI.")
@option("--top", bound=OPTIONS["top"], default=None,
        help="Tracks in the per-track table (0: all) [default: 20 for rich and markdown, all for json, csv].")
@click.option("--sort", type=click.Choice(SORT_KEYS), default="lifetime", show_default=True,
              help="Order of the per-track table (lifetime, distance and speed: largest first).")
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also draw the run from above into this .png, .svg or .pdf "
                   "(several files: one plot each, named PLOT-STEM.png).")
@click.option("--force", is_flag=True, help="Overwrite existing plots.")
def command(files: tuple[Path, ...], fmt: str, top: int | None, sort: str, plot: Path | None, force: bool) -> None:
    """Summarise what processed runs saw: run facts, features, landmarks, tracks by class and mobility
    (counts, lifetimes, distance travelled, speeds, occlusions) and a per-track table.

    FILES are logs that went through datmo track or datmo run. Several files give one row per file and
    a total row. csv prints the track table of one file, or the per-file table of several.

    A folder is a batch of datmo run (-o DIR): its manifest.jsonl gives the batch's figures (inputs done
    and failed, scans, tracks by class, failures), and its outputs the per-file table (csv: one row per
    input of the manifest).

    Example: datmo report out/hall.mcap --plot out/hall.png
    """
    from ..pipeline import read_run_data
    from ..report import render, summarise, summarise_file

    files, batches = _batches(list(files))
    if batches and fmt == "csv":
        click.echo(_batch_csv(batches), nl=False)
        return
    plots = plot_paths(plot, files) if plot else []
    check_plot_outputs(plots, force)
    summaries = []
    for i, path in enumerate(files):
        if not plot:   # one streaming pass; the plot draws every scan and state, so it decodes the whole run
            summaries.append(summarise_file(path))
            continue
        data = read_run_data(path, keep_scans=True)
        summaries.append(summarise(data))
        save_plot(data, plots[i], force)
    if fmt == "rich":
        from ..report import console, render_rich

        if batches:
            render_rich(_batch_tables(batches), console())
        if summaries:
            render(summaries, fmt, top=top, sort=sort, console=console())
    elif fmt == "json" and batches:
        import json

        from ..batch import summary
        from ..report import to_json

        report = json.loads(render(summaries, fmt, top=top, sort=sort)) if summaries else None
        click.echo(to_json({"batches": [{"folder": str(d), "summary": summary(recs), "inputs": recs}
                                        for d, recs in batches], "report": report}))
    else:
        from ..report import render_markdown

        text = render(summaries, fmt, top=top, sort=sort) if summaries else ""
        click.echo((render_markdown(_batch_tables(batches)) + "\n" if batches else "") + text, nl=False)
    for p in plots:
        click.echo(f"{p}: plot written", err=True)


def _batches(paths: list[Path]) -> tuple[list[Path], list[tuple[Path, list[dict]]]]:
    """Split FILES into files and batch folders (with their manifest lines); a batch's outputs that are done
    and present join the files."""
    from ..batch import DONE, SKIPPED, read_batch

    batches = [(p, read_batch(str(p))) for p in paths if p.is_dir()]
    files = [p for p in paths if not p.is_dir()]
    for _, recs in batches:
        files += [Path(r["output"]) for r in recs if r["status"] in (DONE, SKIPPED) and Path(r["output"]).exists()]
    return files, batches


def _batch_tables(batches: list[tuple[Path, list[dict]]]) -> list:
    """The report's tables of batch folders: figures, tracks by class, failures and missing outputs."""
    from ..batch import TRACK_CLASSES, summary
    from ..report import Table

    sums = [(d, summary(recs)) for d, recs in batches]
    figures = Table("Batches (from each folder's manifest.jsonl)",
                    ["folder", "inputs", "done", "failed", "scans", "task s", "scans/s per task", "datmo",
                     "parameters"],
                    [[str(d), s["inputs"], s["done"], s["failed"], s["scans"], s["task_seconds"],
                      s["scans_per_task_second"], ", ".join(s["versions"]), ", ".join(s["params_hashes"])]
                     for d, s in sums], numeric={1, 2, 3, 4, 5, 6})
    keys = ("confirmed", *TRACK_CLASSES, "dynamic")
    tracks = Table("Confirmed tracks by class, every input of the batch",
                   ["folder", *(k.replace("_", " ") for k in keys)],
                   [[str(d), *(s["tracks"][k] for k in keys)] for d, s in sums], numeric=set(range(1, len(keys) + 1)))
    out = [figures, tracks]
    failures = [[str(d), f["input"], f["error"]] for d, s in sums for f in s["failures"]]
    if failures:
        out.append(Table("Failed inputs (run the same command again to retry them)", ["folder", "input", "error"],
                         failures))
    missing = [[str(d), m] for d, s in sums for m in s["missing_outputs"]]
    if missing:
        out.append(Table("Done in the manifest but missing", ["folder", "output"], missing))
    return out


def _batch_csv(batches: list[tuple[Path, list[dict]]]) -> str:
    """One CSV row per input of every batch: its manifest line, tracks by class flattened."""
    from ..batch import TRACK_CLASSES
    from ..report import Table, render_csv

    keys = ["input", "output", "status", "scans", "seconds", "scans_per_s", "input_sha256", "params_hash",
            "datmo_version", "error"]
    tkeys = ["confirmed", *TRACK_CLASSES, "dynamic"]
    rows = [[r.get(k) for k in keys] + [(r.get("tracks") or {}).get(k) for k in tkeys]
            for _, recs in batches for r in recs]
    return render_csv(Table("inputs", keys + tkeys, rows))
