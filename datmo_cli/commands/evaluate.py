"""`datmo evaluate`: CLEAR-MOT, identity and HOTA scores of a tracked log against ground truth."""

from __future__ import annotations

from pathlib import Path

import click

from ..base.bounds import OPTIONS
from .types import option, quiet_option

COLUMNS = {
    "mota": "MOTA",
    "motp": "MOTP m",
    "idf1": "IDF1",
    "hota": "HOTA",
    "deta": "DetA",
    "assa": "AssA",
    "loca": "LocA",
    "num_objects": "objects",
    "num_matches": "matches",
    "num_false_positives": "false pos.",
    "num_misses": "misses",
    "num_switches": "ID switches",
    "precision": "precision",
    "recall": "recall",
    "mostly_tracked": "mostly tracked",
    "mostly_lost": "mostly lost",
    "num_unique_objects": "objects (unique)",
    "ignored_hypotheses": "ignored tracks",
}


def score_file(path: Path, **kwargs) -> dict:
    """evaluate.files.score_file: `path` read and scored (imported on use, so the module loads without numpy)."""
    from ..evaluate.files import score_file as score

    return score(path, **kwargs)


def _table(result: dict, by_metric: bool = False):
    """The scores as a table: one row per class, or (by_metric, narrow enough for a terminal) per metric."""
    from ..report import Table

    scores = result["scores"]
    title = (
        f"{result['file']} against {result['ground_truth']} "
        f"(match radius {result['match_radius_m']:g} m, {scores['all']['num_frames']:,} frames)"
    )

    def value(v: object) -> object:
        return f"{v:.3f}" if isinstance(v, float) else v

    if by_metric:
        rows = [[label] + [value(s.get(k)) for s in scores.values()] for k, label in COLUMNS.items()]
        return Table(title, ["metric"] + list(scores), rows, set(range(1, len(scores) + 1)))
    rows = [[name] + [value(s.get(k)) for k in COLUMNS] for name, s in scores.items()]
    return Table(title, ["class"] + list(COLUMNS.values()), rows, set(range(1, len(COLUMNS) + 1)))


def csv_text(result: dict) -> str:
    """The scores as CSV with raw values: one row per class ("all" first), a column per figure (the keys
    of the JSON's scores; ignored_hypotheses and frames_without_tracks only on the "all" row)."""
    from ..report import Table, render_csv

    scores = result["scores"]
    keys = list(scores["all"])
    rows = [[name] + [s.get(k) for k in keys] for name, s in scores.items()]
    return render_csv(Table("scores", [], rows), ["class"] + keys)


def _gate(file: Path, scores: dict, name: str, key: str, minimum: float | None) -> str | None:
    """The failure of a --min-NAME gate, or None when it passes (or was not asked)."""
    value = scores["all"][key]
    if minimum is None or (value is not None and value >= minimum):
        return None
    shown = "undefined" if value is None else f"{value:.3f}"
    return f"{name} {shown} is below --min-{key} {minimum:g}"


@click.command(name="evaluate")
@click.argument("file", type=click.Path(path_type=Path))
@click.option(
    "--gt",
    "gt_csv",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Ground truth as CSV (stamp_ns,id,x,y in the sensor frame, metres; optional class column) "
    "instead of the log's /datmo/ground_truth channel.",
)
@option(
    "--match-radius",
    bound=OPTIONS["match_radius"],
    default=0.5,
    show_default=True,
    help="Largest distance, metres, at which a track can match a ground-truth object.",
)
@click.option(
    "--include-occluded", is_flag=True, help="Also score movers no beam hits, with coasting tracks as hypotheses."
)
@click.option("--exclude-static", is_flag=True, help="Do not count tracks the tracker classifies static.")
@click.option(
    "--format",
    "fmt",
    type=click.Choice(["rich", "json", "csv", "markdown"]),
    default="rich",
    show_default=True,
    help="rich tables for a terminal; json, csv (a row per class) or markdown for scripts and CI.",
)
@option(
    "--min-mota",
    bound=OPTIONS["min_mota"],
    default=None,
    help="Exit with status 1 when the overall MOTA is below this (for CI).",
)
@option(
    "--min-hota",
    bound=OPTIONS["min_hota"],
    default=None,
    help="Exit with status 1 when the overall HOTA is below this (for CI).",
)
@quiet_option
def command(
    file: Path,
    gt_csv: Path | None,
    match_radius: float,
    include_occluded: bool,
    exclude_static: bool,
    fmt: str,
    min_mota: float | None,
    min_hota: float | None,
) -> None:
    """Score FILE's tracks against ground truth: MOTA, MOTP, IDF1, false positives, misses and identity
    switches (py-motmetrics), and HOTA with DetA, AssA and LocA (TrackEval), overall and per class.

    Targets are the ground-truth people, circle and rectangular objects that move during the run, in the
    scans where the scanner hits them; hypotheses are confirmed tracks; a track matches a target within
    --match-radius metres in the sensor frame. Tracks on scene structure, on objects that never move or
    on hidden targets are ignored (neither matches nor false positives). MOTP is the mean distance of
    matches, in metres. HOTA's similarity of a track and a target d metres apart is 1 - d / --match-radius
    (0 beyond it); HOTA, DetA, AssA and LocA are means over the thresholds 0.05 to 0.95.

    Needs the eval extra (motmetrics, TrackEval and scipy).

    Example: datmo evaluate out/hall.mcap --format json --min-mota 0.6 --min-hota 0.4
    """
    from .. import api
    from ..base.errors import DatmoError
    from ..base.progress import bar, console
    from ..evaluate import require_scoring
    from ..report import render_markdown, render_rich, to_json

    require_scoring()  # before the bar: a missing eval extra is one line
    with bar("scoring", None, unit="frames", info=True) as b:
        b.update(0, info="reading")
        result = api.evaluate(
            file,
            gt_csv=gt_csv,
            match_radius=match_radius,
            include_occluded=include_occluded,
            exclude_static=exclude_static,
            progress=lambda done, total, stage: b.update(done, total, info=stage),
        )
    if fmt == "json":
        click.echo(to_json(result))
    elif fmt == "csv":
        click.echo(csv_text(result), nl=False)
    elif fmt == "markdown":
        click.echo(render_markdown([_table(result)]), nl=False)
    else:
        render_rich([_table(result, by_metric=True)], console())
    failed = [
        g
        for g in (
            _gate(file, result["scores"], "MOTA", "mota", min_mota),
            _gate(file, result["scores"], "HOTA", "hota", min_hota),
        )
        if g
    ]
    if failed:
        raise DatmoError(f"{file}: {'; '.join(failed)}")
