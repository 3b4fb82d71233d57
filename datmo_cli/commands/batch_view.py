"""What `datmo run` prints of its batch (workflows.batch_run does the work): the final table and totals line on
stderr, the failures as errors, the report on stdout, and the exit status."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import click

if TYPE_CHECKING:
    from ..workflows.batch_run import BatchResult

FINAL_ROWS = 50


def report_options(f: Callable) -> Callable:
    """--format, --top, --sort and --no-report: the report printed at the end of datmo run."""
    from ..base.bounds import OPTIONS
    from ..report import FORMATS, SORT_KEYS
    from .types import option

    for decorate in reversed(
        [
            click.option(
                "--format",
                "fmt",
                type=click.Choice(FORMATS),
                default="rich",
                show_default=True,
                help="Format of the report printed at the end (see datmo report).",
            ),
            option("--top", bound=OPTIONS["top"], default=None, help="Tracks in the report's track table (0: all)."),
            click.option(
                "--sort",
                type=click.Choice(SORT_KEYS),
                default="lifetime",
                show_default=True,
                help="Order of the report's track table.",
            ),
            click.option("--no-report", is_flag=True, help="Do not print the report."),
        ]
    ):
        f = decorate(f)
    return f


def ran(result: BatchResult) -> None:
    """The batch's table and totals (final_table), then each failure as an error line (even under --quiet)."""
    from ..base.text import printable
    from ..batch import FAILED

    final_table(result.records, result.seconds, result.where)
    for r in result.records:
        if r["status"] == FAILED:
            click.echo(f"datmo: error: {printable(r['error'])}", err=True)


def plotted(line: str) -> None:
    """A plot written, said on stderr."""
    from ..base.text import printable

    click.echo(printable(line), err=True)


def exit_status(result: BatchResult) -> None:
    """Raise what ends the command after failures: DatmoError with the count for several inputs, exit 1 for
    one (its error is printed already); nothing when every input is done or skipped."""
    from ..base.errors import DatmoError

    failed, n = len(result.failed), len(result.records)
    if failed == n and failed > 1:
        raise DatmoError(f"all {failed} inputs failed")
    if failed and n > 1:
        raise DatmoError(f"{failed} of {n} inputs failed; the other outputs are complete")
    if failed:
        raise SystemExit(1)  # the one error is printed above


def final_table(records: list[dict], seconds: float, where: str) -> None:
    """The batch's table on stderr (every input up to FINAL_ROWS, then only failures) and its totals line;
    nothing under --quiet (failures are said as errors all the same)."""
    from ..base.progress import console, quiet
    from ..base.progress import table as make_table
    from ..batch import DONE, FAILED, SKIPPED

    if quiet():
        return

    done = [r for r in records if r["status"] == DONE]
    scans = sum(r["scans"] for r in done)
    shown = records if len(records) <= FINAL_ROWS else [r for r in records if r["status"] == FAILED][:FINAL_ROWS]
    if shown:
        err = console(stderr=True)
        table = make_table(err, title_justify="left")
        for col in ("input", "status", "scans", "scans/s", "tracks", "people", "output or error"):
            table.add_column(
                col, justify="right" if col in ("scans", "scans/s", "tracks", "people") else "left", overflow="fold"
            )
        for r in shown:
            t = r.get("tracks") or {}
            table.add_row(
                Path(r["input"]).name,
                r["status"],
                f"{r['scans']:,}" if r["status"] != FAILED else "",
                f"{r['scans_per_s']:,.0f}" if r["status"] == DONE else "",
                str(t.get("confirmed", "")),
                str(t.get("person", "")),
                r["error"] if r["status"] == FAILED else r["output"],
            )
        err.print(table)
    counts = {s: sum(r["status"] == s for r in records) for s in (DONE, SKIPPED, FAILED)}
    rate = scans / seconds if seconds > 0 else 0.0
    click.echo(
        f"{len(records)} input{'s' if len(records) != 1 else ''}: {counts[DONE]} done, {counts[SKIPPED]} "
        f"skipped (already in the manifest), {counts[FAILED]} failed; {scans:,} scans in {seconds:.1f} s on "
        f"{where} ({rate:,.0f} scans/s)",
        err=True,
    )


def print_report(summaries: list, fmt: str, top: int | None, sort: str) -> None:
    """The report of `summaries` (report.RunSummary) in `fmt` on stdout."""
    from ..report import console, render

    if fmt == "rich":
        render(summaries, fmt, top=top, sort=sort, console=console())
    elif fmt:
        click.echo(render(summaries, fmt, top=top, sort=sort), nl=False)


def report(
    outputs: list[Path],
    plots: list[Path],
    fmt: str | None,
    top: int | None,
    sort: str,
    force: bool = False,
    made: list | None = None,
) -> None:
    """Draw the plots (`plots[i]` of `outputs[i]`), and print the report of `outputs` in `fmt` (None: no
    report), as datmo run does at its end (workflows.batch_run.gather_report, then print_report)."""
    from ..workflows.batch_run import gather_report

    summaries, _ = gather_report(outputs, list(plots), fmt is not None, force, made, plotted)
    if fmt and summaries is not None:
        print_report(summaries, fmt, top, sort)
