"""`datmo train-legs`: train the learned leg detector on labelled and empty recordings, with held-out figures: the
options, one call of datmo_cli.api.train_legs (workflows.training) and what it prints."""

from __future__ import annotations

from pathlib import Path

import click

from ..workflows.training import LABELS_TOPIC
from .options import force_option, no_stdout, output_option, quiet_option

_MANY = ("--positive", "--negative")


class _ManyFilesCommand(click.Command):
    """Lets `--positive A B C` stand for `--positive A --positive B --positive C` (shell globs work): the
    words after --positive or --negative up to the next option are its files."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        out: list[str] = []
        current, pending = None, False
        for a in args:
            if a in _MANY or (a.startswith("-") and a != "-"):
                if pending:
                    raise click.UsageError(f"{current} needs at least one file", ctx)
                current, pending = (a, True) if a in _MANY else (None, False)
                if current is None:
                    out.append(a)
                continue
            if current is not None:
                out.append(current)
                pending = False
            out.append(a)
        if pending:
            raise click.UsageError(f"{current} needs at least one file", ctx)
        return super().parse_args(ctx, out)


def _fmt(v: float | None, digits: int = 3) -> str:
    return "n/a" if v is None or v != v else f"{v:.{digits}f}"


def print_figures(held_out: list, mean: dict, console) -> None:
    """The held-out figures as a rich table: learned detector beside the paper's circle rule."""
    from ..base.progress import table as make_table

    table = make_table(
        console, title="Held-out figures (clusters within 5 m; learned | circle rule)", title_justify="left"
    )
    for col in ("held out", "empty scanner", "threshold", "precision", "recall", "AP", "false legs / empty scan"):
        table.add_column(col, justify="left" if col in ("held out", "empty scanner") else "right")

    def pair(a: float | None, b: float | None, digits: int = 3) -> str:
        return f"{_fmt(a, digits)} | {_fmt(b, digits)}"

    for h in held_out:
        L, C = h.learned, h.circle
        table.add_row(
            h.labelled,
            h.empty or "-",
            f"{h.threshold:.2f}",
            pair(L.precision, C.precision),
            pair(L.recall, C.recall),
            pair(L.ap, C.ap),
            pair(L.false_per_scan, C.false_per_scan, 2),
        )
    L, C = mean["learned"], mean["circle"]
    table.add_row(
        "mean",
        "",
        f"{mean['threshold']:.2f}",
        pair(L["precision"], C["precision"]),
        pair(L["recall"], C["recall"]),
        pair(L["ap"], C["ap"]),
        pair(L.get("false_per_scan"), C.get("false_per_scan"), 2),
        style="bold",
    )
    console.print(table)


@click.command(name="train-legs", cls=_ManyFilesCommand)
@click.option(
    "--positive",
    "positives",
    multiple=True,
    type=click.Path(path_type=Path),
    metavar="FILE...",
    help="Labelled files: ROS 1 bags, ROS 2 bag folders or MCAP files with LaserScans and a "
    "geometry_msgs/PoseArray of the legs in each scan (laser frame).",
)
@click.option(
    "--negative",
    "negatives",
    multiple=True,
    type=click.Path(path_type=Path),
    metavar="FILE...",
    help="Files of rooms with no people: every LaserScan topic is one empty recording.",
)
@click.option("--topic", default=None, help="The LaserScan topic of the labelled files [default: the only one].")
@click.option(
    "--labels-topic",
    default=LABELS_TOPIC,
    show_default=True,
    help="The geometry_msgs/PoseArray topic of the labelled legs.",
)
@output_option("The model to write (.npz).", callback=no_stdout("a model"))
@force_option()
@click.option(
    "--with-simulated",
    is_flag=True,
    help="Also train on simulated LMS200 recordings with exact leg positions (datmo's simulator; never "
    "held out): for scanners like the LMS200 (0.5°-1° steps, legs to 8 m). The shipped model uses it.",
)
@quiet_option
def command(
    positives: tuple[Path, ...],
    negatives: tuple[Path, ...],
    topic: str | None,
    labels_topic: str,
    output: Path,
    force: bool,
    with_simulated: bool,
) -> None:
    """Train the learned leg detector (a tree ensemble over per-segment shape features) and estimate how it
    does on recordings it has not seen.

    Each scan is segmented as datmo does; a segment is a leg when a labelled leg lies within 0.15 m of its
    centroid; every segment of a --negative file is not a leg. Held-out figures: each --positive file is
    held out in turn with one empty recording (cycling), the model is trained on the others, its threshold
    tuned on them alone, and precision, recall and average precision per cluster within 5 m, and false legs
    per empty scan, are printed beside the paper's circle rule. Then the model is trained on everything and
    written with its provenance (data files and SHA-256, parameters, threshold, figures). With a single
    --positive file there are no held-out figures: the model is trained and written all the same. Needs
    scikit-learn: pip install 'datmo-cli[train]'.

    \b
    Example: datmo train-legs --positive ../shared/data/legtracker/positive_*.bag \\
        --negative ../shared/data/legtracker/negative_2.bag -o legs.npz
    """
    from .. import api
    from ..base.progress import console, say

    def figures(result) -> None:
        if result.held_out:
            print_figures(result.held_out, result.mean, console())
        else:
            say(
                "datmo: no held-out figures: they need two or more --positive files (one is held out while "
                "the others train)"
            )

    trained = api.train_legs(
        positives,
        negatives,
        output,
        topic=topic,
        labels_topic=labels_topic,
        force=force,
        with_simulated=with_simulated,
        on_trained=figures,
    )
    say(trained.summary)
