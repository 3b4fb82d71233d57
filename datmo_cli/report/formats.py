"""The report printed: rich tables, GitHub markdown, CSV and JSON (`render` for any number of runs, in the
shapes tables.REPORT_SCHEMA gives)."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np

from ..base.csvsafe import neutralise
from ..base.text import markdown, printable
from .summary import RunSummary
from .tables import FILE_COLUMNS, PARAM_WIDTH, SCHEMA, TRACK_CSV_KEYS, Table, file_table, file_tables, total_row

FORMATS = ("rich", "json", "csv", "markdown")


def _cell(v: object) -> str:
    """A value as the rich and markdown tables show it (text with its control characters escaped)."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:,.2f}"
    if isinstance(v, int):
        return f"{v:,}"
    return printable(v)


def console():
    """A rich console on stdout: the terminal's width on a terminal, else a plain, unlimited width (no
    wrapping, no colour) so piped names stay whole (progress.console)."""
    from ..base.progress import console as make

    return make()


def render_rich(tabs: list[Table], console) -> None:
    """Print tables with rich. On a terminal a text cell longer than PARAM_WIDTH is cut there ("…"); piped or
    redirected, every cell is printed whole."""
    from ..base.progress import table as rich_table

    cut = not getattr(console, "datmo_plain", False)

    for t in tabs:
        rt = rich_table(console, title=t.title, title_justify="left")
        for i, c in enumerate(t.columns):
            rt.add_column(c, justify="right" if i in t.numeric else "left", overflow="fold")
        for row in t.rows:
            style = "bold" if row and row[0] == "total" else None
            rt.add_row(*(_cut(_cell(v)) if cut else _cell(v) for v in row), style=style)
        if not t.rows:
            rt.add_row(*(["(none)"] + [""] * (len(t.columns) - 1)))
        console.print(rt)


def _cut(text: str) -> str:
    return text if len(text) <= PARAM_WIDTH else text[: PARAM_WIDTH - 1] + "…"


def render_markdown(tabs: list[Table]) -> str:
    """GitHub-flavoured markdown: a heading and a pipe table per table. Text (a log's frame ids and file names
    among it) is escaped for Markdown (text.markdown): no link, image, heading or HTML tag comes from a log."""
    parts = []
    for t in tabs:
        head = "| " + " | ".join(t.columns) + " |"
        rule = "|" + "|".join("---:" if i in t.numeric else "---" for i in range(len(t.columns))) + "|"
        body = ["| " + " | ".join(markdown(_cell(v)) for v in row) + " |" for row in t.rows]
        parts.append("\n".join([f"### {markdown(t.title)}", "", head, rule, *body]))
    return "\n\n".join(parts) + "\n"


def render_csv(table: Table, keys: list[str] | None = None) -> str:
    """One table as CSV with raw (unformatted) values; header = `keys` when given, else the column titles.
    Text cells have their control characters escaped (text.printable: the CSV is often printed) and, when a
    spreadsheet would run them as a formula (`=`, `+`, `@`, or `-` not a number), an apostrophe in front
    (csvsafe.neutralise, as every CSV writer)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(keys or table.columns)
    for row in table.rows:
        w.writerow(["" if v is None else neutralise(printable(v)) if isinstance(v, str) else v for v in row])
    return buf.getvalue()


def to_json(obj: object) -> str:
    """JSON text; NaN and infinities become null."""

    def clean(o: object) -> object:
        if isinstance(o, float):
            return o if np.isfinite(o) else None
        if isinstance(o, dict):
            return {str(k): clean(v) for k, v in o.items()}
        if isinstance(o, list | tuple):
            return [clean(v) for v in o]
        if isinstance(o, Path):
            return str(o)
        if isinstance(o, np.generic):
            return clean(o.item())
        return o

    return json.dumps(clean(obj), indent=2)


def track_rows(summaries: list[RunSummary], top: int | None, sort: str) -> list[dict]:
    """The `--tracks` rows, TRACK_CSV_KEYS: every confirmed track of each file (a table for scripts, which
    filter on class and mobility themselves), ordered by `sort`, the first `top` of each file."""
    return [
        {"file": s.run["file"], **{k: t[k] for k in TRACK_CSV_KEYS[1:]}}
        for s in summaries
        for t in s.shown(top, sort, True)
    ]


def report_dict(
    summaries: list[RunSummary], *, top: int | None, sort: str, tracks: bool = False, batches: list[dict] | None = None
) -> dict:
    """The JSON report (REPORT_SCHEMA): schema, files, total, batches and, with `tracks`, tracks."""
    out = {
        "schema": SCHEMA,
        "files": [s.to_dict(top, sort) for s in summaries],
        "total": total_row([s.file_row() for s in summaries]),
        "batches": batches or [],
    }
    if tracks:
        out["tracks"] = track_rows(summaries, top, sort)
    return out


def render(
    summaries: list[RunSummary],
    fmt: str,
    *,
    top: int | None,
    sort: str,
    tracks: bool = False,
    all_tracks: bool = False,
    batches: list[dict] | None = None,
    console=None,
    before: list[Table] | None = None,
) -> str | None:
    """The report of any number of runs in `fmt` (one of FORMATS), in the shapes REPORT_SCHEMA gives.
    Returns the text, or prints to `console` (rich). `top` limits each file's track table (None: 20 for rich
    and markdown, all for json and csv); rich and markdown show the files table, then each file's tables,
    after the tables `before` (a batch folder's)."""
    if fmt == "json":
        return to_json(report_dict(summaries, top=top, sort=sort, tracks=tracks, batches=batches))
    if fmt == "csv":
        if tracks:
            rows = track_rows(summaries, top, sort)
            return render_csv(Table("tracks", TRACK_CSV_KEYS, [[r[k] for k in TRACK_CSV_KEYS] for r in rows]))
        return render_csv(file_table(summaries), list(FILE_COLUMNS))
    top = 20 if top is None else top
    tabs = list(before or []) + [file_table(summaries)]
    for s in summaries:
        tabs += file_tables(s, top, sort, all_tracks)
    if fmt == "markdown":
        return render_markdown(tabs)
    render_rich(tabs, console)
    return None
