"""`datmo tune`: search a space of parameters for the setting that scores best against ground truth."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..base.bounds import OPTIONS
from .options import config_options, executor_options, force_option, no_stdout, output_option, quiet_option
from .types import option

if TYPE_CHECKING:
    from ..passes.config import DatmoConfig


@click.command(name="tune")
@click.argument("logs", nargs=-1, required=True, type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--space",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="TOML file of the parameters to tune: [track] person_maintain = [0.05, 0.3] (a range), "
    '[features] leg_model = ["default", "paper"] (choices); see docs/tune.md.',
)
@output_option(
    "Folder for trials.parquet, best.toml, tune.png and manifest.jsonl (the ledger a rerun continues from).",
    "-o",
    "--output-dir",
    "out_dir",
    file=False,
    callback=no_stdout("outputs", "a folder"),
)
@click.option(
    "--objective",
    default="hota",
    show_default=True,
    help="The figure to optimise, averaged over the logs: a figure datmo evaluate prints (hota, mota, idf1, "
    "motp, num_switches, ...), of one class (people_mota, people_idf1, circle_hota, rect_mota) or a rate "
    "(false_people_s, false_positives_s, switches_s: per second of log).",
)
@click.option(
    "--max",
    "maxima",
    multiple=True,
    metavar="NAME=VALUE",
    help="A constraint: the figure's mean over the logs must be at most VALUE (e.g. false_people_s=1). Repeatable.",
)
@click.option(
    "--min",
    "minima",
    multiple=True,
    metavar="NAME=VALUE",
    help="A constraint: the figure's mean over the logs must be at least VALUE (e.g. mota=0.8). Repeatable.",
)
@option("--trials", bound=OPTIONS["trials"], default=24, show_default=True, help="Settings tried, the start included.")
@option("--seed", bound=OPTIONS["seed"], default=0, show_default=True, help="Seed of the Sobol samples.")
@click.option("--cv", is_flag=True, help="Also tune leaving each log out in turn, and score the best on it.")
@executor_options("Evaluations run", "an evaluation", "the evaluations")
@force_option("Redo every evaluation and replace the outputs of another tune in the folder.")
@config_options("TOML file of parameters to start from (trial 0; the space's keys are tuned from there).")
@click.option("--plot", is_flag=True, help="Also draw DIR/tune.png (needs the plot extra, matplotlib).")
@option("--top", bound=OPTIONS["top"], default=10, show_default=True, help="Trials in the table (0: all).")
@quiet_option
def command(
    logs: tuple[Path, ...],
    space: Path,
    out_dir: Path,
    objective: str,
    maxima: tuple[str, ...],
    minima: tuple[str, ...],
    trials: int,
    seed: int,
    cv: bool,
    jobs: int | None,
    scheduler: str | None,
    retries: int,
    force: bool,
    cfg: DatmoConfig,
    plot: bool,
    top: int,
) -> None:
    """Find the setting of the parameters in --space that scores best on LOGS against their ground truth.

    LOGS are logs with ground truth: a /datmo/ground_truth channel (datmo simulate) or a CSV beside the log,
    NAME.gt.csv (stamp_ns,id,x,y as datmo evaluate --gt reads). Trial 0 is the start (the defaults or
    --config), the others quasi-random settings of the space (Sobol, --seed). Each trial is scored as datmo
    run and datmo evaluate score it; successive halving scores every trial on the first third of each log
    and the best third on the whole logs. Every evaluation is a batch task (local processes or --scheduler)
    kept in DIR/manifest.jsonl: run the same command again after Ctrl-C to continue; a finished tune prints
    its result again. Writes DIR/trials.parquet (needs pyarrow) and DIR/best.toml (use it as --config).

    Example: datmo tune sample_logs/hall.mcap sample_logs/corridor.mcap --space space.toml -o tuned --trials 12
    """
    import time

    from .. import api
    from ..base.progress import bar, console, quiet
    from ..report import render_rich
    from ..tune.results import tables

    t0 = time.perf_counter()
    with bar("tune", None, unit="evaluations", info=True) as b:
        result = api.tune(
            list(logs),
            space,
            out_dir,
            config=cfg,
            objective=objective,
            maxima=maxima,
            minima=minima,
            trials=trials,
            seed=seed,
            cv=cv,
            jobs=jobs,
            scheduler=scheduler,
            retries=retries,
            force=force,
            plot=plot,
            progress=lambda done, total, what: b.update(done, total, info=what),
        )
    render_rich(tables(result, top or len(result.trials)), console())
    s, start = result.best_score, result.start_score
    click.echo(
        f"best: trial {result.best.index}, {objective} {s.value!r} on the whole logs (start: {start.value!r}); "
        + ", ".join(str(p) for p in result.outputs)
    )
    if not quiet():
        click.echo(
            f"{result.ran} evaluations run, {result.reused} reused from {Path(out_dir) / 'manifest.jsonl'}, "
            f"in {time.perf_counter() - t0:.1f} s",
            err=True,
        )
