"""`datmo report`'s work as a call (datmo_cli.api.report): the summaries of processed logs and of `datmo run`
batch folders, and their plots; the command renders them (commands/report.py)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from ..report import RunSummary


@dataclass
class ReportResult:
    """`summaries`: the report of each file (report.RunSummary: run facts, features, landmarks, tracks), in
    the order of `files`; `files`: the logs reported, those given then the outputs of the batch folders;
    `batches`: each batch folder with its manifest lines; `written`: a line per plot drawn."""

    summaries: list[RunSummary] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    batches: list[tuple[Path, list[dict]]] = field(default_factory=list)
    written: list[str] = field(default_factory=list)


def report_files(
    paths: Sequence[str | os.PathLike],
    *,
    plot: str | os.PathLike | None = None,
    plot_kind: str = "auto",
    all_tracks: bool = False,
    force: bool = False,
) -> ReportResult:
    """`datmo report FILES`: the report of processed logs (outputs of `datmo track` or `datmo run`), each read
    in one streaming pass; a folder is a `datmo run` batch whose outputs that are done join the files and
    whose manifest gives the batch's figures. `plot`: also draw each run into this .png/.svg/.pdf (several
    files: PLOT-STEM.png each; needs matplotlib), `plot_kind` auto, top, counts, speeds or all, labelling
    every track with `all_tracks`; an existing plot needs `force`. A progress bar on stderr in a terminal."""
    from ..base.progress import bar
    from ..passes.pipeline import read_run_data
    from ..report import summarise, summarise_file
    from ..report.plot_files import check_plot_outputs, plot_paths, save_plot

    files, batches = batch_folders([Path(p) for p in paths])
    plots = plot_paths(Path(plot), files) if plot else []
    check_plot_outputs(plots, force)
    counts = scan_counts(files)
    result = ReportResult(files=files, batches=batches)
    with bar("report", sum(counts)) as progress:
        done = 0
        for i, path in enumerate(files):
            if plot:  # the plot draws every scan and state, so it decodes the whole run
                data = read_run_data(path, keep_scans=True)
                result.summaries.append(summarise(data))
                result.written.append(save_plot(data, plots[i], force, plot_kind, all_tracks))
            else:  # one streaming pass

                def advance(n: int, d: int = done) -> None:
                    progress.update(d + n)

                result.summaries.append(summarise_file(path, progress=advance))
            done += counts[i]
            progress.update(done)
    return result


def scan_counts(files: list[Path]) -> list[int]:
    """Scans on /scan of each file, from its summary (the progress bar's total)."""
    from ..logs import mcapio

    counts = []
    for f in files:
        ch = mcapio.summary(f).topics().get(mcapio.TOPIC_SCAN)
        counts.append(ch.count if ch is not None else 0)
    return counts


def batch_folders(paths: list[Path]) -> tuple[list[Path], list[tuple[Path, list[dict]]]]:
    """Split FILES into files and batch folders (with their manifest lines, batch.read_batch: only outputs
    under the folder, each once); a batch's outputs that are done and present join the files."""
    from ..base.progress import say
    from ..batch import DONE, SKIPPED, read_batch

    batches: list[tuple[Path, list[dict]]] = []
    for p in paths:
        if p.is_dir():
            recs, left_out = cast(tuple[list[dict], int], read_batch(str(p), with_left_out=True))
            if left_out:
                say(
                    f"datmo: warning: {p}: {left_out} manifest line{'s' if left_out > 1 else ''} left out (an output "
                    "outside the folder, or one another line already names)"
                )
            batches.append((p, recs))
    files = [p for p in paths if not p.is_dir()]
    for _, recs in batches:
        files += [Path(r["output"]) for r in recs if r["status"] in (DONE, SKIPPED) and Path(r["output"]).exists()]
    return files, batches
