"""`datmo report`: the per-run classification summary of processed logs."""

from __future__ import annotations

from pathlib import Path

import click

from ..report import FORMATS, SORT_KEYS

PLOT_SUFFIXES = (".png", ".svg", ".pdf")


def plot_paths(plot: Path, files: list[Path]) -> list[Path]:
    """Where each file's plot goes: `plot` itself for one file, else PLOT-STEM.SUFFIX per file."""
    if len(files) == 1:
        return [plot]
    return [plot.with_name(f"{plot.stem}-{f.stem}{plot.suffix}") for f in files]


def check_plot_outputs(paths: list[Path], force: bool) -> None:
    """Refuse a bad plot suffix, a missing folder or an existing plot without --force, before any work."""
    from ..errors import InputError, OutputExistsError

    for p in paths:
        if p.suffix.lower() not in PLOT_SUFFIXES:
            raise InputError(f"{p}: plot format must be one of {', '.join(PLOT_SUFFIXES)}")
        if not (p.parent if str(p.parent) else Path(".")).is_dir():
            raise InputError(f"{p.parent}: output folder does not exist")
        if p.exists() and not force:
            raise OutputExistsError(f"{p}: exists; use --force to overwrite it")


@click.command(name="report")
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--format", "fmt", type=click.Choice(FORMATS), default="rich", show_default=True,
              help="rich tables for a terminal; json, csv or markdown for scripts and CI.")
@click.option("--top", type=click.IntRange(min=0), default=None,
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

    Example: datmo report out/hall.mcap --plot out/hall.png
    """
    from ..pipeline import read_run_data
    from ..report import render, summarise

    files = list(files)
    plots = plot_paths(plot, files) if plot else []
    check_plot_outputs(plots, force)
    summaries = []
    for i, path in enumerate(files):
        data = read_run_data(path, keep_scans=bool(plot))
        summaries.append(summarise(data))
        if plot:
            from ..plot import plot_run

            plot_run(data, plots[i])
    if fmt == "rich":
        from ..report import console

        render(summaries, fmt, top=top, sort=sort, console=console())
    else:
        click.echo(render(summaries, fmt, top=top, sort=sort), nl=False)
    for p in plots:
        click.echo(f"{p}: plot written", err=True)
