"""`datmo run`'s batch as a call (datmo_cli.api.run_batch): segment, extract features and track each input in
one pass, in parallel, resumed by the output folder's manifest; then the plots and the report of every output.

The command is its options, `run_batch` and what it prints (commands/batch_view.py); a script gets the same
outputs, manifest lines and report summaries in a BatchResult.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from . import as_config

if TYPE_CHECKING:
    from ..batch import Batch
    from ..passes.config import DatmoConfig
    from ..report import RunSummary
    from . import Config


@dataclass
class BatchResult:
    """What a batch did. `records`: each input's manifest line (dicts: input, output, status done, skipped,
    failed or cancelled, scans, tracks by class, error, ...; a done line also carries its report under
    batch.SUMMARY_KEY), in the order they finished; `where`: the executor ("4 local processes", a scheduler);
    `seconds`: the batch's wall time; `summaries`: the report (report.RunSummary) of each output done or
    skipped, in the order of `ok` (None when the report was not asked and no plot drawn, or the folder is
    remote); `plots`: the plots drawn."""

    out_dir: str
    records: list[dict] = field(default_factory=list)
    where: str = ""
    seconds: float = 0.0
    summaries: list[RunSummary] | None = None
    plots: list[Path] = field(default_factory=list)

    @property
    def ok(self) -> list[dict]:
        """The lines of the inputs done or skipped (already in the manifest)."""
        from ..batch import DONE, SKIPPED

        return [r for r in self.records if r["status"] in (DONE, SKIPPED)]

    @property
    def failed(self) -> list[dict]:
        """The lines of the inputs that failed or were cancelled."""
        from ..batch import DONE, SKIPPED

        return [r for r in self.records if r["status"] not in (DONE, SKIPPED)]


def run_batch(
    inputs: Sequence[str | os.PathLike],
    out_dir: str | os.PathLike,
    *,
    config: Config = None,
    markers: bool = False,
    covariance: bool = False,
    topic: str | None = None,
    odom_topic: str | None = None,
    bag_dir: bool = False,
    force: bool = False,
    jobs: int | None = None,
    scheduler: str | None = None,
    retries: int = 2,
    threads: int | None = None,
    plot: bool = False,
    report: bool = True,
    on_record: Callable[[dict], None] | None = None,
    on_scans: Callable[[int, int, int], None] | None = None,
    on_ran: Callable[[BatchResult], None] | None = None,
    on_plot: Callable[[str], None] | None = None,
    command_line: str | None = None,
) -> BatchResult:
    """`datmo run INPUTS -o OUT_DIR`: each input (files, folders searched for .mcap logs, globs, fsspec URLs,
    bags converted by their own task) into OUT_DIR/NAME.mcap, OUT_DIR/manifest.jsonl one line per input.
    Inputs the manifest lists as done with the same input and parameters are skipped (resume) unless `force`.

    `config`: a DatmoConfig, a TOML file, a dict of overrides or None (the defaults); `markers`, `covariance`,
    `topic`, `odom_topic`, `bag_dir`: as the options of `datmo run`. Executor: `jobs` local processes (None:
    all cores) or a Dask `scheduler` (tcp://host:8786, local[:N]) retrying a task `retries` times; `threads`
    for each input's perception (None: all cores; results do not depend on it). `plot`: also OUT_DIR/NAME.png
    (local folders); `report`: gather each output's report (BatchResult.summaries).

    Callbacks: `on_record(line)` as each input finishes, `on_scans(index, done, total)` as its scans go by,
    `on_ran(result)` once every input has run (before the plots and the report), `on_plot(line)` as each plot
    is written. A progress bar is drawn on stderr in a terminal (not under --quiet). Options that do not go
    together raise DatmoError before any input starts; a failing input does not raise: see
    BatchResult.failed. `command_line` goes into each output's provenance."""
    from ..batch import RunOptions, folder_lock, remote
    from ..perception.threads import set_default

    out = os.fsdecode(out_dir)
    set_default(threads)  # a run-time setting: not among the parameters (the outputs do not depend on it)
    check_options(out, scheduler, jobs, plot, bag_dir)
    cfg = as_config(config)
    _check_leg_model(cfg)
    options = RunOptions(markers=markers, covariance=covariance, topic=topic, odom_topic=odom_topic, bag_dir=bag_dir)
    if command_line is None:
        command_line = f"datmo_cli.api.run_batch({[os.fsdecode(i) for i in inputs]!r}, {out!r})"
    result = BatchResult(out)
    with folder_lock(out):  # one batch at a time in a folder: a second is refused, naming the first
        batch = _prepare(inputs, out, cfg, options, force, threads, command_line)
        plot_of = _plots(batch, force, bag_dir) if plot else {}
        executor = _executor(batch, scheduler, jobs, retries)
        t0 = time.perf_counter()
        try:
            with BatchProgress(batch) as bar:
                result.records = _run(batch, executor, bar, on_record, on_scans)
        finally:
            executor.close()
        result.where, result.seconds = executor.where, time.perf_counter() - t0
        if on_ran is not None:
            on_ran(result)
        ok = result.ok
        if ok and (report or plot_of) and not remote(out):
            from ..batch import DONE, SUMMARY_KEY

            made = {Path(r["output"]) for r in ok if r["status"] == DONE}
            plots = {Path(o): p for o, p in plot_of.items() if Path(o) in made}
            outputs = [Path(r["output"]) for r in ok]
            result.summaries, result.plots = gather_report(
                outputs, [plots.get(o) for o in outputs], report, force, [r.get(SUMMARY_KEY) for r in ok], on_plot
            )
    return result


def _prepare(inputs, out_dir: str, cfg: DatmoConfig, options, force: bool, threads, command_line: str) -> Batch:
    from ..batch import prepare
    from ..passes.config import provenance_line

    return prepare(
        [os.fsdecode(i) for i in inputs],
        out_dir,
        config=cfg,
        options=options,
        force=force,
        command_line=provenance_line(command_line),
        threads=threads,
    )


def _plots(batch: Batch, force: bool, bag_dir: bool) -> dict[str, Path]:
    """Each output's plot path (checked: an existing plot needs `force`)."""
    from ..logs import bagdir
    from ..report.plot_files import check_plot_outputs

    plot_of = {
        t.output: bagdir.plot_path(t.output) if bag_dir else Path(t.output).with_suffix(".png") for t in batch.tasks
    }
    if plot_of:
        check_plot_outputs(list(plot_of.values()), force)
    return plot_of


def _executor(batch: Batch, scheduler: str | None, jobs: int | None, retries: int):
    """The executor of the batch: a Dask one on `scheduler`, else `jobs` local processes (the kernels warmed up
    first when there is a pool)."""
    from ..batch import LocalExecutor

    if scheduler is not None and batch.tasks:
        from ..batch.cluster import DaskExecutor

        return DaskExecutor(scheduler, retries=retries)
    executor = LocalExecutor(jobs)
    if batch.tasks and min(executor.workers, len(batch.tasks)) > 1:  # a pool: warmed once before the workers fork
        from ..base.numba_runtime import cache_looks_stale, say_compiling
        from ..base.progress import bar, say
        from ..passes.warm import warm_up

        # the first run after an install compiles the kernels (minutes, then cached): said at once (terminal or
        # not), with a progress bar in a terminal, rather than counted in the inputs' speed
        t0 = time.perf_counter()
        compiled = cache_looks_stale()  # before anything is compiled
        say_compiling()  # said once a process (the command line's first step has said it)
        with bar(f"{'compiling' if compiled else 'loading'} the numba kernels", None, unit="steps") as b:
            warm_up(b.update)
        seconds = time.perf_counter() - t0
        if compiled or seconds > 2.0:
            say(f"compiled the numba kernels in {seconds:.0f} s (first run after an install; cached for the next runs)")
    # else one process compiles or loads just the kernels it runs (the line saying so came first)
    return executor


def _run(batch: Batch, executor, bar: BatchProgress, on_record, on_scans) -> list[dict]:
    from ..batch import run_many

    def record(rec: dict) -> None:
        bar.record(rec)
        if on_record is not None:
            on_record(rec)

    def scans(index: int, done: int, total: int) -> None:
        bar.progress(index, done, total)
        if on_scans is not None:
            on_scans(index, done, total)

    return run_many(batch, executor, on_record=record, on_scans=scans)


def check_options(out_dir: str, scheduler: str | None, jobs: int | None, plot: bool, bag_dir: bool) -> None:
    """Options that do not go together are one error, before any input starts."""
    from ..base.errors import DatmoError
    from ..batch import remote

    if scheduler is not None and jobs is not None:
        raise DatmoError("--jobs is for local runs; with --scheduler the cluster's workers run the inputs")
    if plot and remote(out_dir):
        raise DatmoError(f"{out_dir}: --plot needs a local output folder")
    if bag_dir and remote(out_dir):
        raise DatmoError(f"{out_dir}: --bag-dir needs a local output folder")


def _check_leg_model(cfg: DatmoConfig) -> None:
    """A leg model that does not load is one error, before any input starts."""
    from ..perception.leg_model import load_leg_model

    load_leg_model(cfg.features.leg_model)


def gather_report(
    outputs: list[Path],
    plots: list[Path | None],
    report: bool = True,
    force: bool = False,
    made: list | None = None,
    on_plot: Callable[[str], None] | None = None,
) -> tuple[list[RunSummary] | None, list[Path]]:
    """Draw the plots (`plots[i]` of `outputs[i]`; None: none) and gather the report of `outputs` (with
    `report`, or where a plot decodes the run anyway): (the summaries, None when neither; the plots drawn).
    `made`: each output's report as its task gathered it while writing it (report.RunSummary), None for an
    output not made by this run (skipped: already in the manifest), which is read in one streaming pass.
    `on_plot(line)` as each plot is written."""
    from ..passes.pipeline import read_run_data
    from ..report import summarise, summarise_file

    summaries: list[RunSummary] = []
    drawn: list[Path] = []
    made = made or [None] * len(outputs)
    for i, out in enumerate(outputs):
        where = plots[i] if i < len(plots) else None
        if where is None:  # a plot draws every scan and state, so it decodes the whole run
            if report:
                summaries.append(made[i] if made[i] is not None else summarise_file(out))
            continue
        from ..report.plot_files import save_plot

        data = read_run_data(out, keep_scans=True)
        summaries.append(made[i] if made[i] is not None else summarise(data))
        line = save_plot(data, where, force)
        drawn.append(where)
        if on_plot is not None:
            on_plot(line)
    return (summaries if report or drawn else None), drawn


def _scan_count(spec: str) -> int | None:
    """The scans of a local log from its summary (no payloads read), or None (remote, unreadable: the
    task itself says what is wrong)."""
    from ..batch import local, remote
    from ..logs import mcapio

    if remote(spec):
        return None
    try:
        return mcapio.summary(local(spec), warn=False).topics()[mcapio.TOPIC_SCAN].count or None  # the task warns
    except Exception:  # only an estimate for the bar
        return None


class BatchProgress:
    """One progress bar over the batch's scans on stderr, each scan counted once (all stages run in one pass
    over it), across every worker; beside it the inputs done of all, scans/s and failures. The total is the
    scans of the inputs to run, from their summaries; an input whose count is not known up front adds it
    when it starts, and a failed one its scans done."""

    def __init__(self, batch: Batch) -> None:
        from ..base.progress import bar

        self.t0 = time.perf_counter()
        self.n_inputs = batch.total
        self.index = {t.input: t.index for t in batch.tasks}
        self.totals: dict[int, int | None] = {t.index: _scan_count(t.input) for t in batch.tasks}
        self.running: dict[int, int] = {}
        self.scans = self.failed = self.inputs = 0
        self._bar = bar("run", self._total(), info=True)

    def _total(self) -> int | None:
        return sum(n for n in self.totals.values() if n is not None) or None

    def __enter__(self) -> BatchProgress:
        self.bar: Any = self._bar.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._bar.__exit__(*exc)

    def _show(self) -> None:
        scans = self.scans + sum(self.running.values())
        rate = scans / max(time.perf_counter() - self.t0, 1e-9)
        info = f"inputs {self.inputs}/{self.n_inputs}  {rate:,.0f} scans/s" + (
            f"  {self.failed} failed" if self.failed else ""
        )
        self.bar.update(scans, self._total(), info=info)

    def record(self, rec: dict) -> None:
        from ..batch import DONE, FAILED

        if rec["status"] == DONE:
            for line in rec.get("notes") or ():
                self.bar.tell(line)
        i = self.index.get(rec["input"], -1)
        done = self.running.pop(i, 0)
        if rec["status"] == DONE:
            self.scans += rec["scans"]
            self.totals[i] = rec["scans"]
        elif i in self.totals:  # failed or cancelled: what it did is all it will do
            self.scans += done
            self.totals[i] = done
        self.inputs += 1
        self.failed += rec["status"] == FAILED
        self._show()

    def progress(self, index: int, done: int, total: int) -> None:
        self.running[index] = done
        self.totals[index] = total
        self._show()
