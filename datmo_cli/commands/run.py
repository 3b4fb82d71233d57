"""`datmo run`: segment, extract features and track in one pass per input, in parallel; then the report."""

from __future__ import annotations

from pathlib import Path

import click

from ..report import FORMATS, SORT_KEYS


def _progress_bar():  # noqa: ANN202 - rich.progress.Progress, imported lazily
    from rich.console import Console
    from rich.progress import BarColumn, Progress, ProgressColumn, TextColumn, TimeRemainingColumn
    from rich.text import Text

    class Scans(ProgressColumn):
        """Scans done of the total, and the recent rate in scans/s."""

        def render(self, task) -> Text:  # noqa: ANN001 - rich's signature
            total = f"{task.total:,.0f}" if task.total is not None else "?"
            rate = f"{task.speed:,.0f} scans/s" if task.speed else "- scans/s"
            return Text(f"{task.completed:,.0f}/{total} scans  {rate}", style="progress.data.speed")

    return Progress(TextColumn("{task.description}"), BarColumn(), Scans(), TimeRemainingColumn(),
                    console=Console(stderr=True), transient=True)


@click.command(name="run")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--output-dir", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Folder for the outputs, one OUT_DIR/NAME.mcap per input (created if missing).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None,
              help="Inputs processed at once, in separate processes [default: all cores].")
@click.option("--force", is_flag=True, help="Overwrite existing outputs (and plots).")
@click.option("--config", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="TOML file of parameters: its [features] table as for datmo features, its [track] table as "
                   "for datmo track.")
@click.option("--plot", is_flag=True, help="Also draw each run from above into OUT_DIR/NAME.png.")
@click.option("--format", "fmt", type=click.Choice(FORMATS), default="rich", show_default=True,
              help="Format of the report printed at the end (see datmo report).")
@click.option("--top", type=click.IntRange(min=0), default=None, help="Tracks in the report's track table (0: all).")
@click.option("--sort", type=click.Choice(SORT_KEYS), default="lifetime", show_default=True,
              help="Order of the report's track table.")
@click.option("--no-report", is_flag=True, help="Do not print the report.")
@click.option("--ego-motion", type=click.Choice(["auto", "on", "off"]), default=None,
              help="For logs without /odom: track in poses estimated by scan matching (written to /odom, frame "
                   "scan_odom) when the scanner moves ('auto'), always ('on') or never ('off') [default: auto].")
@click.option("--leg-model", default=None, metavar="MODEL",
              help="Leg detector: 'default' (the model shipped with datmo), a model file from datmo train-legs, "
                   "or 'paper' (the paper's circle rule and walking pattern) [default: default].")
def command(inputs: tuple[Path, ...], out_dir: Path, jobs: int | None, force: bool, config: Path | None, plot: bool,
            fmt: str, top: int | None, sort: str, no_report: bool, ego_motion: str | None,
            leg_model: str | None) -> None:
    """Segment, extract features and track each input in one pass, then print the report.

    Each output holds the input's channels and /datmo/segments, /datmo/features, /datmo/landmarks,
    /datmo/tracks and markers, with the same messages as datmo segment, datmo features and datmo track
    run one after another. Several inputs run in parallel; a failing input is reported and the others'
    outputs are kept (the exit status is then 1).

    Example: datmo run sample_logs/hall.mcap sample_logs/corridor.mcap -o out --plot
    """
    from ..cli import invocation
    from ..errors import DatmoError, InputError
    from ..perception.params import FeatureParams
    from ..perception.params import load_toml as load_features
    from ..pipeline import output_paths, run_many
    from ..tracking.params import TrackingParams
    from ..tracking.params import load_toml as load_track

    inputs = list(inputs)
    params = {"features": load_features(config) if config is not None else FeatureParams(),
              "track": load_track(config) if config is not None else TrackingParams()}
    params["features"] = params["features"].replace(leg_model=leg_model)
    params["track"] = params["track"].replace(ego_motion=ego_motion)
    from ..perception.legs import load_leg_model

    load_leg_model(params["features"].leg_model)   # a bad model is one error here, not one per input
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(f"{out_dir}: exists and is not a folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    outs = output_paths(inputs, out_dir)
    plots = [o.with_suffix(".png") for o in outs] if plot else []
    if plots:
        from .report import check_plot_outputs

        check_plot_outputs(plots, force)

    _warm_up()
    with _progress_bar() as bar:
        tasks = [bar.add_task(p.name, total=None) for p in inputs]
        results = run_many(inputs, out_dir, jobs=jobs, force=force, params=params, command_line=invocation("run"),
                           progress=lambda i, done, total: bar.update(tasks[i], completed=done, total=total))
    ok = [r for r in results if r.error is None]
    for r in results:
        if r.error is None:
            rate = r.scans / r.seconds if r.seconds > 0 else float("inf")
            click.echo(f"{r.input} -> {r.output}: {r.scans:,} scans in {r.seconds:.1f} s ({rate:,.0f} scans/s)",
                       err=True)
        else:
            click.echo(f"datmo: error: {r.error}", err=True)
    if ok and (not no_report or plots):
        ok_plots = [p for p, r in zip(plots, results, strict=True) if r.error is None] if plots else []
        _report([r.output for r in ok], ok_plots, None if no_report else fmt, top, sort)
    failed = len(results) - len(ok)
    if failed == len(results) and failed > 1:
        raise DatmoError(f"all {failed} inputs failed")
    if failed and len(results) > 1:
        raise DatmoError(f"{failed} of {len(results)} inputs failed; the other outputs are complete")
    if failed:
        raise SystemExit(1)  # the one error is printed above


def _warm_up() -> None:
    """Load the numba kernels before the clock of any input starts; the first run after an install
    compiles them (tens of seconds, then cached), which is said rather than counted in the inputs' speed."""
    import time

    from ..pipeline import warm_up
    from .compiling import said_if_slow

    t0 = time.perf_counter()
    with said_if_slow():
        warm_up()
    seconds = time.perf_counter() - t0
    if seconds > 2.0:
        click.echo(f"compiled the numba kernels in {seconds:.0f} s (first run after an install; cached for the next "
                   "runs)", err=True)


def _report(outputs: list[Path], plots: list[Path], fmt: str | None, top: int | None, sort: str) -> None:
    """Draw the plots, and print the report of `outputs` in `fmt` (None: no report)."""
    from ..pipeline import read_run_data
    from ..report import console, render, summarise

    summaries = []
    for i, out in enumerate(outputs):
        data = read_run_data(out, keep_scans=bool(plots))
        summaries.append(summarise(data))
        if plots:
            from ..plot import plot_run

            plot_run(data, plots[i])
            click.echo(f"{plots[i]}: plot written", err=True)
    if fmt == "rich":
        render(summaries, fmt, top=top, sort=sort, console=console())
    elif fmt:
        click.echo(render(summaries, fmt, top=top, sort=sort), nl=False)
